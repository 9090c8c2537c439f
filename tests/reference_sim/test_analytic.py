"""Closed forms of reference_sim.analytic against a high-accuracy ODE solve written here, and the
course scheme's error predictions against reference_sim.simulate runs.

The ODE below is the full free-body system in the course's variables (world ω)::

    ẋ = v,  v̇ = a(x, v),  q̇ = ½ [0, ω_W] q,  I_W ω̇ = −ω × (I_W ω),  I_W = R I_B Rᵀ

solved with DOP853 at rtol = 1e-13, atol = 1e-14. At that setting the solver's own global error over
10 s of rotation at a few rad/s is ≤ ~2e-11 (measured: halving the tolerances shrinks the
closed-form/ODE gap proportionally), which is what the 1e-10 tolerances below leave room for.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from reference_sim.analytic import (
    axisymmetric_top,
    constant_spin,
    course_spin_phase_lag,
    course_spin_phase_lag_exact,
    harmonic_oscillator,
    jacobi_body_rates,
    linear_drag,
    projectile,
    symplectic_euler_gravity_error,
    torque_free,
    torque_free_asymmetric,
)
from reference_sim.body import RigidBody
from reference_sim.forces import ForceModel
from reference_sim.quaternion import (
    geodesic_angle,
    matrix_from_quat,
    quat_conj,
    quat_mul,
    quat_normalize,
    rotate,
)
from reference_sim.simulate import simulate
from reference_sim.state import Problem, State
from tests.helpers.tolerances import CLOSED_FORM_PREDICTION_REL

ODE_RTOL, ODE_ATOL = 1e-13, 1e-14
# Closed form vs ODE, rotation over 10 s: ODE error ≤ ~2e-11 (see module docstring) + closed-form
# round-off ~1e-14; 1e-10 is the accuracy the references promise.
ROT_TOL = 1e-10
# Conservation by the closed forms: only round-off of R I Rᵀ ω (a few ε per product, ~1e-15) and of
# the phase (ε · |ω| t ≈ 1e-14 rad); 1e-12 relative leaves a ≥ 100× margin.
CONSERVE_TOL = 1e-12
# The course runs vs the error predictions: "at least 6 significant digits" (one source: the tolerances).
PREDICTION_RTOL = CLOSED_FORM_PREDICTION_REL

T_ROT = np.linspace(0.0, 10.0, 101)  # 10 s of rotation, sampled every 0.1 s


def _ode(inertia_B, q0_WB, w0_W, t_s, x0_W=(0.0, 0.0, 0.0), v0_W=(0.0, 0.0, 0.0), accel=None):
    """DOP853 solution of the full free-body equations; returns x (T,3), v (T,3), q (T,4), w (T,3)."""
    I_B = np.diag(inertia_B) if np.ndim(inertia_B) == 1 else np.asarray(inertia_B, dtype=float)

    def rhs(_t, y):
        x, v, q, w = y[0:3], y[3:6], y[6:10], y[10:13]
        R = matrix_from_quat(q / np.linalg.norm(q))
        I_W = R @ I_B @ R.T
        dw = np.linalg.solve(I_W, -np.cross(w, I_W @ w))
        dq = 0.5 * quat_mul(np.concatenate([[0.0], w]), q)
        dv = np.zeros(3) if accel is None else accel(x, v)
        return np.concatenate([v, dv, dq, dw])

    y0 = np.concatenate([x0_W, v0_W, quat_normalize(q0_WB), w0_W])
    sol = solve_ivp(rhs, (t_s[0], t_s[-1]), y0, method="DOP853", rtol=ODE_RTOL, atol=ODE_ATOL, t_eval=t_s)
    assert sol.success, sol.message
    y = sol.y.T
    return y[:, 0:3], y[:, 3:6], quat_normalize(y[:, 6:10]), y[:, 10:13]


def _euler_ode(moments, w0_B, t_s):
    """DOP853 solution of Euler's equations in a principal frame (body rates only)."""
    I1, I2, I3 = moments

    def rhs(_t, w):
        return [(I2 - I3) * w[1] * w[2] / I1, (I3 - I1) * w[2] * w[0] / I2, (I1 - I2) * w[0] * w[1] / I3]

    sol = solve_ivp(rhs, (t_s[0], t_s[-1]), w0_B, method="DOP853", rtol=ODE_RTOL, atol=ODE_ATOL, t_eval=t_s)
    assert sol.success, sol.message
    return sol.y.T


