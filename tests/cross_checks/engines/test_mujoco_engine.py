"""The MuJoCo adapter (cross_checks.engines.mujoco_engine): model, conventions, forces, divergence."""
from __future__ import annotations

import numpy as np
import pytest

from tests.helpers import tolerances as tol

mujoco = pytest.importorskip("mujoco", reason="mujoco is not installed")

from cross_checks.engines import mujoco_engine as me  # noqa: E402
from cross_checks.engines import run_variant  # noqa: E402
from cross_checks.scenario import catalog_path, load_scenario, parse_scenario  # noqa: E402
from reference_sim.ground_truth import ground_truth  # noqa: E402
from reference_sim.quaternion import geodesic_angle, quat_from_axis_angle, quat_from_matrix, quat_mul
from tests.helpers.scenarios import SQ, YAW90  # noqa: E402,F401
from tests.helpers.scenarios import scenario_from_parts as _scenario

# --- model ----------------------------------------------------------------------------------------

def test_version_is_the_pinned_release():
    assert me.version() == mujoco.__version__ == "4.0.0"


def test_model_keeps_the_scenario_body_frame_and_mass_properties():
    sc = load_scenario("particle_body")          # full (non-diagonal) inertia tensor
    m = me.build_model(sc, "euler", 0.002)
    moments, R_BP = sc.problem.body.principal_axes()
    assert m.nbody == 2 and m.njnt == 1 and m.jnt_type[0] == mujoco.mjtJoint.mjJNT_FREE
    assert m.ngeom == 0
    np.testing.assert_array_equal(m.body_ipos[1], 0.0)           # body origin = COM
    np.testing.assert_array_equal(m.body_pos[1], 0.0)
    np.testing.assert_array_equal(m.body_quat[1], [1.0, 0.0, 0.0, 0.0])
    assert m.body_mass[1] == sc.problem.body.mass_kg
    np.testing.assert_allclose(m.body_inertia[1], moments, rtol=1e-15)
    # the inertial frame carries the principal axes: R_BP diag(moments) R_BPᵀ == the scenario tensor
    assert geodesic_angle(quat_from_matrix(R_BP), m.body_iquat[1]) < 1e-15
    R = np.zeros(9)
    mujoco.mju_quat2Mat(R, m.body_iquat[1])
    R = R.reshape(3, 3)
    np.testing.assert_allclose(R @ np.diag(m.body_inertia[1]) @ R.T, sc.problem.body.inertia_B, atol=1e-15)
    assert m.opt.timestep == 0.002
    np.testing.assert_array_equal(m.opt.gravity, [0.0, 0.0, -9.81])
    assert m.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_AUTORESET


@pytest.mark.parametrize("variant, integrator", [("euler", "mjINT_EULER"), ("rk4", "mjINT_RK4"),
                                                 ("implicit", "mjINT_IMPLICIT"),
                                                 ("implicitfast", "mjINT_IMPLICITFAST")])
def test_variant_selects_the_integrator(variant, integrator):
    m = me.build_model(load_scenario("tennis_racket"), variant, 0.001)
    assert m.opt.integrator == getattr(mujoco.mjtIntegrator, integrator)


def test_rejected_model_raises_engine_error_with_mujocos_message():
    from tests.helpers.scenarios import with_body
    sc = with_body(_scenario(), 1e-20, 1e-20)   # below mjMINVAL (the parser refuses it: the Python API path)
    with pytest.raises(me.EngineError, match="mjMINVAL|larger than"):
        me.simulate(sc, "euler", 0.01, 10)
    assert issubclass(me.EngineError, RuntimeError)


# --- conventions ------------------------------------------------------------------------------------

