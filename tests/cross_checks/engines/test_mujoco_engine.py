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
                                                 ("implicitfast", "mjINT_IMPLICITFAST"),
                                                 ("discrete", "mjINT_DISCRETE")])
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
        np.testing.assert_allclose(me.packed_floats(qpos[i].tolist(), qvel[i].tolist()),
                                   me.to_packed(qpos[i], qvel[i]), atol=tol.ADAPTER_ROUND_TRIP)
    # MuJoCo itself reads qpos[3:7] as (w, x, y, z): its body pose after mj_forward is that rotation
    sc = _scenario(initial=YAW90)
    m = me.build_model(sc, "euler", 0.01)
    d = mujoco.MjData(m)
    d.qpos[:], d.qvel[:] = me.to_qpos_qvel(sc.problem.initial_packed())
    mujoco.mj_forward(m, d)
    np.testing.assert_allclose(d.xmat[1].reshape(3, 3), [[0, -1, 0], [1, 0, 0], [0, 0, 1]],
                               atol=tol.ADAPTER_ROUND_TRIP)


def test_yawed_body_spinning_about_body_x_reads_world_y():
    """Body yawed 90° about z, spinning about its BODY x axis: world angular velocity is +y, qvel holds
    the body-axes (1, 0, 0), and MuJoCo turns the body about world y."""
    sc = _scenario(initial=YAW90 + "\nangular_velocity_body = [1.0, 0.0, 0.0]")
    y0 = sc.problem.initial_packed()
    np.testing.assert_allclose(y0[10:13], [0.0, 1.0, 0.0], atol=tol.ADAPTER_ROUND_TRIP)
    _, qvel = me.to_qpos_qvel(y0)
    np.testing.assert_allclose(qvel[3:6], [1.0, 0.0, 0.0], atol=tol.ADAPTER_ROUND_TRIP)
    run = me.simulate(sc, "euler", 0.01, 100)                       # principal-axis spin: exact
    np.testing.assert_allclose(run.y[:, 10:13], np.tile([0.0, 1.0, 0.0], (101, 1)),
                               atol=tol.ADAPTER_SPIN_100_STEPS)
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
    np.testing.assert_allclose(run.y[:, 3:6], np.tile([0.5, -0.2, 4.0], (101, 1)),
                               rtol=0, atol=tol.ADAPTER_ROUND_TRIP * 4)


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
def test_rollout_runs_are_bit_identical_to_the_mj_step_loop(name, variant):
    from cross_checks.engines.base import RunRequest
    sc = load_scenario(name)
    n = min(sc.n_steps(), 3000)
    fast = me.MujocoAdapter().simulate_many(variant, [RunRequest(sc, sc.dt_s, n)])[0]
    loop = me.simulate(sc, variant, sc.dt_s, n)
    assert np.array_equal(fast.y, loop.y) and np.array_equal(fast.t_s, loop.t_s)


def test_runs_of_one_scenario_in_a_row_take_its_model_with_a_new_models_numbers():
    """A scenario's next world (a job's one-step batch after its free run, a fuzz case's rungs) takes the
    model compiled for its previous one, set to its own integrator and step, with a new MjData: the numbers of
    a new model, bit for bit; another scenario compiles."""
    sc, other = load_scenario("spring_pendulum"), load_scenario("tumbling_box")
    ys = me.simulate(sc, "rk4", 0.004, 40).y[::5]
    for variant in ("rk4", "euler"):
        me._LAST.models = []
        fresh = me.one_step(sc, variant, 0.004, ys)             # compiled anew
        model = me._model([sc] * len(ys), variant, 0.004)
        me.simulate(sc, "implicit", 0.002, 40)
        me.simulate(other, variant, 0.004, 5)
        assert np.array_equal(me.one_step(sc, variant, 0.004, ys), fresh)
        assert me._model([sc] * len(ys), variant, 0.004) is model  # the scenario's model, reused
        assert me._model(other, variant, 0.004) is not model       # another scenario: its own


# --- many runs in one call (simulate_many) ------------------------------------------------------------

def _fuzz_cases(n=6):
    from cross_checks.fuzz import generate
    from cross_checks.fuzz.pipeline import scenario_of
    return [scenario_of(generate.draw(31, i).spec(0.005 * (1 + i % 2), 8)) for i in range(n)]


def _ladder_requests(scs, rungs=3):
    from cross_checks.engines.base import RunRequest
    return [RunRequest(sc, sc.dt_s / 2 ** r, 8 * 2 ** r) for r in range(rungs) for sc in scs]


def test_many_runs_in_one_call_are_the_adapters_runs_bit_for_bit_whatever_ran_before():
    """One compiled model per scenario, switched between integrators and steps in place: every variant's
    runs (three steps of each case, several rollout rounds) and its one steps at four steps of each case are
    simulate's and one_step's on a freshly compiled model, bit for bit, whichever variant ran before."""
    import copy
    scs = _fuzz_cases(4)
    assert (any(sc.problem.forces.state_dependent for sc in scs)
            and any(sc.problem.forces.has_decay for sc in scs))
    assert any(not sc.problem.body.is_diagonal() for sc in scs)
    adapter = me.MujocoAdapter()
    for variant in ("implicit", "rk4", "euler", "implicitfast", "implicit"):
        requests = _ladder_requests(scs)
        got = adapter.simulate_many(variant, requests)
        for r, run in zip(requests, got):
            want = me.simulate(copy.deepcopy(r.scenario), variant, r.dt_s, r.n_steps)
            assert run.diverged_at_s is None and np.array_equal(run.t_s, want.t_s), (variant, r)
            assert np.array_equal(run.y, want.y), (variant, r)
        for sc in scs:
            for k in range(4):
                y = sc.problem.initial_packed()[None, :]
                assert np.array_equal(adapter.one_step(sc, variant, sc.dt_s / 2 ** k, y),
                                      me.one_step(copy.deepcopy(sc), variant,
                                                  sc.dt_s / 2 ** k, y)), (variant, k)


