"""The Brax adapter (cross_checks.engines.brax_engine): every convention it relies on, pinned on brax itself
(docs/engine_conventions.md, "Brax 0.14.2"), every default it neutralises, one step of each pipeline against
its hand-derived step, the forces brax can and cannot take, divergence, batching, the compile time it reports,
and the declared order on catalog scenarios. JAX compiles each executable once per process (and keeps it in
rbcheck's persistent cache), so the tests share batch sizes (one_step pads to 64 rows, runs to 1)."""
import importlib.util
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tests.helpers import tolerances as tol

# never `importorskip("brax")`: that imports JAX at COLLECTION (4 CPU s, in every xdist worker, also the one
# that runs none of these tests), in the process whose later tests fork sweeps; JAX starts in the tests below
# that need it (tests/test_architecture.py::test_no_test_module_starts_jax_at_collection)
if importlib.util.find_spec("brax") is None:
    pytest.skip("brax is not installed (pip install -e '.[brax]')", allow_module_level=True)

from cross_checks.engines import brax_engine as be  # noqa: E402
from cross_checks.engines.base import RunRequest  # noqa: E402
from cross_checks.scenario import load_scenario  # noqa: E402
from reference_sim.quaternion import geodesic_angle, matrix_from_quat, quat_exp, quat_mul  # noqa: E402
from tests.helpers.scenarios import YAW90, scenario_from_parts  # noqa: E402

Q_TILT = np.array([0.9, 0.1, 0.3, -0.2]) / np.linalg.norm([0.9, 0.1, 0.3, -0.2])
FULL_INERTIA = "mass = 2.0\ninertia = [[2.0, 0.1, 0.05], [0.1, 3.0, -0.2], [0.05, -0.2, 4.0]]"
NO_GRAVITY = "gravity = [0.0, 0.0, 0.0]"
WRENCH = ('gravity = [0.0, 0.0, -9.81]\n[[forces.torque]]\ntorque = [0.3, -0.2, 0.5]\nframe = "world"\n'
          '[[forces.point]]\nforce = [1.0, 2.0, 3.0]\nframe = "world"')
ROOT = Path(__file__).resolve().parents[3]


def _tilted(body=FULL_INERTIA, forces=NO_GRAVITY, **initial):
    lines = [f"orientation = {Q_TILT.tolist()}", "position = [1.0, -2.0, 0.5]"]
    lines += [f"{k} = {v}" for k, v in initial.items()]
    return scenario_from_parts(body=body, initial="\n".join(lines), forces=forces)


def _lib():
    return be._lib()


def _init(sc, variant, y, dt=0.01):
    """brax's state of packed state ``y`` (through the adapter's boundary conversion)."""
    jp = _lib()["jp"]
    q, qd = be.to_q_qd(y)
    return _lib()["pipelines"][variant].init(be.build_system(sc, variant, dt), jp.asarray(q), jp.asarray(qd))


def test_version_is_the_pinned_release():
    assert be.version() == "0.14.2 (jax 0.10.2)"


