"""Cross-engine agreement: the NumPy reference, MuJoCo and PyBullet on the same scenarios.

Engine variants whose package is missing are skipped with the reason (pytest.importorskip).
"""
from __future__ import annotations

import numpy as np
import pytest

from cross_checks.engines import run_variant
from cross_checks.scenario import catalog_names, load_scenario, parse_scenario
from reference_sim.quaternion import geodesic_angle, quat_conj, rotate
from tests.helpers import tolerances as tol

ENGINE_VARIANTS = ["mujoco:euler", "mujoco:rk4", "mujoco:implicit", "mujoco:implicitfast",
                   "pybullet:multibody", "pybullet:maximal"]


def _need(name):
    engine = name.split(":")[0]
    if engine != "reference":
        pytest.importorskip(engine, reason=f"{engine} is not installed")


def _run(sc, name, **kw):
    _need(name)
    traj = run_variant(sc, name, **kw)
    assert traj.meta["status"] == "ok", traj.meta["message"]
    return traj


# --- projectile closed forms --------------------------------------------------------------------------

@pytest.mark.parametrize("name", ["reference:course", "mujoco:euler", "mujoco:implicit",
                                  "mujoco:implicitfast", "pybullet:multibody", "pybullet:maximal"])
def test_projectile_semi_implicit_closed_form(name):
    sc = load_scenario("projectile")
    tr = _run(sc, name)
    h, x0, v0, g = sc.dt_s, sc.problem.initial.x_W, sc.problem.initial.v_W, sc.problem.forces.gravity_W
    n = np.arange(len(tr.t_s))[:, None]
    assert len(tr.t_s) == 101
    np.testing.assert_allclose(tr.y[:, 0:3], x0 + n * h * v0 + g * h * h * n * (n + 1) / 2,
                               rtol=0, atol=tol.AGREE_PROJECTILE)
    np.testing.assert_allclose(tr.y[:, 3:6], v0 + n * h * g, rtol=0, atol=tol.AGREE_PROJECTILE)


def test_projectile_mujoco_rk4_exact_parabola():
    sc = load_scenario("projectile")
    tr = _run(sc, "mujoco:rk4")
    t = tr.t_s[:, None]
    x0, v0, g = sc.problem.initial.x_W, sc.problem.initial.v_W, sc.problem.forces.gravity_W
    np.testing.assert_allclose(tr.y[:, 0:3], x0 + v0 * t + 0.5 * g * t * t, rtol=0, atol=tol.AGREE_PROJECTILE)
    np.testing.assert_allclose(tr.y[:, 3:6], v0 + g * t, rtol=0, atol=tol.AGREE_PROJECTILE)


# --- the same scheme in three codes ---------------------------------------------------------------------

@pytest.mark.parametrize("scenario, n_steps", [("applied_torque", 2000), ("particle_body", 5000)])
def test_expmap_gyro_mujoco_euler_pybullet_multibody_agree(scenario, n_steps):
    sc = load_scenario(scenario)
    T = n_steps * sc.dt_s
    ref = _run(sc, "reference:expmap_gyro", duration_s=T)
    assert len(ref.t_s) == n_steps + 1
    for name in ("mujoco:euler", "pybullet:multibody"):
        tr = _run(sc, name, duration_s=T)
        assert np.max(np.abs(tr.y[:, 0:3] - ref.y[:, 0:3])) < tol.AGREE_SAME_SCHEME, name
        assert np.max(geodesic_angle(ref.y[:, 6:10], tr.y[:, 6:10])) < tol.AGREE_SAME_SCHEME, name
        assert np.max(np.abs(tr.y[:, 10:13] - ref.y[:, 10:13])) < tol.AGREE_SAME_SCHEME, name


DECAY_WITH_FORCES = parse_scenario("""
name = "decay_with_forces"
duration = 2.0
dt = 0.01
reference = "ground_truth"
[body]
mass = 2.0
inertia = [0.2, 0.3, 0.4]
[initial]
velocity = [1.0, 0.5, 3.0]
angular_velocity_body = [0.0, 0.0, 2.0]
[forces]
gravity = [0.0, 0.0, -9.81]
linear_drag = 0.7
velocity_decay = 0.98
angular_velocity_decay = 0.99
[[forces.spring]]
anchor = [0.0, 0.0, 1.0]
stiffness = 10.0
rest_length = 0.2
[[forces.torque]]
torque = [0.0, 0.0, 0.3]
frame = "body"
""")


@pytest.mark.parametrize("scenario", ["velocity_decay", "decay_with_forces"])
def test_velocity_decay_harness_reproduces_the_course_decay(scenario):
    """base.py: decay before the step with force/torque scaled reproduces v <- γ (v + h f/m) exactly in
    a semi-implicit engine, and the rotation exactly when the spin is about a principal axis — also
    with state-dependent forces (drag, spring) and a body torque along the spin axis."""
    sc = DECAY_WITH_FORCES if scenario == "decay_with_forces" else load_scenario(scenario)
    for dt in (sc.dt_s, 0.5 * sc.dt_s):  # at the course's own step (γ) and at another (e^{−kΔt})
        _assert_decay_harness_matches(sc, dt)


def _assert_decay_harness_matches(sc, dt):
    ref = _run(sc, "reference:expmap_gyro", dt_s=dt)
    for name in ("mujoco:euler", "pybullet:multibody", "pybullet:maximal"):
        tr = _run(sc, name, dt_s=dt)
        assert np.max(np.abs(tr.y[:, 0:6] - ref.y[:, 0:6])) < tol.AGREE_SAME_SCHEME, name
        assert np.max(geodesic_angle(ref.y[:, 6:10], tr.y[:, 6:10])) < tol.AGREE_SAME_SCHEME, name
        assert np.max(np.abs(tr.y[:, 10:13] - ref.y[:, 10:13])) < tol.AGREE_SAME_SCHEME, name


