"""The MJX adapter (cross_checks.engines.mjx_engine): every convention it relies on, pinned on MJX itself
(docs/engine_conventions.md, "MJX 3.17.0"), every default it neutralises, one step against the hand-derived
semi-implicit Euler step, float64, the forces held over RK4's stages, the same-scheme pairs with MuJoCo's
Euler, divergence, the batched paths against the single ones, the compile bookkeeping, and that neither
importing the adapter nor asking its version starts JAX (the sweep forks its workers).

Compilation dominates this module's time (each executable 3-15 s on one core): the tests share executables
(Euler, the diagonal-tensor structure, one run per call) wherever they can; the RK4 ladders are
slow-marked."""
import importlib.util
import os
import subprocess
import sys

import numpy as np
import pytest

from tests.helpers import tolerances as tol

# never `importorskip("mujoco.mjx")`: that imports JAX at COLLECTION, in the process whose later tests fork
# sweeps; JAX starts in the tests below that need it
if importlib.util.find_spec("mujoco.mjx") is None:
    pytest.skip("mujoco-mjx is not installed (pip install -e '.[mjx]')", allow_module_level=True)

from cross_checks.engines import mjx_engine as xe  # noqa: E402
from cross_checks.engines import mujoco_engine as me  # noqa: E402
from cross_checks.engines.base import RunRequest  # noqa: E402
from cross_checks.scenario import load_scenario  # noqa: E402
from reference_sim.quaternion import geodesic_angle, matrix_from_quat, quat_exp, quat_mul  # noqa: E402
from tests.helpers.scenarios import YAW90, scenario_from_parts  # noqa: E402

Q_TILT = np.array([0.9, 0.1, 0.3, -0.2]) / np.linalg.norm([0.9, 0.1, 0.3, -0.2])
FULL_INERTIA = "mass = 2.0\ninertia = [[2.0, 0.1, 0.05], [0.1, 3.0, -0.2], [0.05, -0.2, 4.0]]"
NO_GRAVITY = "gravity = [0.0, 0.0, 0.0]"


def _tilted(body=FULL_INERTIA, forces=NO_GRAVITY, **initial):
    """A scenario whose body starts at Q_TILT, at (1, −2, 0.5) m, with the initial fields given (TOML
    values)."""
    lines = [f"orientation = {Q_TILT.tolist()}", "position = [1.0, -2.0, 0.5]"]
    lines += [f"{k} = {v}" for k, v in initial.items()]
    return scenario_from_parts(body=body, initial="\n".join(lines), forces=forces)


def _world_inertia(sc, q):
    R = matrix_from_quat(q)
    return R @ sc.problem.body.inertia_B @ R.T


def test_version_is_the_pinned_release():
    assert xe.version() == "3.17.0 (jax 0.10.2)"


