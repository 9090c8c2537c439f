"""The DART adapter (cross_checks.engines.dart_engine): every convention it relies on, pinned on dartpy itself
(docs/engine_conventions.md, "DART 6.x"), every default it neutralises, one step against the hand-derived
semi-implicit Euler step, the rotation update's Taylor branch, its order on catalog scenarios, divergence."""
import math

import numpy as np
import pytest

from cross_checks.core.tolerances import SAME_SCHEME_REL
from tests.helpers import tolerances as tol

dart = pytest.importorskip("dartpy", reason="dartpy is not installed (pip install -e '.[dart]')")

from cross_checks.engines import dart_engine as de  # noqa: E402
from cross_checks.scenario import load_scenario  # noqa: E402
from reference_sim.quaternion import geodesic_angle, matrix_from_quat, quat_exp, quat_log, quat_mul  # noqa: E402
from tests.helpers.scenarios import FAST_SPIN, YAW90, scenario_from_parts  # noqa: E402

VARIANT = "semi_implicit_euler"
Q_TILT = np.array([0.9, 0.1, 0.3, -0.2]) / np.linalg.norm([0.9, 0.1, 0.3, -0.2])
FULL_INERTIA = "mass = 2.0\ninertia = [[2.0, 0.1, 0.05], [0.1, 3.0, -0.2], [0.05, -0.2, 4.0]]"
NO_GRAVITY = "gravity = [0.0, 0.0, 0.0]"
#: Every JOINT_SETTINGS entry set to a value that is not the scenario's physics (per DOF).
HOSTILE = {"setDampingCoefficient": 0.5, "setSpringStiffness": 3.0, "setRestPosition": 0.2,
           "setCoulombFriction": 0.1, "setPositionLowerLimit": -0.05, "setPositionUpperLimit": 0.05,
           "setVelocityLowerLimit": -0.5, "setVelocityUpperLimit": 0.5, "setAccelerationLowerLimit": -1.0,
           "setAccelerationUpperLimit": 1.0, "setForceLowerLimit": -1.0, "setForceUpperLimit": 1.0}


def _tilted(body=FULL_INERTIA, forces=NO_GRAVITY, **initial):
    """A scenario whose body starts at Q_TILT, 1 m, −2 m, 0.5 m from the origin (not parallel to the forces
    below), with the initial fields given (TOML values)."""
    lines = [f"orientation = {Q_TILT.tolist()}", "position = [1.0, -2.0, 0.5]"]
    lines += [f"{k} = {v}" for k, v in initial.items()]
    return scenario_from_parts(body=body, initial="\n".join(lines), forces=forces)


def _world_inertia(sc, q):
    R = matrix_from_quat(q)
    return R @ sc.problem.body.inertia_B @ R.T


def test_version_is_the_pinned_release():
    assert de.version() == "6.20.0"


# --- conventions -------------------------------------------------------------------------------------

def test_positions_are_the_rotation_vector_then_the_position():
    B = de.DartBody(_tilted(), 0.01)
    r = quat_log(Q_TILT)
    B.skeleton.setPositions(np.r_[r, 1.0, -2.0, 0.5])
    T = B.node.getWorldTransform()
    np.testing.assert_allclose(T.rotation(), matrix_from_quat(Q_TILT), rtol=0, atol=tol.DART_ROUND_TRIP)
    np.testing.assert_array_equal(T.translation(), [1.0, -2.0, 0.5])
    y = np.r_[1.0, -2.0, 0.5, 4.0, 5.0, 6.0, Q_TILT, 0.1, 0.2, 0.3]
    np.testing.assert_array_equal(de.to_dart_state(y), np.r_[r, 1.0, -2.0, 0.5, 0.1, 0.2, 0.3, 4.0, 5.0, 6.0])
    np.testing.assert_allclose(de.from_dart_state(de.to_dart_state(y)), y, rtol=0, atol=tol.DART_ROUND_TRIP)


def test_quaternion_order_at_the_boundary():
    # (w, x, y, z) = (√½, 0, 0, √½) is 90° about z: rotation vector (0, 0, π/2), body x along world y
    sc = scenario_from_parts(initial=YAW90)
    B = de.DartBody(sc, 0.01)
    B.set_state(sc.problem.initial_packed())
    np.testing.assert_allclose(B.skeleton.getPositions()[0:3], [0.0, 0.0, math.pi / 2],
                               rtol=0, atol=tol.DART_ROUND_TRIP)
    np.testing.assert_allclose(B.node.getWorldTransform().rotation() @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0],
                               atol=tol.DART_ROUND_TRIP)


