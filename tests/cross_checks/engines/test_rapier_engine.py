"""The Rapier adapter (cross_checks.engines.rapier_engine): every convention it relies on, pinned on rapier3d
itself (docs/engine_conventions.md, "Rapier 0.36.1"), every default it neutralises, one step against the
scheme read in Rapier's source written out here in NumPy, its float32 arithmetic, batching, divergence.

Rapier computes in float32: a comparison with a float64 hand computation allows a few float32 roundings
(F32 below, relative to the quantity's scale), and each test that tells two schemes apart checks that the
other scheme is farther than that by a wide margin."""
import math
import os
import signal
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

rapier = pytest.importorskip("rapier3d", reason="rapier3d is not installed (pip install -e '.[rapier]')")

from cross_checks.engines import rapier_engine as ra  # noqa: E402
from cross_checks.engines.base import RunRequest  # noqa: E402
from cross_checks.engines.world import MANY_BODIES  # noqa: E402
from cross_checks.engines.worlds import rapier as rpw  # noqa: E402
from cross_checks.scenario import load_scenario  # noqa: E402
from reference_sim.quaternion import (  # noqa: E402
    geodesic_angle,
    matrix_from_quat,
    quat_exp,
    quat_mul,
    quat_normalize,
)
from tests.helpers.scenarios import YAW90, scenario_from_parts  # noqa: E402

GYRO, NO_GYRO = "symplectic_euler", "symplectic_euler_no_gyro"
#: float32's machine epsilon 2⁻²³: one step of Rapier leaves a few of its roundings in each number.
EPS32 = 2.0 ** -23
#: A hand-derived float64 step vs Rapier's float32 step, relative to the quantity's scale: 16 float32
#: roundings (measured ≤ 3 ε on the states below).
F32 = 16 * EPS32
Q_TILT = np.array([0.9, 0.1, 0.3, -0.2]) / np.linalg.norm([0.9, 0.1, 0.3, -0.2])
FULL_INERTIA = "mass = 2.0\ninertia = [[2.0, 0.1, 0.05], [0.1, 3.0, -0.2], [0.05, -0.2, 4.0]]"
NO_GRAVITY = "gravity = [0.0, 0.0, 0.0]"


def _tilted(body=FULL_INERTIA, forces=NO_GRAVITY, **initial):
    """A scenario whose body starts at Q_TILT, at (1, −2, 0.5) m, with the initial fields given (TOML)."""
    lines = [f"orientation = {Q_TILT.tolist()}", "position = [1.0, -2.0, 0.5]"]
    lines += [f"{k} = {v}" for k, v in initial.items()]
    return scenario_from_parts(body=body, initial="\n".join(lines), forces=forces)


def _world_inertia(sc, q):
    R = matrix_from_quat(q)
    return R @ sc.problem.body.inertia_B @ R.T


def _close(a, b, scale=1.0, rel=F32):
    np.testing.assert_allclose(a, b, rtol=0, atol=rel * scale)


def _world(sc, dt=0.01, variant=GYRO):
    """The adapter's world of one body of ``sc`` (its gravity) at step ``dt`` for a run of 1000 steps, put at
    the initial state; the body is ``W.bodies[0]``."""
    W = ra.RapierWorld([RunRequest(sc, dt, 1000)], variant, dt)
    W.set_state(sc.problem.initial_packed()[None])
    return W


# --- the scheme read in Rapier's source, in NumPy (float64) ------------------------------------------------

def _gyro_corrected(w_W, q, body, h):
    """rapier src/dynamics/rigid_body.rs ``gyroscopic_corrected_angvel``: in the principal frame at attitude
    ``q``, L = I w, L' = L − h w × L rescaled to |L|, back to world axes."""
    moments, R_BP = body.principal_axes()
    R_WP = matrix_from_quat(q) @ R_BP
    w = R_WP.T @ w_W
    L = moments * w
    L2 = L - h * np.cross(w, L)
    L2 = L2 * math.sqrt(np.dot(L, L) / np.dot(L2, L2))
    return R_WP @ (L2 / moments)


def _hand_step(sc, y, h, f_W, tau_W, gyro=True):
    """One Rapier step (worker.rs, one substep): v += h f/m (f including the weight), ω += h I_W⁻¹ τ (start
    attitude), the gyroscopic correction, then x += h v and q ← normalize((1, ½hω) ⊗ q) with the new ones."""
    p = sc.problem
    m = p.body.mass_kg
    v1 = y[3:6] + h * (np.asarray(f_W) / m + np.asarray(p.forces.gravity_W))
    w1 = y[10:13] + h * np.linalg.solve(_world_inertia(sc, y[6:10]), tau_W)
    if gyro:
        w1 = _gyro_corrected(w1, y[6:10], p.body, h)
    q1 = quat_normalize(quat_mul(np.r_[1.0, 0.5 * h * w1], y[6:10]))
    return np.r_[y[0:3] + h * v1, v1, q1, w1]


# --- version, conventions ----------------------------------------------------------------------------------

def test_version_is_the_pinned_release_of_the_official_float32_bindings():
    from importlib.metadata import metadata
    assert ra.version() == "0.36.1"
    meta = metadata("rapier3d")
    assert "(3D, f32)" in meta["Summary"] and "dimforge/rapier" in " ".join(meta.get_all("Project-URL"))


def test_numbers_are_stored_in_float32():
    assert rapier.Vec3(0.1, 0.0, 0.0).x == float(np.float32(0.1)) != 0.1
    sc = scenario_from_parts(initial="velocity = [0.1, 0.0, 0.0]")
    run = ra.simulate(sc, GYRO, 0.01, 3)
    assert run.y[0, 3] == 0.1                                 # the first row is the scenario's, as given
    assert all(float(np.float32(v)) == v for v in run.y[1:].ravel())