def _random_rotation_tensor(moments, seed):
    """Full 3×3 inertia with the given principal moments about random principal axes."""
    R = matrix_from_quat(quat_normalize(np.random.default_rng(seed).normal(size=4)))
    return R @ np.diag(moments) @ R.T


def _regime(inertia_B, q0_WB, w0_W):
    """sign of 2 E I_mid − L² (−1: polar axis = largest moment, +1: smallest)."""
    I_B = np.diag(inertia_B) if np.ndim(inertia_B) == 1 else np.asarray(inertia_B)
    w_B = rotate(quat_conj(quat_normalize(q0_WB)), w0_W)
    L_B = I_B @ w_B
    I_mid = np.sort(np.linalg.eigvalsh(I_B))[1]
    return np.sign(I_mid * (w_B @ L_B) - L_B @ L_B)


def _momentum_energy(inertia_B, q_WB, w_W):
    I_B = np.diag(inertia_B) if np.ndim(inertia_B) == 1 else np.asarray(inertia_B)
    R = matrix_from_quat(q_WB)
    I_W = R @ I_B @ np.swapaxes(R, -1, -2)
    L_W = np.einsum("tij,tj->ti", I_W, w_W)
    return L_W, 0.5 * np.einsum("ti,ti->t", w_W, L_W)


# --- translation ---------------------------------------------------------------------------------------

def test_projectile_matches_ode():
    x0, v0, g = np.array([1.0, 2.0, -0.5]), np.array([3.0, 4.0, -1.0]), np.array([0.0, 0.0, -9.81])
    t = np.linspace(0.0, 3.0, 31)
    x, v = projectile(x0, v0, g, t)
    xo, vo, _, _ = _ode([1.0, 1.0, 1.0], [1, 0, 0, 0], np.zeros(3), t, x0, v0, lambda x, v: g)
    # DOP853 integrates a quadratic exactly: only round-off (~1e-15 × |x| ≤ 50 m) remains.
    np.testing.assert_allclose(x, xo, rtol=0, atol=1e-12)
    np.testing.assert_allclose(v, vo, rtol=0, atol=1e-12)


@pytest.mark.parametrize("c_N_s_per_m", [1e-9, 0.1, 3.0])  # k t: series only / crosses ½ / direct
def test_linear_drag_matches_ode(c_N_s_per_m):
    m, x0, v0, g = 2.0, np.array([0.0, 1.0, 5.0]), np.array([10.0, -2.0, 3.0]), np.array([0.0, 0.0, -9.81])
    t = np.linspace(0.0, 10.0, 41)
    x, v = linear_drag(m, c_N_s_per_m, x0, v0, g, t)
    xo, vo, _, _ = _ode([1.0, 1.0, 1.0], [1, 0, 0, 0], np.zeros(3), t, x0, v0,
                        lambda x, v: g - (c_N_s_per_m / m) * v)
    # The ODE's error is ~2e-13 of the largest coordinate (|x| up to 390 m: 6.5e-11 m measured, and it
    # shrinks 5× at rtol 2.3e-14); 1e-12 of the scale leaves a 5× margin.
    np.testing.assert_allclose(x, xo, rtol=0, atol=1e-12 * np.max(np.abs(xo)))
    np.testing.assert_allclose(v, vo, rtol=0, atol=1e-12 * np.max(np.abs(vo)))


