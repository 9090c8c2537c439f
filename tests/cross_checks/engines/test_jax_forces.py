"""cross_checks.engines.jax_forces: the loop's harness forces evaluated inside compiled JAX code are the
host's (Harness.wrench: the compiled definition, the decay factors, the weight taken off), bit for bit, for
every kind of force, compiled alone and inside a vmapped loop whose other arithmetic XLA fuses with them."""
import importlib.util
from pathlib import Path

import numpy as np
import pytest

# never import JAX at collection (a later test forks sweeps): it starts in the tests that need it
if importlib.util.find_spec("jax") is None:
    pytest.skip("jax is not installed (pip install -e '.[mjx]')", allow_module_level=True)

from cross_checks.engines import jax_forces  # noqa: E402
from cross_checks.engines.loop import Harness  # noqa: E402
from cross_checks.scenario import load_scenario  # noqa: E402
from cross_checks.scenario.parse import catalog_names  # noqa: E402
from tests.helpers.scenarios import scenario_from_parts  # noqa: E402

#: the snapshot's extras with every force kind (benchmarks/bit_identity/skew.toml and skew2.toml)
EXTRAS = sorted((Path(__file__).resolve().parents[3] / "benchmarks" / "bit_identity").glob("skew*.toml"))


def _jax():
    from cross_checks.engines import runtimes
    jax = runtimes.start_jax()
    return jax


def _every_force_kind():
    """Scenarios of every kind of state-dependent force (springs, drag, points off the COM in world and body
    axes, body torques) with decay, and some without: a world where bodies have different numbers of each."""
    many = scenario_from_parts(
        body="mass = 1.3\ninertia = [[2.0, 0.1, 0.05], [0.1, 3.0, -0.2], [0.05, -0.2, 4.0]]",
        forces='gravity = [0.3, -0.2, -9.81]\nlinear_drag = 0.7\nvelocity_decay = 0.99\n'
               'angular_velocity_decay = 0.97\n'
               '[[forces.spring]]\nanchor = [0.0, 0.0, 1.0]\nattach = [0.1, 0.0, 0.05]\nstiffness = 40.0\n'
               'rest_length = 0.5\n'
               '[[forces.spring]]\nanchor = [1.0, -1.0, 0.0]\nattach = [0.0, 0.2, -0.1]\nstiffness = 7.0\n'
               '[[forces.point]]\nforce = [0.1, 0.0, 0.2]\npoint = [0.0, 0.1, 0.0]\nframe = "body"\n'
               '[[forces.point]]\nforce = [1.0, 2.0, -0.5]\npoint = [0.3, 0.0, 0.1]\nframe = "world"\n'
               '[[forces.point]]\nforce = [0.5, 0.5, 0.5]\nframe = "world"\n'
               '[[forces.torque]]\ntorque = [0.0, 0.05, 0.02]\nframe = "body"\n'
               '[[forces.torque]]\ntorque = [0.3, -0.1, 0.0]\nframe = "world"', dt=0.01)
    names = [n for n in catalog_names() if load_scenario(n).problem.forces.state_dependent]
    return [many, *map(load_scenario, names), *map(load_scenario, map(str, EXTRAS)),
            load_scenario("velocity_decay"), load_scenario("tennis_racket")]


def _states(rng, n):
    """Packed states (n, 13) of every scale, the attitude not normalised (the harness normalises it)."""
    y = rng.standard_normal((n, 13)) * rng.choice([1e-3, 1.0, 30.0, 1e3], size=(n, 1))
    y[:, 6:10] = rng.standard_normal((n, 4)) * rng.choice([0.5, 1.0, 1.0 + 1e-9], size=(n, 1))
    return y


def _wrench_fn(jax):
    def fn(a, y, z):
        return jax.vmap(lambda a, y: jax_forces.wrench(a, y[0:3], y[3:6], y[6:10], z))(a, y)
    return jax.jit(fn)