def test_the_registry_and_version_never_import_jax():
    # a sweep's parent lists the engines and calls version() before forking its workers: JAX must not be there
    code = ("import sys\nfrom cross_checks import engines\nengines.all_variants()\n"
            "from cross_checks.engines import brax_engine\nbrax_engine.version()\n"
            "print(sorted(m for m in ('jax', 'jaxlib', 'brax') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"


def test_float64_is_on_and_the_compilation_cache_is_rbchecks():
    jax = _lib()["jax"]
    assert jax.config.jax_enable_x64
    sysm = be.build_system(load_scenario("projectile"), "generalized", 0.01)
    assert sysm.link.inertia.i.dtype == np.float64 and sysm.opt.timestep.dtype == np.float64
    folder = Path(jax.config.jax_compilation_cache_dir)
    assert folder.name == "jax"
    assert folder.parent.name == "kernels" or os.environ.get("RBCHECK_KERNEL_CACHE_DIR")


# --- the model ---------------------------------------------------------------------------------------------

def test_the_geom_neither_collides_nor_changes_mass_or_inertia():
    import mujoco
    sc = _tilted()
    m = mujoco.MjModel.from_xml_string(be.mjcf_text(sc, 0.01, actuators=False))
    assert m.ngeom == 1 and m.geom_contype[0] == 0 and m.geom_conaffinity[0] == 0
    assert m.body_mass[1] == 2.0
    R = matrix_from_quat(m.body_iquat[1])
    np.testing.assert_allclose(R @ np.diag(m.body_inertia[1]) @ R.T, sc.problem.body.inertia_B, rtol=0,
                               atol=tol.BRAX_INERTIA_ROUND_TRIP)
    np.testing.assert_array_equal(m.body_ipos[1], 0.0)
    assert m.opt.viscosity == 0.0 and m.opt.density == 0.0


@pytest.mark.parametrize("name", ["tennis_racket", "symmetric_top"])
def test_a_turned_body_frame_on_the_triangle_boundary_is_given_by_its_principal_moments(name):
    # A + B = C (tennis_racket 1, 2, 3; symmetric_top 1, 1, 2 kg m²) in a non-principal body frame: as a
    # fullinertia, MuJoCo's compiler decomposes it 1e-15 beyond the boundary and refuses it (the invariance
    # check's body_frame was "broken" for every brax pipeline on the four such catalog scenarios); given as
    # its principal moments on the boundary and the principal frame, it is the same tensor, and it holds
    import mujoco

    from cross_checks.scenario.transforms import BodyFrame, apply, default_transforms
    t = next(x for x in default_transforms() if isinstance(x, BodyFrame))
    sc = apply(t, load_scenario(name))
    text = be.mjcf_text(sc, 0.01, actuators=False)
    assert "diaginertia" in text and "fullinertia" not in text
    m = mujoco.MjModel.from_xml_string(text)
    R = matrix_from_quat(m.body_iquat[1])
    np.testing.assert_allclose(R @ np.diag(m.body_inertia[1]) @ R.T, sc.problem.body.inertia_B, rtol=0,
                               atol=tol.BRAX_INERTIA_ROUND_TRIP)
    assert "fullinertia" in be.mjcf_text(load_scenario(name), 0.01, actuators=False)   # diagonal: as before
    assert "fullinertia" in be.mjcf_text(load_scenario("particle_body"), 0.01, actuators=False)  # off it
    from cross_checks.engines import resolve
    from cross_checks.sweep.invariance import check_invariance
    (r,) = check_invariance(load_scenario(name), resolve("brax:spring"), [t])
    assert r["verdict"] == "holds", r["assessment"]


@pytest.mark.parametrize("variant", list(be.VARIANTS))
def test_the_brax_system_holds_the_scenarios_full_tensor_in_body_axes_gravity_and_step(variant):
    sc = _tilted(forces="gravity = [0.1, -0.2, -9.81]")
    s = be.build_system(sc, variant, 0.004)
    link = s.link.inertia
    assert float(link.mass[0]) == 2.0
    R = matrix_from_quat(np.asarray(link.transform.rot[0]))
    np.testing.assert_allclose(R @ np.asarray(link.i[0]) @ R.T, sc.problem.body.inertia_B, rtol=0,
                               atol=tol.BRAX_INERTIA_ROUND_TRIP)
    np.testing.assert_array_equal(np.asarray(s.gravity), [0.1, -0.2, -9.81])
    assert float(s.opt.timestep) == 0.004 and s.link_types == "f"


def test_mjcf_motors_on_a_free_joint_reach_only_its_first_dof_so_the_adapter_sets_all_six():
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        raw = _lib()["mjcf"].loads(be.mjcf_text(_tilted(), 0.01, actuators=True))
    np.testing.assert_array_equal(np.asarray(raw.actuator.qd_id), [0] * 6)
    np.testing.assert_array_equal(np.asarray(raw.actuator.gear), [1, 0, 0, 0, 0, 0])
    s = be.build_system(_tilted(), "generalized", 0.01)
    np.testing.assert_array_equal(np.asarray(s.actuator.qd_id), np.arange(6))
    np.testing.assert_array_equal(np.asarray(s.actuator.gear), np.ones(6))
    np.testing.assert_array_equal(np.asarray(s.actuator.bias_qd), np.zeros(6))
    assert s.act_size() == 6 and np.all(np.isinf(np.asarray(s.actuator.force_range)))


def test_mujocos_refusal_is_an_engine_error_in_its_words(monkeypatch):
    # rbcheck's own body check refuses such moments first; a model MuJoCo's compiler rejects still reads as
    # its words
    world = be._lib()["world"]   # the MJCF the adapter loads: cross_checks.engines.worlds.brax's
    real = world.mjcf_text
    monkeypatch.setattr(world, "mjcf_text",
                        lambda *a, **k: real(*a, **k).replace('fullinertia="', 'fullinertia="9 '))
    sc = _tilted(velocity="[0.0, 0.0, 1.0]")           # a scenario object of its own: nothing cached for it
    with pytest.raises(be.EngineError, match="rejected the model of scenario 't'.*fullinertia"):
        be.simulate(sc, "generalized", 0.01, 2)


# --- defaults -------------------------------------------------------------------------------------------

def test_brax_s_own_defaults_are_the_neutral_values_but_the_approximate_inverse():
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        raw = _lib()["mjcf"].loads(be.mjcf_text(_tilted(), 0.01, actuators=False))
    for field, value in be.NEUTRAL_SYSTEM:
        if field == "matrix_inv_iterations":
            assert raw.matrix_inv_iterations == 10     # brax's default: Newton-Schulz from the last inverse
        else:
            assert float(getattr(raw, field)) == value, field
    for field, value in be.NEUTRAL_DOF:
        np.testing.assert_array_equal(np.asarray(getattr(raw.dof, field)), value)
    assert not raw.enable_fluid


def test_neutralise_sets_every_default_whatever_it_was():
    jp = _lib()["jp"]
    s = be.build_system(_tilted(), "generalized", 0.01)
    hostile = s.replace(vel_damping=-1.0, ang_damping=-2.0, spring_mass_scale=0.5, spring_inertia_scale=0.5,
                        matrix_inv_iterations=10,
                        dof=s.dof.replace(damping=jp.full(6, 0.3), armature=jp.full(6, 0.1)))
    back = be.neutralise(hostile)
    for field, value in be.NEUTRAL_SYSTEM:
        assert float(getattr(back, field)) == value, field
    for field, value in be.NEUTRAL_DOF:
        np.testing.assert_array_equal(np.asarray(getattr(back.dof, field)), value)


@pytest.mark.parametrize("field, value, variant", [
    ("vel_damping", -1.0, "spring"), ("ang_damping", -1.0, "spring"),
    ("vel_damping", -1.0, "positional"), ("ang_damping", -1.0, "positional")])
def test_each_neutralised_damping_would_change_the_physics(field, value, variant):
    # a tumbling, falling body: each hostile value changes one step, so neutralising it matters
    # (spring_mass_scale and spring_inertia_scale scale only the forces and torques that reach a body: none
    # but gravity here, so they are set to 0 without a measurable effect on the catalog)
    jax = _lib()["jax"]
    sc = _tilted(forces="gravity = [0.0, 0.0, -9.81]", velocity="[0.3, 0.1, 0.2]",
                 angular_velocity="[0.4, 1.5, -0.7]")
    P = _lib()["pipelines"][variant]
    s = be.build_system(sc, variant, 0.01)
    st = _init(sc, variant, sc.problem.initial_packed())
    step = jax.jit(P.step)
    a = step(s, st, _lib()["jp"].zeros(0))
    b = step(s.replace(**{field: value}), st, _lib()["jp"].zeros(0))
    assert not np.allclose(np.asarray(be.packed(a)), np.asarray(be.packed(b)), rtol=0, atol=1e-6)


@pytest.mark.parametrize("field", ["damping", "armature"])
def test_dof_damping_and_armature_would_change_the_generalized_step(field):
    jax, jp = _lib()["jax"], _lib()["jp"]
    sc = _tilted(velocity="[0.3, 0.1, 0.2]", angular_velocity="[0.4, 1.5, -0.7]")
    s = be.build_system(sc, "generalized", 0.01)
    st = _init(sc, "generalized", sc.problem.initial_packed())
    P = _lib()["pipelines"]["generalized"]
    hostile = s.replace(dof=s.dof.replace(**{field: jp.full(6, 0.5)}))
    act = jp.array([1.0, 0, 0, 0.2, 0, 0])
    a = jax.jit(P.step)(s, st, act)
    b = jax.jit(P.step)(hostile, P.init(hostile, st.q, st.qd), act)
    assert not np.allclose(np.asarray(be.packed(a)), np.asarray(be.packed(b)), rtol=0, atol=1e-6)


# --- conventions ------------------------------------------------------------------------------------------

@pytest.mark.parametrize("variant", list(be.VARIANTS))
def test_quaternion_order_is_w_first_and_init_takes_body_axes_omega_and_reads_world_omega(variant):
    sc = scenario_from_parts(initial=YAW90)
    st = _init(sc, variant, sc.problem.initial_packed())
    np.testing.assert_allclose(np.asarray(st.x.rot[0]), [math.sqrt(0.5), 0, 0, math.sqrt(0.5)], rtol=0,
                               atol=tol.BRAX_ROUND_TRIP)
    # qd = [v_W, ω_B]; state.xd.ang is ω_W, state.xd.vel v_W: a tilted body
    w_W, v_W = np.array([0.1, 0.2, 0.3]), np.array([4.0, 5.0, 6.0])
    y = np.r_[1.0, -2.0, 0.5, v_W, Q_TILT, w_W]
    q, qd = be.to_q_qd(y)
    np.testing.assert_allclose(qd[3:6], matrix_from_quat(Q_TILT).T @ w_W, rtol=0, atol=tol.BRAX_ROUND_TRIP)
    st = _init(_tilted(), variant, y)
    np.testing.assert_allclose(np.asarray(st.xd.ang[0]), w_W, rtol=0, atol=tol.BRAX_ROUND_TRIP)
    np.testing.assert_allclose(np.asarray(st.xd.vel[0]), v_W, rtol=0, atol=tol.BRAX_ROUND_TRIP)
    np.testing.assert_allclose(np.asarray(be.packed(st)), y, rtol=0, atol=4 * tol.BRAX_ROUND_TRIP)


def test_the_generalized_force_of_the_free_joint_is_the_world_force_then_the_body_torque():
    jax, jp = _lib()["jax"], _lib()["jp"]
    sc = _tilted()
    s = be.build_system(sc, "generalized", 0.01)
    st = _init(sc, "generalized", sc.problem.initial_packed())
    step = jax.jit(_lib()["pipelines"]["generalized"].step)
    a = np.asarray(be.packed(step(s, st, jp.array([1.0, 2.0, 3.0, 0.0, 0.0, 0.0]))))
    np.testing.assert_allclose(a[3:6], 0.01 * np.array([1.0, 2.0, 3.0]) / 2.0, rtol=0,
                               atol=tol.BRAX_HAND_STEP)
    b = np.asarray(be.packed(step(s, st, jp.array([0.0, 0.0, 0.0, 0.3, -0.2, 0.5]))))
    R, I_B = matrix_from_quat(Q_TILT), sc.problem.body.inertia_B
    np.testing.assert_allclose(b[10:13], 0.01 * R @ np.linalg.solve(I_B, [0.3, -0.2, 0.5]), rtol=0,
                               atol=tol.BRAX_HAND_STEP)


@pytest.mark.parametrize("variant", ["positional", "spring"])
def test_positional_and_spring_give_a_free_joint_no_actuator_force(variant):
    jax, jp = _lib()["jax"], _lib()["jp"]
    sc = _tilted(velocity="[0.3, 0.1, 0.2]", angular_velocity="[0.4, 1.5, -0.7]")
    s = be.six_dof_actuator(be.build_system(sc, "generalized", 0.01))   # six motors on the free joint
    P = _lib()["pipelines"][variant]
    st = P.init(s, *(jp.asarray(a) for a in be.to_q_qd(sc.problem.initial_packed())))
    step = jax.jit(P.step)
    a, b = step(s, st, jp.zeros(6)), step(s, st, jp.array([10.0, 20.0, 30.0, 1.0, 2.0, 3.0]))
    np.testing.assert_array_equal(np.asarray(be.packed(a)), np.asarray(be.packed(b)))


@pytest.mark.parametrize("variant", ["positional", "spring"])
@pytest.mark.parametrize("name", ["applied_torque", "linear_drag", "spring_oscillator", "spring_pendulum"])
def test_positional_and_spring_refuse_every_force_but_gravity(variant, name):
    sc = load_scenario(name)
    words = f"brax's {variant} pipeline takes no applied force but gravity"
    with pytest.raises(be.EngineError, match=words):
        be.simulate(sc, variant, sc.dt_s, 2)
    assert be.BraxAdapter().expressible(sc, variant).startswith(words)   # the sweep's question
    assert be.BraxAdapter().expressible(sc, "generalized") == ""
    assert be.expressible(load_scenario("velocity_decay"), variant, 0.01) == ""
    assert be.expressible(load_scenario("projectile"), variant, 0.01) == ""


# --- one step of each pipeline, by hand ---------------------------------------------------------------------

def test_one_generalized_step_is_semi_implicit_euler_with_the_gyroscopic_term_in_body_axes():
    sc = _tilted(forces=WRENCH, velocity="[0.3, -0.1, 0.2]", angular_velocity="[0.4, 1.5, -0.7]")
    h, y0 = 0.01, sc.problem.initial_packed()
    y1 = be.one_step(sc, "generalized", h, y0[None])[0]
    R, I_B = matrix_from_quat(Q_TILT), sc.problem.body.inertia_B
    wb = R.T @ y0[10:13]
    wb1 = wb + h * np.linalg.solve(I_B, R.T @ np.array([0.3, -0.2, 0.5]) - np.cross(wb, I_B @ wb))
    v1 = y0[3:6] + h * (np.array([1.0, 2.0, 3.0]) / 2.0 + [0.0, 0.0, -9.81])
    q1 = quat_mul(Q_TILT, quat_exp(h * wb1))
    np.testing.assert_allclose(y1[3:6], v1, rtol=0, atol=tol.BRAX_HAND_STEP)
    np.testing.assert_allclose(y1[0:3], y0[0:3] + h * v1, rtol=0, atol=tol.BRAX_HAND_STEP)
    np.testing.assert_allclose(y1[10:13], matrix_from_quat(q1) @ wb1, rtol=0, atol=tol.BRAX_HAND_STEP)
    assert geodesic_angle(q1, y1[6:10]) < tol.BRAX_ROTATION_BIAS


@pytest.mark.parametrize("variant", ["spring", "positional"])
def test_one_maximal_coordinate_step_has_no_gyroscopic_term_and_a_first_order_quaternion_update(variant):
    sc = _tilted(forces="gravity = [0.0, 0.0, -9.81]", velocity="[0.3, -0.1, 0.2]",
                 angular_velocity="[0.4, 1.5, -0.7]")
    h, y0 = 0.01, sc.problem.initial_packed()
    y1 = be.one_step(sc, variant, h, y0[None])[0]
    w = y0[10:13]
    v1 = y0[3:6] + h * np.array([0.0, 0.0, -9.81])
    q1 = Q_TILT + 0.5 * h * quat_mul(np.r_[0.0, w], Q_TILT)
    q1 /= np.linalg.norm(q1)
    np.testing.assert_allclose(y1[0:3], y0[0:3] + h * v1, rtol=0, atol=tol.BRAX_HAND_STEP)
    np.testing.assert_allclose(y1[6:10], q1, rtol=0, atol=tol.BRAX_HAND_STEP)
    if variant == "spring":      # ω_W unchanged: no −ω × I ω
        np.testing.assert_allclose(y1[10:13], w, rtol=0, atol=tol.BRAX_HAND_STEP)
        np.testing.assert_allclose(y1[3:6], v1, rtol=0, atol=tol.BRAX_HAND_STEP)
    else:                        # ω from the quaternion change: |ω| shrinks by 1/√(1 + (|ω|h/2)²)
        shrink = 1.0 / math.sqrt(1.0 + (np.linalg.norm(w) * h / 2) ** 2)
        np.testing.assert_allclose(y1[10:13], shrink * w, rtol=0, atol=tol.BRAX_HAND_STEP)
        np.testing.assert_allclose(y1[3:6], v1, rtol=0, atol=tol.BRAX_POSITIONAL_VELOCITY)


@pytest.mark.parametrize("variant", list(be.VARIANTS))
def test_projectile_is_the_semi_implicit_closed_form(variant):
    sc = load_scenario("projectile")
    n, h = 100, 0.01
    run = be.simulate(sc, variant, h, n)
    p = sc.problem
    k = np.arange(n + 1)[:, None]
    exact = p.initial.x_W + k * h * p.initial.v_W + np.asarray(p.forces.gravity_W) * h * h * k * (k + 1) / 2
    np.testing.assert_allclose(run.y[:, 0:3], exact, rtol=0, atol=tol.AGREE_PROJECTILE)


def test_state_dependent_forces_are_evaluated_every_step_from_the_start_state():
    # linear drag through the host callback: v1 = v0 + h (g − c v0 / m), each step from its own start
    sc = load_scenario("linear_drag")
    run = be.simulate(sc, "generalized", 0.01, 5)
    c, m, g = 0.8, 2.0, np.array([0.0, 0.0, -9.81])
    for k in range(5):
        v0 = run.y[k, 3:6]
        np.testing.assert_allclose(run.y[k + 1, 3:6], v0 + 0.01 * (g - c * v0 / m), rtol=0,
                                   atol=tol.BRAX_HAND_STEP)


@pytest.mark.parametrize("variant", list(be.VARIANTS))
def test_decay_is_applied_before_the_step(variant):
    sc = load_scenario("velocity_decay")
    h, y0 = 0.01, sc.problem.initial_packed()
    y1 = be.one_step(sc, variant, h, y0[None])[0]
    gv, gw = sc.problem.forces.decay_factors(h)
    np.testing.assert_allclose(y1[3:6], gv * y0[3:6], rtol=0, atol=tol.BRAX_POSITIONAL_VELOCITY)
    np.testing.assert_allclose(y1[0:3], y0[0:3] + h * gv * y0[3:6], rtol=0, atol=tol.BRAX_HAND_STEP)
    if variant != "positional":
        np.testing.assert_allclose(y1[10:13], gw * y0[10:13], rtol=0, atol=tol.BRAX_HAND_STEP)


# --- runs -------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("variant, name", [("generalized", "spring_pendulum"),
                                           ("generalized", "velocity_decay"),
                                           ("generalized", "applied_torque"), ("spring", "velocity_decay"),
                                           ("positional", "tumbling_box")])