def test_importing_the_adapter_asking_its_version_and_its_files_start_no_jax():
    # the registry imports every adapter and asks its version at CLI start, and the sweep hashes its source
    # files before forking its workers: none of it may import JAX (whose backend is multithreaded once
    # started)
    code = ("import sys; from cross_checks.engines import mjx_engine as m, all_variants; m.version(); "
            "m.MjxAdapter().source_files(); all_variants(); print(sorted(k for k in sys.modules "
            "if k.split('.')[0] in ('jax', 'jaxlib') or k.startswith('mujoco.mjx')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


# --- precision and the model ---------------------------------------------------------------------------

def test_results_are_float64_with_x64_turned_on_process_wide():
    import jax
    sc = load_scenario("projectile")
    run = xe.simulate(sc, "euler", 0.01, 10)
    assert run.y.dtype == np.float64 and jax.config.jax_enable_x64
    key, xm = xe.device_model(sc, "euler", 0.01)
    assert xm.body_mass.dtype == np.float64 and xm.opt.timestep.dtype == np.float64
    # float32 would leave ~1e-7 of the metres and m/s; MuJoCo's C Euler is the same arithmetic in float64
    ref = me.simulate(sc, "euler", 0.01, 10)
    np.testing.assert_allclose(run.y, ref.y, rtol=0, atol=tol.MJX_SAME_AS_MUJOCO_EULER_REL)


@pytest.mark.parametrize("variant, integrator", [("euler", 0), ("rk4", 1), ("implicitfast", 3)])
def test_the_model_is_mujocos_with_every_default_that_is_not_the_physics_neutral(variant, integrator):
    sc = _tilted(forces="gravity = [1.0, -2.0, 0.5]")
    _, xm = xe.device_model(sc, variant, 0.004)
    assert int(xm.opt.integrator) == integrator          # mjx.IntegratorType: EULER 0, RK4 1, IMPLICITFAST 3
    assert float(xm.opt.timestep) == 0.004
    np.testing.assert_array_equal(np.asarray(xm.opt.gravity), [1.0, -2.0, 0.5])
    np.testing.assert_array_equal(np.asarray(xm.body_mass), [0.0, 2.0])
    # no damping, armature, friction loss, stiffness; no geom (nothing to collide with: no contact, no
    # ground), no actuator, no tendon, no equality constraint; one free joint
    for field in ("dof_damping", "dof_armature", "dof_frictionloss"):
        np.testing.assert_array_equal(np.asarray(getattr(xm, field)), np.zeros(6))
    np.testing.assert_array_equal(np.asarray(xm.jnt_stiffness), [0.0])
    assert (xm.ngeom, xm.nu, xm.na, xm.ntendon, xm.neq, xm.njnt, xm.nq, xm.nv) == (0, 0, 0, 0, 0, 1, 7, 6)
    np.testing.assert_array_equal(np.asarray(xm.body_gravcomp), [0.0, 0.0])
    # density and viscosity 0: no fluid forces; wind 0
    assert float(xm.opt.density) == 0.0 and float(xm.opt.viscosity) == 0.0
    np.testing.assert_array_equal(np.asarray(xm.opt.wind), np.zeros(3))


def test_a_scenarios_model_at_another_step_is_a_fresh_put_of_it():
    # device_model keeps a scenario's model and changes opt.timestep for its other steps: the same leaves as
    # mjx.put_model of the model compiled at that step
    import jax
    from mujoco import mjx
    sc = _tilted()
    xe.device_model(sc, "euler", 0.01)
    _, again = xe.device_model(sc, "euler", 0.005)
    fresh = mjx.put_model(me.build_model(sc, "euler", 0.005))
    a, b = jax.tree_util.tree_leaves_with_path(again), jax.tree_util.tree_leaves_with_path(fresh)
    assert [p for p, _ in a] == [p for p, _ in b]
    for (path, x), (_, y) in zip(a, b):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y), err_msg=jax.tree_util.keystr(path))


def test_mjx_has_no_velocity_clamp_sleep_or_substep_a_fast_body_keeps_its_speed():
    # 1e4 m/s and 100 rad/s about a principal axis (isotropic body: no gyroscopic term) for 100 steps:
    # unchanged
    sc = scenario_from_parts(body="mass = 1.0\ninertia = [1.0, 1.0, 1.0]",
                             initial="velocity = [1e4, 0.0, 0.0]\nangular_velocity = [0.0, 0.0, 100.0]")
    run = xe.simulate(sc, "euler", 1e-3, 100)
    np.testing.assert_allclose(run.y[:, 3:6], np.tile([1e4, 0.0, 0.0], (101, 1)), rtol=0,
                               atol=tol.MJX_FAST_BODY)
    np.testing.assert_allclose(run.y[:, 10:13], np.tile([0.0, 0.0, 100.0], (101, 1)), rtol=0,
                               atol=tol.MJX_FAST_BODY)
    np.testing.assert_allclose(run.y[:, 0], 1e4 * run.t_s, rtol=1e-14, atol=0)


def test_projectile_is_the_semi_implicit_closed_form_one_integration_per_step():
    sc = load_scenario("projectile")
    n, h = 100, 0.01
    run = xe.simulate(sc, "euler", h, n)
    p = sc.problem
    k = np.arange(n + 1)[:, None]
    exact = p.initial.x_W + k * h * p.initial.v_W + np.asarray(p.forces.gravity_W) * h * h * k * (k + 1) / 2
    np.testing.assert_allclose(run.y[:, 0:3], exact, rtol=0, atol=tol.AGREE_PROJECTILE)


# --- conventions -----------------------------------------------------------------------------------------

