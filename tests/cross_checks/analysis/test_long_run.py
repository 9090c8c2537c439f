"""Long runs: the separatrix-distance finding names a scheme whose energy drifts toward L²/2I₂ (a planted
one, and Jolt's momentum-clamped step), and no scheme that keeps the energy and |L| (cross_checks.analysis
.long_run)."""
import numpy as np
import pytest

from cross_checks.analysis.long_run import drift_metrics, finding, long_runs
from reference_sim.integrators import get_step, members
from reference_sim.quaternion import matrix_from_quat
from reference_sim.simulate import run_members
from reference_sim.vec import mat_t_vec3, matvec3

#: A planted drift: RK4, then the body-axes momentum turned towards the intermediate axis at |Π| kept
#: (Π₂ grows at PLANTED_RATE per second): the energy moves to L²/2I₂ from either side, |L| stays.
PLANTED_RATE = 0.05


def planted_step(problem, y, dt):
    y1 = get_step("rk4")(problem, y, dt)
    p = members(problem)
    R = matrix_from_quat(y1[..., 6:10])
    Pi = matvec3(p.inertia_B, mat_t_vec3(R, y1[..., 10:13]))
    nudged = Pi + PLANTED_RATE * dt * Pi * np.array([0.0, 1.0, 0.0])
    nudged *= np.linalg.norm(Pi, axis=-1, keepdims=True) / np.linalg.norm(nudged, axis=-1, keepdims=True)
    y1[..., 10:13] = matvec3(R, matvec3(p.inertia_inv_B, nudged))
    return y1


def _run(lr, step):
    """The long run's metrics; ``step`` a variant name (compiled where it has a kernel) or a step function."""
    run = run_members(lr.problem.members, step, [lr.dt_s], [lr.n_steps], lr.problem.initial_packed()[None])[0]
    assert run.diverged_at_s is None
    return drift_metrics(lr.problem, run.t_s, run.y)


# 50 periods at Δt = 0.04 s (3927 steps): long enough for the planted drift (e^{7.9}) and Jolt's, short enough
# for the default test run; the catalog-length runs (2000 periods) are the slow test below
SHORT = dict(periods=50.0, dt_s=0.04)


@pytest.mark.parametrize("name", ["major_axis_spin", "minor_axis_spin"])
def test_a_planted_drift_toward_the_intermediate_axis_is_named(name):
    lr = next(r for r in long_runs(**SHORT) if r.name == name)
    m = _run(lr, planted_step)
    text = finding("planted", name, m)
    # |L| kept by the nudge; RK4 itself drifts ≤ 4.3e-6 here (measured)
    assert m.toward_intermediate and "drifts toward the intermediate axis (energy → L²/2I₂) at rate" in text
    assert abs(m.separatrix_end) < 0.9 * abs(m.separatrix_start) and m.momentum_drift_max < 1e-4, text


@pytest.mark.parametrize("name", ["major_axis_spin", "minor_axis_spin"])
def test_jolts_momentum_clamped_step_is_named(name):
    lr = next(r for r in long_runs(**SHORT) if r.name == name)
    m = _run(lr, "jolt_gyro")
    assert m.toward_intermediate and m.momentum_drift_max < 1e-11, finding("reference:jolt_gyro", name, m)
    assert "drifts toward the intermediate axis" in finding("reference:jolt_gyro", name, m)


@pytest.mark.parametrize("variant", ["rk4", "leapfrog", "lp_midpoint", "implicit_gyro_body"])
def test_schemes_that_keep_the_separatrix_distance_are_not_named(variant):
    # the midpoint rule keeps E and |L|; leapfrog and RK4 keep them to O(Δt²) and O(Δt⁴); Bullet's implicit
    # step damps E and |L|² together (a time rescaling), which keeps δ on a stable spin
    for lr in long_runs(**SHORT)[:2]:
        m = _run(lr, variant)
        assert not m.toward_intermediate and not finding(variant, lr.name, m), (lr.name, m)


def test_the_implicit_steps_damping_settles_the_tennis_racket_into_a_spin():
    lr = long_runs(**SHORT)[2]
    m = _run(lr, "implicit_gyro_body")
    assert m.away_from_intermediate and "drifts away from the intermediate axis" in finding("b", lr.name, m)


def test_the_metrics_of_a_kept_motion():
    lr = long_runs(**SHORT)[0]
    m = _run(lr, "lp_midpoint")
    assert m.energy_drift_max < 1e-12 and m.momentum_drift_max < 1e-12 and abs(m.energy_rate_per_s) < 1e-14
    assert m.direction_drift_max_rad < 1e-6


@pytest.mark.slow
@pytest.mark.parametrize("variant,named", [("jolt_gyro", True), ("rk4", False), ("leapfrog", False)])
def test_a_thousand_periods(variant, named):
    for lr in long_runs(periods=1000.0, dt_s=0.02)[:2]:
        m = _run(lr, variant)
        assert m.toward_intermediate == named, finding(variant, lr.name, m)