def test_one_step_replays_the_run(variant, name):
    sc = load_scenario(name)
    run = be.simulate(sc, variant, 0.01, 20)
    again = be.one_step(sc, variant, 0.01, run.y[:-1])
    scale = np.maximum(1.0, np.abs(run.y[1:]))
    assert np.max(np.abs(again - run.y[1:]) / scale) < tol.BRAX_REPLAY_REL


def test_simulate_many_is_simulate_and_keeps_the_order():
    sc, sc2 = load_scenario("applied_torque"), load_scenario("tennis_racket")
    reqs = [RunRequest(sc, 0.02, 30), RunRequest(sc2, 0.01, 700), RunRequest(sc, 0.01, 40),
            RunRequest(sc, 0.005, 600)]
    many = be.simulate_many("generalized", reqs)
    for r, run in zip(reqs, many):
        one = be.simulate(r.scenario, "generalized", r.dt_s, r.n_steps)
        assert run.y.shape == (r.n_steps + 1, 13)
        np.testing.assert_allclose(run.y, one.y, rtol=0, atol=tol.BRAX_BATCH)
        np.testing.assert_array_equal(run.t_s, one.t_s)


def test_one_step_runs_of_several_steps_in_one_call_each_take_their_own_step():
    # a world of one-step runs at two Δt is a batch of runs (not the one-step mode, which has one Δt)
    sc = load_scenario("projectile")
    reqs = [RunRequest(sc, 0.01, 1), RunRequest(sc, 0.02, 1)]
    for r, run in zip(reqs, be.simulate_many("generalized", reqs)):
        one = be.simulate(sc, "generalized", r.dt_s, 1)
        np.testing.assert_array_equal(run.t_s, [0.0, r.dt_s])
        np.testing.assert_allclose(run.y, one.y, rtol=0, atol=tol.BRAX_BATCH)