def test_quaternion_order_and_angular_velocity_frames_at_the_boundary():
    # (w, x, y, z) = (√½, 0, 0, √½) is 90° about z; MJX's qvel holds ω in BODY axes, the packed state in WORLD
    # axes
    sc = scenario_from_parts(initial=YAW90 + "\nangular_velocity_body = [2.0, 0.0, 0.0]")
    qpos, qvel = me.to_qpos_qvel(sc.problem.initial_packed())
    np.testing.assert_allclose(qpos[3:7], [np.sqrt(0.5), 0.0, 0.0, np.sqrt(0.5)], rtol=0, atol=1e-16)
    np.testing.assert_allclose(qvel[3:6], [2.0, 0.0, 0.0], rtol=0, atol=1e-15)
    # a torque-free spin about principal body x of a body yawed by 90°: ω_W = (0, 2, 0) throughout, and the
    # attitude turns about WORLD y: q(t) = exp(ω_W t) ⊗ q0
    run = xe.simulate(sc, "euler", 0.01, 50)
    np.testing.assert_allclose(run.y[:, 10:13], np.tile([0.0, 2.0, 0.0], (51, 1)), rtol=0,
                               atol=tol.ADAPTER_SPIN_100_STEPS)
    expected = quat_mul(quat_exp(np.outer(run.t_s, [0.0, 2.0, 0.0])), run.y[0, 6:10])
    assert np.max(geodesic_angle(expected, run.y[:, 6:10])) < tol.ADAPTER_SPIN_100_STEPS


def test_one_step_is_the_hand_derived_semi_implicit_euler_step_with_a_full_tensor_in_body_axes():
    # v and ω from the start-of-step forces (world force at the COM, world torque, gravity) with the
    # gyroscopic term of the full tensor taken in the scenario's body axes, then x and the attitude from the
    # NEW velocities, the attitude by the exponential map: q1 = exp(Δt ω1_W) ⊗ q0
    sc = _tilted(forces='gravity = [0.0, 0.0, -9.81]\n[[forces.torque]]\ntorque = [0.3, -0.2, 0.5]\n'
                        'frame = "world"\n[[forces.point]]\nforce = [1.0, 2.0, 3.0]\nframe = "world"',
                 velocity="[0.3, -0.1, 0.2]", angular_velocity="[0.4, 1.5, -0.7]")
    h, y0 = 0.01, sc.problem.initial_packed()
    y1 = xe.one_step(sc, "euler", h, y0[None])[0]
    I_W, w = _world_inertia(sc, Q_TILT), y0[10:13]
    w1 = w + h * np.linalg.solve(I_W, np.array([0.3, -0.2, 0.5]) - np.cross(w, I_W @ w))
    v1 = y0[3:6] + h * (np.array([1.0, 2.0, 3.0]) / 2.0 + [0.0, 0.0, -9.81])
    np.testing.assert_allclose(y1[10:13], w1, rtol=0, atol=tol.MJX_HAND_STEP)
    np.testing.assert_allclose(y1[3:6], v1, rtol=0, atol=tol.MJX_HAND_STEP)
    np.testing.assert_allclose(y1[0:3], y0[0:3] + h * v1, rtol=0, atol=tol.MJX_HAND_STEP)
    assert geodesic_angle(quat_mul(quat_exp(h * w1), Q_TILT), y1[6:10]) < tol.MJX_HAND_STEP


def test_state_dependent_forces_reach_mjx_as_the_force_models_wrench():
    # a body-frame force off the COM and a spring off the COM: one step changes v by Δt f/m and ω by
    # Δt I_W⁻¹(τ − ω × I_W ω), f and τ from ForceModel.force_torque at the start-of-step state
    sc = _tilted(forces='[[forces.point]]\nforce = [0.4, -1.0, 2.0]\npoint = [0.1, 0.2, -0.3]\n'
                        'frame = "body"\n[[forces.spring]]\nanchor = [0.0, 0.0, 1.0]\n'
                        'attach = [0.2, 0.0, 0.1]\nstiffness = 5.0',
                 angular_velocity="[0.4, 1.5, -0.7]", velocity="[0.3, -0.1, 0.2]")
    y0 = sc.problem.initial_packed()
    f, tau = sc.problem.forces.force_torque(sc.problem.body, y0[0:3], y0[3:6], y0[6:10])
    y1 = xe.one_step(sc, "euler", 1e-3, y0[None])[0]
    I_W, w = _world_inertia(sc, Q_TILT), y0[10:13]
    np.testing.assert_allclose(y1[3:6], y0[3:6] + 1e-3 * np.asarray(f) / 2.0, rtol=0, atol=tol.MJX_HAND_STEP)
    w1 = w + 1e-3 * np.linalg.solve(I_W, np.asarray(tau) - np.cross(w, I_W @ w))
    np.testing.assert_allclose(y1[10:13], w1, rtol=0, atol=tol.MJX_HAND_STEP)