def test_linear_drag_without_drag_is_the_projectile_exactly():
    x0, v0, g = np.array([1.0, 2.0, -0.5]), np.array([3.0, 4.0, -1.0]), np.array([0.0, -9.81, 0.0])
    t = np.linspace(0.0, 3.0, 31)
    xd, vd = linear_drag(1.5, 0.0, x0, v0, g, t)
    xp, vp = projectile(x0, v0, g, t)
    # φ1(0) = 1 and φ2(0) = ½ exactly: the same floating-point operations, so bitwise equal.
    np.testing.assert_array_equal(xd, xp)
    np.testing.assert_array_equal(vd, vp)


def test_linear_drag_tiny_drag_is_first_order_correction_of_projectile():
    # x = parabola − k (v0 t²/2 + g t³/6) + O(k²): checks the series branch has no cancellation.
    m, c = 1.0, 1e-7
    x0, v0, g = np.zeros(3), np.array([1.0, 2.0, 3.0]), np.array([0.0, 0.0, -9.81])
    t = np.linspace(0.0, 2.0, 5)[:, None]
    x, _ = linear_drag(m, c, x0, v0, g, t[:, 0])
    xp, _ = projectile(x0, v0, g, t[:, 0])
    k = c / m
    expected = -k * (v0 * t ** 2 / 2 + g * t ** 3 / 6)
    # O(k²) remainder ≈ k² g t⁴/24 ≈ 1e-14 m; round-off of x − xp ≈ 1e-15 × 20 m.
    np.testing.assert_allclose(x - xp, expected, rtol=0, atol=1e-13)


def test_harmonic_oscillator_zero_rest_length_matches_ode():
    m, k = 2.0, 50.0
    anchor, x0, v0 = np.array([0.5, -1.0, 2.0]), np.array([1.0, 0.3, 1.0]), np.array([-0.5, 2.0, 0.7])
    g = np.array([0.0, 0.0, -9.81])
    t = np.linspace(0.0, 10.0, 51)
    x, v = harmonic_oscillator(m, k, 0.0, anchor, x0, v0, g, t)
    xo, vo, _, _ = _ode([1.0, 1.0, 1.0], [1, 0, 0, 0], np.zeros(3), t, x0, v0,
                        lambda x, v: g - (k / m) * (x - anchor))
    # 25 periods at ω0 = 5 rad/s; ODE phase error ~1e-12 on amplitudes of ~1 m.
    np.testing.assert_allclose(x, xo, rtol=0, atol=1e-10)
    np.testing.assert_allclose(v, vo, rtol=0, atol=1e-9)


def test_harmonic_oscillator_rest_length_on_a_line_matches_ode():
    m, k, L0 = 1.0, 40.0, 1.0
    anchor = np.array([0.0, 0.0, 3.0])
    u = np.array([0.0, 0.0, -1.0])  # hanging below the anchor, gravity along the line
    x0, v0, g = anchor + 1.4 * u, 0.8 * u, np.array([0.0, 0.0, -9.81])
    t = np.linspace(0.0, 10.0, 51)
    x, v = harmonic_oscillator(m, k, L0, anchor, x0, v0, g, t)

    def accel(x, v):
        d = x - anchor
        L = np.linalg.norm(d)
        return g - (k / m) * (L - L0) * d / L

    xo, vo, _, _ = _ode([1.0, 1.0, 1.0], [1, 0, 0, 0], np.zeros(3), t, x0, v0, accel)
    # As above: ~1e-12 ODE error on ~1 m amplitudes.
    np.testing.assert_allclose(x, xo, rtol=0, atol=1e-10)
    np.testing.assert_allclose(v, vo, rtol=0, atol=1e-9)