def test_state_round_trip_and_quaternion_order():
    rng = np.random.default_rng(1)
    y = rng.normal(size=(20, 13))
    y[:, 6:10] /= np.linalg.norm(y[:, 6:10], axis=1, keepdims=True)
    qpos, qvel = me.to_qpos_qvel(y)
    np.testing.assert_array_equal(qpos[:, 3:7], y[:, 6:10])          # (w, x, y, z) in both
    np.testing.assert_allclose(me.to_packed(qpos, qvel), y, atol=tol.ADAPTER_ROUND_TRIP * 10)
    for i in range(3):
        np.testing.assert_allclose(me._packed1(qpos[i], qvel[i]), me.to_packed(qpos[i], qvel[i]), atol=tol.ADAPTER_ROUND_TRIP)
    # MuJoCo itself reads qpos[3:7] as (w, x, y, z): its body pose after mj_forward is that rotation
    sc = _scenario(initial=YAW90)
    m = me.build_model(sc, "euler", 0.01)
    d = mujoco.MjData(m)
    d.qpos[:], d.qvel[:] = me.to_qpos_qvel(sc.problem.initial_packed())
    mujoco.mj_forward(m, d)
    np.testing.assert_allclose(d.xmat[1].reshape(3, 3), [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=tol.ADAPTER_ROUND_TRIP)


def test_yawed_body_spinning_about_body_x_reads_world_y():
    """Body yawed 90° about z, spinning about its BODY x axis: world angular velocity is +y, qvel holds
    the body-axes (1, 0, 0), and MuJoCo turns the body about world y."""
    sc = _scenario(initial=YAW90 + "\nangular_velocity_body = [1.0, 0.0, 0.0]")
    y0 = sc.problem.initial_packed()
    np.testing.assert_allclose(y0[10:13], [0.0, 1.0, 0.0], atol=tol.ADAPTER_ROUND_TRIP)
    _, qvel = me.to_qpos_qvel(y0)
    np.testing.assert_allclose(qvel[3:6], [1.0, 0.0, 0.0], atol=tol.ADAPTER_ROUND_TRIP)
    run = me.simulate(sc, "euler", 0.01, 100)                       # principal-axis spin: exact
    np.testing.assert_allclose(run.y[:, 10:13], np.tile([0.0, 1.0, 0.0], (101, 1)), atol=tol.ADAPTER_SPIN_100_STEPS)
    expected = quat_mul(quat_from_axis_angle(np.array([0.0, 1.0, 0.0]), run.t_s), y0[6:10])
    assert np.max(geodesic_angle(expected, run.y[:, 6:10])) < tol.ADAPTER_SPIN_100_STEPS


def test_linear_velocity_and_position_are_the_coms():
    """A spinning, tumbling body with no force: the reported position moves at the constant velocity
    (it would wobble if it were a point other than the COM)."""
    sc = load_scenario("particle_body")
    sc = _scenario(body="particles = " + str(sc.raw["body"]["particles"]),
                   initial="velocity = [0.5, -0.2, 4.0]\nangular_velocity = [1.0, 2.0, -0.5]", dt=0.01)
    run = me.simulate(sc, "euler", 0.01, 100)
    n = np.arange(101)[:, None]
    np.testing.assert_allclose(run.y[:, 0:3], 0.01 * n * np.array([0.5, -0.2, 4.0]), atol=1e-13)
    np.testing.assert_allclose(run.y[:, 3:6], np.tile([0.5, -0.2, 4.0], (101, 1)), rtol=0, atol=tol.ADAPTER_ROUND_TRIP * 4)


@pytest.mark.parametrize("variant", sorted(me.VARIANTS))
def test_one_step_replays_the_run(variant):
    for name in ("applied_torque", "particle_body", "velocity_decay"):
        sc = load_scenario(name)
        run = me.simulate(sc, variant, sc.dt_s, 30)
        y1 = me.one_step(sc, variant, sc.dt_s, run.y[:-1])
        np.testing.assert_allclose(y1, run.y[1:], rtol=0, atol=tol.ADAPTER_ONE_STEP_REPLAY * 10)


# --- forces and RK4 ---------------------------------------------------------------------------------

def test_tennis_racket_rk4_matches_ground_truth():
    sc = load_scenario("tennis_racket")
    run = me.simulate(sc, "rk4", 1e-3, sc.n_steps(1e-3))
    gt = ground_truth(sc.problem, run.t_s)
    assert run.diverged_at_s is None
    assert np.max(geodesic_angle(gt[:, 6:10], run.y[:, 6:10])) < tol.MJ_RK4_VS_GROUND_TRUTH
    assert np.max(np.abs(gt[:, 10:13] - run.y[:, 10:13])) < tol.MJ_RK4_VS_GROUND_TRUTH


def _final_errors(sc, ladder, T):
    gt = ground_truth(sc.problem, np.array([0.0, T]))[-1]
    pos, ori = [], []
    for h in ladder:
        y = me.simulate(sc, "rk4", h, int(round(T / h))).y[-1]
        pos.append(np.linalg.norm(y[0:3] - gt[0:3]))
        ori.append(geodesic_angle(gt[6:10], y[6:10]))
    return np.array(pos), np.array(ori)


def _order(ladder, err):
    return np.polyfit(np.log(ladder), np.log(err), 1)[0]


# Ladders whose errors stay well above round-off: applied_torque's RK4 error is already at round-off
# (1e-12) at its catalog ladder (4e-3 ... 2.5e-4), so its order is measured at larger steps.
AT_LADDER = [0.1, 0.05, 0.025]
SP_LADDER = [0.004, 0.002, 0.001]


def test_rk4_keeps_fourth_order_with_state_dependent_forces():
    _, ori = _final_errors(load_scenario("applied_torque"), AT_LADDER, 1.0)
    assert abs(_order(AT_LADDER, ori) - 4.0) < tol.MJ_RK4_ORDER_TOL, ori
    pos, ori = _final_errors(load_scenario("spring_pendulum"), SP_LADDER, 1.0)
    assert abs(_order(SP_LADDER, pos) - 4.0) < tol.MJ_RK4_ORDER_TOL, pos
    assert abs(_order(SP_LADDER, ori) - 4.0) < tol.MJ_RK4_ORDER_TOL, ori


def test_rk4_with_forces_held_over_the_step_is_first_order(monkeypatch):
    """Why the stage callback exists: xfrc_applied set once per step is held fixed in world axes over
    the 4 stages, and a state-dependent force or body torque then costs RK4 its order."""
    monkeypatch.setattr(me, "_RK4_STAGE_FORCES", False)
    _, ori = _final_errors(load_scenario("applied_torque"), AT_LADDER, 1.0)
    assert abs(_order(AT_LADDER, ori) - 1.0) < tol.MJ_HELD_ORDER_TOL, ori


def test_global_callbacks_are_cleared_during_runs_and_restored():
    """A user's control/passive callback neither breaks the compile (any Python callback there makes
    MjSpec.compile fail) nor adds forces to the adapter's body; both are restored afterwards, and the
    adapter's own RK4 stage callback is gone after the run."""
    calls = []

    def user_cb(m, d):
        calls.append(1)
        d.qfrc_applied[:] = 1e3          # would wreck the run if it were called

    assert mujoco.get_mjcb_control() is None
    sc = load_scenario("spring_pendulum")
    mujoco.set_mjcb_control(user_cb)
    mujoco.set_mjcb_passive(user_cb)
    try:
        with_user_cb = {}
        for variant in ("rk4", "euler"):
            with_user_cb[variant] = me.simulate(sc, variant, 0.01, 5).y
            assert calls == []
            assert mujoco.get_mjcb_control() is user_cb and mujoco.get_mjcb_passive() is user_cb
            assert mujoco.get_mju_user_warning() is None
    finally:
        mujoco.set_mjcb_control(None)
        mujoco.set_mjcb_passive(None)
    for variant, y in with_user_cb.items():
        np.testing.assert_array_equal(y, me.simulate(sc, variant, 0.01, 5).y)
    assert mujoco.get_mjcb_control() is None and mujoco.get_mjcb_passive() is None


def test_exception_inside_the_stage_callback_is_reported_and_cleaned_up(monkeypatch):
    def boom(scenario, y):
        raise ZeroDivisionError("boom")

    monkeypatch.setattr(me, "stage_force_torque_floats", boom)
    with pytest.raises(me.EngineError, match="boom"):
        me.simulate(load_scenario("spring_pendulum"), "rk4", 0.01, 5)
    assert mujoco.get_mjcb_control() is None
    assert mujoco.get_mju_user_warning() is None


# --- divergence ---------------------------------------------------------------------------------------

def test_fast_spin_diverges_and_is_reported_without_log_file(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    text = catalog_path("tennis_racket").read_text().replace(
        "angular_velocity = [0.01, 2.0, 0.01]", "angular_velocity = [0.1, 20.0, 0.1]")
    sc = parse_scenario(text)
    traj = run_variant(sc, "mujoco:euler", dt_s=1e-2, duration_s=10.0)
    assert traj.meta["status"] == "diverged"
    # ENGINE_FACTS: MuJoCo flags the QACC at t = 8.65 s, i.e. the state after that step (8.66 s) is bad
    assert traj.meta["diverged_at_s"] == pytest.approx(8.66)
    assert "QACC" in traj.meta["message"] and "diverged at t = 8.66 s" in traj.meta["message"]
    assert np.all(np.isfinite(traj.y)) and len(traj.t_s) == 866
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()
    assert list(tmp_path.iterdir()) == []
    # the same in the implicit schemes stays bounded (implicit gyroscopic term)
    assert run_variant(sc, "mujoco:implicitfast", dt_s=1e-2, duration_s=10.0).meta["status"] == "ok"


@pytest.mark.parametrize("variant", ["euler", "rk4", "implicit", "implicitfast"])
@pytest.mark.parametrize("name", ["tennis_racket", "particle_body", "projectile"])
def test_rollout_path_is_bit_identical_to_the_mj_step_loop(monkeypatch, name, variant):
    sc = load_scenario(name)
    n = min(sc.n_steps(), 3000)
    fast = me.simulate(sc, variant, sc.dt_s, n)
    monkeypatch.setattr(me, "USE_ROLLOUT", False)
    loop = me.simulate(sc, variant, sc.dt_s, n)
    assert np.array_equal(fast.y, loop.y) and np.array_equal(fast.t_s, loop.t_s)


def test_rollout_path_reports_divergence_like_the_loop(monkeypatch):
    sc = parse_scenario(FAST_SPIN_FOR_ROLLOUT, "fast.toml")
    fast = me.simulate(sc, "euler", 0.01, 2000)
    monkeypatch.setattr(me, "USE_ROLLOUT", False)
    loop = me.simulate(sc, "euler", 0.01, 2000)
    assert fast.diverged_at_s == loop.diverged_at_s and fast.diverged_at_s is not None
    assert np.array_equal(fast.y, loop.y)


FAST_SPIN_FOR_ROLLOUT = """
name = "fast_spin"
duration = 20.0
dt = 0.01
[body]
mass = 1.0
inertia = [1.0, 2.0, 3.0]
[initial]
angular_velocity = [0.1, 20.0, 0.1]
"""


def test_runs_on_lent_models_reuse_one_mjdata_per_layout_with_a_fresh_ones_numbers():
    """models_from: the runs reuse one MjData per model layout (reset with mj_resetData) instead of allocating
    one per run; every run and one-step batch is still the one on a new model and a new MjData, bit for bit,
    whichever body (diagonal or rotated inertia, any force kind) the reused MjData served before."""
    from cross_checks.fuzz import generate
    from cross_checks.fuzz.pipeline import scenario_of
    scs = [scenario_of(generate.draw(47, i).spec(0.004, 8)) for i in range(10)]
    assert {sc.problem.body.is_diagonal() for sc in scs} == {True, False}
    models = {}

    def lend(sc, variant, h):
        key = (id(sc), variant, h)
        if key not in models:
            models[key] = me.build_model(sc, variant, h)
        return models[key]
    for variant in sorted(me.VARIANTS):
        want = [(me.simulate(sc, variant, sc.dt_s, 12).y,
                 me.one_step(sc, variant, sc.dt_s, sc.problem.initial_packed()[None])) for sc in scs]
        me._LENT_DATA.clear()
        with me.models_from(lend):
            for _ in range(2):
                for sc, (y, y1) in zip(scs[::-1], want[::-1]):
                    assert np.array_equal(me.simulate(sc, variant, sc.dt_s, 12).y, y), (variant, sc.name)
                    assert np.array_equal(me.one_step(sc, variant, sc.dt_s, sc.problem.initial_packed()[None]), y1)
        assert len(me._LENT_DATA) == 2


def test_a_one_step_batch_after_the_run_on_the_same_model_is_the_one_on_a_new_model():
    """A job's one-step batch after its free run (same scenario, variant, step) reuses the compiled model and
    its reset MjData: the numbers of a new model, bit for bit; another scenario, variant or step compiles."""
    sc, other = load_scenario("spring_pendulum"), load_scenario("tumbling_box")
    ys = me.simulate(sc, "rk4", 0.004, 40).y[::5]
    for variant in ("rk4", "euler"):
        me.simulate(other, variant, 0.004, 5)
        fresh = me.one_step(sc, variant, 0.004, ys)             # after another scenario's run: compiled anew
        me.simulate(sc, variant, 0.004, 40)
        model = me._LAST.run[4]
        assert np.array_equal(me.one_step(sc, variant, 0.004, ys), fresh)
        assert me._LAST.run[4] is model                            # the run's model, reused
        me.one_step(sc, variant, 0.002, ys)
        assert me._LAST.run[4] is not model                        # another step: compiled