def test_mjx_keeps_xfrc_applied_after_a_step_so_the_adapter_writes_it_before_every_step():
    import jax
    import mujoco
    from mujoco import mjx
    sc = scenario_from_parts(forces=NO_GRAVITY)
    m = me.build_model(sc, "euler", 0.01)
    xm = mjx.put_model(m)
    d = mjx.put_data(m, mujoco.MjData(m))
    d = d.replace(xfrc_applied=d.xfrc_applied.at[1].set(jax.numpy.array([1.0, 2.0, 3.0, 0.0, 0.0, 0.0])))
    d1 = jax.jit(mjx.step)(xm, d)
    np.testing.assert_array_equal(np.asarray(d1.xfrc_applied[1]), [1.0, 2.0, 3.0, 0.0, 0.0, 0.0])  # kept
    np.testing.assert_allclose(np.asarray(d1.qvel[0:3]), 0.01 * np.array([1.0, 2.0, 3.0]), rtol=1e-15)


def test_decay_is_applied_before_the_step_with_that_steps_force_scaled():
    # harness semantics (base.py): v ← γ v, the force × γ, then MJX's step: v1 = γ (v0 + Δt (F/m + g))
    # (isotropic body: no gyroscopic term, ω1 = γ_ω (ω0 + Δt τ/I))
    sc = scenario_from_parts(body="mass = 2.0\ninertia = [0.5, 0.5, 0.5]",
                             initial="velocity = [1.0, -2.0, 0.5]\nangular_velocity = [0.3, 0.0, 3.0]",
                             forces='gravity = [0.0, 0.0, -9.81]\nvelocity_decay = 0.99\n'
                                    'angular_velocity_decay = 0.95\n[[forces.point]]\n'
                                    'force = [1.0, 2.0, 3.0]\n'
                                    'frame = "world"\n'
                                    '[[forces.torque]]\ntorque = [0.1, 0.2, -0.3]\nframe = "world"', dt=0.01)
    y0 = sc.problem.initial_packed()
    y1 = xe.one_step(sc, "euler", 0.01, y0[None])[0]
    v1 = 0.99 * (y0[3:6] + 0.01 * (np.array([0.5, 1.0, 1.5]) + [0.0, 0.0, -9.81]))
    np.testing.assert_allclose(y1[3:6], v1, rtol=0, atol=tol.MJX_HAND_STEP)
    np.testing.assert_allclose(y1[10:13], 0.95 * (y0[10:13] + 0.01 * np.array([0.2, 0.4, -0.6])), rtol=0,
                               atol=tol.MJX_HAND_STEP)
    run = xe.simulate(sc, "euler", 0.01, 3)                                     # the free run does the same
    np.testing.assert_allclose(run.y[1], y1, rtol=0, atol=tol.MJX_REPLAY_REL)


def test_a_model_mujoco_refuses_is_an_engine_error_with_mujocos_words():
    from cross_checks.engines.base import EngineError
    from tests.helpers.scenarios import with_body
    sc = with_body(scenario_from_parts(), 1e-20, 1e-20)
    run = xe.simulate_many("euler", [RunRequest(sc, 0.01, 5)])[0]
    assert isinstance(run, EngineError) and "MuJoCo" in str(run) and "rejected the model" in str(run)


# --- runs ------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", ["spring_pendulum", "velocity_decay", "applied_torque"])
def test_one_step_replays_the_run(name):
    # the free run evaluates state-dependent forces through the host callback, one_step on the host: the same
    sc = load_scenario(name)
    run = xe.simulate(sc, "euler", 0.01, 20)
    again = xe.one_step(sc, "euler", 0.01, run.y[:-1])
    scale = np.maximum(1.0, np.abs(run.y[1:]))
    assert np.max(np.abs(again - run.y[1:]) / scale) < tol.MJX_REPLAY_REL