def test_rotation3_is_constructed_w_first_but_its_tuples_are_x_y_z_w():
    r = rapier.Rotation3(0.5, 0.5, 0.5, 0.5)                  # (w, x, y, z): 120° about (1, 1, 1)
    assert (r.w, r.i, r.j, r.k) == (0.5, 0.5, 0.5, 0.5)
    r = rapier.Rotation3(*[float(c) for c in Q_TILT])
    assert r.to_tuple() == r.quaternion
    _close(r.to_tuple(), np.r_[Q_TILT[1:], Q_TILT[0]], rel=EPS32)
    _close([r.w, r.i, r.j, r.k], Q_TILT, rel=EPS32)
    _close(np.reshape(r.to_matrix(), (3, 3)), matrix_from_quat(Q_TILT), rel=4 * EPS32)      # body → world


def test_quaternion_order_at_the_boundary():
    # (w, x, y, z) = (√½, 0, 0, √½) is 90° about z: body x along world y, read back as set
    sc = scenario_from_parts(initial=YAW90)
    W = _world(sc)
    _close(W.bodies[0].rotation.transform_vector((1.0, 0.0, 0.0)).to_tuple(), [0.0, 1.0, 0.0], rel=EPS32)
    _close(W.read()[0][6:10], sc.problem.initial_packed()[6:10], rel=EPS32)


def test_angular_velocity_is_in_world_axes_and_the_rotation_update_is_the_normalised_linear_one():
    # 90° yaw: body x is world y. A torque-free spin of 20 rad/s about body x (a principal axis) stays there:
    # ω_W = (0, 20, 0) throughout, and each step turns the body about WORLD y by 2 atan(|ω|Δt/2) — Rapier's
    # q ← normalize((1, ½Δt ω_W) ⊗ q) — not by |ω|Δt (the exponential map: 0.033 rad apart after 50 steps)
    sc = scenario_from_parts(initial=YAW90 + "\nangular_velocity_body = [20.0, 0.0, 0.0]",
                             dt=0.01, duration=0.5)
    run = ra.simulate(sc, GYRO, 0.01, 50)
    # float32: the gyroscopic pass moves |ω| by about an ulp a step (see the constant_spin test below)
    _close(run.y[:, 10:13], np.tile([0.0, 20.0, 0.0], (51, 1)), 20.0, rel=2 * 50 * EPS32)
    k = np.arange(51)
    linearised = quat_mul(quat_exp(np.outer(k * 2 * math.atan(0.1), [0.0, 1.0, 0.0])), run.y[0, 6:10])
    exp_map = quat_mul(quat_exp(np.outer(run.t_s, [0.0, 20.0, 0.0])), run.y[0, 6:10])
    assert np.max(geodesic_angle(linearised, run.y[:, 6:10])) < 50 * F32
    assert np.max(geodesic_angle(exp_map, run.y[:, 6:10])) > 0.03


def test_mass_properties_are_the_scenarios_about_the_com_and_take_effect_at_the_first_step():
    sc = _tilted()
    W = _world(sc)
    assert W.bodies[0].mass == 0.0                             # not yet: Rapier updates it in its step
    W.step()
    rb = W.bodies[0]
    assert rb.mass == 2.0
    assert rb.local_center_of_mass.to_tuple() == (0.0, 0.0, 0.0)
    mp = rb.mass_properties
    R_BP = matrix_from_quat([mp.principal_inertia_local_frame.w, mp.principal_inertia_local_frame.i,
                             mp.principal_inertia_local_frame.j, mp.principal_inertia_local_frame.k])
    I_B = R_BP @ np.diag(mp.principal_inertia.to_tuple()) @ R_BP.T
    _close(I_B, sc.problem.body.inertia_B, 4.0, rel=4 * EPS32)  # the full tensor, in body axes
    # body origin = COM: the translation and linvel are the COM's
    _close(rb.center_of_mass.to_tuple(), rb.translation.to_tuple(), rel=0.0)


def test_a_diagonal_tensor_gets_no_principal_frame_rotation_at_all():
    sc = scenario_from_parts(body="mass = 1.0\ninertia = [1.0, 2.0, 3.0]")
    mp = rpw.mass_properties(*ra.body_spec(sc.problem.body))
    assert mp.principal_inertia.to_tuple() == (1.0, 2.0, 3.0)
    assert mp.principal_inertia_local_frame.to_tuple() == (0.0, 0.0, 0.0, 1.0)


# --- the step ----------------------------------------------------------------------------------------------

FORCED = ('gravity = [0.0, 0.0, -9.81]\n[[forces.torque]]\ntorque = [0.3, -0.2, 0.5]\nframe = "world"\n'
          '[[forces.point]]\nforce = [1.0, 2.0, 3.0]\nframe = "world"')


