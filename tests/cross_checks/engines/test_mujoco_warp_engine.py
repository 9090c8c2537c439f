"""The MuJoCo Warp adapter (cross_checks.engines.mujoco_warp_engine): every convention it relies on, pinned on
mujoco_warp itself (docs/engine_conventions.md, "MuJoCo Warp 4.0.0"); every default it neutralises, read from
the engine's own Model; one step of each scheme against the scheme written out by hand in NumPy below (semi-
implicit Euler, the body-frame linearised implicit step, Runge-Kutta-Munthe-Kaas RK4); float32 throughout;
the per-stage force kernel against the package's force model; the captured step against the uncaptured one;
the batch of Δt rungs against single runs; the same scheme as MuJoCo C (float64) to float32 round-off;
divergence; compile bookkeeping; and that neither importing the adapter nor asking its version imports Warp.

Warp compiles mujoco_warp's kernels once per machine into rbcheck's kernel cache (minutes the first time);
after that a process loads them in ~1-4 s per variant. The order measurements and a real forked sweep are
slow-marked.
"""
import importlib.util
import os
import subprocess
import sys

import numpy as np
import pytest

from tests.helpers import tolerances as ctol

if importlib.util.find_spec("mujoco_warp") is None:
    pytest.skip("mujoco-warp is not installed (pip install -e '.[mujoco_warp]')", allow_module_level=True)

from cross_checks.engines import mujoco_engine as me  # noqa: E402
from cross_checks.engines import mujoco_warp_engine as we  # noqa: E402
from cross_checks.engines import resolve
from cross_checks.engines.base import EngineError, RunRequest  # noqa: E402
from cross_checks.engines.forces import stage_force_torque_floats  # noqa: E402
from cross_checks.scenario import load_scenario  # noqa: E402
from reference_sim.quaternion import geodesic_angle, matrix_from_quat, quat_exp, quat_mul  # noqa: E402
from tests.helpers.scenarios import YAW90, scenario_from_parts  # noqa: E402

Q_TILT = np.array([0.9, 0.1, 0.3, -0.2]) / np.linalg.norm([0.9, 0.1, 0.3, -0.2])
FULL_INERTIA = "mass = 2.0\ninertia = [[2.0, 0.1, 0.05], [0.1, 3.0, -0.2], [0.05, -0.2, 4.0]]"
NO_GRAVITY = "gravity = [0.0, 0.0, 0.0]"
EPS32 = 2.0 ** -23


def _tilted(body=FULL_INERTIA, forces=NO_GRAVITY, **initial):
    lines = [f"orientation = {Q_TILT.tolist()}", "position = [1.0, -2.0, 0.5]"]
    lines += [f"{k} = {v}" for k, v in initial.items()]
    return scenario_from_parts(body=body, initial="\n".join(lines), forces=forces)


def _world_inertia(sc, q):
    R = matrix_from_quat(q)
    return R @ sc.problem.body.inertia_B @ R.T


def _skew(a):
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


def test_version_is_the_pinned_release():
    assert we.version() == "4.0.0 (warp 1.19.0)"