def test_simulate_many_equals_simulate_and_a_ladder_compiles_once():
    sc = load_scenario("symmetric_top")
    hs = [0.02, 0.01, 0.005]
    reqs = [RunRequest(sc, h, int(round(1.0 / h))) for h in hs]
    before = xe.timings()
    runs = xe.simulate_many("euler", reqs)
    mid = xe.timings()
    again = xe.simulate_many("euler", [RunRequest(sc, 0.004, 250),
                                       RunRequest(load_scenario("tennis_racket"), 0.01, 7),
                                       RunRequest(sc, 0.0025, 400)])
    after = xe.timings()
    assert mid["compilations"] - before["compilations"] <= 1           # one executable for the whole ladder
    assert after["compilations"] == mid["compilations"]               # Δt, steps, mass, inertia: all traced
    assert mid["compile_seconds"] >= before["compile_seconds"]
    assert after["step_seconds"] > before["step_seconds"]
    for r, run in zip(reqs, runs):
        single = xe.simulate(sc, "euler", r.dt_s, r.n_steps)
        np.testing.assert_allclose(run.y, single.y, rtol=0, atol=tol.MJX_BATCH_VS_SINGLE)
        assert len(run.t_s) == r.n_steps + 1 and run.diverged_at_s is None
    assert [len(r.t_s) for r in again] == [251, 8, 401]


def test_a_blow_up_is_reported_as_divergence_with_the_rows_before_it():
    # k/m = 1e6: semi-implicit Euler is unstable for ωΔt > 2; here ωΔt = 10
    sc = scenario_from_parts(initial="position = [0.1, 0.0, 0.0]",
                             forces="[[forces.spring]]\nanchor = [0.0, 0.0, 0.0]\nattach = [0.0, 0.0, 0.0]\n"
                                    "stiffness = 1e6\nrest_length = 0.0", dt=0.01, duration=1.0)
    run = xe.simulate(sc, "euler", 0.01, 100)
    assert run.diverged_at_s is not None and 0.0 < run.diverged_at_s < 0.2
    assert run.message == f"diverged at t = {run.diverged_at_s:.6g} s (state beyond 1e+08)"
    assert len(run.t_s) == round(run.diverged_at_s / 0.01) and np.all(np.abs(run.y) <= 1e8)


def test_a_run_longer_than_a_chunk_continues_from_the_chunks_last_state():
    sc = load_scenario("projectile")
    n = xe.CHUNK + 5
    run = xe.simulate(sc, "euler", 1e-4, n)
    k = np.arange(n + 1)[:, None]
    p, h = sc.problem, 1e-4
    exact = p.initial.x_W + k * h * p.initial.v_W + np.asarray(p.forces.gravity_W) * h * h * k * (k + 1) / 2
    np.testing.assert_allclose(run.y[:, 0:3], exact, rtol=0, atol=tol.AGREE_PROJECTILE)


def test_the_compile_stats_keep_compilation_apart_from_stepping():
    xe.simulate(load_scenario("projectile"), "euler", 0.01, 3)
    stats = xe.timings()
    assert set(stats) == {"compilations", "compile_seconds", "step_seconds", "body_steps"}
    assert stats["compilations"] >= 1 and stats["compile_seconds"] > 0.0 and stats["body_steps"] > 0
    assert any(name.startswith("chunk:euler:") for name in xe.MjxAdapter.per_executable)


# --- the same scheme as MuJoCo's Euler; implicitfast; RK4 holds the forces
# -----------------------------------

@pytest.mark.parametrize("name", ["tennis_racket", "applied_torque", "spring_pendulum", "tumbling_box"])
def test_euler_is_mujoco_eulers_arithmetic(name):
    # the same-scheme pair of cross_checks.analysis.expectations.EQUIVALENT_PAIRS: within the sweep's
    # tolerance everywhere, and to round-off away from tumbling_box's separatrix (which amplifies it ~1e3 over
    # 10 s)
    from cross_checks.core.tolerances import SAME_SCHEME_REL
    sc = load_scenario(name)
    n = sc.n_steps(sc.dt_s)
    a, b = xe.simulate(sc, "euler", sc.dt_s, n), me.simulate(sc, "euler", sc.dt_s, n)
    rel = np.max(np.abs(a.y - b.y) / np.maximum(1.0, np.abs(b.y)))
    assert rel < (SAME_SCHEME_REL if name == "tumbling_box" else tol.MJX_SAME_AS_MUJOCO_EULER_REL)