def test_one_step_is_rapiers_scheme_written_out_by_hand():
    # a tilted full-tensor body tumbling under gravity, a world force and a world torque, Δt = 0.05 s so that
    # the candidate schemes are far apart in float32
    sc = _tilted(forces=FORCED, velocity="[0.3, -0.1, 0.2]", angular_velocity="[0.4, 1.5, -0.7]")
    h, y0 = 0.05, sc.problem.initial_packed()
    f, tau = np.array([1.0, 2.0, 3.0]), np.array([0.3, -0.2, 0.5])     # applied (the hand step adds m g)
    y1 = ra.one_step(sc, GYRO, h, y0[None])[0]
    hand = _hand_step(sc, y0, h, f, tau)
    _close(y1[3:6], hand[3:6], 1.0)
    _close(y1[0:3], hand[0:3], 2.0)
    _close(y1[10:13], hand[10:13], 1.7)
    assert geodesic_angle(hand[6:10], y1[6:10]) < F32
    # the candidates it is not: the explicit gyroscopic step without the |L| rescaling (MuJoCo/DART Euler's),
    # the gyroscopic term at the NEW attitude, the exponential-map attitude update
    I_W, w_ = _world_inertia(sc, Q_TILT), y0[10:13]
    w_explicit = w_ + h * np.linalg.solve(I_W, tau - np.cross(w_, I_W @ w_))
    assert np.max(np.abs(w_explicit - y1[10:13])) > 50 * F32
    assert np.max(np.abs(_gyro_corrected(y0[10:13] + h * np.linalg.solve(I_W, tau), hand[6:10],
                                         sc.problem.body, h) - y1[10:13])) > 50 * F32
    assert geodesic_angle(quat_mul(quat_exp(h * hand[10:13]), Q_TILT), y1[6:10]) > 10 * F32


def test_without_gyroscopic_forces_omega_changes_only_by_the_torque():
    sc = _tilted(forces=FORCED, velocity="[0.3, -0.1, 0.2]", angular_velocity="[0.4, 1.5, -0.7]")
    h, y0 = 0.05, sc.problem.initial_packed()
    f, tau = np.array([1.0, 2.0, 3.0]), np.array([0.3, -0.2, 0.5])     # applied (the hand step adds m g)
    y1 = ra.one_step(sc, NO_GYRO, h, y0[None])[0]
    hand = _hand_step(sc, y0, h, f, tau, gyro=False)
    _close(y1[10:13], hand[10:13], 1.7)
    assert geodesic_angle(hand[6:10], y1[6:10]) < F32
    assert not _world(sc, h, NO_GYRO).bodies[0].gyroscopic_forces_enabled
    assert _world(sc, h, GYRO).bodies[0].gyroscopic_forces_enabled


def test_the_gyroscopic_step_keeps_the_angular_momentum_magnitude_and_moves_the_energy():
    # torque-free tumble: |L| is kept to float32 round-off by the rescaling, the energy is not (it drifts at
    # O(Δt²) per step): the drift of Traits(rotation_drift="whole_state") — here towards the separatrix:
    # up for a spin near the major axis (I3 = 3), down near the minor one (I1 = 1)
    body = "mass = 1.0\ninertia = [1.0, 2.0, 3.0]"
    for w_B, sign in (([0.3, 0.2, 2.0], +1), ([2.0, 0.3, 0.2], -1)):
        sc = scenario_from_parts(body=body, initial=f"angular_velocity_body = {w_B}", dt=0.02, duration=2.0)
        run = ra.simulate(sc, GYRO, 0.02, 100)
        R = np.array([matrix_from_quat(q) for q in run.y[:, 6:10]])
        wB = np.einsum("nji,nj->ni", R, run.y[:, 10:13])
        L = np.linalg.norm(wB * [1.0, 2.0, 3.0], axis=1)
        E = 0.5 * np.sum(wB * wB * [1.0, 2.0, 3.0], axis=1)
        assert np.max(np.abs(L / L[0] - 1.0)) < 100 * F32
        assert sign * (E[-1] / E[0] - 1.0) > 100 * F32


def test_a_spin_about_a_principal_axis_gains_about_an_ulp_of_omega_per_step_from_float32_round_off():
    # constant_spin: |ω| = 3 rad/s about the major axis. Exactly, the gyroscopic correction is the identity
    # there (ω × Iω = 0); in float32 each pass (world → principal frame → world, I then I⁻¹ rounded) adds
    # about one ulp of |ω| (2.4e-7 rad/s), always up: the error grows like N, not √N, as Δt shrinks. Without
    # the gyroscopic pass |ω| stays within one rounding of the initial value whatever the number of steps.
    sc = load_scenario("constant_spin")
    for n in (500, 4000):
        dt = sc.duration_s / n
        gain = np.linalg.norm(ra.simulate(sc, GYRO, dt, n).y[-1, 10:13]) - 3.0
        assert 0.3 * n * 3.0 * EPS32 < gain < 3.0 * n * 3.0 * EPS32
        drift = np.linalg.norm(ra.simulate(sc, NO_GYRO, dt, n).y[-1, 10:13]) - 3.0
        assert abs(drift) < 2 * 3.0 * EPS32


# --- forces ------------------------------------------------------------------------------------------------

def _wrench_of_one_step(apply, sc=None):
    """The world force (N) and the world torque (N m) that ``apply(rigid_body)`` exerts, read from one step of
    a tilted body at rest (no gyroscopic term at rest): f = m Δv/Δt, τ = I_W Δω/Δt."""
    sc = sc or _tilted()
    W = _world(sc, 1e-3)
    apply(W.bodies[0])
    W.step()
    y = np.array(W.read()[0])
    return 2.0 * y[3:6] / 1e-3, _world_inertia(sc, Q_TILT) @ y[10:13] / 1e-3


def test_add_force_is_a_world_force_at_the_com_and_add_torque_a_world_torque():
    F, T = np.array([1.0, 2.0, 3.0]), np.array([0.5, -0.3, 0.2])
    f, tau = _wrench_of_one_step(lambda rb: rb.add_force(tuple(F)))
    _close(f, F, 3.0, rel=4 * F32)
    _close(tau, np.zeros(3), rel=0.0)
    f, tau = _wrench_of_one_step(lambda rb: rb.add_torque(tuple(T)))
    _close(tau, T, 1.0, rel=4 * F32)
    _close(f, np.zeros(3), rel=0.0)
    # add_force_at_point takes a WORLD point (lever arm p − x_COM): not used, pinned as the trap it is
    p = np.array([1.1, -2.2, 0.8])
    f, tau = _wrench_of_one_step(lambda rb: rb.add_force_at_point(tuple(F), tuple(p)))
    _close(tau, np.cross(p - [1.0, -2.0, 0.5], F), 1.0, rel=32 * F32)