def test_velocities_are_angular_then_linear_both_in_world_axes():
    B = de.DartBody(_tilted(), 0.01)
    w, v = np.array([0.1, 0.2, 0.3]), np.array([4.0, 5.0, 6.0])
    B.set_state(np.r_[1.0, -2.0, 0.5, v, Q_TILT, w])
    np.testing.assert_array_equal(B.skeleton.getVelocities(), np.r_[w, v])
    # DART's own world-frame readings equal them although the body is tilted; its
    # spatial velocity is in body axes
    np.testing.assert_allclose(B.node.getAngularVelocity(), w, rtol=0, atol=tol.DART_ROUND_TRIP)
    np.testing.assert_allclose(B.node.getLinearVelocity(), v, rtol=0, atol=4 * tol.DART_ROUND_TRIP)
    R = matrix_from_quat(Q_TILT)
    np.testing.assert_allclose(B.node.getSpatialVelocity(), np.r_[R.T @ w, R.T @ v],
                               rtol=0, atol=4 * tol.DART_ROUND_TRIP)
    # body origin = COM: the COM's position and velocity are the joint's translation and linear velocity
    np.testing.assert_allclose(B.node.getCOM(), [1.0, -2.0, 0.5], rtol=0, atol=tol.DART_ROUND_TRIP)
    np.testing.assert_allclose(B.node.getCOMLinearVelocity(), v, rtol=0, atol=4 * tol.DART_ROUND_TRIP)


def test_a_yawed_body_spinning_about_body_x_turns_about_world_y():
    # 90° yaw: body x is world y. A torque-free spin about a principal axis stays there, ω_W constant, and the
    # attitude turns about WORLD y: q(t) = exp(ω_W t) ⊗ q0 (|ω|Δt = 0.02 rad per step: the exact branch)
    sc = scenario_from_parts(initial=YAW90 + "\nangular_velocity_body = [2.0, 0.0, 0.0]",
                             dt=0.01, duration=0.5)
    run = de.simulate(sc, VARIANT, 0.01, 50)
    np.testing.assert_allclose(run.y[:, 10:13], np.tile([0.0, 2.0, 0.0], (51, 1)),
                               rtol=0, atol=tol.ADAPTER_SPIN_100_STEPS)
    expected = quat_mul(quat_exp(np.outer(run.t_s, [0.0, 2.0, 0.0])), run.y[0, 6:10])
    assert np.max(geodesic_angle(expected, run.y[:, 6:10])) < tol.ADAPTER_SPIN_100_STEPS


def test_the_inertia_is_about_the_com_in_body_axes_and_the_mass_matrix_has_no_armature():
    sc = _tilted()
    B = de.DartBody(sc, 0.01)
    inertia = B.node.getInertia()
    assert inertia.getMass() == 2.0
    np.testing.assert_array_equal(inertia.getLocalCOM(), np.zeros(3))
    np.testing.assert_array_equal(inertia.getMoment(), sc.problem.body.inertia_B)   # the full tensor as given
    # in the coordinates [ω_W, v_W] at a tilted pose the mass matrix is diag(I_W, m 1): no armature, no rotor
    # inertia, nothing but the body (DART 6.20's joints have no armature at all)
    B.set_state(sc.problem.initial_packed())
    M = B.skeleton.getMassMatrix()
    np.testing.assert_allclose(M[0:3, 0:3], _world_inertia(sc, Q_TILT), rtol=0, atol=1e-14)
    np.testing.assert_allclose(M[3:6, 3:6], 2.0 * np.eye(3), rtol=0, atol=1e-14)
    np.testing.assert_allclose(M[0:3, 3:6], np.zeros((3, 3)), rtol=0, atol=1e-14)
    assert not any("rmature" in n for n in dir(B.joint) + dir(B.skeleton.getDof(0)))


def test_the_gyroscopic_term_is_darts_own():
    # torque-free full-tensor tumble: one step gives ω1 = ω0 − Δt I_W⁻¹ (ω0 × I_W ω0),
    # nothing of it from rbcheck
    sc = _tilted(angular_velocity="[0.4, 1.5, -0.7]")
    y0 = sc.problem.initial_packed()
    y1 = de.one_step(sc, VARIANT, 0.01, y0[None])[0]
    I_W, w = _world_inertia(sc, Q_TILT), y0[10:13]
    np.testing.assert_allclose(y1[10:13], w - 0.01 * np.linalg.solve(I_W, np.cross(w, I_W @ w)), rtol=0,
                               atol=tol.DART_HAND_STEP)


def test_one_step_is_the_hand_derived_semi_implicit_euler_step():
    # v and ω from the start-of-step forces (world force at the COM, world torque, gravity), then x and the
    # attitude from the NEW velocities, the attitude by the exponential map (|ω1|Δt = 0.017 rad > 1e-3)
    sc = _tilted(forces='gravity = [0.0, 0.0, -9.81]\n'
                        '[[forces.torque]]\n'
                        'torque = [0.3, -0.2, 0.5]\n'
                        'frame = "world"\n[[forces.point]]\nforce = [1.0, 2.0, 3.0]\nframe = "world"',
                 velocity="[0.3, -0.1, 0.2]", angular_velocity="[0.4, 1.5, -0.7]")
    h, y0 = 0.01, sc.problem.initial_packed()
    y1 = de.one_step(sc, VARIANT, h, y0[None])[0]
    I_W, w = _world_inertia(sc, Q_TILT), y0[10:13]
    w1 = w + h * np.linalg.solve(I_W, np.array([0.3, -0.2, 0.5]) - np.cross(w, I_W @ w))
    v1 = y0[3:6] + h * (np.array([1.0, 2.0, 3.0]) / 2.0 + [0.0, 0.0, -9.81])
    np.testing.assert_allclose(y1[10:13], w1, rtol=0, atol=tol.DART_HAND_STEP)
    np.testing.assert_allclose(y1[3:6], v1, rtol=0, atol=tol.DART_HAND_STEP)
    np.testing.assert_allclose(y1[0:3], y0[0:3] + h * v1, rtol=0, atol=tol.DART_HAND_STEP)
    assert geodesic_angle(quat_mul(quat_exp(h * w1), Q_TILT), y1[6:10]) < tol.DART_HAND_STEP