def test_simulate_many_returns_a_refusal_in_place():
    reqs = [RunRequest(load_scenario("projectile"), 0.01, 10),
            RunRequest(load_scenario("linear_drag"), 0.01, 10)]
    ok, refused = be.simulate_many("spring", reqs)
    assert ok.y.shape == (11, 13) and isinstance(refused, be.EngineError)


def test_a_blow_up_is_reported_as_divergence_with_the_rows_before_it():
    sc = scenario_from_parts(initial="position = [0.1, 0.0, 0.0]",
                             forces="[[forces.spring]]\nanchor = [0.0, 0.0, 0.0]\nattach = [0.0, 0.0, 0.0]\n"
                                    "stiffness = 1e6\nrest_length = 0.0", dt=0.01, duration=1.0)
    run = be.simulate(sc, "generalized", 0.01, 100)
    assert run.diverged_at_s is not None and 0.0 < run.diverged_at_s < 0.2
    assert run.message == f"diverged at t = {run.diverged_at_s:.6g} s (state beyond 1e+08)"
    assert len(run.t_s) == round(run.diverged_at_s / 0.01) and np.all(np.abs(run.y) <= 1e8)


def test_the_adapter_reports_its_compile_time_apart_from_stepping():
    from cross_checks.engines import get_adapter
    adapter = get_adapter("brax")
    be.simulate(load_scenario("projectile"), "generalized", 0.01, 3)
    seconds, stats = adapter.per_executable, adapter.timings()
    assert seconds["run:generalized:const:1"] > 0.0 and stats["compile_seconds"] > 0.0
    assert stats["compilations"] >= len(seconds) and stats["step_seconds"] > 0.0 and stats["body_steps"] >= 3