def test_implicitfast_takes_eulers_step_on_a_lone_free_body_unlike_mujocos():
    # MJX's implicit() solves (M − Δt ∂f/∂v) qacc = f with derivative.deriv_smooth_vel: actuators and damping
    # only ("TODO(team): rne derivative"); MuJoCo C's implicitfast has an implicit gyroscopic term
    sc = load_scenario("tennis_racket")
    a, b = xe.simulate(sc, "implicitfast", 0.01, 300), xe.simulate(sc, "euler", 0.01, 300)
    assert np.max(np.abs(a.y - b.y)) < tol.MJX_IMPLICITFAST_VS_EULER
    c = me.simulate(sc, "implicitfast", 0.01, 300)
    assert np.max(np.abs(c.y[:, 10:13] - b.y[:, 10:13])) > tol.MJX_IMPLICITFAST_VS_C_MIN_DIFF


def test_one_rk4_step_adds_the_stages_body_axes_velocities_before_one_exponential():
    # mujoco/mjx/_src/forward.py rungekutta4, torque-free (ω̇_B = I⁻¹(−ω_B × I ω_B) depends on ω_B alone): the
    # classical RK4 stages of ω_B, then q1 = q0 ⊗ exp(Δt Σ b_i ω_B,i) — one exponential of the weighted sum of
    # body-axes velocities taken at different attitudes: second order on the rotation group (the sweep's
    # tumbling scenarios measure 2.00), the velocities' own RK4 fourth order
    sc = scenario_from_parts(body="mass = 1.0\ninertia = [1.0, 2.0, 3.0]",
                             initial="angular_velocity_body = [0.4, 1.5, -0.7]", forces=NO_GRAVITY)
    inertia = np.array([1.0, 2.0, 3.0])
    h, y0 = 0.05, sc.problem.initial_packed()

    def f(w):
        return -np.cross(w, inertia * w) / inertia

    w0 = me.to_qpos_qvel(y0)[1][3:6]
    k1 = f(w0)
    w2 = w0 + 0.5 * h * k1
    k2 = f(w2)
    w3 = w0 + 0.5 * h * k2
    k3 = f(w3)
    w4 = w0 + h * k3
    k4 = f(w4)
    w1 = w0 + h * (k1 / 6 + k2 / 3 + k3 / 3 + k4 / 6)
    q1 = quat_mul(y0[6:10], quat_exp(h * (w0 / 6 + w2 / 3 + w3 / 3 + w4 / 6)))
    y1 = xe.one_step(sc, "rk4", h, y0[None])[0]
    qpos, qvel = me.to_qpos_qvel(y1)
    np.testing.assert_allclose(qvel[3:6], w1, rtol=0, atol=tol.MJX_HAND_STEP)
    assert geodesic_angle(q1, qpos[3:7]) < tol.MJX_HAND_STEP


def _error_ratio(sc, variant, h, T):
    """The final-state error of ``variant`` at h and h/2 over T against MuJoCo C RK4 (forces at every stage)
    at h/64, and their ratio (2^p for order p)."""
    fine = me.simulate(sc, "rk4", h / 64, int(round(64 * T / h))).y[-1]
    reqs = [RunRequest(sc, h, int(round(T / h))), RunRequest(sc, h / 2, int(round(2 * T / h)))]
    errs = [np.max(np.abs(r.y[-1] - fine)) for r in xe.simulate_many(variant, reqs)]
    return errs, errs[0] / errs[1]


@pytest.mark.slow
def test_rk4_holds_the_forces_over_its_stages_first_order_where_they_change_within_a_step():
    # applied_torque: a body-frame torque (state-dependent), held over the four stages: first order
    _, ratio = _error_ratio(load_scenario("applied_torque"), "rk4", 0.02, 1.0)
    assert ratio == pytest.approx(2.0, rel=tol.MJX_ORDER_RATIO_REL)