def _closed_form_run(w0_W, periods=20.0, n=4001):
    """The torque-free body's exact motion (reference_sim.analytic.torque_free, Landau & Lifshitz §37) sampled
    at n times: E and L are its constants, so every drift measured on it is the metric's own error."""
    from reference_sim.analytic import torque_free
    lr = long_runs(periods=1.0)[0]
    I = lr.problem.body.inertia_B
    t = np.linspace(0.0, periods * 2 * np.pi / np.linalg.norm(w0_W), n)
    q, w = torque_free(I, np.array([1.0, 0.0, 0.0, 0.0]), np.asarray(w0_W, dtype=float), t)
    y = np.zeros((n, 13))
    y[:, 6:10], y[:, 10:13] = q, w
    return lr.problem, t, y


@pytest.mark.parametrize("w0", [[0.02, 0.02, 2.0], [2.0, 0.02, 0.02], [0.3, 1.0, 0.2]])
def test_the_metrics_of_the_closed_form_show_no_drift(w0):
    problem, t, y = _closed_form_run(w0)
    m = drift_metrics(problem, t, y)
    assert m.energy_drift_max < 1e-12 and m.momentum_drift_max < 1e-12 and m.direction_drift_max_rad < 1e-12
    assert m.kind == "none" and not finding("closed form", "run", m) and not m.energy_secular


def test_a_crossing_of_the_separatrix_is_named_as_such():
    # Π turned (body axes, |Π| kept) from near the major axis to near the minor one: δ from −1/3 to +1
    problem, t, _ = _closed_form_run([0.02, 0.02, 2.0], n=2001)
    th = np.linspace(0.05, np.pi / 2 - 0.05, len(t))
    Pi = 6.0 * np.column_stack([np.sin(th), np.zeros_like(th), np.cos(th)])
    y = np.zeros((len(t), 13))
    y[:, 6] = 1.0
    y[:, 10:13] = Pi / np.array([1.0, 2.0, 3.0])
    m = drift_metrics(problem, t, y)
    assert m.crossed_separatrix and m.kind == "crosses_separatrix"
    assert "crosses the intermediate-axis separatrix" in finding("x", "run", m)


def test_the_series_for_the_report():
    from cross_checks.analysis.long_run import drift_series
    problem, t, y = _closed_form_run([0.3, 1.0, 0.2], n=1001)
    s = drift_series(problem, t, y, 100)
    assert set(s) == {"t_s", "energy_rel", "momentum_rel", "direction_rad", "separatrix", "L_B"}
    assert all(a.shape == ((100, 3) if k == "L_B" else (100,)) and a.dtype == np.float32
               for k, a in s.items())
    assert np.max(np.abs(s["energy_rel"])) < 1e-6 and s["t_s"][-1] == np.float32(t[-1])
    # the polhode's body-axes L: I_B ω_B of the decimated states, with the world |L| and the energy
    from cross_checks.core.quantities import decimation_indices
    from reference_sim.quaternion import matrix_from_quat
    k = decimation_indices(len(t), 100)
    R = matrix_from_quat(y[k, 6:10])
    w_B = np.einsum("nji,nj->ni", R, y[k, 10:13])
    assert np.allclose(s["L_B"], w_B @ problem.body.inertia_B.T, rtol=1e-6, atol=1e-6)
    E = 0.5 * np.sum(w_B * (w_B @ problem.body.inertia_B.T), axis=1)
    assert np.allclose(0.5 * np.sum(s["L_B"] * (s["L_B"] @ np.linalg.inv(problem.body.inertia_B).T), axis=1),
                       E, rtol=1e-6)


def test_reaching_the_separatrix_is_not_crossing_it():
    # Jolt's step brings the tennis racket's δ = −5e-5 onto the separatrix (+2e-16 after 1000 periods): a
    # drift toward the intermediate axis, not a crossing — drawn here with |Π| kept and E moved onto L²/2I₂
    problem, t, _ = _closed_form_run([0.02, 0.02, 2.0], n=2001)
    d = -5e-5 * np.exp(-t / 50.0) + 2e-16
    # a body-axes Π with |Π| = 6 whose δ is d(t): Π = |Π| (sin θ, 0, cos θ) on I = (1, 2, 3) gives
    # δ = 2 sin²θ + (2/3) cos²θ − 1, so sin²θ = (δ + 1/3) · 3/4
    th = np.arcsin(np.sqrt((d + 1.0 / 3.0) * 0.75))
    Pi = 6.0 * np.column_stack([np.sin(th), np.zeros_like(th), np.cos(th)])
    y = np.zeros((len(t), 13))
    y[:, 6] = 1.0
    y[:, 10:13] = Pi / np.array([1.0, 2.0, 3.0])
    m = drift_metrics(problem, t, y)
    assert m.kind == "toward_intermediate" and not m.crossed_separatrix, m