def test_user_forces_are_kept_from_step_to_step_so_the_adapter_replaces_them():
    sc = scenario_from_parts(body="mass = 1.0\ninertia = [1.0, 1.0, 1.0]")
    W = _world(sc)
    rb = W.bodies[0]
    rb.add_force((1.0, 0.0, 0.0))
    rb.add_force((1.0, 0.0, 0.0))                        # add_force ACCUMULATES
    for _ in range(3):
        W.step()
    assert rb.user_force.to_tuple() == (2.0, 0.0, 0.0)
    _close(rb.linvel.to_tuple(), [0.06, 0.0, 0.0], rel=F32)    # 3 steps of 2 N: not cleared by a step
    W.apply(np.array([[0.0, 1.0, 0.0]]), np.array([[0.0, 0.0, 0.5]]))
    assert rb.user_force.to_tuple() == (0.0, 1.0, 0.0)
    assert rb.user_torque.to_tuple() == (0.0, 0.0, 0.5)
    assert ra.RapierAdapter.keeps_forces                 # so the loop sets constant forces once


def test_state_dependent_forces_reach_rapier_as_the_force_models_wrench():
    # a body-frame force off the COM and a spring off the COM: one step from a tumbling state is the hand step
    # with f and τ from ForceModel.force_torque (the gyroscopic term off: ω changes by h I_W⁻¹ τ alone)
    sc = _tilted(forces='[[forces.point]]\nforce = [0.4, -1.0, 2.0]\npoint = [0.1, 0.2, -0.3]\n'
                        'frame = "body"\n[[forces.spring]]\nanchor = [0.0, 0.0, 1.0]\n'
                        'attach = [0.2, 0.0, 0.1]\nstiffness = 5.0',
                 angular_velocity="[0.4, 1.5, -0.7]", velocity="[0.3, -0.1, 0.2]")
    y0 = sc.problem.initial_packed()
    p = sc.problem
    f, tau = p.forces.force_torque(p.body, y0[0:3], y0[3:6], y0[6:10])
    for variant, gyro in ((NO_GYRO, False), (GYRO, True)):
        y1 = ra.one_step(sc, variant, 1e-3, y0[None])[0]
        hand = _hand_step(sc, y0, 1e-3, f, tau, gyro=gyro)
        _close(y1[3:6], hand[3:6], 1.0)
        _close(y1[10:13], hand[10:13], 1.7)
    run = ra.simulate(sc, NO_GYRO, 1e-3, 30)               # the free run evaluates them every step
    again = ra.one_step(sc, NO_GYRO, 1e-3, run.y[:-1])
    _close(again, run.y[1:], 3.0, rel=4 * EPS32)


def test_decay_is_applied_before_the_step_with_that_steps_force_scaled():
    # harness semantics (base.py): v ← γ v, the force × γ, then Rapier's step: v1 = γ (v0 + Δt (F/m + g)) —
    # the course's step (isotropic body: no gyroscopic term, ω1 = γ_ω (ω0 + Δt τ/I))
    sc = scenario_from_parts(body="mass = 2.0\ninertia = [0.5, 0.5, 0.5]",
                             initial="velocity = [1.0, -2.0, 0.5]\nangular_velocity = [0.3, 0.0, 3.0]",
                             forces='gravity = [0.0, 0.0, -9.81]\nvelocity_decay = 0.99\n'
                                    'angular_velocity_decay = 0.95\n'
                                    '[[forces.point]]\nforce = [1.0, 2.0, 3.0]\nframe = "world"\n'
                                    '[[forces.torque]]\ntorque = [0.1, 0.2, -0.3]\nframe = "world"', dt=0.01)
    y0 = sc.problem.initial_packed()
    y1 = ra.one_step(sc, GYRO, 0.01, y0[None])[0]
    _close(y1[3:6], 0.99 * (y0[3:6] + 0.01 * (np.array([0.5, 1.0, 1.5]) + [0.0, 0.0, -9.81])), 2.0)
    _close(y1[10:13], 0.95 * (y0[10:13] + 0.01 * np.array([0.2, 0.4, -0.6])), 3.0)
    run = ra.simulate(sc, GYRO, 0.01, 3)                                  # the free run does the same
    _close(run.y[1], y1, 3.0, rel=EPS32)


def test_projectile_is_the_semi_implicit_closed_form():
    sc = load_scenario("projectile")
    n, h = 100, 0.01
    run = ra.simulate(sc, GYRO, h, n)
    p = sc.problem
    k = np.arange(n + 1)[:, None]
    exact = p.initial.x_W + k * h * p.initial.v_W + np.asarray(p.forces.gravity_W) * h * h * k * (k + 1) / 2
    # float32: each of the n steps rounds x (|x| ≤ 3 m) once; the explicit Euler position (k(k−1)/2) is
    # 4.9e-3 m away at the end
    _close(run.y[:, 0:3], exact, 3.0, rel=n * EPS32)
    explicit = exact - np.asarray(p.forces.gravity_W) * h * h * k
    assert np.max(np.abs(run.y[-1, 0:3] - explicit[-1])) > 100 * n * EPS32 * 3.0