def test_harmonic_oscillator_rest_length_off_the_line_raises():
    anchor, x0, g = np.zeros(3), np.array([0.0, 0.0, -1.0]), np.array([0.0, 0.0, -9.81])
    with pytest.raises(ValueError, match="v0_W is not parallel"):
        harmonic_oscillator(1.0, 10.0, 0.5, anchor, x0, np.array([0.1, 0.0, 0.0]), g, [0.0, 1.0])
    with pytest.raises(ValueError, match="g_W is not parallel"):
        harmonic_oscillator(1.0, 10.0, 0.5, anchor, x0, np.zeros(3), np.array([0.0, -9.81, 0.0]), [0.0, 1.0])
    with pytest.raises(ValueError, match="at the anchor"):
        harmonic_oscillator(1.0, 10.0, 0.5, anchor, anchor, np.zeros(3), g, [0.0, 1.0])


def test_harmonic_oscillator_rest_length_reaching_the_anchor_raises():
    # Starts 1 m below the anchor moving up at 20 m/s: the amplitude exceeds the distance.
    anchor, x0, v0, g = np.zeros(3), np.array([0.0, 0.0, -1.0]), np.array([0.0, 0.0, 20.0]), np.zeros(3)
    with pytest.raises(ValueError, match="reaches the anchor"):
        harmonic_oscillator(1.0, 10.0, 1.0, anchor, x0, v0, g, np.linspace(0.0, 2.0, 5))
    # The same start is fine over a window too short to reach it (first crossing at t ≈ 0.05 s).
    harmonic_oscillator(1.0, 10.0, 1.0, anchor, x0, v0, g, np.linspace(0.0, 0.04, 5))


# --- torque-free rotation --------------------------------------------------------------------------------

Q0 = quat_normalize(np.array([0.9, -0.2, 0.3, 0.25]))


@pytest.mark.parametrize("inertia_B, w0_W", [
    ([1.0, 2.0, 3.0], rotate(Q0, [0.0, 0.0, -2.5])),   # about the largest axis (stable)
    ([1.0, 2.0, 3.0], rotate(Q0, [0.0, 1.5, 0.0])),    # about the intermediate axis (unstable; exact data)
    ([2.0, 2.0, 2.0], np.array([1.0, -2.0, 0.5])),      # isotropic, any ω
])
def test_constant_spin_matches_ode(inertia_B, w0_W):
    q, w = constant_spin(Q0, w0_W, T_ROT)
    _, _, qo, wo = _ode(inertia_B, Q0, w0_W, T_ROT)
    # Intermediate axis: round-off in ω_W (~1e-16) grows like e^{λ t}, λ = 1.5·sqrt(1/3) ≈ 0.87/s → ×6e3.
    assert np.max(geodesic_angle(qo, q)) < ROT_TOL
    assert np.max(np.abs(w - wo)) < ROT_TOL


AXISYMMETRIC_CASES = {
    "oblate_symmetry_axis_largest": ([1.0, 1.0, 1.8], [0.7, -1.2, 2.0]),
    "prolate_symmetry_axis_smallest": ([0.4, 1.5, 1.5], [-2.0, 0.6, 1.1]),
    "full_tensor_random_axes": (_random_rotation_tensor([1.2, 2.1, 2.1], seed=7), [1.3, 1.7, -0.9]),
}


@pytest.mark.parametrize("case", list(AXISYMMETRIC_CASES))
def test_axisymmetric_top_matches_ode(case):
    inertia_B, w0_W = AXISYMMETRIC_CASES[case]
    q, w = axisymmetric_top(inertia_B, Q0, w0_W, T_ROT)
    _, _, qo, wo = _ode(inertia_B, Q0, np.asarray(w0_W), T_ROT)
    assert np.max(geodesic_angle(qo, q)) < ROT_TOL
    assert np.max(np.abs(w - wo)) < ROT_TOL


