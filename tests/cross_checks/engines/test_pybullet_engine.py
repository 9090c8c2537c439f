"""The PyBullet adapter (cross_checks.engines.pybullet_engine): settings, conventions, forces, divergence."""
from __future__ import annotations

import numpy as np
import pytest

from cross_checks.core.tolerances import SAME_SCHEME_REL
from tests.helpers import tolerances as tol

p = pytest.importorskip("pybullet", reason="pybullet is not installed")

from cross_checks.engines import pybullet_engine as pe  # noqa: E402
from cross_checks.engines import run_variant  # noqa: E402
from cross_checks.engines.worlds import pybullet as pbw  # noqa: E402
from cross_checks.scenario import catalog_path, load_scenario, parse_scenario  # noqa: E402
from reference_sim.quaternion import geodesic_angle, quat_from_axis_angle, quat_mul  # noqa: E402
from tests.helpers.scenarios import SQ, YAW90  # noqa: E402,F401
from tests.helpers.scenarios import scenario_from_parts as _scenario
from tests.helpers.wrong_engines import BulletBody  # noqa: E402

Q_TILT = np.array([0.9, 0.1, 0.3, -0.2]) / np.linalg.norm([0.9, 0.1, 0.3, -0.2])


def test_version_and_engine_error():
    assert pe.version().startswith("3.2.7")
    assert issubclass(pe.EngineError, RuntimeError)


def test_one_client_per_process_and_a_clean_world_per_run():
    c1 = pe._connect()
    pe.simulate(load_scenario("projectile"), "multibody", 0.01, 3)
    pe.simulate(load_scenario("projectile"), "maximal", 0.01, 3)
    assert pe._connect() == c1
    assert p.getNumBodies(physicsClientId=c1) == 1
    params = p.getPhysicsEngineParameters(physicsClientId=c1)
    assert params["fixedTimeStep"] == 0.01 and params["numSubSteps"] == 0
    assert params["gravityAccelerationZ"] == -9.81


@pytest.mark.parametrize("variant", sorted(pe.VARIANTS))
def test_body_settings(variant):
    sc = load_scenario("tumbling_box")
    B = BulletBody(sc, variant, 0.001, sc.problem.initial_packed())
    info = p.getDynamicsInfo(B.b, -1, physicsClientId=B.c)
    assert info[0] == 10.0                                                   # mass
    np.testing.assert_array_equal(info[2], np.diag(sc.problem.body.inertia_B))   # local inertia diagonal
    # (getDynamicsInfo does not report linear/angular damping; the projectile test below proves it is 0)


# --- conventions ------------------------------------------------------------------------------------

@pytest.mark.parametrize("variant", sorted(pe.VARIANTS))
def test_yawed_body_spinning_about_body_x_reads_world_y(variant):
    sc = _scenario(body="mass = 1.0\ninertia = [1.0, 1.0, 1.0]",
                   initial=YAW90 + "\nangular_velocity_body = [1.0, 0.0, 0.0]")
    run = pe.simulate(sc, variant, 0.01, 100)
    np.testing.assert_allclose(run.y[:, 10:13], np.tile([0.0, 1.0, 0.0], (101, 1)),
                               atol=tol.ADAPTER_SPIN_100_STEPS)
    expected = quat_mul(quat_from_axis_angle(np.array([0.0, 1.0, 0.0]), run.t_s), run.y[0, 6:10])
    assert np.max(geodesic_angle(expected, run.y[:, 6:10])) < tol.ADAPTER_SPIN_100_STEPS
    # PyBullet's own angular velocity is in world axes (getBaseVelocity), no conversion involved
    raw = BulletBody(sc, variant, 0.01, sc.problem.initial_packed())
    raw.set_state(sc.problem.initial_packed())
    np.testing.assert_allclose(p.getBaseVelocity(raw.b, physicsClientId=raw.c)[1],
                               [0.0, 1.0, 0.0], atol=tol.ADAPTER_ROUND_TRIP)