# --- defaults ----------------------------------------------------------------------------------------------

def test_rapiers_own_defaults():
    w = rapier.PhysicsWorld()
    assert w.gravity.to_tuple() == (0.0, 0.0, 0.0)
    ip = w.integration_parameters
    assert (ip.num_solver_iterations, ip.normalized_max_linear_velocity, ip.max_ccd_substeps,
            ip.length_unit) == (4, 400.0, 1, 1.0)
    assert ip.dt == pytest.approx(1 / 60)
    rb = rapier.RigidBody.dynamic().build()
    assert (rb.linear_damping, rb.angular_damping, rb.gravity_scale) == (0.0, 0.0, 1.0)
    assert not rb.allow_fast_rotation and rb.gyroscopic_forces_enabled and not rb.ccd_enabled
    assert rb.additional_solver_iterations == 0 and rb.locked_axes.is_empty()
    a = rb.activation
    assert (a.linear_threshold, a.angular_threshold, a.time_until_sleep) == (
        pytest.approx(0.05), pytest.approx(0.5), pytest.approx(0.5))
    assert w.num_threads == os.cpu_count()              # rayon's global pool: every core


def test_a_world_has_the_scenarios_gravity_and_step_and_neutral_settings():
    sc = scenario_from_parts(forces="gravity = [1.0, -2.0, 0.5]")
    W = _world(sc, 0.004)
    assert W.world.gravity.to_tuple() == (1.0, -2.0, 0.5)
    ip = W.world.integration_parameters
    assert ip.dt == float(np.float32(0.004))
    for attr, value in rpw.WORLD_SETTINGS:
        assert getattr(ip, attr) == value, attr
    rb = W.bodies[0]
    assert (rb.linear_damping, rb.angular_damping, rb.gravity_scale) == (0.0, 0.0, 1.0)
    assert rb.allow_fast_rotation and not rb.ccd_enabled and rb.additional_solver_iterations == 0
    assert rb.is_dynamic and rb.colliders == [] and len(W.world.colliders) == 0   # nothing to touch
    W.step()
    assert not rb.is_sleeping


def _pool_workers() -> set:
    """This process's threads that a world's own pool started (rapier3d names them ``rapier-worker-N``)."""
    tasks = Path(f"/proc/{os.getpid()}/task")
    return {t.name for t in tasks.iterdir() if (t / "comm").read_text().startswith("rapier-worker")}


def _bodies(n: int):
    """A world of ``n`` free bodies (worlds.rapier.Bodies), stepped 5 times."""
    W = rpw.Bodies([(1.0, np.array([1.0, 2.0, 3.0]), np.array([1.0, 0.0, 0.0, 0.0]))] * n,
                   (0.0, 0.0, -9.81), "symplectic_euler", 1e-2)
    for _ in range(5):
        W.step()
    return W


@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="reads the threads from /proc")
def test_a_few_bodies_step_on_the_calling_thread_and_many_on_a_pool_of_their_own():
    """Up to OWN_POOL_ABOVE bodies no worker thread is started: a pool of one's own hands each step to its
    worker and back (15-50 us a step against ~3 us: benchmarks/rapier_step_between.py); more bodies get one
    (rayon's global pool would use every core and hang a forked process)."""
    before = _pool_workers()
    few = _bodies(rpw.OWN_POOL_ABOVE)
    assert _pool_workers() - before == set()
    many = _bodies(rpw.OWN_POOL_ABOVE + 1)
    assert len(_pool_workers() - before) == 1
    del few, many


def test_a_process_forked_after_rapier_ran_steps_new_worlds_of_any_size():
    """The sweep forks its workers, maybe from a process that ran Rapier. Rayon's global pool gives work to
    threads a fork does not copy from 257 bodies on (rapier3d 0.36.1, measured: the child then hangs); a world
    of 300 bodies has a pool of its own, and the few-body worlds that use the global pool give it none."""
    code = ("import os, sys\nimport numpy as np\nfrom cross_checks.engines.worlds import rapier as rpw\n"
            "def world(n):\n"
            "    W = rpw.Bodies([(1.0, np.array([1.0, 2.0, 3.0]), np.eye(4)[0])] * n, (0.0, 0.0, -9.81),\n"
            "                   'symplectic_euler', 1e-2)\n"
            "    for _ in range(5):\n"
            "        W.step()\n"
            "    return W\n"
            f"sizes = (1, {rpw.OWN_POOL_ABOVE}, 300)\n"
            "kept = [world(n) for n in sizes]\n"
            "pid = os.fork()\n"
            "if pid == 0:\n"
            "    [world(n) for n in sizes]\n"
            "    os._exit(0)\n"
            "sys.exit(os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1]))\n")
    proc = subprocess.Popen([sys.executable, "-c", code], start_new_session=True)
    try:
        assert proc.wait(timeout=60) == 0
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)   # the forked child hung: it and its parent


def _lone_world(dt, nsi=None, fast_rotation=True, max_lin=math.inf, can_sleep=False):
    w = rapier.PhysicsWorld()
    w.set_num_threads(1)
    ip = w.integration_parameters
    ip.dt = dt
    if nsi is not None:
        ip.num_solver_iterations = nsi
    ip.normalized_max_linear_velocity = max_lin
    mp = rapier.MassProperties(local_com=(0.0, 0.0, 0.0), mass=1.0, principal_inertia=(1.0, 2.0, 3.0))
    b = rapier.RigidBody.dynamic().additional_mass_properties(mp).allow_fast_rotation(fast_rotation)
    return w, w.add_body(b.can_sleep(can_sleep))