def _asymmetric_cases():
    rng = np.random.default_rng(2024)
    cases = {
        # polar axis = largest moment (2 E I2 < L²) and = smallest (2 E I2 > L²), hand-picked octants
        "largest_polar": ([1.0, 2.0, 2.7], [1, 0, 0, 0], [0.4, -0.9, -1.8]),
        "smallest_polar": ([1.0, 2.0, 2.7], [1, 0, 0, 0], [-1.9, 0.8, -0.3]),
        "near_separatrix_k2_0.994": ([0.5, 1.3, 1.6], [1, 0, 0, 0], [-0.2, 1.5, -0.16]),
    }
    for i in range(3):  # random initial conditions (mixed signs), principal-moment inertia
        cases[f"random_{i}"] = ([0.5, 1.3, 1.6], quat_normalize(rng.normal(size=4)), 2.0 * rng.normal(size=3))
    for i in range(2):  # full tensors with random principal axes
        cases[f"full_tensor_{i}"] = (_random_rotation_tensor([1.0, 2.0, 2.7], seed=100 + i),
                                     quat_normalize(rng.normal(size=4)), 2.0 * rng.normal(size=3))
    return cases


ASYMMETRIC_CASES = _asymmetric_cases()


def test_asymmetric_cases_cover_both_energy_regimes():
    regimes = {_regime(np.asarray(I), q0, np.asarray(w0)) for I, q0, w0 in ASYMMETRIC_CASES.values()}
    assert regimes == {-1.0, 1.0}
    full = {_regime(np.asarray(I), q0, np.asarray(w0)) for name, (I, q0, w0) in ASYMMETRIC_CASES.items()
            if name.startswith("full")}
    assert full == {-1.0, 1.0}


@pytest.mark.parametrize("case", list(ASYMMETRIC_CASES))
def test_torque_free_asymmetric_matches_ode(case):
    inertia_B, q0, w0_W = ASYMMETRIC_CASES[case]
    w0_W = np.asarray(w0_W, dtype=float)
    q, w = torque_free_asymmetric(inertia_B, q0, w0_W, T_ROT)
    _, _, qo, wo = _ode(inertia_B, q0, w0_W, T_ROT)
    assert np.max(geodesic_angle(qo, q)) < ROT_TOL
    assert np.max(np.abs(w - wo)) < ROT_TOL


@pytest.mark.parametrize("w_abs", [[0.4, 0.9, 1.8], [1.9, 0.8, 0.3]])  # polar axis 3, then axis 1
@pytest.mark.parametrize("octant", range(8))
def test_jacobi_body_rates_match_euler_equations_in_every_octant(w_abs, octant):
    moments = np.array([1.0, 2.0, 2.7])
    signs = np.array([1.0 if octant & (1 << i) == 0 else -1.0 for i in range(3)])
    w0 = signs * np.array(w_abs)
    t = np.linspace(0.0, 10.0, 41)
    # Body rates alone are cheaper to integrate, and the same ROT_TOL argument applies.
    np.testing.assert_allclose(jacobi_body_rates(moments, w0, t),
                               _euler_ode(moments, w0, t), rtol=0, atol=ROT_TOL)


# unsorted labelling, either handedness
@pytest.mark.parametrize("moments", [[2.7, 1.0, 2.0], [1.0, 2.7, 2.0]])
def test_jacobi_body_rates_accept_any_axis_order(moments):
    w0 = np.array([-0.7, 1.1, 0.9])
    t = np.linspace(0.0, 10.0, 41)
    np.testing.assert_allclose(jacobi_body_rates(moments, w0, t),
                               _euler_ode(moments, w0, t), rtol=0, atol=ROT_TOL)