def test_quaternion_order_at_the_boundary():
    sc = _scenario(initial=YAW90)
    B = BulletBody(sc, "multibody", 0.01, sc.problem.initial_packed())
    B.set_state(sc.problem.initial_packed())
    orn = p.getBasePositionAndOrientation(B.b, physicsClientId=B.c)[1]
    np.testing.assert_allclose(orn, [0.0, 0.0, SQ, SQ], atol=tol.ADAPTER_ROUND_TRIP)            # (x, y, z, w)
    R = np.array(p.getMatrixFromQuaternion(orn)).reshape(3, 3)
    np.testing.assert_allclose(R, [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=tol.ADAPTER_ROUND_TRIP)
    np.testing.assert_allclose(B.raw_to_packed(B.read_raw()),
                               sc.problem.initial_packed(), atol=tol.ADAPTER_ROUND_TRIP)


@pytest.mark.parametrize("variant", sorted(pe.VARIANTS))
def test_full_tensor_reports_the_scenario_body_frame(variant):
    """PyBullet holds the principal frame P; the adapter reports q_WB = q_WP q_BP⁻¹."""
    sc = load_scenario("particle_body")
    y0 = sc.problem.initial_packed()
    B = BulletBody(sc, variant, 0.001, y0)
    B.set_state(y0)
    q_WP = np.roll(p.getBasePositionAndOrientation(B.b, physicsClientId=B.c)[1], 1)
    assert geodesic_angle(q_WP, quat_mul(y0[6:10], B.q_BP)) < tol.ADAPTER_ROUND_TRIP * 10
    assert geodesic_angle(q_WP, y0[6:10]) > 0.1                # P really differs from B here
    run = pe.simulate(sc, variant, 0.001, 10)
    assert geodesic_angle(run.y[0, 6:10], y0[6:10]) < tol.ADAPTER_ROUND_TRIP * 10


def test_linear_velocity_and_position_are_the_coms():
    sc = load_scenario("particle_body")
    sc = _scenario(body="particles = " + str(sc.raw["body"]["particles"]),
                   initial="velocity = [0.5, -0.2, 4.0]\nangular_velocity = [1.0, 2.0, -0.5]")
    for variant in pe.VARIANTS:
        run = pe.simulate(sc, variant, 0.01, 100)
        n = np.arange(101)[:, None]
        np.testing.assert_allclose(run.y[:, 0:3], 0.01 * n * np.array([0.5, -0.2, 4.0]), atol=1e-13)
        np.testing.assert_allclose(run.y[:, 3:6], np.tile([0.5, -0.2, 4.0], (101, 1)),
                                   rtol=0, atol=tol.ADAPTER_ROUND_TRIP * 4)


# --- PyBullet's traps the adapter works around ------------------------------------------------------------

def _projectile_error(run, h):
    sc = load_scenario("projectile")
    n = np.arange(len(run.t_s))[:, None]
    x = (sc.problem.initial.x_W + n * h * sc.problem.initial.v_W
         + np.array([0, 0, -9.81]) * h * h * n * (n + 1) / 2)
    return float(np.max(np.abs(run.y[:, 0:3] - x)))


def test_default_multibody_damping_fails_projectile_and_adapter_settings_pass(monkeypatch):
    sc = load_scenario("projectile")
    assert _projectile_error(pe.simulate(sc, "multibody", 0.01, 100), 0.01) < tol.PYB_PROJECTILE_EXACT
    monkeypatch.setattr(pbw, "DYNAMICS_SETTINGS", {})      # PyBullet's defaults (damping 0.04, clamp 100)
    err = _projectile_error(pe.simulate(sc, "multibody", 0.01, 100), 0.01)
    assert err > tol.PYB_DEFAULT_DAMPING_MIN_ERROR
    # maximal-coordinate bodies have no default damping
    assert _projectile_error(pe.simulate(sc, "maximal", 0.01, 100), 0.01) < tol.PYB_PROJECTILE_EXACT


def test_default_multibody_velocity_clamp_is_lifted(monkeypatch):
    sc = _scenario(body="mass = 1.0\ninertia = [1.0, 1.0, 1.0]",
                   initial="velocity = [150.0, 0.0, 0.0]\nangular_velocity = [0.0, 0.0, 150.0]")
    run = pe.simulate(sc, "multibody", 0.01, 2)
    np.testing.assert_array_equal(run.y[-1, [3, 12]], [150.0, 150.0])
    monkeypatch.setattr(pbw, "DYNAMICS_SETTINGS", {"linearDamping": 0.0, "angularDamping": 0.0})
    run = pe.simulate(sc, "multibody", 0.01, 2)
    np.testing.assert_allclose(run.y[-1, [3, 12]], [100.0, 100.0])   # clamped by PyBullet


def test_maximal_pose_reset_zeroes_velocity_so_velocity_is_reset_last():
    sc = _scenario()
    B = BulletBody(sc, "maximal", 0.01, sc.problem.initial_packed())
    p.resetBaseVelocity(B.b, [1.0, 0.0, 0.0], [0.0, 0.0, 1.0], physicsClientId=B.c)
    p.resetBasePositionAndOrientation(B.b, [0, 0, 0], [0, 0, 0, 1], physicsClientId=B.c)
    assert np.all(np.array(p.getBaseVelocity(B.b, physicsClientId=B.c)) == 0.0)
    y = sc.problem.initial_packed()
    y[3:6], y[10:13] = [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]
    B.set_state(y)
    np.testing.assert_array_equal(p.getBaseVelocity(B.b, physicsClientId=B.c),
                                  ([1.0, 0.0, 0.0], [0.0, 0.0, 1.0]))


@pytest.mark.parametrize("variant", sorted(pe.VARIANTS))
def test_external_force_is_cleared_after_each_step(variant):
    sc = _scenario()
    B = BulletBody(sc, variant, 0.01, sc.problem.initial_packed())
    B.set_state(sc.problem.initial_packed())
    B.apply(np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 3.0]), [0.0, 0.0, 0.0])
    p.stepSimulation(physicsClientId=B.c)
    v1 = B.read_raw()
    p.stepSimulation(physicsClientId=B.c)
    v2 = B.read_raw()
    np.testing.assert_allclose(v1[3], 0.01, rtol=1e-14)          # one step of 1 N on 1 kg
    np.testing.assert_allclose(v1[12], 0.01, rtol=1e-14)         # one step of 3 N m about I_zz = 3
    assert v2[3] == v1[3]                                        # nothing applied in the second step
    # (maximal: implicit gyro round-off)
    np.testing.assert_allclose(v2[12], v1[12], rtol=tol.ADAPTER_ROUND_TRIP * 4)