def test_importing_the_adapter_asking_its_version_and_its_files_import_no_warp():
    # the registry imports every adapter and asks its version at CLI start, and the sweep hashes its source
    # files before forking its workers: none of it may import Warp or mujoco_warp
    code = ("import sys; from cross_checks.engines import mujoco_warp_engine as m, all_variants; "
            "m.version(); m.MujocoWarpAdapter().source_files(); all_variants(); "
            "print(sorted(k for k in sys.modules if k.split('.')[0] in ('warp', 'mujoco_warp')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


# --- device, precision, the model ---------------------------------------------------------------------------

def test_warp_runs_on_the_cpu_in_float32_with_its_kernels_in_rbchecks_kernel_cache():
    from cross_checks.core.files import kernel_cache_dir
    wp, mjw, _ = we._engine()
    # Warp appends its version to the folder it is given (wp.config.kernel_cache_dir, set before wp.init)
    assert str(wp.config.kernel_cache_dir) == str(kernel_cache_dir("mujoco_warp") / "1.19.0")
    sc = load_scenario("tennis_racket")
    wm = we.device_model(we.host_model(sc, "euler", 0.01), [0.01, 0.005])
    assert wm.body_mass.dtype == wp.float32 and wm.opt.timestep.dtype == wp.float32
    assert str(wm.body_mass.device) == "cpu"
    np.testing.assert_array_equal(wm.opt.timestep.numpy(), np.float32([0.01, 0.005]))   # one per world
    # the results: float32 numbers (each recorded value is exactly a float32), the first row the scenario's
    # own
    run = we.simulate(sc, "euler", 0.01, 20)
    assert run.y.dtype == np.float64
    np.testing.assert_array_equal(run.y[0], sc.problem.initial_packed())
    qpos, qvel = me.to_qpos_qvel(run.y[1:])
    assert np.max(np.abs(qpos - qpos.astype(np.float32))) < 1e-7 * np.max(np.abs(qpos))
    # MuJoCo C Euler (float64) is the same scheme: float32 round-off apart, not float64's
    ref = me.simulate(sc, "euler", 0.01, 20)
    diff = np.max(np.abs(run.y - ref.y))
    assert 1e-12 < diff < ctol.MJW_SAME_AS_MUJOCO_REL


@pytest.mark.parametrize("variant", list(we.VARIANTS))
def test_the_model_is_mujocos_with_every_default_that_is_not_the_physics_neutral(variant):
    from mujoco_warp import DisableBit, EnableBit, IntegratorType
    sc = _tilted(forces="gravity = [1.0, -2.0, 0.5]")
    wm = we.device_model(we.host_model(sc, variant, 0.004), [0.004])
    assert int(wm.opt.integrator) == int(getattr(IntegratorType, variant.upper()))
    np.testing.assert_array_equal(wm.opt.timestep.numpy(), np.float32([0.004]))
    np.testing.assert_array_equal(wm.opt.gravity.numpy(), np.float32([[1.0, -2.0, 0.5]]))
    np.testing.assert_array_equal(wm.body_mass.numpy(), np.float32([[0.0, 2.0]]))   # the body's mass
    np.testing.assert_array_equal(wm.body_ipos.numpy()[0, 1], np.zeros(3))           # body origin = COM
    # no damping, armature, friction loss, stiffness, gravity compensation; no geom (no contact, no ground),
    # no actuator, tendon or equality; one free joint
    for field in ("dof_damping", "dof_armature", "dof_frictionloss"):
        np.testing.assert_array_equal(getattr(wm, field).numpy(), np.zeros((1, 6)), err_msg=field)
    np.testing.assert_array_equal(wm.jnt_stiffness.numpy(), [[0.0]])
    np.testing.assert_array_equal(wm.body_gravcomp.numpy(), [[0.0, 0.0]])
    assert (wm.ngeom, wm.nu, wm.na, wm.ntendon, wm.neq, wm.njnt, wm.nq, wm.nv) == (0, 0, 0, 0, 0, 1, 7, 6)
    # no fluid forces; sleeping off (enableflags 0), nothing disabled: implicitfast takes its implicit
    # free-body path only while ACTUATION, SPRING and DAMPER are not all disabled (forward.py ``implicit``),
    # and RK4's per-stage callback runs only with ACTUATION enabled (``_forward``)
    assert float(wm.opt.density.numpy()[0]) == 0.0 and float(wm.opt.viscosity.numpy()[0]) == 0.0
    np.testing.assert_array_equal(wm.opt.wind.numpy(), np.zeros((1, 3)))
    assert int(wm.opt.enableflags) & int(EnableBit.SLEEP) == 0
    assert int(wm.opt.disableflags) == 0 and int(DisableBit.ACTUATION) and int(DisableBit.DAMPER)
    assert wm.callback.control is None


def test_mujoco_warp_has_no_velocity_clamp_sleep_or_substep_a_fast_body_keeps_its_speed():
    # 1e4 m/s and 100 rad/s about a principal axis (isotropic body: no gyroscopic term) for 100 steps:
    # unchanged to float32 (mujoco_warp's spatial-velocity arithmetic mixes the two: measured 6.3e-4 m/s
    # across, a fraction of the float32 spacing of 1e4, 9.8e-4; a clamp or a sleep would be O(1e4)); x = 1e4 t
    sc = scenario_from_parts(body="mass = 1.0\ninertia = [1.0, 1.0, 1.0]",
                             initial="velocity = [1e4, 0.0, 0.0]\nangular_velocity = [0.0, 0.0, 100.0]")
    run = we.simulate(sc, "euler", 1e-3, 100)
    np.testing.assert_allclose(run.y[:, 3:6], np.tile([1e4, 0.0, 0.0], (101, 1)), rtol=0,
                               atol=1e4 * 8 * EPS32)
    np.testing.assert_allclose(run.y[:, 10:13], np.tile([0.0, 0.0, 100.0], (101, 1)), rtol=0,
                               atol=100 * 4 * EPS32)
    np.testing.assert_allclose(run.y[:, 0], 1e4 * run.t_s, rtol=100 * EPS32, atol=0)


def test_projectile_is_the_semi_implicit_closed_form_one_integration_per_step():
    sc = load_scenario("projectile")
    n, h = 100, 0.01
    run = we.simulate(sc, "euler", h, n)
    p = sc.problem
    k = np.arange(n + 1)[:, None]
    exact = p.initial.x_W + k * h * p.initial.v_W + np.asarray(p.forces.gravity_W) * h * h * k * (k + 1) / 2
    scale = np.max(np.abs(exact))
    np.testing.assert_allclose(run.y[:, 0:3], exact, rtol=0, atol=n * 4 * EPS32 * scale)
    # Δt/2 steps (a substep, or the position from the OLD velocity) would be off by g h² k / 2 = 5e-2 m here


# --- conventions ----------------------------------------------------------------------------------

def test_quaternion_order_and_angular_velocity_frames_at_the_boundary():
    # (w, x, y, z) = (√½, 0, 0, √½) is 90° about z; mujoco_warp's qvel holds ω in BODY axes, the packed state
    # in WORLD axes: a torque-free spin about principal body x of a body yawed by 90° keeps ω_W = (0, 2, 0)
    # and turns the attitude about WORLD y: q(t) = exp(ω_W t) ⊗ q0
    sc = scenario_from_parts(initial=YAW90 + "\nangular_velocity_body = [2.0, 0.0, 0.0]")
    run = we.simulate(sc, "euler", 0.01, 50)
    np.testing.assert_allclose(run.y[:, 10:13], np.tile([0.0, 2.0, 0.0], (51, 1)), rtol=0,
                               atol=50 * 8 * EPS32)
    expected = quat_mul(quat_exp(np.outer(run.t_s, [0.0, 2.0, 0.0])), run.y[0, 6:10])
    assert np.max(geodesic_angle(expected, run.y[:, 6:10])) < 50 * 8 * EPS32


def test_the_recorded_quaternion_is_sign_continuous_over_turns_past_pi():
    # 3 full turns: q passes w = 0 six times; the record stays one continuous curve (consecutive rows on the
    # same side), ending at q(T) = exp(ω_W T) ⊗ q0 with the sign of that formula
    sc = scenario_from_parts(body="mass = 1.0\ninertia = [1.0, 1.0, 1.0]",
                             initial="angular_velocity = [0.0, 0.0, 6.0]")
    run = we.simulate(sc, "euler", 0.01, int(round(np.pi / 0.01)))
    q = run.y[:, 6:10]
    assert np.all(np.einsum("ij,ij->i", q[1:], q[:-1]) > 0.0)
    np.testing.assert_allclose(q[-1], quat_exp(np.array([0.0, 0.0, 6.0]) * run.t_s[-1]), rtol=0, atol=1e-5)


def test_one_euler_step_is_the_hand_derived_semi_implicit_step_with_a_full_tensor_in_body_axes():
    # v and ω from the start-of-step forces (world force at the COM, world torque, gravity) with the
    # gyroscopic term of the full tensor in the scenario's body axes, then x and the attitude from the NEW
    # velocities, the attitude by the exponential map: q1 = exp(Δt ω1_W) ⊗ q0
    sc = _tilted(forces='gravity = [0.0, 0.0, -9.81]\n[[forces.torque]]\ntorque = [0.3, -0.2, 0.5]\n'
                        'frame = "world"\n[[forces.point]]\nforce = [1.0, 2.0, 3.0]\nframe = "world"',
                 velocity="[0.3, -0.1, 0.2]", angular_velocity="[0.4, 1.5, -0.7]")
    h, y0 = 0.01, sc.problem.initial_packed()
    y1 = we.one_step(sc, "euler", h, y0[None])[0]
    I_W, w = _world_inertia(sc, Q_TILT), y0[10:13]
    w1 = w + h * np.linalg.solve(I_W, np.array([0.3, -0.2, 0.5]) - np.cross(w, I_W @ w))
    v1 = y0[3:6] + h * (np.array([1.0, 2.0, 3.0]) / 2.0 + [0.0, 0.0, -9.81])
    np.testing.assert_allclose(y1[10:13], w1, rtol=0, atol=ctol.MJW_HAND_STEP)
    np.testing.assert_allclose(y1[3:6], v1, rtol=0, atol=ctol.MJW_HAND_STEP)
    np.testing.assert_allclose(y1[0:3], y0[0:3] + h * v1, rtol=0, atol=ctol.MJW_HAND_STEP * 4)
    assert geodesic_angle(quat_mul(quat_exp(h * w1), Q_TILT), y1[6:10]) < ctol.MJW_HAND_STEP


TOP = "mass = 2.0\ninertia = [1.0, 2.0, 3.0]"


def _tumbling():
    """A torque-free asymmetric body at an oblique attitude, ω off every principal axis
    (ω̇_B = −I⁻¹ ω × I ω)."""
    initial = f"orientation = {Q_TILT.tolist()}\nangular_velocity_body = [0.4, 1.5, -0.7]"
    return scenario_from_parts(body=TOP, initial=initial, forces=NO_GRAVITY)


@pytest.mark.parametrize("variant", ["implicit", "implicitfast", "discrete"])
def test_one_implicit_step_is_the_hand_derived_body_frame_linearised_implicit_step(variant):
    # forward.py ``implicit``/``discrete``: (M − Δt ∂f/∂v) qacc = f with the free body's gyroscopic derivative
    # (math.free_bias_vel_blocks): in body axes ω1 = ω0 + Δt (I − Δt J)⁻¹ (−ω0 × I ω0), J = ∂(−ω × Iω)/∂ω at
    # ω0 = −([ω0]× I − [I ω0]×), then q1 = q0 ⊗ exp(Δt ω1). Euler's explicit step differs by ~1e-2 here.
    sc, inertia, h = _tumbling(), np.diag([1.0, 2.0, 3.0]), 0.05
    y0 = sc.problem.initial_packed()
    w0 = me.to_qpos_qvel(y0)[1][3:6]
    J = -(_skew(w0) @ inertia - _skew(inertia @ w0))
    w1 = w0 + h * np.linalg.solve(inertia - h * J, -np.cross(w0, inertia @ w0))
    qpos, qvel = me.to_qpos_qvel(we.one_step(sc, variant, h, y0[None])[0])
    np.testing.assert_allclose(qvel[3:6], w1, rtol=0, atol=ctol.MJW_HAND_STEP)
    assert geodesic_angle(quat_mul(y0[6:10], quat_exp(h * w1)), qpos[3:7]) < ctol.MJW_HAND_STEP
    w_explicit = w0 + h * (-np.cross(w0, inertia @ w0)) / np.diag(inertia)
    assert np.max(np.abs(w_explicit - w1)) > 100 * ctol.MJW_HAND_STEP


def _dexpinv(r, v):
    """The Bortz/dexp⁻¹ map of math.deriv_expmap: the rate of the rotation vector r of q = q0 ⊗ exp(r)
    given the body-axes velocity v: v + ½ r × v + c r × (r × v), c = (1 − (x/2) cot(x/2))/x², x = |r|."""
    x = np.linalg.norm(r)
    c = (1.0 - 0.5 * x / np.tan(0.5 * x)) / (x * x) if x > 1e-6 else 1.0 / 12.0
    return v + 0.5 * np.cross(r, v) + c * np.cross(r, np.cross(r, v))


def test_one_rk4_step_is_the_hand_derived_runge_kutta_munthe_kaas_step():
    # forward.py ``rungekutta4``: classical RK4 stages of ω_B; stage attitudes q0 ⊗ exp(a_i Δt K_{i−1}), with
    # K_i = dexp⁻¹(a_i Δt K_{i−1}, ω_i) the corrected stage rates (``_rk_correct_velocity``); then
    # q1 = q0 ⊗ exp(Δt Σ b_i K_i): fourth order on the rotation group. Without the correction (MJX 3.17's
    # one exponential of Σ b_i ω_i: second order) the attitude differs by ~2e-5 rad here.
    sc, h = _tumbling(), 0.05
    inertia = np.array([1.0, 2.0, 3.0])
    y0 = sc.problem.initial_packed()

    def f(w):
        return -np.cross(w, inertia * w) / inertia

    w0 = me.to_qpos_qvel(y0)[1][3:6]
    k1, K1 = f(w0), w0
    w2 = w0 + 0.5 * h * k1
    k2, K2 = f(w2), _dexpinv(0.5 * h * K1, w2)
    w3 = w0 + 0.5 * h * k2
    k3, K3 = f(w3), _dexpinv(0.5 * h * K2, w3)
    w4 = w0 + h * k3
    k4, K4 = f(w4), _dexpinv(h * K3, w4)
    w1 = w0 + h * (k1 / 6 + k2 / 3 + k3 / 3 + k4 / 6)
    q1 = quat_mul(y0[6:10], quat_exp(h * (K1 / 6 + K2 / 3 + K3 / 3 + K4 / 6)))
    qpos, qvel = me.to_qpos_qvel(we.one_step(sc, "rk4", h, y0[None])[0])
    np.testing.assert_allclose(qvel[3:6], w1, rtol=0, atol=ctol.MJW_HAND_STEP)
    assert geodesic_angle(q1, qpos[3:7]) < ctol.MJW_HAND_STEP
    q_mjx = quat_mul(y0[6:10], quat_exp(h * (w0 / 6 + w2 / 3 + w3 / 3 + w4 / 6)))
    assert geodesic_angle(q_mjx, qpos[3:7]) > 10 * ctol.MJW_HAND_STEP


ALL_FORCES = ('gravity = [0.0, 0.0, -9.81]\nlinear_drag = 0.3\nvelocity_decay = 0.99\n'
              'angular_velocity_decay = 0.95\n'
              '[[forces.spring]]\nanchor = [0.0, 0.0, 1.0]\nattach = [0.2, 0.0, 0.1]\nstiffness = 5.0\n'
              'rest_length = 0.3\n'
              '[[forces.point]]\nforce = [0.4, -1.0, 2.0]\npoint = [0.1, 0.2, -0.3]\nframe = "body"\n'
              '[[forces.point]]\nforce = [1.0, 0.5, -0.2]\npoint = [-0.1, 0.0, 0.2]\nframe = "world"\n'
              '[[forces.point]]\nforce = [0.0, 0.3, 0.0]\nframe = "world"\n'
              '[[forces.torque]]\ntorque = [0.3, -0.2, 0.5]\nframe = "world"\n'
              '[[forces.torque]]\ntorque = [-0.1, 0.2, 0.05]\nframe = "body"')


@pytest.mark.parametrize("name", ["all_forces", "spring_pendulum", "applied_torque", "linear_drag",
                                  "velocity_decay"])
def test_the_stage_force_kernel_is_the_force_model_with_the_decay_as_damping(name):
    # RK4's per-stage forces are evaluated by a Warp kernel (float32) launched from Model.callback.control:
    # on random states it writes forces.stage_force_torque minus the weight into xfrc_applied, to float32
    # round-off
    wp, mjw, mujoco = we._engine()
    sc = (scenario_from_parts(body=FULL_INERTIA, forces=ALL_FORCES) if name == "all_forces"
          else load_scenario(name))
    rng = np.random.default_rng(7)
    y = np.zeros((40, 13))
    y[:, 0:3], y[:, 3:6], y[:, 10:13] = rng.normal(size=(3, 40, 3))
    q = rng.normal(size=(40, 4))
    y[:, 6:10] = q / np.linalg.norm(q, axis=1)[:, None]
    qpos, qvel = me.to_qpos_qvel(y)
    m = we.host_model(sc, "rk4", 0.01)
    with wp.ScopedDevice("cpu"):
        d = mjw.put_data(m, mujoco.MjData(m), nworld=40)
    d.qpos.numpy()[:], d.qvel.numpy()[:] = qpos, qvel
    we.stage_callback(sc)(None, d)
    got = d.xfrc_applied.numpy()[:, 1].astype(float)
    weight = np.r_[sc.problem.body.mass_kg * np.asarray(sc.problem.forces.gravity_W), 0.0, 0.0, 0.0]
    want = np.array([stage_force_torque_floats(sc, row) for row in y.tolist()]) - weight
    scale = max(1.0, np.max(np.abs(want)))
    assert np.max(np.abs(got - want)) < ctol.MJW_STAGE_FORCES_REL * scale
    assert np.max(np.abs(want[:, 3:6])) > 0.0 or name in ("linear_drag",)


def test_mujoco_warp_keeps_xfrc_applied_force_then_torque_so_the_adapter_writes_it_before_every_step():
    wp, mjw, mujoco = we._engine()
    sc = scenario_from_parts(body="mass = 2.0\ninertia = [1.0, 1.0, 1.0]", forces=NO_GRAVITY)
    m = we.host_model(sc, "euler", 0.01)
    with wp.ScopedDevice("cpu"):
        wm = mjw.put_model(m)
        d = mjw.put_data(m, mujoco.MjData(m))
        d.xfrc_applied.numpy()[0, 1] = [1.0, 2.0, 3.0, 0.5, 0.0, 0.0]
        mjw.step(wm, d)
    kept = d.xfrc_applied.numpy()[0, 1]
    np.testing.assert_array_equal(kept, np.float32([1.0, 2.0, 3.0, 0.5, 0.0, 0.0]))
    np.testing.assert_allclose(d.qvel.numpy()[0], [0.005, 0.01, 0.015, 0.005, 0.0, 0.0], rtol=4 * EPS32)


def test_decay_is_applied_before_the_step_with_that_steps_force_scaled():
    # harness semantics (base.py): v ← γ v, the force × γ, then the engine's step: v1 = γ (v0 + Δt (F/m + g))
    # (isotropic body: no gyroscopic term, ω1 = γ_ω (ω0 + Δt τ/I))
    sc = scenario_from_parts(body="mass = 2.0\ninertia = [0.5, 0.5, 0.5]",
                             initial="velocity = [1.0, -2.0, 0.5]\nangular_velocity = [0.3, 0.0, 3.0]",
                             forces='gravity = [0.0, 0.0, -9.81]\nvelocity_decay = 0.99\n'
                                    'angular_velocity_decay = 0.95\n[[forces.point]]\n'
                                    'force = [1.0, 2.0, 3.0]\nframe = "world"\n[[forces.torque]]\n'
                                    'torque = [0.1, 0.2, -0.3]\nframe = "world"',
                             dt=0.01)
    y0 = sc.problem.initial_packed()
    y1 = we.one_step(sc, "euler", 0.01, y0[None])[0]
    v1 = 0.99 * (y0[3:6] + 0.01 * (np.array([0.5, 1.0, 1.5]) + [0.0, 0.0, -9.81]))
    np.testing.assert_allclose(y1[3:6], v1, rtol=0, atol=ctol.MJW_HAND_STEP)
    np.testing.assert_allclose(y1[10:13], 0.95 * (y0[10:13] + 0.01 * np.array([0.2, 0.4, -0.6])), rtol=0,
                               atol=ctol.MJW_HAND_STEP)
    run = we.simulate(sc, "euler", 0.01, 3)        # the free run does the same, its decay on float32 qvel
    np.testing.assert_allclose(run.y[1], y1, rtol=2 * EPS32, atol=0)


# --- runs -----------------------------------------------------------------------------------------

def test_a_captured_step_replays_the_uncaptured_step_bit_for_bit_and_recording_does_not_step():
    sc = load_scenario("tumbling_box")
    for variant in ("euler", "rk4"):
        y0 = sc.problem.initial_packed()
        qpos0, qvel0 = me.to_qpos_qvel(np.repeat(y0[None], 3, axis=0))
        a = we._worlds(sc, variant, [0.01, 0.005, 0.0025], qpos0, qvel0)
        b = we._worlds(sc, variant, [0.01, 0.005, 0.0025], qpos0, qvel0)
        a.capture()
        np.testing.assert_array_equal(a.qpos, b.qpos)         # recording the graph did not advance the state
        for _ in range(20):
            a.step()
            b.step()
        assert b.graph is None
        np.testing.assert_array_equal(a.qpos, b.qpos)
        np.testing.assert_array_equal(a.qvel, b.qvel)


def test_simulate_many_runs_a_ladder_as_worlds_of_one_batch_equal_to_single_runs():
    sc = load_scenario("spring_pendulum")                    # state-dependent forces: written every step
    hs = [0.02, 0.01, 0.005]
    reqs = [RunRequest(sc, h, int(round(0.5 / h))) for h in hs]
    before = we.compile_stats()
    runs = we.simulate_many("euler", reqs)
    after = we.compile_stats()
    assert after["captures"] - before["captures"] == 1         # one batch, one graph for the three Δt
    assert after["steps"] - before["steps"] == reqs[-1].n_steps
    for r, run in zip(reqs, runs):
        single = we.simulate(sc, "euler", r.dt_s, r.n_steps)
        np.testing.assert_array_equal(run.y, single.y)
        assert len(run.t_s) == r.n_steps + 1 and run.diverged_at_s is None


@pytest.mark.parametrize("name", ["spring_pendulum", "applied_torque", "tennis_racket"])
def test_a_batch_of_many_worlds_takes_its_forces_at_once_and_equals_each_run_alone(name):
    """A batch of more than 4 worlds evaluates its state-dependent forces (springs, a body torque turned
    with the body) for all at once, from the vectorised packed states; a run alone, from its own in plain
    floats: the same numbers, and every world in one batch (one capture) up to MAX_WORLDS."""
    sc = load_scenario(name)
    hs = [0.02, 0.015, 0.01, 0.008, 0.005, 0.004]
    reqs = [RunRequest(sc, h, int(round(0.2 / h))) for h in hs]
    before = we.compile_stats()
    runs = we.simulate_many("euler", reqs)
    assert we.compile_stats()["captures"] - before["captures"] == 1
    for r, run in zip(reqs, runs):
        assert np.array_equal(run.y, we.simulate(sc, "euler", r.dt_s, r.n_steps).y)


@pytest.mark.parametrize("name", ["spring_pendulum", "velocity_decay", "applied_torque"])
@pytest.mark.parametrize("variant", ["euler", "rk4"])
def test_one_step_replays_the_run(name, variant):
    sc = load_scenario(name)
    run = we.simulate(sc, variant, 0.01, 20)
    again = we.one_step(sc, variant, 0.01, run.y[:-1])
    scale = np.maximum(1.0, np.abs(run.y[1:]))
    assert np.max(np.abs(again - run.y[1:]) / scale) < 4 * EPS32        # float32 state in, float32 step


def test_a_blow_up_is_reported_as_divergence_with_the_rows_before_it():
    # k/m = 1e6: semi-implicit Euler is unstable for ωΔt > 2; here ωΔt = 10
    sc = scenario_from_parts(initial="position = [0.1, 0.0, 0.0]",
                             forces="[[forces.spring]]\nanchor = [0.0, 0.0, 0.0]\nattach = [0.0, 0.0, 0.0]\n"
                                    "stiffness = 1e6\nrest_length = 0.0", dt=0.01, duration=1.0)
    for variant in ("euler", "rk4"):
        run = we.simulate(sc, variant, 0.01, 100)
        assert run.diverged_at_s is not None and 0.0 < run.diverged_at_s < 0.5
        assert run.message.startswith(f"diverged at t = {run.diverged_at_s:.6g} s (")
        assert len(run.t_s) == round(run.diverged_at_s / 0.01) and np.all(np.abs(run.y) <= 1e8)


def test_a_model_mujoco_refuses_is_an_engine_error_with_mujocos_words():
    from tests.helpers.scenarios import with_body
    sc = with_body(scenario_from_parts(), 1e-20, 1e-20)
    run = we.simulate_many("euler", [RunRequest(sc, 0.01, 5)])[0]
    assert isinstance(run, EngineError) and "MuJoCo" in str(run) and "rejected the model" in str(run)


def test_compile_stats_keep_compilation_apart_from_stepping():
    we.simulate(load_scenario("projectile"), "euler", 0.01, 5)
    stats = we.compile_stats()
    assert set(stats) == {"compilations", "compile_seconds", "step_seconds", "steps", "body_steps",
                          "captures"}
    assert stats["compilations"] >= 1 and stats["compile_seconds"] > 0.0 and stats["step_seconds"] > 0.0
    assert stats["body_steps"] >= stats["steps"] > 0


@pytest.mark.filterwarnings("ignore:os.fork:RuntimeWarning")
def test_a_process_forked_after_warp_started_runs_it_with_the_same_numbers():
    # a process may fork after it ran the engine (a user's script, a pytest process before a sweep):
    # unlike JAX (mjx_engine refuses there), Warp's CPU runtime keeps working in the child — the same run
    # bit for bit, a captured RK4 with its stage kernel and a new variant
    sc = load_scenario("spring_pendulum")
    parent = we.simulate(sc, "rk4", 0.01, 50).y
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:                                                          # the child
        os.close(r)
        try:
            child = we.simulate(sc, "rk4", 0.01, 50).y
            we.simulate(sc, "implicit", 0.01, 5)
            os.write(w, repr(float(np.max(np.abs(child - parent)))).encode())
        finally:
            os._exit(0)
    os.close(w)
    with os.fdopen(r) as f:
        said = f.read()
    os.waitpid(pid, 0)
    assert said == "0.0"


# --- the same schemes as MuJoCo C (float64), to float32 round-off -------------------------------------------

@pytest.mark.parametrize("variant", list(we.VARIANTS))
@pytest.mark.parametrize("name", ["tennis_racket", "applied_torque", "spring_pendulum", "velocity_decay"])
def test_each_variant_is_mujocos_same_integrator_to_float32_round_off(variant, name):
    # mujoco:rk4 evaluates state-dependent forces and the decay at every stage (mjcb_control), as this
    # adapter's kernel does; the implicit family has the free body's gyroscopic derivative in both; a held
    # force, a missing gyroscopic derivative or Euler's step would differ by 1.5e-4 … 0.2 here
    sc = load_scenario(name)
    a, b = we.simulate(sc, variant, 0.01, 100), me.simulate(sc, variant, 0.01, 100)
    rel = np.max(np.abs(a.y - b.y) / np.maximum(1.0, np.abs(b.y)))
    assert rel < ctol.MJW_SAME_AS_MUJOCO_REL


def test_implicitfast_and_implicit_take_one_step_on_a_free_body_which_is_not_eulers():
    sc = load_scenario("tennis_racket")
    a, b = we.simulate(sc, "implicitfast", 0.01, 300), we.simulate(sc, "implicit", 0.01, 300)
    np.testing.assert_array_equal(a.y, b.y)
    c = we.simulate(sc, "euler", 0.01, 300)
    assert np.max(np.abs(c.y[:, 10:13] - a.y[:, 10:13])) > 1e-3


def _final_errors(sc, variant, hs, T):
    """Final-state errors of ``variant`` at the steps ``hs`` over T against MuJoCo C RK4 (float64) at
    hs[-1]/64."""
    fine = me.simulate(sc, "rk4", hs[-1] / 64, int(round(64 * T / hs[-1]))).y[-1]
    runs = we.simulate_many(variant, [RunRequest(sc, h, int(round(T / h))) for h in hs])
    return [np.max(np.abs(r.y[-1] - fine)) for r in runs]


@pytest.mark.slow
def test_rk4_is_fourth_order_on_a_torque_free_tumble_unlike_mjx():
    # the Munthe-Kaas correction keeps RK4 fourth order on the rotation group (MJX 3.17: 2, a ratio of 4). The
    # sweep's float32 rungs for this scenario (T = 10 s, 31 and 62 steps): errors ~2.5e-3 and ~1.4e-4 rad, far
    # above the float32 round-off of these runs (~1e-6 rad at these step counts)
    errs = _final_errors(load_scenario("tennis_racket"), "rk4", [10.0 / 31, 10.0 / 62], 10.0)
    assert min(errs) > 5e-5
    assert errs[0] / errs[1] == pytest.approx(16.0, rel=0.25)


@pytest.mark.slow
def test_rk4_keeps_its_order_with_state_dependent_forces_evaluated_per_stage():
    errs = _final_errors(load_scenario("spring_pendulum"), "rk4", [0.04, 0.02], 1.0)
    assert min(errs) > 1e-5
    assert errs[0] / errs[1] == pytest.approx(16.0, rel=0.25)


@pytest.mark.slow
def test_a_real_sweep_forks_two_workers_that_run_mujoco_warp(tmp_path):
    import json
    env = {**os.environ, "RBCHECK_CACHE_DIR": str(tmp_path / "cache"), "MPLBACKEND": "Agg"}
    out = tmp_path / "sweep"
    done = subprocess.run([sys.executable, "-m", "cross_checks.cli", "sweep", "projectile", "spring_pendulum",
                           "--engines", "mujoco_warp:euler", "mujoco_warp:rk4", "--jobs", "2", "--no-cache",
                           "--out", str(out)], capture_output=True, text=True, env=env, timeout=900)
    assert done.returncode == 0, done.stderr[-2000:]
    summary = json.loads((out / "summary.json").read_text())
    assert all(r["matches_expectation"] is not False for r in summary["convergence"])
    assert "CUDA" not in done.stdout + done.stderr


def test_version_and_list_name_mujoco_warp_with_float32_traits():
    from cross_checks.analysis import expectations
    from cross_checks.cli.parser import _version_text
    from cross_checks.engines import all_variants
    assert "mujoco_warp 4.0.0 (warp 1.19.0)" in _version_text()
    info = {v.name: v for v in all_variants()}
    assert [info[f"mujoco_warp:{v}"].order for v in we.VARIANTS] == [1.0, 4.0, 1.0, 1.0, 1.0]
    assert info["mujoco_warp:euler"].available and not info["mujoco_warp:euler"].required
    for v in we.VARIANTS:
        t = expectations.traits(resolve(f"mujoco_warp:{v}"))
        assert t.precision == "float32" and t.gyroscopic_term
        assert not t.forces_held and t.rotation_order is None
    assert expectations.traits(resolve("mujoco_warp:euler")).rotation_sign == +1
    assert expectations.traits(resolve("mujoco_warp:implicit")).rotation_sign == -1