@pytest.mark.parametrize("solver, inertia_B, w0_W", [
    (axisymmetric_top, AXISYMMETRIC_CASES["full_tensor_random_axes"][0], [1.3, 1.7, -0.9]),
    (torque_free_asymmetric, ASYMMETRIC_CASES["full_tensor_0"][0], ASYMMETRIC_CASES["full_tensor_0"][2]),
    (torque_free_asymmetric, ASYMMETRIC_CASES["full_tensor_1"][0], ASYMMETRIC_CASES["full_tensor_1"][2]),
    (torque_free_asymmetric, [0.5, 1.3, 1.6], [-0.2, 1.5, -0.16]),
])
def test_torque_free_closed_forms_conserve_momentum_and_energy(solver, inertia_B, w0_W):
    t = np.linspace(0.0, 100.0, 2001)  # long horizon: conservation must not drift
    q, w = solver(inertia_B, Q0, np.asarray(w0_W, dtype=float), t)
    L_W, E = _momentum_energy(inertia_B, q, w)
    assert np.max(np.linalg.norm(L_W - L_W[0], axis=-1)) < CONSERVE_TOL * np.linalg.norm(L_W[0])
    assert np.max(np.abs(E - E[0])) < CONSERVE_TOL * E[0]


def test_jacobi_orientation_is_continuous_in_time():
    inertia_B, q0, w0 = ASYMMETRIC_CASES["random_0"]
    t = np.linspace(0.0, 10.0, 10001)
    q, w = torque_free_asymmetric(inertia_B, q0, w0, t)
    # Rotation per sample ≤ |ω| Δt ≈ 5e-3 rad, so consecutive q have dot ≈ 1 unless the sign flips.
    assert np.min(np.sum(q[1:] * q[:-1], axis=-1)) > 0.99
    np.testing.assert_allclose(q[0], q0, rtol=0, atol=1e-15)


def test_torque_free_dispatches_to_the_applicable_closed_form():
    w0 = np.array([0.3, -1.2, 0.8])
    # isotropic, principal-axis spin, axisymmetric, asymmetric: equal to the chosen function exactly
    for expected_fn, inertia_B, w in [
        (constant_spin, [2.0, 2.0, 2.0], w0),
        (constant_spin, [1.0, 2.0, 3.0], rotate(Q0, [0.0, 0.0, 1.7])),
        (axisymmetric_top, [1.0, 2.0, 2.0], w0),
        (axisymmetric_top, [1.0, 1.0 + 1e-14, 2.0], w0),
        (torque_free_asymmetric, [1.0, 2.0, 3.0], w0),
    ]:
        if expected_fn is constant_spin:
            expected = constant_spin(Q0, w, T_ROT)
        else:
            expected = expected_fn(inertia_B, Q0, w, T_ROT)
        got = torque_free(inertia_B, Q0, w, T_ROT)
        np.testing.assert_array_equal(got[0], expected[0])
        np.testing.assert_array_equal(got[1], expected[1])


def test_principal_axis_spin_in_asymmetric_solver_is_constant_spin():
    w = np.array([0.0, 0.0, 2.0])
    q, wt = torque_free_asymmetric([1.0, 2.0, 3.0], [1, 0, 0, 0], w, T_ROT)
    qc, wc = constant_spin([1, 0, 0, 0], w, T_ROT)
    np.testing.assert_array_equal(q, qc)
    np.testing.assert_array_equal(wt, wc)


def test_separatrix_raises():
    # 2 E I2 − L² = I1 ω1² (I2 − I1) − I3 ω3² (I3 − I2) = ω1² − 3 ω3² for I = (1, 2, 3); ω2 drops out.
    # ω1 = sqrt(3), ω3 = 1 puts it at zero up to the rounding of sqrt(3)² (~1e-16 relative).
    with pytest.raises(ValueError, match="separatrix"):
        jacobi_body_rates([1.0, 2.0, 3.0], [np.sqrt(3.0), 0.5, 1.0], [0.0, 1.0])
    with pytest.raises(ValueError, match="separatrix"):
        torque_free_asymmetric([1.0, 2.0, 3.0], [1, 0, 0, 0], [np.sqrt(3.0), 0.5, 1.0], [0.0, 1.0])