@pytest.mark.parametrize("theta", [2e-4, 5e-4, 9e-4, 2e-3])
def test_below_1e_3_rad_per_step_the_rotation_update_is_a_second_order_taylor_polynomial(theta):
    # DART's expMapRot(θu) is I + S + S²/2 below θ = 1e-3 rad (dart/math/Geometry.cpp, EPSILON_EXPMAP_THETA):
    # the step turns by θ + θ³/6 instead of θ; above it, by θ to round-off (isotropic body: ω stays (0, 0, 1))
    sc = scenario_from_parts(body="mass = 1.0\ninertia = [1.0, 1.0, 1.0]",
                             initial="angular_velocity = [0.0, 0.0, 1.0]")
    y1 = de.one_step(sc, VARIANT, theta, sc.problem.initial_packed()[None])[0]
    excess = 2.0 * math.atan2(y1[9], y1[6]) - theta
    if theta < 1e-3:
        assert excess == pytest.approx(theta ** 3 / 6, rel=tol.DART_TAYLOR_EXCESS_REL)
    else:
        assert abs(excess) < tol.DART_ROUND_TRIP


def test_same_scheme_as_mujoco_euler_where_every_step_turns_by_more_than_1e_3_rad_only():
    from cross_checks.engines import mujoco_engine as me
    sc = load_scenario("tennis_racket")                        # |ω|Δt ≈ 2e-3 rad per step at 1e-3 s
    a, b = de.simulate(sc, VARIANT, 1e-3, 2000), me.simulate(sc, "euler", 1e-3, 2000)
    assert np.max(geodesic_angle(a.y[:, 6:10], b.y[:, 6:10])) < tol.DART_SAME_AS_MUJOCO_EULER
    assert np.max(np.abs(a.y[:, 10:13] - b.y[:, 10:13])) < tol.DART_SAME_AS_MUJOCO_EULER
    sc = load_scenario("spring_pendulum")   # the pendulum's ω passes through 0: Taylor steps
    n = sc.n_steps(sc.dt_s)
    a, b = de.simulate(sc, VARIANT, sc.dt_s, n), me.simulate(sc, "euler", sc.dt_s, n)
    assert np.max(np.abs(a.y[:, 10:13] - b.y[:, 10:13])) > tol.DART_TAYLOR_BRANCH_MIN_DIFF


# --- forces ------------------------------------------------------------------------------------------

def _wrench_of_one_step(apply, sc=None):
    """The world force (N) and the world torque about the COM (N m) that ``apply(node)`` exerts, read from
    one step of a body at rest (no gyroscopic term): f = m Δv/Δt, τ = I_W Δω/Δt."""
    sc = sc or _tilted()
    B = de.DartBody(sc, 1e-3)
    B.set_state(sc.problem.initial_packed())
    apply(B.node)
    B.world.step()
    v = B.skeleton.getVelocities()
    return 2.0 * v[3:6] / 1e-3, _world_inertia(sc, Q_TILT) @ v[0:3] / 1e-3


@pytest.mark.parametrize("force_local, offset_local",
                         [(False, False), (False, True), (True, False), (True, True)])
def test_ext_force_frames_and_lever_arms(force_local, offset_local):
    # addExtForce(F, p, isForceLocal, isOffsetLocal): F in body axes if local, else world; p a body-frame
    # offset from the body origin (= COM) if local, else a WORLD POINT (lever arm p − x_W)
    F, p = np.array([1.0, 2.0, 3.0]), np.array([0.1, -0.2, 0.3])
    f, tau = _wrench_of_one_step(lambda node: node.addExtForce(F, p, force_local, offset_local))
    R = matrix_from_quat(Q_TILT)
    F_W = R @ F if force_local else F
    lever = R @ p if offset_local else p - np.array([1.0, -2.0, 0.5])
    np.testing.assert_allclose(f, F_W, rtol=0, atol=1e-11)
    np.testing.assert_allclose(tau, np.cross(lever, F_W), rtol=0, atol=1e-11)


def test_ext_force_and_torque_defaults_are_world_axes_at_the_body_origin():
    F = np.array([1.0, 2.0, 3.0])
    f, tau = _wrench_of_one_step(lambda node: node.addExtForce(F))
    np.testing.assert_allclose(f, F, rtol=0, atol=1e-11)
    np.testing.assert_allclose(tau, np.zeros(3), rtol=0, atol=1e-11)
    f, tau = _wrench_of_one_step(lambda node: node.setExtTorque(F))
    np.testing.assert_allclose(tau, F, rtol=0, atol=1e-11)
    f, tau = _wrench_of_one_step(lambda node: node.setExtTorque(F, True))            # local: body axes
    np.testing.assert_allclose(tau, matrix_from_quat(Q_TILT) @ F, rtol=0, atol=1e-11)


