"""The PhysX adapter (cross_checks.engines.physx_engine, PhysX 5.3.1 through SAPIEN 3.0.3): every convention
it relies on, pinned on the engine itself (docs/engine_conventions.md, "PhysX 5.3.1 (SAPIEN 3.0.3)"), every
default it neutralises (read back from the engine), one step of each solver against PhysX's step written out
by hand in numpy below (and against the candidate schemes it is not), batching, divergence, its order on
catalog scenarios."""
import os
import subprocess
import sys

import numpy as np
import pytest

from tests.helpers import tolerances as ctol

pytest.importorskip("sapien", reason="sapien is not installed (pip install -e '.[physx]')")

from cross_checks.engines import physx_engine as pe  # noqa: E402
from cross_checks.engines import resolve
from cross_checks.engines.base import RunRequest  # noqa: E402
from cross_checks.engines.world import MANY_BODIES  # noqa: E402
from cross_checks.scenario import load_scenario  # noqa: E402
from reference_sim.quaternion import geodesic_angle, matrix_from_quat, quat_exp, quat_mul  # noqa: E402
from tests.helpers.scenarios import YAW90, scenario_from_parts  # noqa: E402

pw = pe._world_class().W   # worlds.physx, imported as the adapter imports it
sapien, px = pw.sapien, pw.px

Q_TILT = np.array([0.9, 0.1, 0.3, -0.2]) / np.linalg.norm([0.9, 0.1, 0.3, -0.2])
FULL_INERTIA = "mass = 2.0\ninertia = [[2.0, 0.1, 0.05], [0.1, 3.0, -0.2], [0.05, -0.2, 4.0]]"
NO_GRAVITY = "gravity = [0.0, 0.0, 0.0]"
HAND = ctol.PHYSX_HAND_STEP
BOTH = ["tgs", "pgs"]


def _tilted(body=FULL_INERTIA, forces=NO_GRAVITY, **initial):
    lines = [f"orientation = {Q_TILT.tolist()}", "position = [1.0, -2.0, 0.5]"]
    lines += [f"{k} = {v}" for k, v in initial.items()]
    return scenario_from_parts(body=body, initial="\n".join(lines), forces=forces)


def _world(sc, variant="pgs", dt=0.01, y=None):
    """The adapter's world of one body of ``sc`` (its gravity) at step ``dt``, put at ``y`` (the initial
    state by default); the body's rigid dynamic is ``W.comps[0]``."""
    W = pe.PhysxWorld([RunRequest(sc, dt, 1000)], variant, dt)
    W.set_state(np.atleast_2d(sc.problem.initial_packed() if y is None else y))
    return W


def _raw_body(scene_variant="pgs", dt=0.01, inertia=(1.0, 1.0, 1.0), mass=1.0):
    """A scene of the adapter's (no gravity) and, beside its body, one rigid dynamic with SAPIEN/PhysX's own
    defaults (mass and inertia set, nothing neutralised)."""
    W = _world(scenario_from_parts(), scene_variant, dt)
    e = sapien.Entity()
    c = px.PhysxRigidDynamicComponent()
    e.add_component(c)
    c.set_mass(mass)
    c.set_inertia(np.asarray(inertia, dtype=np.float32))
    W.scene.add_entity(e)
    return W, c


# --- PhysX's step, written out by hand (PhysX 5.3.1: ScBodySim.cpp updateForces, DyBodyCoreIntegrator.h,
# DyRigidBodyToSolverBody.cpp copyToSolverBodyData), in float64 ---------------------------------------------

def physx_step(sc, y, F, tau, h, gyro="renormalised"):
    """One step from the packed state ``y``: world force ``F`` (N, at the COM, gravity excluded) and world
    torque ``tau`` (N m) as velocity changes with I_W at the start attitude, then gravity, then the
    gyroscopic term in the principal frame at the start attitude (``gyro``: "renormalised" = PhysX's
    explicit step rescaled to |L|, "explicit" = without the rescaling, "none"), then x and q (exponential
    map, world ω) with the new v, ω."""
    body, g = sc.problem.body, np.asarray(sc.problem.forces.gravity_W, float)
    x, v, q, w = y[0:3], y[3:6], y[6:10], y[10:13]
    R = matrix_from_quat(q)
    I_W = R @ body.inertia_B @ R.T
    v1 = v + h * np.asarray(F) / body.mass_kg + h * g
    w1 = w + h * np.linalg.solve(I_W, tau)
    if gyro != "none":
        lam, R_BP = body.principal_axes()
        RP = R @ R_BP
        wP = RP.T @ w1
        L = lam * wP
        L1 = L - h * np.cross(wP, L)
        if gyro == "renormalised":
            L1 *= np.linalg.norm(L) / np.linalg.norm(L1)
        w1 = RP @ (L1 / lam)
    return np.r_[x + h * v1, v1, quat_mul(quat_exp(h * w1), q), w1]