def test_rapiers_default_four_solver_iterations_are_four_substeps_of_a_quarter_step():
    def run(dt, nsi, n):
        w, h = _lone_world(dt, nsi)
        rb = w.rigid_bodies[h]
        rb.angvel, rb.linvel = (0.4, 1.5, -0.7), (1.0, 0.0, 0.0)
        rb.add_force((0.3, -0.2, 0.5))          # (a torque's increment is held over the substeps: it differs)
        for _ in range(n):
            w.step()
        rb = w.rigid_bodies[h]
        return rb.angvel.to_tuple() + rb.rotation.to_tuple() + rb.translation.to_tuple()
    assert run(0.04, None, 5) == run(0.01, 1, 20)        # the default: bit for bit 4 steps of Δt/4
    assert run(0.04, 1, 5) != run(0.01, 1, 20)           # the adapter's nsi = 1: one integration per step


def test_rapiers_default_speed_caps_would_change_the_motion_and_are_lifted():
    for max_lin, expect in ((400.0, 400.0), (math.inf, 1000.0)):
        w, h = _lone_world(0.01, 1, max_lin=max_lin)
        w.rigid_bodies[h].linvel = (1000.0, 0.0, 0.0)
        w.step()
        assert w.rigid_bodies[h].linvel.x == pytest.approx(expect)
    for fast, expect in ((False, (math.pi / 4) / 0.01), (True, 100.0)):
        w, h = _lone_world(0.01, 1, fast_rotation=fast)
        w.rigid_bodies[h].angvel = (0.0, 0.0, 100.0)          # a spin about a principal axis: |ω| constant
        w.step()
        assert w.rigid_bodies[h].angvel.z == pytest.approx(expect, rel=1e-6)
    sc = scenario_from_parts(body="mass = 1.0\ninertia = [1.0, 2.0, 3.0]",
                             initial="velocity = [1000.0, 0.0, 0.0]\nangular_velocity = [0.0, 0.0, 100.0]")
    y = ra.simulate(sc, GYRO, 0.01, 3).y
    _close(y[-1, 3:6], [1000.0, 0.0, 0.0], 1000.0, rel=EPS32)
    _close(y[-1, 10:13], [0.0, 0.0, 100.0], 100.0, rel=8 * EPS32)


def test_rapiers_default_sleeping_would_stop_a_slow_body_and_is_off():
    # Rapier's default body falls asleep after 0.5 s below its thresholds and stops where it is
    w = rapier.PhysicsWorld()
    w.set_num_threads(1)
    w.integration_parameters.dt, w.integration_parameters.num_solver_iterations = 0.01, 1
    mp = rapier.MassProperties(local_com=(0.0, 0.0, 0.0), mass=1.0, principal_inertia=(1.0, 2.0, 3.0))
    h = w.add_body(rapier.RigidBody.dynamic().additional_mass_properties(mp).linvel((0.01, 0.0, 0.0)))
    for _ in range(200):
        w.step()
    assert w.rigid_bodies[h].is_sleeping and w.rigid_bodies[h].translation.x < 0.006
    sc = scenario_from_parts(initial="velocity = [0.01, 0.0, 0.0]", duration=2.0)
    y = ra.simulate(sc, GYRO, 0.01, 200).y
    assert y[-1, 0] == pytest.approx(0.02, rel=1e-5)


# --- runs --------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", ["spring_pendulum", "velocity_decay", "applied_torque"])
def test_one_step_replays_the_run(name):
    # the free run's state k, set again (float32 values, the quaternion renormalised by Rotation3): one step
    # gives the free run's state k + 1 to a few float32 roundings
    sc = load_scenario(name)
    run = ra.simulate(sc, GYRO, 0.01, 20)
    again = ra.one_step(sc, GYRO, 0.01, run.y[:-1])
    scale = np.maximum(1.0, np.abs(run.y[1:]))
    assert np.max(np.abs(again - run.y[1:]) / scale) < 4 * EPS32


def test_simulate_many_runs_each_request_as_it_runs_alone_bit_for_bit(monkeypatch):
    names = ["spring_pendulum", "tennis_racket", "applied_torque", "velocity_decay", "projectile"]
    # runs of different lengths in one world: a finished body is disabled while the others go on
    reqs = [RunRequest(load_scenario(n), dt, steps + 7 * k) for k, n in enumerate(names)
            for dt, steps in ((0.01, 40), (0.005, 25))]
    many = ra.simulate_many(GYRO, reqs)
    for r, run in zip(reqs, many):
        alone = ra.simulate(r.scenario, GYRO, r.dt_s, r.n_steps)
        np.testing.assert_array_equal(run.y, alone.y)
        np.testing.assert_array_equal(run.t_s, alone.t_s)
    worlds, build = [], ra.RapierEngine.build
    monkeypatch.setattr(ra.RapierEngine, "build",
                        lambda self, rs, v, dt: worlds.append(len(rs)) or build(self, rs, v, dt))
    ra.simulate_many(GYRO, reqs)
    # one world per (Δt, gravity), whatever the run lengths: 2 gravities here
    from collections import Counter
    keys = Counter((r.dt_s, tuple(r.scenario.problem.forces.gravity_W)) for r in reqs)
    assert len(keys) == 4 and sorted(worlds) == sorted(keys.values()) == [2, 2, 3, 3]
    # gravities that float32 does not tell apart share a world (Rapier's is float32), as each runs alone
    twins = [scenario_from_parts(forces=f"gravity = [0.0, 0.0, {z!r}]") for z in (-9.81, -9.81 * (1 + 1e-12))]
    worlds.clear()
    many = ra.simulate_many(GYRO, [RunRequest(sc, 0.01, 30 + 5 * k) for k, sc in enumerate(twins)])
    assert worlds == [2]
    for k, (sc, run) in enumerate(zip(twins, many)):
        assert np.array_equal(run.y, ra.simulate(sc, GYRO, 0.01, 30 + 5 * k).y)