def test_version_and_list_name_brax():
    from cross_checks.cli.parser import _version_text
    from cross_checks.engines import all_variants
    assert "brax 0.14.2 (jax 0.10.2)" in _version_text()
    infos = {v.name: v for v in all_variants()}
    for variant in be.VARIANTS:
        info = infos[f"brax:{variant}"]
        assert info.available and info.order == 1.0 and not info.required


def _checks(variant, scenarios, tmp_path):
    """cross_checks.testing.run_engine_checks in THIS process (jobs = 1): this process has run JAX, and a
    sweep worker forked from it could not (see the test that a process forked after JAX started refuses
    instead of hanging)."""
    from cross_checks.testing import run_engine_checks
    return run_engine_checks(variant, scenarios, cache_dir=tmp_path / "cache", jobs=1)


def test_a_process_forked_after_jax_started_refuses_instead_of_hanging():
    import multiprocessing as mp
    be.simulate(load_scenario("projectile"), "spring", 0.01, 2)      # JAX's backend runs here
    with mp.get_context("fork").Pool(1) as pool:
        words = pool.apply_async(_run_in_child).get(timeout=120)
    assert "brax cannot run in a process forked after JAX started in its parent" in words
    assert "--jobs 1" in words


def _run_in_child():
    try:
        be.simulate(load_scenario("projectile"), "spring", 0.01, 2)
    except be.EngineError as exc:
        return str(exc)
    return "ran"