def _close(a, b, atol):
    np.testing.assert_allclose(a, b, rtol=0, atol=atol * max(1.0, float(np.max(np.abs(b)))))


# --- version, defaults --------------------------------------------------------------------------------------

def test_version_is_the_pinned_release():
    assert pe.version() == "3.0.3 (PhysX 5.3.1)"
    assert px.version() == "105.1-physx-5.3.1.patch0"     # the engine's own words agree with the header read


def test_sapien_and_physx_own_defaults():
    cfg = px.PhysxSceneConfig()
    np.testing.assert_array_equal(cfg.gravity, np.float32([0.0, 0.0, -9.81]))
    assert cfg.enable_tgs and not cfg.enable_ccd
    body = px.get_body_config()
    assert (body.solver_position_iterations, body.solver_velocity_iterations) == (10, 1)
    assert body.sleep_threshold == pytest.approx(0.005)
    system = px.PhysxCpuSystem()
    assert system.timestep == pytest.approx(0.01)
    e, c = sapien.Entity(), px.PhysxRigidDynamicComponent()
    e.add_component(c)
    assert c.angular_damping == pytest.approx(0.05) and c.linear_damping == 0.0
    assert c.max_angular_velocity == pytest.approx(100.0)
    assert c.max_linear_velocity == pytest.approx(1e16)
    assert c.max_depenetration_velocity == pytest.approx(1e32)
    assert c.max_contact_impulse == pytest.approx(1e32)
    assert c.sleep_threshold == pytest.approx(0.005)
    assert (c.solver_position_iterations, c.solver_velocity_iterations) == (10, 1)
    assert c.auto_compute_mass and c.mass == pytest.approx(1e-6) and not c.kinematic
    assert not c.disable_gravity and c.locked_motion_axes == [False] * 6 and c.collision_shapes == []


def test_a_model_has_the_scenarios_gravity_step_solver_and_neutral_settings():
    sc = scenario_from_parts(forces="gravity = [1.0, -2.0, 0.5]")
    default = px.get_scene_config()
    for variant in BOTH:
        S = _world(sc, variant, 0.004)
        c = S.comps[0]
        cfg = S.system.get_config()
        np.testing.assert_array_equal(cfg.gravity, np.float32([1.0, -2.0, 0.5]))
        assert cfg.enable_tgs == (variant == "tgs")
        assert S.system.timestep == np.float32(0.004)                   # PhysX keeps Δt in float32
        for setter, value in pw.BODY_SETTINGS:
            got = getattr(c, "get_" + setter[4:])() if setter != "set_kinematic" else c.kinematic
            assert got == pytest.approx(value), setter
        assert not c.auto_compute_mass and c.collision_shapes == [] and c.locked_motion_axes == [False] * 6
        # nothing else in the scene: no ground, no static body, no articulation
        assert len(S.system.rigid_dynamic_components) == 1 and not S.system.rigid_static_components
        assert not S.system.articulation_link_components
        # SAPIEN's process-wide default scene config is left as it was
        after = px.get_scene_config()
        assert after.enable_tgs == default.enable_tgs
        np.testing.assert_array_equal(after.gravity, default.gravity)


def test_neutralise_sets_every_setting_whatever_it_was():
    S, c = _raw_body()
    hostile = {"set_linear_damping": 0.5, "set_angular_damping": 0.7, "set_max_linear_velocity": 0.1,
               "set_max_angular_velocity": 0.1, "set_max_depenetration_velocity": 0.1,
               "set_max_contact_impulse": 0.1, "set_sleep_threshold": 10.0,
               "set_solver_position_iterations": 7, "set_solver_velocity_iterations": 3,
               "set_disable_gravity": True, "set_kinematic": True}
    assert set(hostile) == {s for s, _ in pw.BODY_SETTINGS}
    for setter, value in hostile.items():
        getattr(c, setter)(value)
    pw.neutralise(c)
    for setter, value in pw.BODY_SETTINGS:
        got = getattr(c, "get_" + setter[4:])() if setter != "set_kinematic" else c.kinematic
        assert got == pytest.approx(value), setter


def test_default_angular_damping_and_clamp_change_a_spin_and_neutralised_they_do_not():
    # isotropic body (no gyroscopic term), ω = 500 rad/s about z: SAPIEN's defaults damp it by (1 − 0.05 Δt)
    # and clamp it to 100 rad/s in the first step (DyBodyCoreIntegrator.h
    # bodyCoreComputeUnconstrainedVelocity)
    S, c = _raw_body()
    c.set_angular_velocity(np.float32([0.0, 0.0, 500.0]))
    S.step()
    assert c.angular_velocity[2] == pytest.approx(100.0, rel=1e-6)
    S, c = _raw_body()
    c.set_max_angular_velocity(1e16)
    c.set_angular_velocity(np.float32([0.0, 0.0, 50.0]))
    S.step()
    assert c.angular_velocity[2] == pytest.approx(50.0 * (1 - 0.05 * 0.01), rel=1e-6)
    S, c = _raw_body()
    pw.neutralise(c)
    c.set_angular_velocity(np.float32([0.0, 0.0, 500.0]))
    for _ in range(10):
        S.step()
    assert c.angular_velocity[2] == pytest.approx(500.0, rel=1e-6)