def test_set_ext_force_replaces_a_torque_set_before_it_so_the_adapter_sets_the_force_first():
    F, T = np.array([1.0, 2.0, 3.0]), np.array([0.5, -0.3, 0.2])
    f, tau = _wrench_of_one_step(lambda node: (node.setExtTorque(T, False),
                                               node.setExtForce(F, np.zeros(3), False, True)))
    np.testing.assert_allclose(tau, np.zeros(3), rtol=0, atol=1e-11)   # the trap: the torque is gone
    sc = _tilted()
    B = de.DartBody(sc, 1e-3)
    B.set_state(sc.problem.initial_packed())
    B.apply(F, T)
    B.world.step()
    v = B.skeleton.getVelocities()
    np.testing.assert_allclose(_world_inertia(sc, Q_TILT) @ v[0:3] / 1e-3, T, rtol=0, atol=1e-11)
    np.testing.assert_allclose(2.0 * v[3:6] / 1e-3, F, rtol=0, atol=1e-11)


def test_external_forces_are_cleared_after_each_step():
    sc = _tilted()
    B = de.DartBody(sc, 1e-3)
    B.set_state(sc.problem.initial_packed())
    B.apply(np.array([1.0, 2.0, 3.0]), np.array([0.5, -0.3, 0.2]))
    B.world.step()
    np.testing.assert_array_equal(B.node.getExternalForceGlobal(), np.zeros(6))
    v1 = B.skeleton.getVelocities()
    B.world.step()
    np.testing.assert_array_equal(B.skeleton.getVelocities()[3:6], v1[3:6])   # no force in the second step


def test_step_false_keeps_a_local_torque_and_step_clears_it():
    """Pins what the world's ``step(False)`` relies on (World::step's resetCommand): the wrench set before it
    stays set after it, so a body-axes torque set once moves a spinning full-tensor body exactly as the same
    torque set before every ``step()`` (which clears it) does, bit for bit."""
    sc = _tilted(angular_velocity=[1.0, -2.0, 0.5])
    tau_B = np.array([0.3, -0.2, 0.5])
    kept, reset = de.DartBody(sc, 1e-3), de.DartBody(sc, 1e-3)
    for b in (kept, reset):
        b.set_state(sc.problem.initial_packed())
    kept.node.setExtTorque(tau_B, True)
    for _ in range(200):
        kept.world.step(False)
        reset.node.setExtTorque(tau_B, True)
        reset.world.step()
    assert np.any(kept.node.getExternalForceGlobal() != 0.0)
    np.testing.assert_array_equal(reset.node.getExternalForceGlobal(), np.zeros(6))
    np.testing.assert_array_equal(np.r_[kept.skeleton.getPositions(), kept.skeleton.getVelocities()],
                                  np.r_[reset.skeleton.getPositions(), reset.skeleton.getVelocities()])
    kept.world.step()
    np.testing.assert_array_equal(kept.node.getExternalForceGlobal(), np.zeros(6))


def test_a_wrench_set_in_world_axes_is_held_in_body_axes_so_the_world_sets_it_before_every_step():
    """DART turns a world torque into body axes when it is set: kept over ``step(False)``s it turns with the
    body (no longer the world torque asked for), which is why the world sets world forces and torques before
    every step and keeps only the body-axes torques; its runs with a world torque are those of the wrench set
    before every ``step()``, bit for bit."""
    sc = _tilted(angular_velocity=[1.0, -2.0, 0.5])
    tau_W = np.array([0.1, 0.0, -0.2])
    b = de.DartBody(sc, 1e-3)
    b.set_state(sc.problem.initial_packed())
    b.node.setExtTorque(tau_W, False)
    np.testing.assert_allclose(b.node.getExternalForceGlobal()[0:3], tau_W, rtol=0, atol=1e-15)
    for _ in range(300):
        b.world.step(False)
    assert np.max(np.abs(b.node.getExternalForceGlobal()[0:3] - tau_W)) > 0.01
    fm = "[[forces.torque]]\ntorque = [0.1, 0.0, -0.2]\nframe = \"world\"\n[[forces.torque]]\n" \
         "torque = [0.3, -0.2, 0.5]\nframe = \"body\""
    sc = _tilted(forces=fm, angular_velocity=[1.0, -2.0, 0.5])
    run = de.simulate(sc, VARIANT, 1e-3, 300)
    hand = de.DartBody(sc, 1e-3)
    hand.set_state(sc.problem.initial_packed())
    rows = []
    for _ in range(300):
        hand.apply(np.zeros(3), tau_W)
        hand.node.addExtTorque(np.array([0.3, -0.2, 0.5]), True)
        hand.world.step()
        rows.append(np.r_[hand.skeleton.getPositions(), hand.skeleton.getVelocities()])
    np.testing.assert_array_equal(run.y[1:, 0:3], de.from_dart_state(np.array(rows))[:, 0:3])
    np.testing.assert_array_equal(run.y[1:, 10:13], de.from_dart_state(np.array(rows))[:, 10:13])