def test_the_state_is_read_from_one_serialisation_per_body_as_the_getters_give_it():
    """rapier3d's own serialisation of a body (``RigidBody.to_bytes``) holds its state at fixed places
    (:func:`state_bytes_layout`, found and checked on this rapier3d); decoded, it is what the getters give bit
    for bit — the quaternion normalised as ``Rotation3.to_tuple`` does — for bodies with a principal frame,
    at random states and after steps under random torques."""
    layout = ra.state_bytes_layout()
    assert layout is not None
    rng = np.random.default_rng(7)
    n = 40
    spec = ra.body_spec(scenario_from_parts(body=FULL_INERTIA).problem.body)
    assert not np.array_equal(spec[2], [1.0, 0.0, 0.0, 0.0])
    W = rpw.Bodies([spec] * n, (0.0, 0.0, -9.81), GYRO, 0.01)
    y = np.zeros((n, 13))
    y[:, 0:6], y[:, 10:13] = rng.normal(size=(n, 6)) * 100.0, rng.normal(size=(n, 3)) * 20.0
    q = rng.normal(size=(n, 4))
    y[:, 6:10] = q / np.linalg.norm(q, axis=1, keepdims=True)
    W.set_state(y)
    for _ in range(5):
        got = ra._decode(b"".join(rb.to_bytes() for rb in W.bodies), n, layout)
        assert np.array_equal(got, np.asarray(rpw.Bodies.read(W), dtype=float))
        W.apply(rng.normal(size=(n, 3)), rng.normal(size=(n, 3)) * 10.0)
        W.step()


@pytest.mark.parametrize("variant", [GYRO, NO_GYRO])
def test_a_world_of_many_bodies_reads_serialisations_and_gives_each_run_alone_bit_for_bit(variant):
    """Above MANY_BODIES bodies a world reads its states from the bodies' serialisations and gives a body a
    force or torque only where it changed; alone, a run reads the getters and replaces both every step: the
    same numbers for every force kind (none beyond gravity, springs, a body torque, decay, a full inertia
    tensor) and runs of different lengths (a finished body disabled while the others go on)."""
    names = ["spring_pendulum", "tennis_racket", "applied_torque", "velocity_decay", "projectile"]
    scs = [load_scenario(n) for n in names] + [scenario_from_parts(body=FULL_INERTIA)]
    reqs = [RunRequest(scs[k % len(scs)], 0.01, 20 + 3 * k) for k in range(4 * len(scs))]
    worlds = {(r.dt_s, tuple(r.scenario.problem.forces.gravity_W)) for r in reqs}
    assert all(sum(1 for r in reqs if (r.dt_s, tuple(r.scenario.problem.forces.gravity_W)) == w)
               > MANY_BODIES for w in worlds)
    many = ra.simulate_many(variant, reqs)
    for r, run in zip(reqs, many):
        alone = ra.simulate(r.scenario, variant, r.dt_s, r.n_steps)
        assert np.array_equal(run.y, alone.y) and run.message == alone.message, r.scenario.name


def test_a_world_of_many_bodies_ends_the_runs_the_getters_would_end(monkeypatch):
    """A body at a state beyond BLOWUP_LIMIT, one non-finite, one at its last step and one already dead:
    the serialisations' read gives the rows, the dead bodies and the disabled ones the getters' read
    gives."""
    sc = load_scenario("tennis_racket")
    n = MANY_BODIES + 4
    reqs = [RunRequest(sc, 0.01, 3 if k == 2 else 10) for k in range(n)]
    y = np.tile(sc.problem.initial_packed(), (n, 1))
    y[0, 0], y[1, 11] = 2e8, np.nan
    worlds = []
    for layout in (ra.state_bytes_layout(), None):
        monkeypatch.setattr(ra, "state_bytes_layout", lambda layout=layout: layout)
        W = ra.RapierWorld(reqs, GYRO, 0.01)
        assert (W.layout is None) == (layout is None)
        W.set_state(y)
        W.dead.add(3)
        W.bodies[3].is_enabled = False
        W.n = 3
        worlds.append((np.asarray(W.read(), dtype=float), set(W.dead), [rb.is_enabled for rb in W.bodies]))
    (a, dead_a, on_a), (b, dead_b, on_b) = worlds
    assert np.array_equal(a, b, equal_nan=True) and dead_a == dead_b == {0, 1, 2, 3} and on_a == on_b


@pytest.mark.parametrize("decode", ["reversed", "raises", "not found"])
def test_a_serialisation_laid_out_otherwise_is_refused_and_the_getters_read(monkeypatch, decode):
    """The layout the probe finds is kept only if it decodes 256 random bodies as the getters read them: one
    whose decoding differs, fails, or whose probe values are not in the serialisation (another rapier3d) is
    None, and a world of many bodies then reads the getters."""
    real = ra._decode
    wrong = {"reversed": lambda blobs, n, layout: real(blobs, n, layout)[::-1],
             "raises": lambda blobs, n, layout: real(blobs[1:], n, layout),
             "not found": lambda blobs, n, layout: real(blobs, n, (layout[0], layout[1] * 0 - 1))}
    monkeypatch.setattr(ra, "_decode", wrong[decode])
    ra.state_bytes_layout.cache_clear()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")   # garbage decoded is refused, not warned about
            assert ra.state_bytes_layout() is None
        sc = load_scenario("tennis_racket")
        assert ra.RapierWorld([RunRequest(sc, 0.01, 5)] * (MANY_BODIES + 2), GYRO, 0.01).layout is None
    finally:
        ra.state_bytes_layout.cache_clear()
    monkeypatch.undo()
    assert ra.state_bytes_layout() is not None