def test_a_slow_spin_falls_asleep_with_the_default_threshold_and_never_with_zero():
    # 1 mrad/s: mass-normalised energy 5e-7 < 0.005: PhysX puts the body to sleep once its wake counter
    # (0.4 s) runs out, and a sleeping body is stopped (its ω zeroed; DySleep.cpp); threshold 0 resets the
    # counter every step (a constant linear drift is not put to sleep: PhysX accumulates the velocities it
    # tests over frames)
    for neutral in (False, True):
        S, c = _raw_body()
        c.set_angular_damping(0.0)
        if neutral:
            pw.neutralise(c)
        c.set_angular_velocity(np.float32([0.0, 0.0, 1e-3]))
        for _ in range(300):
            S.step()
        if neutral:
            assert not c.is_sleeping and c.angular_velocity[2] == pytest.approx(1e-3, rel=1e-6)
        else:
            assert c.is_sleeping and c.angular_velocity[2] == 0.0


@pytest.mark.parametrize("variant", BOTH)
def test_solver_iterations_do_not_substep_a_lone_body(variant):
    # no constraint row: TGS integrates once with the whole Δt whatever its position iterations
    # (DyTGSDynamics.cpp iterativeSolveIsland, numContactConstraintBatches == 0); PGS too
    sc = _tilted(forces="gravity = [0.0, 0.0, -9.81]", angular_velocity="[0.4, 1.5, -0.7]",
                 velocity="[0.3, -0.1, 0.2]")
    states = []
    for iters in (1, 4, 50):
        S = _world(sc, variant)
        c = S.comps[0]
        c.set_solver_position_iterations(iters)
        c.set_solver_velocity_iterations(iters)
        for _ in range(5):
            c.add_force_torque(np.float32([1.0, 2.0, 3.0]), np.float32([0.3, -0.2, 0.5]))
            S.step()
        states.append(S.read())
    np.testing.assert_array_equal(states[0], states[1])
    np.testing.assert_array_equal(states[0], states[2])


# --- conventions ------------------------------------------------------------------------------------------

def test_pack_is_quaternion_w_first_then_position_velocity_and_world_angular_velocity():
    sc = _tilted()
    y = np.r_[1.0, -2.0, 0.5, 4.0, 5.0, 6.0, Q_TILT, 0.1, 0.2, 0.3]
    S = _world(sc, y=y)
    c = S.comps[0]
    row = np.frombuffer(S.system.pack(), dtype=np.float32)
    np.testing.assert_allclose(row[0:4], c.entity_pose.q, rtol=0, atol=1e-7)
    np.testing.assert_allclose(row[0:4], Q_TILT, rtol=0, atol=1e-7)
    np.testing.assert_allclose(row[4:7], [1.0, -2.0, 0.5], rtol=0, atol=1e-7)
    np.testing.assert_array_equal(row[7:10], c.linear_velocity)
    np.testing.assert_array_equal(row[10:13], c.angular_velocity)
    np.testing.assert_allclose(row[pw.PACK_TO_PACKED], y, rtol=0, atol=3e-7)
    np.testing.assert_array_equal(S.read()[0], row[pw.PACK_TO_PACKED])      # what the world reads


def test_quaternion_order_at_the_boundary():
    # (w, x, y, z) = (√½, 0, 0, √½) is 90° about z: body x along world y
    sc = scenario_from_parts(initial=YAW90)
    S = _world(sc)
    T = S.comps[0].entity_pose.to_transformation_matrix()
    np.testing.assert_allclose(T[:3, :3] @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], rtol=0, atol=2 * 2.0 ** -23)


@pytest.mark.parametrize("variant", BOTH)
def test_a_yawed_body_spinning_about_body_x_turns_about_world_y(variant):
    # 90° yaw: body x is world y; a torque-free spin about a principal axis keeps ω_W,
    # and q(t) = exp(ω_W t) q0
    sc = scenario_from_parts(initial=YAW90 + "\nangular_velocity_body = [2.0, 0.0, 0.0]", dt=0.01,
                             duration=0.5)
    run = pe.simulate(sc, variant, 0.01, 50)
    np.testing.assert_allclose(run.y[:, 10:13], np.tile([0.0, 2.0, 0.0], (51, 1)), rtol=0,
                               atol=50 * ctol.PHYSX_TGS_OMEGA_STEP_REL * 2.0)
    expected = quat_mul(quat_exp(np.outer(run.t_s, [0.0, 2.0, 0.0])), run.y[0, 6:10])
    assert np.max(geodesic_angle(expected, run.y[:, 6:10])) < 1e-5