@pytest.mark.slow
def test_rk4_with_constant_forces_is_exact_where_the_rotation_axis_is_fixed():
    # a world force and a world torque along the principal axis z of a body spinning about it: the stages'
    # body-axes velocities are parallel, the motion polynomial — RK4 (with the forces held, they are constant)
    # is exact to round-off at both steps; with constant forces MJX's RK4 is either this or second order (the
    # tumble below): its declared fourth order shows nowhere in the catalog (docs/engine_conventions.md, "MJX
    # 3.17.0")
    sc = scenario_from_parts(body="mass = 2.0\ninertia = [1.0, 2.0, 3.0]",
                             initial="angular_velocity = [0.0, 0.0, 2.0]\nvelocity = [0.5, 0.0, 0.0]",
                             forces='gravity = [0.0, 0.0, -9.81]\n[[forces.torque]]\n'
                                    'torque = [0.0, 0.0, 1.5]\nframe = "world"', duration=2.0)
    errs, _ = _error_ratio(sc, "rk4", 0.05, 2.0)
    assert max(errs) < tol.MJX_RK4_EXACT


@pytest.mark.slow
def test_rk4_is_second_order_on_a_torque_free_tumble_its_stages_add_body_axes_velocities():
    # MJX 3.17 (mujoco/mjx/_src/forward.py rungekutta4) advances the quaternion by exp(Δt Σ b_i ω_B,i): the
    # body-axes velocities of the four stages added as vectors — a second-order combination on the rotation
    # group; MuJoCo 4.0's C RK4 is fourth order on the same body (the sweep's tumbling scenarios)
    _, ratio = _error_ratio(load_scenario("tennis_racket"), "rk4", 0.02, 1.0)
    assert ratio == pytest.approx(4.0, rel=tol.MJX_ORDER_RATIO_REL)


def test_first_order_on_catalog_scenarios():
    # in this process, one worker: the pytest process has JAX running, and a sweep's forked workers cannot use
    # it
    from cross_checks.testing import run_engine_checks
    summary = run_engine_checks("mjx:euler", ["projectile", "applied_torque"], jobs=1)
    fitted = {(c["scenario"], c["quantity"]): c["order"] for c in summary["convergence"]
              if c["verdict"] == "converges"}
    assert fitted[("applied_torque", "orientation")] == pytest.approx(1.0, abs=tol.DRAKE_ORDER_TOL)


@pytest.mark.slow
def test_a_real_sweep_forks_two_workers_that_run_mjx(tmp_path):
    # `rbcheck sweep --jobs 2` in a fresh process: its parent never starts JAX, each forked worker does (a
    # parent with JAX running would hang them); every run ok, as expected
    import json
    env = {**os.environ, "RBCHECK_CACHE_DIR": str(tmp_path / "cache"), "MPLBACKEND": "Agg"}
    out = tmp_path / "sweep"
    done = subprocess.run([sys.executable, "-m", "cross_checks.cli", "sweep", "projectile", "--engines",
                           "mjx:euler", "--jobs", "2", "--no-cache", "--out", str(out)],
                          capture_output=True, text=True, env=env, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    summary = json.loads((out / "summary.json").read_text())
    assert all(r["matches_expectation"] is not False for r in summary["convergence"])
    assert "Failed to import warp" not in done.stdout + done.stderr


@pytest.mark.filterwarnings("ignore:os.fork:RuntimeWarning")
def test_a_process_forked_after_jax_started_refuses_with_an_engine_error_instead_of_hanging():
    xe.simulate(load_scenario("projectile"), "euler", 0.01, 3)         # JAX is running in this process now
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:                                                          # the child: never touches JAX
        os.close(r)
        run = xe.simulate_many("euler", [RunRequest(load_scenario("projectile"), 0.01, 3)])[0]
        os.write(w, str(run).encode()[:500])
        os._exit(0)
    os.close(w)
    with os.fdopen(r) as f:
        said = f.read()
    os.waitpid(pid, 0)
    assert "forked after JAX started in its parent" in said and "--jobs 1" in said


def test_version_and_list_name_mjx():
    from cross_checks.cli.parser import _version_text
    from cross_checks.engines import all_variants
    assert "mjx 3.17.0 (jax 0.10.2)" in _version_text()
    info = {v.name: v for v in all_variants()}
    assert [info[f"mjx:{v}"].order for v in ("euler", "rk4", "implicitfast")] == [1.0, 4.0, 1.0]
    assert info["mjx:euler"].available and not info["mjx:euler"].required