def test_without_a_layout_a_world_of_many_bodies_reads_the_getters(monkeypatch):
    monkeypatch.setattr(ra, "state_bytes_layout", lambda: None)
    sc = load_scenario("tennis_racket")
    W = ra.RapierWorld([RunRequest(sc, 0.01, 5)] * (MANY_BODIES + 2), GYRO, 0.01)
    assert W.layout is None
    monkeypatch.undo()
    assert ra.RapierWorld([RunRequest(sc, 0.01, 5)] * (MANY_BODIES + 2), GYRO, 0.01).layout is not None


def test_the_first_row_is_the_scenarios_and_quaternions_stay_continuous():
    # w < 0 at t = 0 and a spin of 3 rad/s for 2 s (through q → −q)
    sc = scenario_from_parts(body="mass = 1.0\ninertia = [1.0, 1.0, 1.0]",
                             initial=f"orientation = {(-Q_TILT).tolist()}\n"
                                     "angular_velocity = [0.0, 0.0, 3.0]")
    run = ra.simulate(sc, GYRO, 0.01, 200)
    np.testing.assert_array_equal(run.y[0], sc.problem.initial_packed())
    # the continuous curve from −Q_TILT (not merely the same rotations): each step turns by 2 atan(0.015)
    # about world z
    k = np.arange(201)
    expected = quat_mul(quat_exp(np.outer(k * 2 * math.atan(0.015), [0.0, 0.0, 1.0])), -Q_TILT)
    assert np.max(np.linalg.norm(run.y[:, 6:10] - expected, axis=1)) < 200 * F32
    assert np.min(np.einsum("ij,ij->i", run.y[1:, 6:10], run.y[:-1, 6:10])) > 0.99


def test_a_body_rapier_quarantines_ends_the_run_as_divergence(monkeypatch):
    # a force beyond float32's range (no scenario file may ask for one: the harness is replaced): Rapier
    # disables the body, rolls it back and zeroes its velocity instead of going on with a non-finite state;
    # the world reads it as non-finite from then on, with Rapier's words
    sc = scenario_from_parts(initial="velocity = [1.0, 0.0, 0.0]")
    W = _world(sc)
    W.apply(np.array([[1e39, 0.0, 0.0]]), np.zeros((1, 3)))
    W.step()
    assert not W.bodies[0].is_enabled and W.bodies[0].linvel.to_tuple() == (0.0, 0.0, 0.0)
    assert W.warnings == [(0, 1, "Rapier quarantined the body")] and np.isnan(W.read()).all()
    from types import SimpleNamespace

    from cross_checks.engines import forces
    huge = SimpleNamespace(force_torque=lambda y: (1e39, 0.0, 0.0, 0.0, 0.0, 0.0))
    monkeypatch.setattr(forces, "float_forces", lambda scenario: huge)
    run = ra.simulate(sc, GYRO, 0.01, 100)
    assert run.diverged_at_s == 0.01 and len(run.t_s) == 1
    assert run.message == "diverged at t = 0.01 s (Rapier quarantined the body; non-finite state)"
    assert np.isnan(ra.one_step(sc, GYRO, 0.01, sc.problem.initial_packed()[None])).all()


def test_every_catalog_scenario_is_expressible():
    adapter = ra.RapierAdapter()
    from cross_checks.scenario.parse import catalog_names
    for name in catalog_names():
        for variant in ra.VARIANTS:
            assert adapter.expressible(load_scenario(name), variant) == ""


def test_nothing_is_compiled_or_cached_at_run_time(tmp_path, monkeypatch):
    from cross_checks.core.files import kernel_cache_dir
    monkeypatch.setenv("RBCHECK_KERNEL_CACHE_DIR", str(tmp_path))
    ra.simulate(load_scenario("tennis_racket"), GYRO, 0.01, 100)
    assert not kernel_cache_dir("rapier").exists() and list(tmp_path.iterdir()) == []


def test_version_and_list_name_rapier():
    from cross_checks.cli.parser import _version_text
    from cross_checks.engines import all_variants
    assert "rapier 0.36.1" in _version_text()
    infos = {v.name: v for v in all_variants()}
    for variant in ra.VARIANTS:
        info = infos[f"rapier:{variant}"]
        assert info.available and info.order == 1.0 and not info.required
    assert ra.VARIANTS[GYRO].traits.precision == ra.VARIANTS[NO_GYRO].traits.precision == "float32"


def test_first_order_where_float32_resolves_it(assert_engine):
    assert_engine("rapier:symplectic_euler", ["projectile", "applied_torque"])


@pytest.mark.slow
def test_the_tumbling_and_state_dependent_scenarios(assert_engine):
    assert_engine("rapier:symplectic_euler", ["tennis_racket", "spring_pendulum", "tumbling_box"])


@pytest.mark.slow
def test_without_gyroscopic_forces_the_tumbling_bodies_do_not_converge_as_declared(assert_engine):
    summary = assert_engine("rapier:symplectic_euler_no_gyro",
                            ["tennis_racket", "particle_body", "applied_torque"])
    verdicts = {(c["scenario"], c["quantity"]): c["verdict"] for c in summary["convergence"]}
    for name in ("tennis_racket", "particle_body", "applied_torque"):
        assert verdicts[(name, "orientation")] == verdicts[(name, "angular_velocity")] == "does_not_converge"