@pytest.mark.slow
def test_first_order_on_catalog_scenarios(tmp_path):
    summary = _checks("brax:generalized", ["projectile", "applied_torque"], tmp_path)
    fitted = {(c["scenario"], c["quantity"]): c["order"] for c in summary["convergence"]
              if c["verdict"] == "converges"}
    assert fitted[("applied_torque", "orientation")] == pytest.approx(1.0, abs=tol.DRAKE_ORDER_TOL)


@pytest.mark.slow
def test_first_order_where_the_gyroscopic_term_vanishes_without_it(tmp_path):
    for variant in ("brax:spring", "brax:positional"):
        summary = _checks(variant, ["constant_spin", "velocity_decay"], tmp_path)
        fitted = {(c["scenario"], c["quantity"]): c["order"] for c in summary["convergence"]
                  if c["verdict"] == "converges"}
        assert fitted[("velocity_decay", "orientation")] == pytest.approx(1.0, abs=tol.DRAKE_ORDER_TOL)


@pytest.mark.slow
def test_a_real_sweep_forks_two_workers_without_deadlock(tmp_path):
    env = {**os.environ, "MPLBACKEND": "Agg", "RBCHECK_CACHE_DIR": str(tmp_path / "cache")}
    out = subprocess.run([sys.executable, "-m", "cross_checks.cli", "sweep", "projectile", "velocity_decay",
                          "--engines", "brax", "--out", str(tmp_path / "r"), "--no-cache", "--jobs", "2"],
                         capture_output=True, text=True, cwd=ROOT, env=env, timeout=1200)
    assert out.returncode in (0, 1), out.stderr[-2000:]
    import json
    summary = json.loads((tmp_path / "r" / "summary.json").read_text())
    runs = {c["engine"] for c in summary["convergence"] if c["verdict"] not in ("failed", None)}
    assert runs == {f"brax:{v}" for v in be.VARIANTS}