def test_a_lone_body_is_stepped_with_darts_own_call_and_its_torque_set_once(monkeypatch):
    """The world of one body steps with ``World.step(False)`` itself (no Python frame per step), and a
    body-axes torque alone is set once per run, not before every step."""
    import functools

    from cross_checks.engines.base import RunRequest
    from cross_checks.scenario import catalog_path, parse_scenario
    text = catalog_path("applied_torque").read_text()
    sc = parse_scenario(text[:text.index("[[forces.point]]")], "<body torque only>")
    world = de.DartEngine().build([RunRequest(sc, sc.dt_s, 10)], VARIANT, sc.dt_s)
    assert isinstance(world.step, functools.partial) and world.step.args == (False,)
    assert world.step.func == world.bodies[0].world.step
    calls = []
    real = dart.dynamics.BodyNode.setExtTorque
    monkeypatch.setattr(dart.dynamics.BodyNode, "setExtTorque",
                        lambda self, *a: (calls.append(a), real(self, *a)))
    run = de.simulate(sc, VARIANT, sc.dt_s, 50)
    assert len(calls) == 1 and calls[0][1] is True and len(run.y) == 51


def test_a_blown_up_body_is_parked_at_rest_and_the_body_beside_it_runs_as_alone():
    """A body whose state blows up is parked at rest with no force (never stepped from a bad state), its run
    ending at the blow-up; a calm body in the same world runs as it does alone, bit for bit."""
    from cross_checks.engines.base import RunRequest
    spring = "[[forces.spring]]\nanchor = [0.0, 0.0, 0.0]\nattach = [0.0, 0.0, 0.0]\nstiffness = 1e6"
    blow = scenario_from_parts(initial="position = [0.1, 0.0, 0.0]", forces=spring, dt=0.01, duration=1.0)
    calm = load_scenario("tennis_racket")
    reqs = [RunRequest(blow, 0.01, 100), RunRequest(calm, 0.01, 100)]
    world = de.DartEngine().build(reqs, VARIANT, 0.01)
    world.set_state(np.array([blow.problem.initial_packed(), calm.problem.initial_packed()]))
    world._bad([[np.nan] * 12, world.read()[1]])
    assert world.live == [False, True]
    np.testing.assert_array_equal(world.read()[0], np.zeros(12))
    np.testing.assert_array_equal(world.bodies[0].node.getExternalForceGlobal(), np.zeros(6))
    run, other = de.simulate_many(VARIANT, reqs)
    assert run.diverged_at_s is not None and run.diverged_at_s < 0.2
    np.testing.assert_array_equal(other.y, de.simulate(calm, VARIANT, 0.01, 100).y)


def test_body_frame_point_forces_and_springs_reach_dart_as_the_force_models_wrench():
    # a state-dependent scenario (a body-frame force off the COM, a spring off the COM): one
    # step from a tumbling state changes v by Δt f/m and ω by Δt I_W⁻¹(τ − ω × I_W ω), f and τ
    # from ForceModel.force_torque
    sc = _tilted(forces='[[forces.point]]\n'
                        'force = [0.4, -1.0, 2.0]\n'
                        'point = [0.1, 0.2, -0.3]\n'
                        'frame = "body"\n'
                        '[[forces.spring]]\n'
                        'anchor = [0.0, 0.0, 1.0]\nattach = [0.2, 0.0, 0.1]\nstiffness = 5.0',
                 angular_velocity="[0.4, 1.5, -0.7]", velocity="[0.3, -0.1, 0.2]")
    y0 = sc.problem.initial_packed()
    fm, body = sc.problem.forces, sc.problem.body
    f, tau = fm.force_torque(body, y0[0:3], y0[3:6], y0[6:10])
    y1 = de.one_step(sc, VARIANT, 1e-3, y0[None])[0]
    I_W, w = _world_inertia(sc, Q_TILT), y0[10:13]
    np.testing.assert_allclose(y1[3:6], y0[3:6] + 1e-3 * np.asarray(f) / 2.0, rtol=0, atol=tol.DART_HAND_STEP)
    np.testing.assert_allclose(y1[10:13],
                               w + 1e-3 * np.linalg.solve(I_W, np.asarray(tau) - np.cross(w, I_W @ w)),
                               rtol=0, atol=tol.DART_HAND_STEP)


def test_decay_is_applied_before_the_step_with_that_steps_force_scaled():
    # harness semantics (base.py): v ← γ v, the force × γ, then DART's step: v1 = γ (v0 + Δt (F/m + g)) — the
    # course's step (isotropic body: no gyroscopic term, ω1 = γ_ω (ω0 + Δt τ/I))
    sc = scenario_from_parts(body="mass = 2.0\ninertia = [0.5, 0.5, 0.5]",
                             initial="velocity = [1.0, -2.0, 0.5]\nangular_velocity = [0.3, 0.0, 3.0]",
                             forces='gravity = [0.0, 0.0, -9.81]\nvelocity_decay = 0.99\n'
                                    'angular_velocity_decay = 0.95\n'
                                    '[[forces.point]]\nforce = [1.0, 2.0, 3.0]\nframe = "world"\n'
                                    '[[forces.torque]]\ntorque = [0.1, 0.2, -0.3]\nframe = "world"', dt=0.01)
    y0 = sc.problem.initial_packed()
    y1 = de.one_step(sc, VARIANT, 0.01, y0[None])[0]
    np.testing.assert_allclose(y1[3:6],
                               0.99 * (y0[3:6] + 0.01 * (np.array([0.5, 1.0, 1.5]) + [0.0, 0.0, -9.81])),
                               rtol=0, atol=tol.DART_HAND_STEP)
    np.testing.assert_allclose(y1[10:13], 0.95 * (y0[10:13] + 0.01 * np.array([0.2, 0.4, -0.6])), rtol=0,
                               atol=tol.DART_HAND_STEP)
    run = de.simulate(sc, VARIANT, 0.01, 3)                                     # the free run does the same
    np.testing.assert_allclose(run.y[1], y1, rtol=0, atol=tol.DART_ROUND_TRIP)