# --- tennis racket ---------------------------------------------------------------------------------------

def _y_axis_along_world_y(tr):
    return rotate(tr.y[:, 6:10], np.array([0.0, 1.0, 0.0]))[:, 1]


def test_every_engine_variant_flips_the_tennis_racket_the_course_does_not():
    sc = load_scenario("tennis_racket")
    course = _run(sc, "reference:course")
    assert np.min(_y_axis_along_world_y(course)) > tol.AGREE_NO_FLIP_ABOVE
    for name in ENGINE_VARIANTS:
        tr = _run(sc, name)
        assert np.min(_y_axis_along_world_y(tr)) < tol.AGREE_FLIP_BELOW, name
        # seen from the body, the spin component along its y axis reverses (world ω_y does not: ω stays
        # close to the fixed angular momentum)
        w_B = rotate(quat_conj(tr.y[:, 6:10]), tr.y[:, 10:13])
        assert w_B[0, 1] > 0 and np.min(w_B[:, 1]) < -1.0, name


def test_mujoco_implicitfast_vs_pybullet_maximal():
    _need("mujoco:x")
    _need("pybullet:x")
    sc = load_scenario("tennis_racket")
    a = _run(sc, "mujoco:implicitfast", duration_s=2.0)
    b = _run(sc, "pybullet:maximal", duration_s=2.0)
    c = _run(sc, "mujoco:implicit", duration_s=2.0)
    assert np.max(geodesic_angle(a.y[:, 6:10], b.y[:, 6:10])) < tol.AGREE_IMPLICIT_PAIR_TORQUE_FREE
    assert np.max(np.abs(a.y[:, 10:13] - b.y[:, 10:13])) < tol.AGREE_IMPLICIT_PAIR_TORQUE_FREE
    assert np.max(geodesic_angle(a.y[:, 6:10], c.y[:, 6:10])) < tol.AGREE_IMPLICIT_VS_IMPLICITFAST
    # with an applied torque the two implicit schemes part at first order in h
    at = load_scenario("applied_torque")
    diff = []
    for h in (2e-3, 1e-3):
        a = _run(at, "mujoco:implicitfast", dt_s=h)
        b = _run(at, "pybullet:maximal", dt_s=h)
        diff.append(np.max(geodesic_angle(a.y[:, 6:10], b.y[:, 6:10])))
    assert tol.AGREE_FIRST_ORDER_RATIO[0] < diff[0] / diff[1] < tol.AGREE_FIRST_ORDER_RATIO[1], diff


# --- the whole catalog in every engine variant --------------------------------------------------------------

@pytest.mark.parametrize("name", ENGINE_VARIANTS)
def test_every_catalog_scenario_runs(name):
    for scenario in catalog_names():
        sc = load_scenario(scenario)
        T = min(sc.duration_s, 0.5)
        tr = _run(sc, name, duration_s=T)
        assert len(tr.t_s) == sc.n_steps(sc.dt_s, T) + 1 and tr.y.shape == (len(tr.t_s), 13)
        assert np.all(np.isfinite(tr.y))
        np.testing.assert_allclose(np.linalg.norm(tr.y[:, 6:10], axis=1), 1.0, atol=1e-12)
        np.testing.assert_allclose(tr.y[0], sc.problem.initial_packed(), rtol=0, atol=tol.AGREE_INITIAL_ROW)
        assert tr.meta["engine_version"]


@pytest.mark.parametrize("name", ["applied_torque", "spring_pendulum", "linear_drag", "velocity_decay"])
def test_harness_forces_equal_the_force_model(name):
    # The engines' per-step forces come from the plain-float kernel;
    # ForceModel.force_torque is the definition.
    import numpy as np

    from cross_checks.engines.forces import harness_force_torque
    from reference_sim.quaternion import quat_normalize
    sc = load_scenario(name)
    fm, body = sc.problem.forces, sc.problem.body
    rng = np.random.default_rng(5)
    for _ in range(20):
        y = sc.problem.initial_packed() + rng.normal(scale=0.3, size=13)
        y[6:10] = quat_normalize(y[6:10])
        f_ref, tau_ref = fm.force_torque(body, y[0:3], y[3:6], y[6:10])
        for dt in (sc.dt_s, 0.5 * sc.dt_s):  # scaled by the per-step decay e^{−kΔt} of that step
            gv, gw = np.exp(-np.array(fm.decay_rates_per_s()) * dt)
            f, tau = harness_force_torque(sc, y, dt)
            np.testing.assert_allclose(f, f_ref * gv, rtol=1e-14, atol=1e-14)
            np.testing.assert_allclose(tau, tau_ref * gw, rtol=1e-14, atol=1e-14)
        # the multi-stage engines' right-hand side: the decay as a damping
        # force −m k_v v and torque −k_ω I_W ω
        from cross_checks.engines.forces import stage_force_torque
        from reference_sim.quaternion import matrix_from_quat
        k_v, k_w = fm.decay_rates_per_s()
        R = matrix_from_quat(y[6:10])
        f, tau = stage_force_torque(sc, y)
        np.testing.assert_allclose(f, f_ref - body.mass_kg * k_v * y[3:6], rtol=1e-14, atol=1e-14)
        np.testing.assert_allclose(tau, tau_ref - k_w * body.world_inertia(R) @ y[10:13],
                                   rtol=1e-14, atol=1e-14)