@pytest.mark.parametrize("variant", sorted(pe.VARIANTS))
def test_one_step_replays_the_run(variant):
    for name in ("applied_torque", "particle_body", "velocity_decay", "spring_pendulum"):
        sc = load_scenario(name)
        run = pe.simulate(sc, variant, sc.dt_s, 30)
        y1 = pe.one_step(sc, variant, sc.dt_s, run.y[:-1])
        np.testing.assert_allclose(y1, run.y[1:], rtol=0, atol=tol.ADAPTER_ONE_STEP_REPLAY * 10)


# --- divergence ---------------------------------------------------------------------------------------

def test_fast_spin_multibody_diverges_maximal_does_not():
    text = catalog_path("tennis_racket").read_text().replace(
        "angular_velocity = [0.01, 2.0, 0.01]", "angular_velocity = [0.1, 20.0, 0.1]")
    sc = parse_scenario(text)
    traj = run_variant(sc, "pybullet:multibody", dt_s=1e-2, duration_s=10.0)
    assert traj.meta["status"] == "diverged"
    assert 8.5 < traj.meta["diverged_at_s"] < 8.8   # explicit gyroscopic term, like MuJoCo Euler (8.66 s)
    assert traj.meta["message"].startswith("diverged at t = ")
    assert np.all(np.isfinite(traj.y)) and np.max(np.abs(traj.y)) <= 1e8
    assert run_variant(sc, "pybullet:maximal", dt_s=1e-2, duration_s=10.0).meta["status"] == "ok"