def test_wrong_inertia_shape_for_the_solver_raises():
    with pytest.raises(ValueError, match="two equal principal moments"):
        axisymmetric_top([1.0, 2.0, 3.0], Q0, [1.0, 0.0, 0.0], [0.0])
    with pytest.raises(ValueError, match="three distinct"):
        torque_free_asymmetric([1.0, 2.0, 2.0], Q0, [1.0, 0.5, 0.0], [0.0])
    with pytest.raises(ValueError, match="triangle inequality"):
        torque_free([1.0, 1.0, 3.0], Q0, [1.0, 0.5, 0.0], [0.0])


# --- error predictions vs the course scheme ---------------------------------------------------------------

def test_symplectic_euler_gravity_error_matches_course_run():
    g, dt, n = np.array([0.0, -9.81, 0.0]), 1e-2, 200
    x0, v0 = np.array([0.0, 1.0, 0.0]), np.array([2.0, 5.0, -1.0])
    problem = Problem(RigidBody(1.0, [1.0, 2.0, 3.0]), ForceModel(gravity_W=g),
                      State(x0, v0, np.array([1.0, 0.0, 0.0, 0.0]), np.zeros(3)))
    run = simulate(problem, "course", dt, n)
    x_exact, _ = projectile(x0, v0, g, run.t_s)
    error = np.linalg.norm(run.y[:, 0:3] - x_exact, axis=-1)
    predicted = symplectic_euler_gravity_error(g, run.t_s, dt)
    np.testing.assert_allclose(error[1:], predicted[1:], rtol=PREDICTION_RTOL)


def test_course_spin_phase_lag_matches_course_run():
    # Δt|ω| = 1.5e-3: the leading-order form's own relative error 0.15 (Δt|ω|)² ≈ 3.4e-7 < 1e-6, and the lag
    # per step (Δt|ω|)³/12 ≈ 2.8e-10 rad stays far above the ~1e-16 round-off per step.
    dt, n = 1e-3, 4000
    w_W = rotate(Q0, [0.0, 1.5, 0.0])  # about a principal axis: the exact motion is constant_spin
    problem = Problem(RigidBody(1.0, [1.0, 2.0, 3.0]), ForceModel(),
                      State(np.zeros(3), np.zeros(3), Q0, w_W))
    run = simulate(problem, "course", dt, n)
    q_exact, _ = constant_spin(Q0, w_W, run.t_s)
    lag = geodesic_angle(q_exact, run.y[:, 6:10])
    steps = np.arange(n + 1)
    np.testing.assert_allclose(lag[100:], course_spin_phase_lag_exact(w_W, steps, dt)[100:],
                               rtol=PREDICTION_RTOL)
    np.testing.assert_allclose(lag[100:], course_spin_phase_lag(w_W, run.t_s, dt)[100:], rtol=PREDICTION_RTOL)


def test_course_spin_phase_lag_exact_form_has_no_truncation_error():
    # Δt|ω| = 0.03: the leading-order form is off by 0.15 (Δt|ω|)² ≈ 1.4e-4 here, the exact form only by
    # round-off (~1e-16 per step against a lag of 2.2e-6 rad per step): 1e-9 separates the two.
    dt, n = 1e-2, 1000
    w_W = rotate(Q0, [0.0, 0.0, 3.0])
    problem = Problem(RigidBody(1.0, [1.0, 2.0, 3.0]), ForceModel(), State(np.zeros(3), np.zeros(3), Q0, w_W))
    run = simulate(problem, "course", dt, n)
    lag = geodesic_angle(constant_spin(Q0, w_W, run.t_s)[0], run.y[:, 6:10])
    exact = course_spin_phase_lag_exact(w_W, np.arange(n + 1), dt)
    np.testing.assert_allclose(lag[10:], exact[10:], rtol=1e-9)
    leading = course_spin_phase_lag(w_W, run.t_s, dt)
    np.testing.assert_allclose(lag[10:] / leading[10:] - 1.0, -0.15 * (dt * 3.0) ** 2, rtol=0.01)