def test_members_that_blow_up_diverge_where_simulate_says_and_leave_the_others_alone():
    from cross_checks.engines.base import RunRequest
    from tests.helpers.scenarios import with_initial
    scs = _fuzz_cases(3)
    fast = with_initial(scs[0], v_W=[1e9, 0.0, 0.0])   # beyond BLOWUP_LIMIT after one step
    requests = [RunRequest(sc, sc.dt_s, 8) for sc in (scs[1], fast, scs[2])]
    got = me.MujocoAdapter().simulate_many("euler", requests)
    want = [me.simulate(r.scenario, "euler", r.dt_s, r.n_steps) for r in requests]
    assert got[1].diverged_at_s == want[1].diverged_at_s is not None and got[1].message == want[1].message
    for g, w in zip(got, want):
        assert np.array_equal(g.y, w.y)


def test_a_model_mujoco_rejects_is_that_members_engine_error(monkeypatch):
    from cross_checks.engines.base import EngineError
    scs = _fuzz_cases(3)
    spec = me.body_spec

    def rejecting(body):
        if body is scs[1].problem.body:
            raise EngineError("rejected here")
        return spec(body)
    monkeypatch.setattr(me, "body_spec", rejecting)
    monkeypatch.setattr(me._LAST, "models", [])
    requests = _ladder_requests(scs, rungs=2)
    got = me.MujocoAdapter().simulate_many("euler", requests)
    for r, run in zip(requests, got):
        if r.scenario is scs[1]:
            assert isinstance(run, EngineError) and "rejected here" in str(run)
        else:
            assert np.array_equal(run.y, me.simulate(r.scenario, "euler", r.dt_s, r.n_steps).y)


@pytest.mark.parametrize("name", ["tennis_racket", "spring_pendulum", "velocity_decay", "particle_body"])
def test_discrete_takes_implicitfasts_step_on_a_lone_free_body(name):
    # MuJoCo's discrete integrator solves the constraints and the implicit velocity update in one, in the
    # metric M + hD + h²K; with no joint, constraint, damping or stiffness that is implicitfast's step, bit
    # for bit (torque-free tumble, a spring off the COM, decay through the harness, body-frame forces)
    sc = load_scenario(name)
    n = sc.n_steps(sc.dt_s)
    a, b = me.simulate(sc, "implicitfast", sc.dt_s, n), me.simulate(sc, "discrete", sc.dt_s, n)
    assert np.array_equal(a.y, b.y) and np.any(a.y[-1] != a.y[0])


def test_moments_beyond_the_triangle_by_round_off_only_are_put_on_it():
    """A flat body's moments (A + B = C) come back from an eigen-decomposition a few ε beyond the boundary,
    which MuJoCo refuses: they are put on it; a body beyond it by more is left for MuJoCo to refuse."""
    eps = np.finfo(float).eps
    np.testing.assert_array_equal(me.on_the_triangle([1.0, 2.0, 3.0 * (1 + 2 * eps)]), [1.0, 2.0, 3.0])
    np.testing.assert_array_equal(me.on_the_triangle([1.0, 2.0, 3.1]), [1.0, 2.0, 3.1])
    np.testing.assert_array_equal(me.on_the_triangle([1.0, 2.0, 2.5]), [1.0, 2.0, 2.5])


@pytest.mark.parametrize("variant", sorted(me.VARIANTS))
def test_a_world_of_many_bodies_steps_from_python_and_gives_each_run_alone_bit_for_bit(variant, monkeypatch):
    """From STEP_LOOP_BODIES bodies on, a world whose forces are constant steps with mj_step from Python
    instead of mujoco.rollout (faster for many bodies): every run of such a world equals the same run
    alone (a world of one body: mujoco.rollout) bit for bit, a body torque included."""
    from cross_checks.engines.base import RunRequest
    text = catalog_path("applied_torque").read_text()
    torque_only = parse_scenario(text[:text.index("[[forces.point]]")], "<body torque only>")
    # one gravity (a world has one): the body-torque scenario, a projectile and a particle body
    scs = [torque_only, load_scenario("projectile"), load_scenario("particle_body")]
    assert not any(sc.problem.forces.has_decay or me.host_problem(sc.problem, True).forces.state_dependent
                   for sc in scs)
    reqs = [RunRequest(scs[k % len(scs)], 0.002, 60) for k in range(me.STEP_LOOP_BODIES + 3)]
    from mujoco import rollout
    rolled = []
    original = rollout.rollout
    monkeypatch.setattr(rollout, "rollout",
                        lambda m, *a, **k: rolled.append(m.nq // 7) or original(m, *a, **k))
    many = me.simulate_many(variant, reqs)
    assert rolled == []                     # the many bodies: the loop's steps
    for r, run in zip(reqs, many):
        alone = me.simulate(r.scenario, variant, r.dt_s, r.n_steps)
        assert np.array_equal(run.y, alone.y) and run.diverged_at_s == alone.diverged_at_s, r.scenario.name
    assert rolled == [1] * len(reqs)        # a world of one body: mujoco.rollout