# --- many runs in one call (simulate_many) and the kept body -------------------------------------------

def _fuzz_cases(n=12):
    from cross_checks.fuzz import generate
    from cross_checks.fuzz.pipeline import scenario_of
    scs = [scenario_of(generate.draw(47, i).spec(0.004 * (1 + i % 3), 8)) for i in range(n)]
    kinds = {f for i in range(n) for f in generate.draw(47, i).kinds["forces"]}
    assert len(kinds) >= 7 and any(not sc.problem.body.is_diagonal() for sc in scs)
    return scs


@pytest.mark.parametrize("variant", ["multibody", "maximal"])
def test_many_runs_in_one_call_are_the_adapters_runs_bit_for_bit_whatever_ran_before(variant):
    from cross_checks.engines.base import RunRequest
    scs = _fuzz_cases()
    # each scenario's runs on its kept body, after a different previous body in the same world
    requests = [RunRequest(sc, h, n) for sc in scs + scs[::-1] for h, n in ((sc.dt_s, 8), (sc.dt_s / 4, 32))]
    got = pe.PybulletAdapter().simulate_many(variant, requests)
    for r, run in zip(requests, got):
        want = pe.simulate(r.scenario, variant, r.dt_s, r.n_steps)
        assert want.diverged_at_s is None and np.array_equal(run.y, want.y), r.scenario.name


@pytest.mark.parametrize("variant", ["multibody", "maximal"])
def test_a_body_kept_for_the_runs_of_its_case_gives_the_runs_of_a_new_body(variant):
    """Free runs and one steps of a case at other steps, in any order, interleaved, on the body kept from
    the case's previous run, are those of a new body in a reset world (a copy of the scenario is another
    scenario: it never takes the kept body), bit for bit."""
    import copy

    from cross_checks.engines.base import RunRequest
    scs = _fuzz_cases()
    rng = np.random.default_rng(5)
    adapter = pe.PybulletAdapter()
    for sc in scs:
        for kind, h in (("run", sc.dt_s), ("step", sc.dt_s / 8), ("run", sc.dt_s / 2), ("step", sc.dt_s),
                        ("run", sc.dt_s / 4), ("run", sc.dt_s)):
            if kind == "run":
                n = int(round(8 * sc.dt_s / h))
                got = adapter.simulate_many(variant, [RunRequest(sc, h, n)])[0].y
                want = pe.simulate(copy.deepcopy(sc), variant, h, n).y
                # keeps sc's body again
                adapter.one_step(sc, variant, h, sc.problem.initial_packed()[None, :])
            else:
                y = sc.problem.initial_packed() + 0.05 * rng.standard_normal((3, 13))
                y[:, 6:10] /= np.linalg.norm(y[:, 6:10], axis=1, keepdims=True)
                got = adapter.one_step(sc, variant, h, y)
                want = adapter.one_step(copy.deepcopy(sc), variant, h, y)
                adapter.one_step(sc, variant, h, y[:1])   # sc's body kept again for the next one
            assert np.array_equal(got, want), (sc.name, kind, h)


# --- the body-axes torque is PyBullet's own (PybulletEngine.takes_body_torque) ----------------------------

BIT_IDENTITY = catalog_path("applied_torque").parents[3] / "benchmarks" / "bit_identity"