def test_dart_refuses_only_a_non_positive_mass_or_moment_and_the_adapter_says_so():
    from types import SimpleNamespace

    from cross_checks.engines.base import EngineError
    indefinite = np.array([[1.0, 2.0, 0.0], [2.0, 1.0, 0.0], [0.0, 0.0, 1.0]])        # eigenvalue −1
    assert dart.dynamics.Inertia(1.0, np.zeros(3), indefinite).verify()               # DART does not check it
    sc = scenario_from_parts()
    bad = SimpleNamespace(name="massless", problem=SimpleNamespace(
        body=SimpleNamespace(mass_kg=0.0, inertia_B=np.eye(3)), forces=sc.problem.forces))
    with pytest.raises(EngineError, match="DART 6.20.0 rejects the inertia of scenario 'massless'"):
        de.DartBody(bad, 0.01)


# --- defaults ----------------------------------------------------------------------------------------

def test_darts_own_defaults():
    world = dart.simulation.World()
    np.testing.assert_array_equal(world.getGravity(), [0.0, 0.0, -9.81])
    assert world.getTimeStep() == 0.001
    assert world.getDeactivationOptions().mEnabled                     # sleeping is on by default in 6.20
    skeleton = dart.dynamics.Skeleton("b")
    joint, node = skeleton.createFreeJointAndBodyNodePair()
    for setter, neutral in de.JOINT_SETTINGS:
        assert [getattr(joint, "get" + setter[3:])(i) for i in range(6)] == [neutral] * 6, setter
    assert not joint.areLimitsEnforced()
    assert node.isCollidable() and node.getNumShapeNodes() == 0 and not skeleton.isEnabledSelfCollisionCheck()
    assert node.getGravityMode()


def _hostile_world(dt_s):
    """A DART world holding one free body (1 kg, unit inertia), every JOINT_SETTINGS entry set to HOSTILE,
    limits enforced, the body collidable, sleeping on."""
    world = dart.simulation.World()
    world.setTimeStep(dt_s)
    skeleton = dart.dynamics.Skeleton("b")
    joint, node = skeleton.createFreeJointAndBodyNodePair()
    node.setInertia(dart.dynamics.Inertia(1.0, np.zeros(3), np.eye(3)))
    for setter, value in HOSTILE.items():
        for i in range(6):
            getattr(joint, setter)(i, value)
    joint.setLimitEnforcement(True)
    world.addSkeleton(skeleton)
    return world, skeleton, joint, node


def test_neutralise_sets_every_default_that_is_not_the_physics_whatever_it_was():
    assert set(HOSTILE) == {s for s, _ in de.JOINT_SETTINGS}
    world, skeleton, joint, node = _hostile_world(0.01)

    def projectile():
        skeleton.setPositions(np.zeros(6))
        skeleton.setVelocities(np.r_[0.0, 0.0, 0.0, 1.0, 0.0, 3.0])
        for _ in range(100):
            world.step()
        return skeleton.getPositions()[3:6]

    n, h = 100, 0.01
    exact = np.array([1.0, 0.0, 3.0]) * n * h + np.array([0.0, 0.0, -9.81]) * h * h * n * (n + 1) / 2
    assert np.max(np.abs(projectile() - exact)) > 1.0   # the hostile settings change the motion
    de.neutralise(world, joint, node)
    for setter, neutral in de.JOINT_SETTINGS:
        assert [getattr(joint, "get" + setter[3:])(i) for i in range(6)] == [neutral] * 6, setter
    assert not joint.areLimitsEnforced() and not node.isCollidable()
    assert not world.getDeactivationOptions().mEnabled
    np.testing.assert_allclose(projectile(), exact, rtol=0, atol=tol.AGREE_PROJECTILE)


def test_a_model_has_the_scenarios_gravity_and_step_and_is_neutralised():
    sc = scenario_from_parts(forces="gravity = [1.0, -2.0, 0.5]")
    B = de.DartBody(sc, 0.004)
    for holder in (B.world, B.skeleton):
        np.testing.assert_array_equal(holder.getGravity(), [1.0, -2.0, 0.5])
        assert holder.getTimeStep() == 0.004
    for setter, neutral in de.JOINT_SETTINGS:
        assert [getattr(B.joint, "get" + setter[3:])(i) for i in range(6)] == [neutral] * 6, setter
    assert not B.joint.areLimitsEnforced() and not B.node.isCollidable() and B.node.getNumShapeNodes() == 0
    assert not B.world.getDeactivationOptions().mEnabled