def test_linear_velocity_is_the_coms_not_the_actor_origins():
    # a mass frame offset by 0.5 m along body x: a pure spin about the COM leaves the COM in place while the
    # actor origin circles it; linear_velocity is the COM's (0)
    S, c = _raw_body()
    pw.neutralise(c)
    c.set_cmass_local_pose(sapien.Pose(np.float32([0.5, 0.0, 0.0])))
    c.set_angular_velocity(np.float32([0.0, 0.0, 2.0]))
    for _ in range(20):
        S.step()
    np.testing.assert_allclose(c.linear_velocity, [0.0, 0.0, 0.0], atol=1e-6)
    com = c.entity_pose * c.cmass_local_pose
    np.testing.assert_allclose(com.p, [0.5, 0.0, 0.0], atol=1e-6)
    assert np.linalg.norm(c.entity_pose.p) > 0.1


@pytest.mark.parametrize("variant", BOTH)
def test_the_inertia_is_the_full_tensor_in_body_axes_through_principal_moments_and_axes(variant):
    # a world torque on a tilted body at rest: ω1 = Δt I_W⁻¹ τ with I_W = R I_B Rᵀ of the FULL tensor (no
    # gyroscopic term at rest, no armature): the principal moments and the mass frame's rotation reach PhysX
    sc = _tilted()
    S = _world(sc, variant)
    c = S.comps[0]
    lam, R_BP = sc.problem.body.principal_axes()
    np.testing.assert_allclose(c.inertia, lam, rtol=1e-6)
    tau = np.array([0.3, -0.2, 0.5])
    c.add_force_torque(np.float32([0.0, 0.0, 0.0]), np.float32(tau))
    S.step()
    R = matrix_from_quat(Q_TILT)
    _close(c.angular_velocity, 0.01 * np.linalg.solve(R @ sc.problem.body.inertia_B @ R.T, tau), HAND)


def test_mass_and_force_reach_the_velocity_and_forces_are_cleared_after_each_step():
    sc = _tilted()
    S = _world(sc)
    c = S.comps[0]
    assert c.mass == 2.0
    c.add_force_torque(np.float32([1.0, 2.0, 3.0]), np.float32([0.5, -0.3, 0.2]))
    S.step()
    v1, w1 = np.array(c.linear_velocity), np.array(c.angular_velocity)
    _close(v1, 0.01 * np.array([1.0, 2.0, 3.0]) / 2.0, HAND)
    S.step()                                          # no force and no torque in the second step
    np.testing.assert_array_equal(c.linear_velocity, v1)
    assert np.linalg.norm(np.array(c.angular_velocity) - w1) < 1e-3 * np.linalg.norm(w1)   # gyroscopic only


def test_the_mass_a_force_sees_is_the_one_set_when_the_force_is_added():
    # PhysX turns a force into an acceleration when it is added (addForce: F × the current 1/m), and applies
    # it at the start of the next step (BodySim::updateForces): a mass set afterwards does not change it. The
    # adapter sets the mass when it builds the body, before any force.
    sc = _tilted()
    for mass_first, expected_mass in ((True, 4.0), (False, 2.0)):
        S = _world(sc)
        c = S.comps[0]
        if mass_first:
            c.set_mass(4.0)
        c.add_force_torque(np.float32([1.0, 2.0, 3.0]), np.float32([0.0, 0.0, 0.0]))
        if not mass_first:
            c.set_mass(4.0)
        S.step()
        _close(c.linear_velocity, 0.01 * np.array([1.0, 2.0, 3.0]) / expected_mass, HAND)


# --- the step -----------------------------------------------------------------------------------------------

def _one_step_case():
    sc = _tilted(forces='gravity = [0.0, 0.0, -9.81]\n[[forces.torque]]\ntorque = [0.3, -0.2, 0.5]\n'
                        'frame = "world"\n[[forces.point]]\nforce = [1.0, 2.0, 3.0]\nframe = "world"',
                 velocity="[0.3, -0.1, 0.2]", angular_velocity="[0.4, 1.5, -0.7]")
    return sc, sc.problem.initial_packed()


@pytest.mark.parametrize("variant", BOTH)
def test_one_step_is_physx_s_step_written_out_and_not_the_other_candidates(variant):
    # Δt = 0.05 s: the candidates differ from PhysX's step by O(Δt²), TGS's float32 ω error does not shrink
    sc, y0 = _one_step_case()
    h = 0.05
    y1 = pe.one_step(sc, variant, h, y0[None])[0]
    F, tau = [1.0, 2.0, 3.0], [0.3, -0.2, 0.5]
    hand = physx_step(sc, y0, F, tau, h)
    _close(y1[0:3], hand[0:3], HAND)
    _close(y1[3:6], hand[3:6], HAND)
    assert geodesic_angle(hand[6:10], y1[6:10]) < HAND * 4
    w_tol = HAND if variant == "pgs" else ctol.PHYSX_TGS_OMEGA_STEP_REL * np.linalg.norm(hand[10:13])
    np.testing.assert_allclose(y1[10:13], hand[10:13], rtol=0, atol=w_tol)
    # the candidates it is not: the plain explicit gyroscopic step, no gyroscopic term (both ≥ 6× farther)
    for other in ("explicit", "none"):
        assert np.max(np.abs(physx_step(sc, y0, F, tau, h, gyro=other)[10:13] - y1[10:13])) > 6 * w_tol