@pytest.mark.parametrize("variant", sorted(pe.VARIANTS))
def test_a_link_frame_torque_is_in_the_inertial_frames_axes_turns_with_the_body_and_is_cleared(variant):
    """Pins what the adapter relies on: ``applyExternalTorque(LINK_FRAME)`` on the base takes the torque in
    the axes of the inertial frame P PyBullet reports as the base pose, so ``R_BPᵀ τ_B`` re-applied before
    every step moves a tilted, spinning full-tensor body as the torque turned to world axes from each
    step's attitude does (to round-off; τ_B itself, unturned by R_BP, does not); and Bullet clears it after
    the step."""
    from reference_sim.quaternion import rotate
    full = "inertia = [[2.0, 0.3, 0.1], [0.3, 3.0, -0.2], [0.1, -0.2, 4.0]]"
    sc = parse_scenario(catalog_path("applied_torque").read_text().replace("inertia = [1.0, 2.0, 3.0]", full),
                        "<t>")
    assert not sc.problem.body.is_diagonal()
    tau_B, h, n = np.array([0.3, -0.2, 0.5]), 1e-3, 400

    def run(how):
        B = BulletBody(sc, variant, h, sc.problem.initial_packed())
        y0 = sc.problem.initial_packed().copy()
        y0[6:10] = Q_TILT
        y0[10:13] = [1.0, -2.0, 0.5]
        B.set_state(y0)
        tau_P = pbw.Bodies.__new__(pbw.Bodies)   # the world's R_BPᵀ τ_B
        tau_P.q_BP = [B.q_BP]
        tau_P.apply_body_torque(tau_B[None])
        for _ in range(n):
            y = B.raw_to_packed(B.read_raw())
            if how == "world":
                p.applyExternalTorque(B.b, -1, rotate(y[6:10], tau_B).tolist(), p.WORLD_FRAME,
                                      physicsClientId=B.c)
            else:
                t = tau_P.torque_P[0] if how == "link" else tau_B.tolist()
                p.applyExternalTorque(B.b, -1, list(t), p.LINK_FRAME, physicsClientId=B.c)
            p.stepSimulation(physicsClientId=B.c)
        return B.raw_to_packed(B.read_raw())
    world, link, unturned = run("world"), run("link"), run("unturned")
    scale = np.abs(world) + 1.0
    assert np.max(np.abs(link - world) / scale) <= SAME_SCHEME_REL
    assert np.max(np.abs(unturned - world) / scale) > 1e3 * SAME_SCHEME_REL
    # cleared: a sphere (no gyroscopic term) keeps its ω in the step after the torque's
    B = BulletBody(_scenario(), variant, 0.01, _scenario().problem.initial_packed())
    B.set_state(_scenario().problem.initial_packed())
    p.applyExternalTorque(B.b, -1, [0.0, 0.0, 3.0], p.LINK_FRAME, physicsClientId=B.c)
    p.stepSimulation(physicsClientId=B.c)
    w1 = B.read_raw()[10:13]
    p.stepSimulation(physicsClientId=B.c)
    np.testing.assert_allclose(w1[2], 0.01, rtol=1e-14)   # one step of 3 N m about I_zz = 3
    np.testing.assert_allclose(B.read_raw()[10:13], w1, rtol=tol.ADAPTER_ROUND_TRIP * 4)


class _HarnessTorque(pe.PybulletEngine):
    """PyBullet driven by the harness alone: the body-axes torques turned to world axes by rbcheck every step
    (the adapter before it took them in the engine)."""
    takes_body_torque = False