def test_projectile_is_the_semi_implicit_closed_form():
    sc = load_scenario("projectile")
    n, h = 100, 0.01
    run = de.simulate(sc, VARIANT, h, n)
    p = sc.problem
    k = np.arange(n + 1)[:, None]
    exact = p.initial.x_W + k * h * p.initial.v_W + np.asarray(p.forces.gravity_W) * h * h * k * (k + 1) / 2
    np.testing.assert_allclose(run.y[:, 0:3], exact, rtol=0, atol=tol.AGREE_PROJECTILE)


# --- runs --------------------------------------------------------------------------------------------

def test_the_first_row_is_the_scenarios_and_quaternions_stay_continuous_through_pi():
    # w < 0 at t = 0 and a spin of 6 rad: DART's rotation vector wraps at |r| = π (its quaternion flips sign),
    # the recorded quaternion does not
    sc = scenario_from_parts(body="mass = 1.0\ninertia = [1.0, 1.0, 1.0]",
                             initial=f"orientation = {(-Q_TILT).tolist()}\n"
                                     "angular_velocity = [0.0, 0.0, 3.0]")
    run = de.simulate(sc, VARIANT, 0.01, 200)
    np.testing.assert_array_equal(run.y[0], sc.problem.initial_packed())
    # 0.03 rad per step: |Δq| ≈ 0.015
    assert np.max(np.linalg.norm(np.diff(run.y[:, 6:10], axis=0), axis=1)) < 0.02
    expected = quat_mul(quat_exp(np.outer(run.t_s, [0.0, 0.0, 3.0])), -Q_TILT)
    assert np.max(geodesic_angle(expected, run.y[:, 6:10])) < tol.ADAPTER_SPIN_100_STEPS * 2


def test_a_blown_up_body_is_not_stepped_on_into_darts_warnings(capfd):
    # k/m = 1e6: semi-implicit Euler is unstable for ωΔt > 2; here ωΔt = 10. DART goes on after a blow-up, to
    # non-finite states and forces, and warns on stderr at every step; the world leaves the body alone instead
    sc = scenario_from_parts(initial="position = [0.1, 0.0, 0.0]",
                             forces="[[forces.spring]]\nanchor = [0.0, 0.0, 0.0]\nattach = [0.0, 0.0, 0.0]\n"
                                    "stiffness = 1e6\nrest_length = 0.0", dt=0.01, duration=1.0)
    run = de.simulate(sc, VARIANT, 0.01, 300)
    assert run.diverged_at_s is not None and 0.0 < run.diverged_at_s < 0.2
    assert run.message == f"diverged at t = {run.diverged_at_s:.6g} s (state beyond 1e+08)"
    assert "Warning" not in capfd.readouterr().err


def test_the_fast_spin_diverges_where_the_reference_of_the_same_scheme_does():
    # reference:expmap_gyro is the same scheme (every step turns by ~0.2 rad: DART's exact branch): the
    # two agree to round-off over the first second, then the runaway amplifies round-off (MuJoCo Euler vs
    # the reference: 7e-14 rad/s at 1 s, 4 rad/s at 8 s), so both blow up within a step of each other
    # (measured 8.64 s and 8.65 s)
    from reference_sim.simulate import simulate as reference_simulate
    sc = scenario_from_parts(initial=FAST_SPIN, dt=0.01, duration=10.0)
    a, b = de.simulate(sc, VARIANT, 0.01, 1000), reference_simulate(sc.problem, "expmap_gyro", 0.01, 1000)
    np.testing.assert_allclose(a.y[:101, 10:13], b.y[:101, 10:13], rtol=0, atol=tol.DART_SAME_AS_MUJOCO_EULER)
    assert a.diverged_at_s is not None and abs(a.diverged_at_s - b.diverged_at_s) < 0.015
    assert a.message == f"diverged at t = {a.diverged_at_s:.6g} s (state beyond 1e+08)"


def test_the_wheel_ships_a_top_level_tests_package_that_pytest_keeps_apart_from_rbcheck_s():
    from importlib.metadata import files
    from pathlib import Path

    import tests.helpers.scenarios
    # shadows `import tests` outside pytest
    assert ("tests", "__init__.py") in {f.parts for f in files("dartpy")}
    assert Path(tests.helpers.scenarios.__file__).resolve().parents[2] == Path(__file__).resolve().parents[3]


def test_version_and_list_name_dart():
    from cross_checks.cli.parser import _version_text
    from cross_checks.engines import all_variants
    assert "dart 6.20.0" in _version_text()
    info = {v.name: v for v in all_variants()}["dart:semi_implicit_euler"]
    assert info.available and info.order == 1.0 and not info.required


def test_first_order_on_catalog_scenarios(assert_engine):
    summary = assert_engine("dart:semi_implicit_euler", ["projectile", "applied_torque"])
    fitted = {(c["scenario"], c["quantity"]): c["order"]
              for c in summary["convergence"] if c["verdict"] == "converges"}
    assert fitted[("applied_torque", "orientation")] == pytest.approx(1.0, abs=tol.DRAKE_ORDER_TOL)


@pytest.mark.slow
def test_first_order_on_the_tumbling_and_state_dependent_scenarios(assert_engine):
    assert_engine("dart:semi_implicit_euler",
                  ["tennis_racket", "spring_pendulum", "velocity_decay", "tumbling_box"])