@pytest.mark.parametrize("variant", BOTH)
def test_the_gyroscopic_step_keeps_the_momentums_magnitude(variant):
    # torque-free tumble, 1000 steps of 0.01 s: |L| stays (PhysX rescales the explicit step's L' to |L|) where
    # the plain explicit step grows it; the world L = I_W ω turns (only its magnitude is kept per step)
    sc = _tilted(angular_velocity="[0.4, 1.5, -0.7]")
    run = pe.simulate(sc, variant, 0.01, 1000)
    R = matrix_from_quat(run.y[:, 6:10])
    L = np.einsum("nij,jk,nlk,nl->ni", R, sc.problem.body.inertia_B, R, run.y[:, 10:13])
    size = np.linalg.norm(L, axis=1)
    drift = np.max(np.abs(size / size[0] - 1))
    y, explicit = sc.problem.initial_packed(), []
    for _ in range(1000):
        y = physx_step(sc, y, [0, 0, 0], [0, 0, 0], 0.01, gyro="explicit")
        explicit.append(y)
    Re = matrix_from_quat(explicit[-1][6:10])
    grown = np.linalg.norm(Re @ sc.problem.body.inertia_B @ Re.T @ explicit[-1][10:13]) / size[0] - 1
    bound = 1e-4 if variant == "pgs" else 3e-3      # TGS: its ω grows 3-10 ε₃₂ per step (next test)
    assert drift < bound < grown


def test_tgs_multiplies_omega_by_1_plus_10_float32_ulps_per_step_and_pgs_does_not():
    # an isotropic spin (no gyroscopic term, nothing acts): ω is constant in exact arithmetic. TGS carries ω
    # in sqrt-inertia space and back (two float32 world matrices); measured: +1.19e-6 relative per step, the
    # same at Δt = 0.01 and 0.001 s; PGS leaves it to 1 ulp
    sc = _tilted(body="mass = 1.0\ninertia = [2.0, 2.0, 2.0]", angular_velocity="[0.0, 0.0, 3.0]")
    for h in (0.01, 0.001):
        growth = {}
        for variant in BOTH:
            w = pe.one_step(sc, variant, h, sc.problem.initial_packed()[None])[0, 10:13]
            growth[variant] = np.linalg.norm(w) / 3.0 - 1
        assert 5 * 2.0 ** -23 < growth["tgs"] < 20 * 2.0 ** -23
        assert abs(growth["pgs"]) <= 2 * 2.0 ** -23


def test_decay_is_applied_before_the_step_with_that_steps_force_scaled():
    sc = scenario_from_parts(body="mass = 2.0\ninertia = [0.5, 0.5, 0.5]",
                             initial="velocity = [1.0, -2.0, 0.5]\nangular_velocity = [0.3, 0.0, 3.0]",
                             forces='gravity = [0.0, 0.0, -9.81]\nvelocity_decay = 0.99\n'
                                    'angular_velocity_decay = 0.95\n'
                                    '[[forces.point]]\nforce = [1.0, 2.0, 3.0]\nframe = "world"\n'
                                    '[[forces.torque]]\ntorque = [0.1, 0.2, -0.3]\nframe = "world"', dt=0.01)
    y0 = sc.problem.initial_packed()
    for variant in BOTH:
        y1 = pe.one_step(sc, variant, 0.01, y0[None])[0]
        _close(y1[3:6], 0.99 * (y0[3:6] + 0.01 * (np.array([0.5, 1.0, 1.5]) + [0.0, 0.0, -9.81])), HAND)
        _close(y1[10:13], 0.95 * (y0[10:13] + 0.01 * np.array([0.2, 0.4, -0.6])), 10 * HAND)
        run = pe.simulate(sc, variant, 0.01, 3)                             # the free run does the same
        np.testing.assert_array_equal(run.y[1], y1)


def test_body_frame_point_forces_and_springs_reach_physx_as_the_force_models_wrench():
    sc = _tilted(forces='[[forces.point]]\nforce = [0.4, -1.0, 2.0]\npoint = [0.1, 0.2, -0.3]\n'
                        'frame = "body"\n[[forces.spring]]\nanchor = [0.0, 0.0, 1.0]\n'
                        'attach = [0.2, 0.0, 0.1]\nstiffness = 5.0',
                 angular_velocity="[0.4, 1.5, -0.7]", velocity="[0.3, -0.1, 0.2]")
    y0 = sc.problem.initial_packed()
    fm, body = sc.problem.forces, sc.problem.body
    f, tau = fm.force_torque(body, y0[0:3], y0[3:6], y0[6:10])
    y1 = pe.one_step(sc, "pgs", 1e-3, y0[None])[0]
    hand = physx_step(sc, y0, f, tau, 1e-3)
    _close(y1[3:6], hand[3:6], HAND)
    _close(y1[10:13], hand[10:13], HAND)