@pytest.mark.parametrize("applies_gravity", [True, False])
def test_the_wrench_evaluated_by_jax_is_the_harness_s_bit_for_bit(applies_gravity):
    jax = _jax()
    scenarios = _every_force_kind()
    dts = [sc.dt_s * (0.5 if i % 2 else 1.0) for i, sc in enumerate(scenarios)]   # decay off the dt too
    harness = Harness(scenarios, dts, applies_gravity)
    fa = jax_forces.BodyForces(harness)
    assert fa.key[0] == 2 and fa.key[1] >= 1 and fa.key[2] >= 1   # the world pads every kind of entry
    fn = _wrench_fn(jax)
    rng = np.random.default_rng(7)
    for _ in range(50):
        y = _states(rng, len(scenarios))
        f, tau = harness.wrench(y, np.arange(len(scenarios)))
        got = np.asarray(fn(fa.arrays, y, jax_forces.zero()))
        np.testing.assert_array_equal(got, np.concatenate([f, tau], axis=1))


def test_a_subset_of_the_bodies_and_a_padded_batch_take_their_own_rows():
    jax = _jax()
    scenarios = _every_force_kind()
    harness = Harness(scenarios, [sc.dt_s for sc in scenarios], True)
    rows = [3, 0, 0, 5]
    fa = jax_forces.BodyForces(harness, rows)
    y = _states(np.random.default_rng(3), len(rows))
    f, tau = harness.wrench(y, rows)
    got = np.asarray(_wrench_fn(jax)(fa.take([0, 1, 2, 3]), y, jax_forces.zero()))
    np.testing.assert_array_equal(got, np.concatenate([f, tau], axis=1))
    assert len(fa) == 4 and fa.take([1, 1])["g_v"].shape == (2,)


def test_inside_a_vmapped_loop_whose_arithmetic_xla_fuses_with_them_too():
    # the states evolve inside the compiled loop by products and sums XLA contracts into fused multiply-adds;
    # every step's forces, recorded in the loop, are the host's at the state the loop recorded
    jax = _jax()
    import jax.numpy as jnp
    scenarios = _every_force_kind()
    harness = Harness(scenarios, [sc.dt_s for sc in scenarios], True)
    fa = jax_forces.BodyForces(harness)

    def member(a, y0, z):
        def body(i, carry):
            y, ys, ws = carry
            w = jax_forces.wrench(a, y[0:3], y[3:6], y[6:10], z)
            y = y * 1.001 + jnp.concatenate([w, w, jnp.zeros(1)]) * 1e-3
            # recorded as the engines evaluate them: apart from their step (a conditional of its own)
            w1 = jax_forces.wrench_apart(a, y[0:3], y[3:6], y[6:10], z)
            return y, ys.at[i].set(y), ws.at[i + 1].set(w1)
        return jax.lax.fori_loop(0, 20, body, (y0, jnp.zeros((20, 13)), jnp.zeros((21, 6))))[1:]

    y0 = _states(np.random.default_rng(11), len(scenarios))
    ys, ws = jax.jit(jax.vmap(member, in_axes=(0, 0, None)))(fa.arrays, y0, jax_forces.zero())
    ys, ws = np.asarray(ys), np.asarray(ws)
    for k in range(20):
        f, tau = harness.wrench(ys[:, k], np.arange(len(scenarios)))
        np.testing.assert_array_equal(ws[:, k + 1], np.concatenate([f, tau], axis=1))


@pytest.mark.parametrize("engine,variant,module", [("mjx", "euler", "mujoco.mjx"),
                                                   ("brax", "generalized", "brax"),
                                                   ("jaxsim", "semi_implicit_euler", "jaxsim")])
def test_a_jax_engine_runs_state_dependent_forces_without_the_host(engine, variant, module, monkeypatch):
    # before: the compiled loop called the harness back on the host at every step of every body (a
    # jax.pure_callback: 0.05-0.5 ms a step); now the forces are evaluated inside it, so the host's evaluator
    # is called a bounded number of times whatever the steps (none per step)
    if importlib.util.find_spec(module) is None:
        pytest.skip(f"{module} is not installed")
    from cross_checks.engines import get_adapter
    from cross_checks.engines.base import RunRequest
    from reference_sim.compiled import ForceEvaluator
    calls = []
    evaluate = ForceEvaluator.force_torque

    def counted(self, y, stage=False):
        calls.append(1)
        return evaluate(self, y, stage)
    monkeypatch.setattr(ForceEvaluator, "force_torque", counted)
    reqs = [RunRequest(load_scenario(name), 0.01, 40) for name in ("applied_torque", "spring_pendulum")]
    runs = get_adapter(engine).simulate_many(variant, reqs)
    assert all(len(r.y) == 41 and r.diverged_at_s is None for r in runs)
    assert len(calls) < 40, f"{len(calls)} host evaluations of the forces for 2 bodies x 40 steps"