# --- the body-axes torque is DART's own (DartEngine.takes_body_torque) ------------------------------------

def test_a_local_ext_torque_is_in_body_axes_turns_with_the_body_and_is_cleared_after_the_step():
    """Pins what the adapter relies on: ``setExtTorque(τ_B, isLocal=True)`` before every step moves a tilted,
    spinning full-tensor body as the torque turned to world axes from each step's attitude does (to
    round-off; τ_B given as a world torque does not), also added to a world wrench set before it
    (``addExtTorque(τ_B, True)``); and DART clears it after the step."""
    from reference_sim.quaternion import rotate
    tau_B, tau_W, n = np.array([0.3, -0.2, 0.5]), np.array([0.1, 0.0, -0.1]), 400

    def run(how):
        sc = _tilted(angular_velocity=[1.0, -2.0, 0.5])
        B = de.DartBody(sc, 1e-3)
        B.set_state(sc.problem.initial_packed())
        for _ in range(n):
            q = de.from_dart_state(np.r_[B.skeleton.getPositions(), B.skeleton.getVelocities()])[6:10]
            if how == "world":
                B.apply(np.zeros(3), rotate(q, tau_B) + tau_W)
            elif how == "local":
                B.apply(np.zeros(3), tau_W)
                B.node.addExtTorque(tau_B, True)
            else:
                B.apply(np.zeros(3), tau_B + tau_W)
            B.world.step()
        return np.r_[B.skeleton.getPositions(), B.skeleton.getVelocities()]
    world, local, unturned = run("world"), run("local"), run("unturned")
    scale = np.abs(world) + 1.0
    assert np.max(np.abs(local - world) / scale) <= SAME_SCHEME_REL
    assert np.max(np.abs(unturned - world) / scale) > 1e3 * SAME_SCHEME_REL
    sc = _tilted()
    B = de.DartBody(sc, 1e-3)
    B.set_state(sc.problem.initial_packed())
    B.node.setExtTorque(tau_B, True)
    B.world.step()
    np.testing.assert_array_equal(B.node.getExternalForceGlobal(), np.zeros(6))


class _HarnessTorque(de.DartEngine):
    """DART driven by the harness alone: the body-axes torques turned to world axes by rbcheck every step
    (the adapter before it took them in the engine)."""
    takes_body_torque = False


def test_the_body_torque_taken_by_dart_moves_the_body_as_the_harness_s_world_torque(monkeypatch):
    """The harness evaluates no body-axes torque for DART (the world's ``apply`` gets no torque on the
    catalog's body-torque scenario without its point force, once: DART keeps the forces over its
    ``step(False)``s), and the adapter's runs equal the harness-driven runs to round-off there, on a decaying
    full-tensor body with every force kind, and on a torque-free one (there bit for bit)."""
    from pathlib import Path

    from cross_checks.engines.worlds import dart as dtw
    from cross_checks.scenario import catalog_path, parse_scenario
    seen = []
    apply = dtw.Bodies.apply
    monkeypatch.setattr(dtw.Bodies, "apply", lambda self, f, tau: (seen.append(np.abs(tau).max()),
                                                                   apply(self, f, tau)))
    text = catalog_path("applied_torque").read_text()
    sc = parse_scenario(text[:text.index("[[forces.point]]")], "<body torque only>")
    de.simulate(sc, VARIANT, sc.dt_s, 20)
    assert len(seen) == 1 and max(seen) == 0.0
    monkeypatch.setattr(dtw.Bodies, "apply", apply)
    skew = Path(__file__).resolve().parents[3] / "benchmarks" / "bit_identity" / "skew.toml"
    for sc in (load_scenario("applied_torque"), load_scenario(str(skew)), load_scenario("tennis_racket")):
        n = min(sc.n_steps(), 1500)
        own = de.simulate(sc, VARIANT, sc.dt_s, n).y
        harness = _HarnessTorque().simulate(sc, VARIANT, sc.dt_s, n).y
        scale = np.max(np.abs(harness), axis=0) + 1.0
        assert np.max(np.abs(own - harness) / scale) <= SAME_SCHEME_REL, sc.name
        if not any(t.frame == "body" for t in sc.problem.forces.torques):
            assert np.array_equal(own, harness), sc.name


def test_positions_and_velocities_take_two_calls_no_state_getter_is_bound():
    """What the single-run floor (docs/speed.md) rests on: dartpy binds no getter of a skeleton's whole state
    (``getState`` and ``getConfiguration`` return types pybind11 cannot convert), so a driver recording every
    step makes ``getPositions`` and ``getVelocities`` (the free joint's give the same numbers)."""
    b = de.DartBody(_tilted(angular_velocity=[1.0, -2.0, 0.5]), 1e-3)
    for getter in (b.skeleton.getState, b.skeleton.getConfiguration):
        with pytest.raises(TypeError, match="Unable to convert function return value"):
            getter()
    np.testing.assert_array_equal(b.joint.getPositions(), b.skeleton.getPositions())
    np.testing.assert_array_equal(b.joint.getVelocities(), b.skeleton.getVelocities())