# --- runs ---------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", ["spring_pendulum", "velocity_decay", "applied_torque"])
def test_one_step_replays_the_run(name):
    sc = load_scenario(name)
    for variant in BOTH:
        run = pe.simulate(sc, variant, 0.01, 20)
        again = pe.one_step(sc, variant, 0.01, run.y[:-1])
        scale = np.maximum(1.0, np.abs(run.y[1:]))
        # float32: the run's state is PhysX's own, the restart goes through float64 → float32 (≤ 1 ulp each);
        # TGS's ω comes back through its sqrt-inertia round trip, whose ~10-ulp error moves with the
        # attitude's last bits (a principal frame turned by the mass frame's rotation is re-rounded on the
        # way in)
        bound = 8 * 2.0 ** -23 if variant == "pgs" else ctol.PHYSX_TGS_OMEGA_STEP_REL
        assert np.max(np.abs(again - run.y[1:]) / scale) < bound


def test_simulate_many_steps_runs_of_one_dt_and_gravity_together_bit_for_bit(monkeypatch):
    names = ["tennis_racket", "applied_torque", "spring_pendulum", "velocity_decay"]
    scs = [load_scenario(n) for n in names]
    for variant in BOTH:
        reqs = [RunRequest(sc, 0.01, 30 + 7 * k) for k, sc in enumerate(scs)]
        reqs.append(RunRequest(scs[0], 0.005, 12))                    # another Δt: its own scene
        scenes, build = [], pe.PhysxEngine.build

        def counted(self, rs, v, dt, scenes=scenes, build=build):
            scenes.append(len(rs))
            return build(self, rs, v, dt)
        monkeypatch.setattr(pe.PhysxEngine, "build", counted)
        many = pe.simulate_many(variant, reqs)
        monkeypatch.undo()
        # one scene per Δt and float32 gravity, whatever the run lengths (two gravities at Δt = 0.01 s)
        keys = {pe.PhysxAdapter().group_key(r) for r in reqs}
        assert len(keys) == len(scenes) == 3 and sorted(scenes) == [1, 2, 2]
        for r, run in zip(reqs, many):
            alone = pe.simulate(r.scenario, variant, r.dt_s, r.n_steps)
            np.testing.assert_array_equal(run.y, alone.y)
            np.testing.assert_array_equal(run.t_s, alone.t_s)


def test_a_scene_of_many_bodies_takes_array_forces_and_gives_each_run_alone_bit_for_bit():
    """Above MANY_BODIES bodies a scene takes its forces as arrays (one compiled evaluation, float32 rows to
    SAPIEN, the bodies to give one chosen in one pass); alone, a run takes them as plain floats per body:
    the same numbers for every force kind (none beyond gravity, a body torque, springs, decay, a tumble),
    every variant."""
    names = ["projectile", "applied_torque", "spring_pendulum", "velocity_decay", "tennis_racket"]
    scs = [load_scenario(n) for n in names]
    # two scenes (two gravities), each of more than MANY_BODIES bodies
    reqs = [RunRequest(scs[k % len(scs)], 0.01, 25 + k) for k in range(3 * MANY_BODIES + 3)]
    assert min(sum(1 for r in reqs if bool(r.scenario.problem.forces.gravity_W.any()) is g)
               for g in (True, False)) > MANY_BODIES
    for variant in BOTH:
        for r, run in zip(reqs, pe.simulate_many(variant, reqs)):
            alone = pe.simulate(r.scenario, variant, r.dt_s, r.n_steps)
            assert np.array_equal(run.y, alone.y) and run.message == alone.message, r.scenario.name


def test_the_first_row_is_the_scenarios_and_quaternions_stay_continuous():
    sc = scenario_from_parts(body="mass = 1.0\ninertia = [1.0, 1.0, 1.0]",
                             initial=f"orientation = {(-Q_TILT).tolist()}\n"
                                     "angular_velocity = [0.0, 0.0, 3.0]")
    run = pe.simulate(sc, "pgs", 0.01, 400)
    np.testing.assert_array_equal(run.y[0], sc.problem.initial_packed())
    assert np.max(np.linalg.norm(np.diff(run.y[:, 6:10], axis=0), axis=1)) < 0.02
    expected = quat_mul(quat_exp(np.outer(run.t_s, [0.0, 0.0, 3.0])), -Q_TILT)
    assert np.max(geodesic_angle(expected, run.y[:, 6:10])) < 1e-4