@pytest.mark.parametrize("variant", sorted(pe.VARIANTS))
def test_the_body_torque_taken_by_pybullet_moves_the_body_as_the_harness_s_world_torque(variant, monkeypatch):
    """The harness evaluates no body-axes torque for PyBullet (on the catalog's body-torque scenario without
    its point force, PyBullet's only torque calls are one ``applyExternalTorque`` in ``LINK_FRAME`` before
    every step, the same τ_P each time: Bullet turns the torque itself), and the adapter's runs equal the
    harness-driven runs to round-off there, on a decaying full-tensor body with every force kind, and on a
    torque-free one (there bit for bit: nothing changes)."""
    calls = []
    torque = pe.p.applyExternalTorque
    monkeypatch.setattr(pe.p, "applyExternalTorque", lambda *a, **k: (calls.append((tuple(a[2]), a[3])),
                                                                      torque(*a, **k)))
    text = catalog_path("applied_torque").read_text()
    sc = parse_scenario(text[:text.index("[[forces.point]]")], "<body torque only>")
    pe.simulate(sc, variant, sc.dt_s, 20)
    assert len(calls) == 20 and len(set(calls)) == 1 and calls[0][1] == pe.p.LINK_FRAME
    monkeypatch.setattr(pe.p, "applyExternalTorque", torque)
    for sc in (load_scenario("applied_torque"), load_scenario(str(BIT_IDENTITY / "skew.toml")),
               load_scenario("tennis_racket")):
        n = min(sc.n_steps(), 1500)
        own = pe.simulate(sc, variant, sc.dt_s, n).y
        harness = _HarnessTorque().simulate(sc, variant, sc.dt_s, n).y
        scale = np.max(np.abs(harness), axis=0) + 1.0
        assert np.max(np.abs(own - harness) / scale) <= SAME_SCHEME_REL, sc.name
        if not any(t.frame == "body" for t in sc.problem.forces.torques):
            assert np.array_equal(own, harness), sc.name


@pytest.mark.parametrize("variant", sorted(pe.VARIANTS))
def test_constant_torques_are_reapplied_by_pybullets_own_call_with_its_arguments_bound(variant):
    """The world's per-step calls have no Python frame of rbcheck's where PyBullet offers the call itself:
    the step is ``stepSimulation`` with the client bound, and constant torques (the body-axes one in
    ``LINK_FRAME``, a world one in ``WORLD_FRAME``, in ``apply``'s order) are re-applied by
    ``applyExternalTorque`` with its arguments bound; nothing to apply is None, and a world force at the COM
    goes through ``apply`` (its point is the COM's last read position)."""
    import functools

    from cross_checks.engines.base import RunRequest
    sc = load_scenario("tennis_racket")
    world = pe.PybulletEngine().build([RunRequest(sc, sc.dt_s, 10)], variant, sc.dt_s)
    try:
        b, c = world.bodies[0], world.c
        assert isinstance(world.step, functools.partial) and world.step.func is p.stepSimulation
        assert world.step.args == (c,)
        zero = np.zeros((1, 3))
        assert world.applier(zero, zero) is None
        world.apply_body_torque(np.array([[0.0, 0.0, 0.2]]))
        again = world.applier(zero, zero)
        assert again.func is p.applyExternalTorque and again.args == (b, -1, (0.0, 0.0, 0.2), p.LINK_FRAME, c)
        both = world.applier(zero, np.array([[0.1, 0.0, 0.0]]))
        both()   # the world torque, then the body-axes one: apply's calls
        again = world.applier(np.array([[1.0, 0.0, 0.0]]), zero)
        assert again.func == world.apply
    finally:
        world.close()


def test_the_base_state_takes_two_calls_getlinkstate_refuses_the_base():
    """What the single-run floor (docs/speed.md) rests on: PyBullet has no call giving the base's pose and
    velocity together — ``getLinkState`` refuses the base's index −1 (``getLinkStates`` gives a tuple
    holding a NULL for it, not touched here) — so a driver recording every step makes
    ``getBasePositionAndOrientation`` and ``getBaseVelocity``."""
    c = p.connect(p.DIRECT)
    try:
        b = p.createMultiBody(baseMass=1.0, physicsClientId=c)
        with pytest.raises(p.error, match="invalid linkIndex"):
            p.getLinkState(b, -1, 1, 1, physicsClientId=c)
        assert len(p.getBasePositionAndOrientation(b, physicsClientId=c)) == 2
        assert len(p.getBaseVelocity(b, physicsClientId=c)) == 2
    finally:
        p.disconnect(c)