def test_a_state_that_goes_non_finite_is_reported_as_such_and_its_body_parked(monkeypatch):
    # a force beyond float32's range (no scenario file may ask for one: the force model is replaced): PhysX
    # steps the velocity to inf and the position to inf or NaN without passing 1e8 first; the run ends there
    # with the words of that state (not of the rest state the body is parked at), the body beside untouched
    from types import SimpleNamespace

    from cross_checks.engines import forces
    sc, calm = scenario_from_parts(initial="velocity = [1.0, 0.0, 0.0]"), load_scenario("tennis_racket")
    alone = {v: pe.simulate(calm, v, 0.01, 20).y for v in BOTH}
    huge = SimpleNamespace(force_torque=lambda y: (1e39, 0.0, 0.0, 0.0, 0.0, 0.0))
    real = forces.float_forces
    monkeypatch.setattr(forces, "float_forces", lambda scenario: huge if scenario is sc else real(scenario))
    for variant in BOTH:
        run, other = pe.simulate_many(variant, [RunRequest(sc, 0.01, 20), RunRequest(calm, 0.01, 20)])
        assert run.message == "diverged at t = 0.01 s (non-finite state)" and len(run.t_s) == 1
        np.testing.assert_array_equal(other.y, alone[variant])


def test_projectile_is_the_semi_implicit_closed_form_to_float32():
    sc = load_scenario("projectile")
    n, h = 100, 0.01
    p = sc.problem
    k = np.arange(n + 1)[:, None]
    exact = p.initial.x_W + k * h * p.initial.v_W + np.asarray(p.forces.gravity_W) * h * h * k * (k + 1) / 2
    for variant in BOTH:
        run = pe.simulate(sc, variant, h, n)
        scale = np.max(np.abs(exact))
        assert np.max(np.abs(run.y[:, 0:3] - exact)) < n * 2.0 ** -23 * scale


def test_nothing_is_compiled_or_cached_at_run_time(tmp_path, monkeypatch):
    from cross_checks.core.files import kernel_cache_dir
    monkeypatch.setenv("RBCHECK_KERNEL_CACHE_DIR", str(tmp_path))
    pe.simulate(load_scenario("tennis_racket"), "tgs", 0.01, 50)
    assert not kernel_cache_dir("physx").exists() and list(tmp_path.iterdir()) == []


def _python(code: str) -> subprocess.CompletedProcess:
    """``code`` run by a fresh Python (nothing imported yet), its output captured."""
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                          env={**os.environ, "MPLBACKEND": "Agg"})


def test_importing_the_adapter_and_asking_its_version_import_no_sapien():
    code = ("import sys\nfrom cross_checks.engines import physx_engine as pe\n"
            "from cross_checks.engines import all_variants\n"
            "print(pe.version(), pe.PhysxAdapter().source_files()[-1].name, "
            "[v.name for v in all_variants() if v.engine == 'physx'])\n"
            "print('sapien' in sys.modules)\n")
    out = _python(code).stdout.split("\n")
    assert out[0].startswith("3.0.3 (PhysX 5.3.1) libsapien.so ['physx:tgs', 'physx:pgs']")
    assert out[1] == "False"


def test_a_run_where_sapien_finds_no_system_libvulkan_prints_nothing_of_it():
    """SAPIEN warns at its import when it finds no system libvulkan (it falls back to its own; a fresh
    machine); the adapter imports sapien at a run's world build with that warning silenced, so a run (and
    every sweep worker's first) prints nothing of it."""
    code = ("import os\nreal = os.path.isfile\n"
            "os.path.isfile = lambda p: False if 'libvulkan' in str(p) else real(p)\n"
            "from cross_checks.engines import physx_engine as pe\n"
            "from cross_checks.scenario import load_scenario\n"
            "print(len(pe.simulate(load_scenario('projectile'), 'pgs', 0.01, 3).y))\n")
    done = _python(code)
    assert done.stdout == "4\n" and "libvulkan" not in done.stderr, done.stderr


def test_a_world_build_reads_no_package_metadata_once_sapien_is_imported(monkeypatch):
    """The install checks (package metadata and import specs, ~0.5 ms) run once per process, with sapien's
    import, not at every world build (a sweep builds one per run group and per one-step record)."""
    from cross_checks.engines import install
    reqs = [RunRequest(load_scenario("projectile"), 0.01, 1)]
    pe.PhysxAdapter().build(reqs, "pgs", 0.01).close()
    calls = []
    monkeypatch.setattr(install, "installed_version", lambda dist: calls.append(dist) or "3.0.3")
    pe.PhysxAdapter().build(reqs, "pgs", 0.01).close()
    assert calls == []


def test_version_and_list_name_physx():
    from cross_checks.cli.parser import _version_text
    from cross_checks.engines import all_variants
    assert "physx 3.0.3 (PhysX 5.3.1)" in _version_text()
    info = {v.name: v for v in all_variants()}
    assert info["physx:tgs"].available and info["physx:tgs"].order == 1.0 and not info["physx:tgs"].required
    assert info["physx:pgs"].available and info["physx:pgs"].order == 1.0


@pytest.mark.parametrize("variant", BOTH)
def test_first_order_on_catalog_scenarios(assert_engine, variant):
    summary = assert_engine(f"physx:{variant}", ["applied_torque"])
    fitted = {(c["scenario"], c["quantity"]): c["order"]
              for c in summary["convergence"] if c["verdict"] == "converges"}
    assert fitted[("applied_torque", "orientation")] == pytest.approx(1.0, abs=0.15)


@pytest.mark.slow
def test_pgs_on_the_tumbling_and_state_dependent_scenarios(assert_engine):
    assert_engine("physx:pgs", ["tennis_racket", "spring_pendulum", "velocity_decay", "tumbling_box"])


def test_tgs_rounds_omega_more_than_an_ordinary_step_and_within_its_declared_factor():
    """TGS's declared rounding_factor (4): on torque-free spins about a principal axis, where the exact step
    leaves ω as it is, what one step changes in |ω| is TGS's rounding alone. Its largest such change exceeds
    an ordinary step's one-step budget (CHECK_ROUNDINGS_PER_STEP u), so the factor is needed, and stays within
    the declared factor times it; PGS's stays within the ordinary budget."""
    from cross_checks.analysis.expectations import traits
    u = 2.0 ** -24
    worst = {}
    for variant in BOTH:
        changes = []
        for axis, rate in (([1.0, 0.0, 0.0], 2.0), ([0.0, 1.0, 0.0], 1.7), ([0.0, 0.0, 1.0], 3.1)):
            w = "[" + ", ".join(str(rate * a) for a in axis) + "]"
            sc = _tilted(body="mass = 1.0\ninertia = [0.2, 0.3, 0.4]", angular_velocity_body=w)
            y = pe.simulate(sc, variant, 0.01, 40).y
            mag = np.linalg.norm(y[:, 10:13], axis=1)
            changes.append(np.max(np.abs(np.diff(mag)) / mag[:-1]))
        worst[variant] = max(changes)
    budget = ctol.CHECK_ROUNDINGS_PER_STEP * u
    assert worst["pgs"] <= budget, worst
    assert budget < worst["tgs"] <= traits(resolve("physx:tgs")).rounding_factor * budget, worst
    assert traits(resolve("physx:pgs")).rounding_factor == 1.0


def test_the_world_reads_every_body_from_one_pack_as_plain_floats_and_takes_forces_as_rows():
    """One ``pack()`` per read, given as each body's packed row of plain floats (the float32 values exactly:
    no arrays per step), which ``rows`` turns into the chunk's (n, B, 13) float64 array; ``apply`` takes the
    harness's rows of plain floats (``float_rows``) as it takes (B, 3) arrays: the same step."""
    scs = [_tilted(angular_velocity="[0.4, 1.5, -0.7]"), load_scenario("tennis_racket")]
    W = pe.PhysxWorld([RunRequest(sc, 0.01, 10) for sc in scs], "tgs", 0.01)
    W.set_state(np.array([sc.problem.initial_packed() for sc in scs]))
    assert W.float_rows
    rows = W.read()
    packs = np.frombuffer(W.system.pack(), dtype=np.float32).reshape(2, 13)[:, pw.PACK_TO_PACKED]
    assert all(type(r) is tuple and all(type(v) is float for v in r) for r in rows)
    np.testing.assert_array_equal(np.array(rows), packs)
    block = W.rows([rows, rows])
    assert block.shape == (2, 2, 13) and block.dtype == np.float64
    np.testing.assert_array_equal(block[1], packs)
    f, tau = [(0.5, -1.0, 2.0), (0.0, 0.0, 0.0)], [(0.1, 0.2, -0.3), (0.0, 0.3, 0.0)]
    W.apply(f, tau)
    W.step()
    by_rows = W.rows([W.read()])
    W.set_state(np.array([sc.problem.initial_packed() for sc in scs]))
    W.apply(np.array(f), np.array(tau))
    W.step()
    np.testing.assert_array_equal(W.rows([W.read()]), by_rows)


def test_a_body_physx_refuses_fails_its_own_runs_with_physxs_words(monkeypatch):
    """A body whose mass properties PhysX refuses (none of the schema's: docs/hardening.md's ranges are
    float32 PhysX's) is an EngineError with SAPIEN's version and PhysX's words, for its own runs only: the
    other runs of its scene go on."""
    cls = pe._world_class()
    real = cls.add_body

    def add_body(self, mass_kg, moments, q_BP):
        if mass_kg == 7.0:
            raise RuntimeError("invalid mass")
        return real(self, mass_kg, moments, q_BP)
    monkeypatch.setattr(cls, "add_body", add_body)
    ok, bad = (scenario_from_parts(body=f"mass = {m}\ninertia = [1.0, 2.0, 3.0]") for m in (2.0, 7.0))
    runs = pe.simulate_many("pgs", [RunRequest(ok, 0.01, 5), RunRequest(bad, 0.01, 5),
                                    RunRequest(ok, 0.01, 3)])
    assert [len(runs[0].y), len(runs[2].y)] == [6, 4]
    assert isinstance(runs[1], pe.EngineError)
    assert "PhysX (sapien 3.0.3) refuses the body: RuntimeError: invalid mass" in str(runs[1])
