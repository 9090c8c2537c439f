"""Closed-form solutions of the free rigid body and of the course integrator's discretisation error.

These are the analytic references the suite measures simulators against. Every function takes a
time array ``t_s`` of shape ``(T,)`` (s; a scalar counts as ``(1,)``) and returns arrays whose
leading axis is ``T``. Conventions are those of :mod:`reference_sim.quaternion` and
docs/course_equations.md:

* quaternions are scalar first, ``(w, x, y, z)``; ``q_WB`` maps body to world, ``p_W = R(q_WB) p_B``;
* the angular velocity ``w_W`` is in WORLD axes; ``q̇ = ½ [0, ω_W] q`` (left multiplication);
* ``inertia_B`` is the body-frame inertia about the COM (3 principal moments or a 3×3 tensor, kg m²).

Translational closed forms (every force at the COM), torque-free rotation (:func:`torque_free` picks the
closed form that applies) and the discretisation error of the course scheme.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import ellipj, ellipk, ellipkinc, elliprj

from reference_sim.body import check_inertia, principal_axes
from reference_sim.quaternion import quat_conj, quat_exp, quat_from_matrix, quat_mul, quat_normalize, rotate

__all__ = [
    "projectile",
    "linear_drag",
    "harmonic_oscillator",
    "constant_spin",
    "axisymmetric_top",
    "jacobi_body_rates",
    "torque_free_asymmetric",
    "torque_free",
    "symplectic_euler_gravity_error",
    "course_spin_phase_lag",
    "course_spin_phase_lag_exact",
    "EQUAL_MOMENTS_REL_TOL",
    "PRINCIPAL_AXIS_REL_TOL",
    "COLLINEAR_REL_TOL",
    "SEPARATRIX_REL_TOL",
]

# --- tolerances (each decides which closed form applies, never how accurate it is) ---------------

#: Two principal moments count as equal when they differ by at most this times the largest moment.
#: Moments typed with ~15 significant digits, or rotated into a full tensor and back by eigh, differ
#: by ~1e-15 relative; 1e-12 leaves a 1000× margin, and the axisymmetric model built from their mean
#: is then wrong by ≤ 1e-12 relative, below every accuracy the suite asks for.
EQUAL_MOMENTS_REL_TOL = 1e-12

#: ω counts as along a principal axis when its component perpendicular to that axis is at most this
#: times |ω|: rotating ω_W into the principal frame (two 3×3 products) rounds at ~1e-15 relative.
#: About an extreme axis a perpendicular part δ|ω| only adds a nutation of relative size ~δ, so
#: constant spin is exact to 1e-12. About the intermediate axis the true motion is unstable and
#: ill-posed at this level (a δ grows like e^{λt}); constant spin is the answer for exact data.
PRINCIPAL_AXIS_REL_TOL = 1e-12

#: Spring with rest length > 0: x0 − anchor, v0 and g count as parallel when the sine of the angle
#: between them is at most this (round-off of vectors built as multiples of one direction is ~1e-16).
COLLINEAR_REL_TOL = 1e-12

#: Separatrix test of the Jacobi solution: |2 E I_mid − L²| at most this times the sum of the
#: magnitudes of its two terms. Each term carries a relative rounding error of a few 1e-16, so below
#: 1e-13 (a 100× margin) the sign of 2 E I_mid − L², which picks the regime, is round-off.
SEPARATRIX_REL_TOL = 1e-13


# --- small helpers -----------------------------------------------------------------------------------

def _times(t_s) -> np.ndarray:
    t = np.asarray(t_s, dtype=float)
    if t.ndim == 0:
        t = t[None]
    if t.ndim != 1:
        raise ValueError(f"t_s must be a 1-D array of times (T,), got shape {t.shape}")
    if not np.all(np.isfinite(t)):
        raise ValueError("t_s must be finite")
    return t


def _vec3(name: str, a) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    if a.shape != (3,):
        raise ValueError(f"{name} must have shape (3,), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be finite")
    return a


def _quat(name: str, q) -> np.ndarray:
    q = np.asarray(q, dtype=float)
    if q.shape != (4,):
        raise ValueError(f"{name} must be a quaternion (w, x, y, z) of shape (4,), got {q.shape}")
    try:
        return quat_normalize(q)
    except ValueError as exc:
        raise ValueError(f"{name}: {exc}") from None


def _positive(name: str, value) -> float:
    value = float(value)
    if not (np.isfinite(value) and value > 0.0):
        raise ValueError(f"{name} must be a positive finite number, got {value!r}")
    return value


def _principal(inertia_B):
    """Validated inertia: principal moments ``(3,)`` ascending and ``R_BP`` (3, 3), det +1."""
    try:
        I_B = check_inertia(inertia_B)
    except ValueError as exc:
        raise ValueError(f"inertia_B {exc}") from None
    return principal_axes(I_B)


def _qx(angle):
    """Quaternions (..., 4) of rotations by ``angle`` (rad) about x."""
    h = 0.5 * np.asarray(angle, dtype=float)
    z = np.zeros_like(h)
    return np.stack([np.cos(h), np.sin(h), z, z], axis=-1)


def _qz(angle):
    """Quaternions (..., 4) of rotations by ``angle`` (rad) about z."""
    h = 0.5 * np.asarray(angle, dtype=float)
    z = np.zeros_like(h)
    return np.stack([np.cos(h), z, z, np.sin(h)], axis=-1)


# --- translation -------------------------------------------------------------------------------------

def projectile(x0_W, v0_W, g_W, t_s):
    """Exact motion of the COM under uniform gravity (the parabola).

    ``x(t) = x0 + v0 t + ½ g t²``, ``v(t) = v0 + g t`` (elementary kinematics; e.g. J. R. Taylor,
    *Classical Mechanics* (2005), ch. 2).

    Parameters: ``x0_W``, ``v0_W``, ``g_W`` (3,) initial COM position (m), velocity (m/s) and gravitational
    acceleration (m/s²), world; ``t_s`` (T,) times, s.
    Returns: ``x_W`` (T, 3) COM positions, m, and ``v_W`` (T, 3) COM velocities, m/s, world.
    """
    x0, v0, g = _vec3("x0_W", x0_W), _vec3("v0_W", v0_W), _vec3("g_W", g_W)
    t = _times(t_s)[:, None]
    x_W = x0 + v0 * t + g * (t * t) * 0.5
    v_W = v0 + g * t
    return x_W, v_W


def _phi1(z):
    """``(1 − e^{−z}) / z`` (1 at z = 0), accurate to round-off for all z via expm1."""
    z = np.asarray(z, dtype=float)
    safe = np.where(z == 0.0, 1.0, z)
    return np.where(z == 0.0, 1.0, -np.expm1(-z) / safe)


def _phi2(z):
    """``(z − 1 + e^{−z}) / z²`` (½ at z = 0), accurate to round-off for all z.

    Direct formula ``(z + expm1(−z))/z²`` for |z| ≥ ½ (cancellation costs at most a factor 2/|z| ≤ 4
    in relative error there); for |z| < ½ the Taylor series ``Σ_j (−z)^j / (j+2)!`` to j = 16, whose
    truncation error ½^17/19! ≈ 6e-23 is far below round-off.
    """
    z = np.asarray(z, dtype=float)
    small = np.abs(z) < 0.5
    zs = np.where(small, z, 0.0)
    series = np.zeros_like(zs)
    for j in reversed(range(17)):  # Horner: coefficient of (−z)^j is 1/(j+2)!
        series = series * (-zs) + 1.0 / math.factorial(j + 2)
    zd = np.where(small, 1.0, z)
    direct = (zd + np.expm1(-zd)) / (zd * zd)
    return np.where(small, series, direct)


def linear_drag(mass_kg, c_N_s_per_m, x0_W, v0_W, g_W, t_s):
    """Exact COM motion under uniform gravity and linear drag ``m v̇ = m g − c v``.

    With ``k = c/m`` and ``z = k t``::

        v(t) = v0 e^{−z} + g t φ1(z),            φ1(z) = (1 − e^{−z}) / z
        x(t) = x0 + v0 t φ1(z) + g t² φ2(z),     φ2(z) = (z − 1 + e^{−z}) / z²

    (J. R. Taylor, *Classical Mechanics* (2005), ch. 2, linear air resistance). φ1 uses ``expm1`` and
    φ2 a Taylor series for small ``z``, so the result is accurate to round-off for every k·t, and
    ``c = 0`` reproduces :func:`projectile` exactly (φ1 = 1, φ2 = ½).

    Parameters: ``mass_kg`` (> 0); ``c_N_s_per_m`` the drag coefficient c in ``f = −c v``, N s/m (>= 0);
    ``x0_W``, ``v0_W``, ``g_W`` and ``t_s`` as in :func:`projectile`. Returns: as :func:`projectile`.
    """
    m = _positive("mass_kg", mass_kg)
    c = float(c_N_s_per_m)
    if not (np.isfinite(c) and c >= 0.0):
        raise ValueError(f"c_N_s_per_m must be a finite number >= 0, got {c_N_s_per_m!r}")
    x0, v0, g = _vec3("x0_W", x0_W), _vec3("v0_W", v0_W), _vec3("g_W", g_W)
    t = _times(t_s)[:, None]
    z = (c / m) * t
    p1, p2 = _phi1(z), _phi2(z)
    x_W = x0 + v0 * t * p1 + g * (t * t) * p2
    v_W = v0 * np.exp(-z) + g * t * p1
    return x_W, v_W


def harmonic_oscillator(mass_kg, k_N_per_m, rest_length_m, anchor_W, x0_W, v0_W, g_W, t_s):
    """Exact COM motion on a spring from a fixed world anchor to the COM, under uniform gravity.

    Force ``f = m g − k (L − L0) d / L`` with ``d = x − anchor``, ``L = |d|`` (the spring of
    :class:`reference_sim.forces.Spring` with ``attach_B = 0``, so no torque). ``ω0 = sqrt(k/m)``.

    * ``L0 = 0``: the force ``m g − k d`` is linear in 3-D; about the equilibrium
      ``x_eq = anchor + m g / k``: ``x = x_eq + (x0 − x_eq) cos ω0 t + (v0/ω0) sin ω0 t``.
    * ``L0 > 0``: exact only for motion on one line through the anchor. With ``u = d0/|d0|``, this
      needs ``v0`` and ``g`` parallel to ``u`` and ``s = d·u > 0`` for all t (the body never reaches
      the anchor); then ``s`` obeys ``m s̈ = m g·u − k (s − L0)``, the same oscillator about
      ``s_eq = L0 + m g·u / k``.

    (L. D. Landau & E. M. Lifshitz, *Mechanics*, 3rd ed., §21, free oscillations in one dimension.)

    Parameters: ``mass_kg`` (> 0), ``k_N_per_m`` stiffness (> 0), ``rest_length_m`` L0 (>= 0),
    ``anchor_W`` (3,) the anchor, world, m; ``x0_W``, ``v0_W``, ``g_W`` and ``t_s`` as in :func:`projectile`.
    Returns: as :func:`projectile`.

    Raises ValueError for ``L0 > 0`` when the motion is not on one line through the anchor (x0 at the
    anchor, v0 or g not parallel to x0 − anchor), or when the body reaches the anchor at some time between 0
    and the extreme times of ``t_s`` (the 1-D model does not hold there).
    """
    m = _positive("mass_kg", mass_kg)
    k = _positive("k_N_per_m", k_N_per_m)
    L0 = float(rest_length_m)
    if not (np.isfinite(L0) and L0 >= 0.0):
        raise ValueError(f"rest_length_m must be a finite number >= 0, got {rest_length_m!r}")
    anchor, x0, v0, g = (_vec3(n, a) for n, a in
                         (("anchor_W", anchor_W), ("x0_W", x0_W), ("v0_W", v0_W), ("g_W", g_W)))
    t = _times(t_s)
    w0 = np.sqrt(k / m)
    c, s = np.cos(w0 * t)[:, None], np.sin(w0 * t)[:, None]
    if L0 == 0.0:
        x_eq = anchor + (m / k) * g
        dx0 = x0 - x_eq
        x_W = x_eq + dx0 * c + (v0 / w0) * s
        v_W = v0 * c - (w0 * dx0) * s
        return x_W, v_W

    return _oscillator_on_line(m, k, L0, anchor, x0, v0, g, t, w0, c, s)


def _oscillator_on_line(m, k, L0, anchor, x0, v0, g, t, w0, c, s):
    """:func:`harmonic_oscillator` with a rest length ``L0 > 0``: the 1-D oscillator along the line
    ``u = (x0 − anchor)/|x0 − anchor|``, after checking that the motion stays on it and off the anchor.
    ``c, s``: (T, 1) cos and sin of ω0 t."""
    d0 = x0 - anchor
    s0 = float(np.linalg.norm(d0))
    if s0 == 0.0:
        raise ValueError("rest_length_m > 0 and x0_W is at the anchor: the spring direction is undefined")
    u = d0 / s0
    for name, vec in (("v0_W", v0), ("g_W", g)):
        n = float(np.linalg.norm(vec))
        if n > 0.0 and np.linalg.norm(np.cross(u, vec)) > COLLINEAR_REL_TOL * n:
            raise ValueError(
                f"rest_length_m > 0: the closed form needs motion on one line through the anchor, but "
                f"{name} is not parallel to x0_W - anchor_W (the 3-D motion with a rest length is not "
                "solvable in closed form; use a numerical reference)"
            )
    sv, gu = float(v0 @ u), float(g @ u)
    s_eq = L0 + (m / k) * gu
    a_c, a_s = s0 - s_eq, sv / w0
    # s(τ) = s_eq + A cos(ω0 τ − φ); its minimum over the window spanned by 0 and t_s.
    A, phase = float(np.hypot(a_c, a_s)), float(np.arctan2(a_s, a_c))
    t_lo, t_hi = min(0.0, float(t.min())), max(0.0, float(t.max()))
    j_lo = np.ceil((w0 * t_lo - phase - np.pi) / (2.0 * np.pi))
    j_hi = np.floor((w0 * t_hi - phase - np.pi) / (2.0 * np.pi))
    if j_lo <= j_hi:
        s_min = s_eq - A
    else:
        s_min = min(s_eq + A * np.cos(w0 * t_lo - phase), s_eq + A * np.cos(w0 * t_hi - phase))
    if not s_min > 0.0:
        raise ValueError(
            f"rest_length_m > 0: the body reaches the anchor (distance along the line falls to "
            f"{s_min:.6g} m within the time window), where the 1-D spring model stops being valid"
        )
    s_t = s_eq + a_c * c[:, 0] + a_s * s[:, 0]
    sdot = sv * c[:, 0] - (w0 * a_c) * s[:, 0]
    return anchor + s_t[:, None] * u, sdot[:, None] * u


# --- torque-free rotation ----------------------------------------------------------------------------

def constant_spin(q0_WB, w_W, t_s):
    """Spin at constant world angular velocity: ``q(t) = exp(t ω_W) q0`` (left multiplication).

    The exact torque-free motion when ω is along a principal axis of inertia, or for any ω when the
    inertia is isotropic (then ``ω × (I ω) = 0`` and Euler's equations give ω̇ = 0; L. D. Landau &
    E. M. Lifshitz, *Mechanics*, 3rd ed., §36). This function does not know the inertia: checking
    that one of those cases holds is the caller's job (:func:`torque_free` does it).

    Parameters: ``q0_WB`` (4,) initial orientation body→world, quaternion (w, x, y, z) (normalised here);
    ``w_W`` (3,) angular velocity, world axes, rad/s; ``t_s`` (T,) times, s.
    Returns: ``q_WB`` (T, 4) orientations (w, x, y, z), continuous in t, and ``w_W`` (T, 3) angular
    velocities, world axes, rad/s (all equal to the input).
    """
    q0 = _quat("q0_WB", q0_WB)
    w = _vec3("w_W", w_W)
    t = _times(t_s)
    q_WB = quat_mul(quat_exp(t[:, None] * w), q0)
    return q_WB, np.broadcast_to(w, (t.size, 3)).copy()


def _symmetry_axis(moments, R_BP):
    """Symmetry axis ``e_B`` (3,), its moment ``I_s`` and the repeated moment ``I_perp`` (kg m²).

    ``moments`` ascending. Isotropic inertia gives an arbitrary axis with ``I_s = I_perp``.
    Raises ValueError when no two moments are equal within EQUAL_MOMENTS_REL_TOL.
    """
    m0, m1, m2 = moments
    tol = EQUAL_MOMENTS_REL_TOL * m2
    if m2 - m0 <= tol:
        mean = float(np.mean(moments))
        return R_BP[:, 2].copy(), mean, mean
    if m1 - m0 <= tol:
        return R_BP[:, 2].copy(), float(m2), 0.5 * float(m0 + m1)
    if m2 - m1 <= tol:
        return R_BP[:, 0].copy(), float(m0), 0.5 * float(m1 + m2)
    raise ValueError(
        f"axisymmetric_top needs two equal principal moments (relative tolerance "
        f"{EQUAL_MOMENTS_REL_TOL:g}); got {moments.tolist()} - use torque_free_asymmetric"
    )


def axisymmetric_top(inertia_B, q0_WB, w0_W, t_s):
    """Torque-free motion of a body with two equal principal moments (free symmetric top).

    With ``e`` the symmetry axis (body coordinates), ``I_s`` its moment, ``I_perp`` the repeated
    moment and ``ω_s = ω_B·e`` (constant by Euler's equations)::

        R_WB(t) = exp(t [L_W / I_perp]×) R_WB(0) exp(t λ [e]×),    λ = ω_s (1 − I_s / I_perp)
        ω_W(t) = L_W / I_perp + λ R_WB(t) e

    i.e. the body spins about its symmetry axis at rate λ relative to a frame that precesses about the
    constant ``L_W`` at rate ``|L| / I_perp`` (H. Goldstein, C. Poole & J. Safko, *Classical
    Mechanics*, 3rd ed., §5.6; L. D. Landau & E. M. Lifshitz, *Mechanics*, 3rd ed., §33 (free
    regular precession) and §36). Derivation: ``L_B = I_perp ω_B + (I_s − I_perp) ω_s e`` gives
    ``ω_W = L_W / I_perp + λ R e``; the formula satisfies ``Ṙ Rᵀ = [L_W/I_perp + λ R e]×`` (the
    right factor commutes with ``[e]×``) with the right R(0), so it is the solution.

    Parameters: ``inertia_B`` (3,) principal moments or (3, 3) body-frame inertia tensor about the COM,
    kg m², two principal moments equal within EQUAL_MOMENTS_REL_TOL (any axis may be the symmetry axis);
    ``q0_WB``, ``w0_W`` (initial angular velocity) and ``t_s`` as in :func:`constant_spin`.
    Returns: as :func:`constant_spin`.
    """
    moments, R_BP = _principal(inertia_B)
    e_B, I_s, I_perp = _symmetry_axis(moments, R_BP)
    q0 = _quat("q0_WB", q0_WB)
    w0 = _vec3("w0_W", w0_W)
    t = _times(t_s)
    w0_B = rotate(quat_conj(q0), w0)
    w_s = float(w0_B @ e_B)
    L_B = I_perp * w0_B + (I_s - I_perp) * w_s * e_B
    L_W = rotate(q0, L_B)
    lam = w_s * (I_perp - I_s) / I_perp
    precession = quat_exp(t[:, None] * (L_W / I_perp))
    body_spin = quat_exp(t[:, None] * (lam * e_B))
    q_WB = quat_mul(quat_mul(precession, q0), body_spin)
    w_W = L_W / I_perp + lam * rotate(q_WB, e_B)
    return q_WB, w_W


@dataclass(frozen=True)
class _Jacobi:
    """Parameters of the Jacobi solution in the relabelled principal frame P'.

    P' has axis 3 = the polar axis (the extreme axis about which L circulates), axis 2 = the
    intermediate axis, axis 1 = the other extreme axis; ``perm`` (3, 3), det +1, maps P' coordinates
    to the caller's principal coordinates. In P'::

        ω1 = a1 cn u,  ω2 = σ a2 sn u,  ω3 = s3 a3 dn u,  u = p t + u0,  parameter m = k².
    """

    I: np.ndarray       # (3,) moments in P' order, kg m²
    perm: np.ndarray    # (3, 3) columns: P' axes in the caller's principal coordinates
    a: np.ndarray       # (3,) amplitudes a1, a2, a3, rad/s
    sigma: float        # sign of ω2 relative to sn
    s3: float           # sign of ω3 (constant)
    p: float            # rate of the argument u, 1/s
    m: float            # elliptic parameter k²
    K: float            # quarter period K(m) in u
    u0: float           # initial argument
    L: float            # |L|, kg m²/s


def _jacobi_setup(moments, w0_P):
    """Regime, relabelling and Jacobi parameters for moments ``(3,)`` (any order, distinct) and body
    rates ``w0_P`` (3,) in the same principal frame. Returns None when ω0 is along a principal axis
    (or zero): then ω is constant."""
    I = np.asarray(moments, dtype=float)
    w = np.asarray(w0_P, dtype=float)
    if np.count_nonzero(w) <= 1:
        return None
    lo, mid, hi = np.argsort(I)
    # 2 E I_mid − L² = Σ I_i ω_i² (I_mid − I_i): two terms of opposite signs.
    t_lo = I[lo] * w[lo] ** 2 * (I[mid] - I[lo])
    t_hi = I[hi] * w[hi] ** 2 * (I[hi] - I[mid])
    D = t_lo - t_hi
    if abs(D) <= SEPARATRIX_REL_TOL * (t_lo + t_hi):
        raise ValueError(
            "initial condition is on the separatrix 2 E I_mid = L² (relative difference "
            f"{abs(D) / (t_lo + t_hi):.3g} <= {SEPARATRIX_REL_TOL:g}): the motion is the homoclinic orbit "
            "of the intermediate axis (period infinite), which the Jacobi cn/sn/dn solution does not "
            "cover; use a numerical reference"
        )
    polar, other = (hi, lo) if D < 0.0 else (lo, hi)
    order = [other, mid, polar]
    perm = np.eye(3)[:, order]
    if np.linalg.det(perm) < 0.0:
        perm[:, 1] *= -1.0  # keep P' right-handed so Euler's equations keep their cyclic form
    Ip = I[order]
    w1, w2, w3 = perm.T @ w
    I1, I2, I3 = Ip
    d31, d32, d21 = I3 - I1, I3 - I2, I2 - I1  # all > 0 (polar = largest) or all < 0 (smallest)
    # Every sum below has terms of one sign (no cancellation): 2E I3 − L² = I1 ω1² d31 + I2 ω2² d32,
    # L² − 2E I1 = I2 ω2² d21 + I3 ω3² d31 (Landau & Lifshitz §37, written without differences).
    a1 = np.sqrt(w1 * w1 + I2 * d32 * w2 * w2 / (I1 * d31))
    a2 = np.sqrt(I1 * d31 * w1 * w1 / (I2 * d32) + w2 * w2)
    a3 = np.sqrt(w3 * w3 + I2 * d21 * w2 * w2 / (I3 * d31))
    lead = I2 * d21 * w2 * w2 + I3 * d31 * w3 * w3
    p = np.sqrt(d32 * lead / (I1 * I2 * I3))
    m = float(d21 * (I1 * d31 * w1 * w1 + I2 * d32 * w2 * w2) / (d32 * lead))
    s3 = float(np.sign(w3))
    sigma = s3 * float(np.sign(d32))
    # Initial phase: cn u0 = ω1/a1, sn u0 = σ ω2/a2, so am(u0) = atan2(σ ω2/a2, ω1/a1).
    u0 = float(ellipkinc(np.arctan2(sigma * w2 / a2, w1 / a1), m))
    L = float(np.sqrt((I1 * w1) ** 2 + (I2 * w2) ** 2 + (I3 * w3) ** 2))
    return _Jacobi(Ip, perm, np.array([a1, a2, a3]), sigma, s3, float(p), m, float(ellipk(m)), u0, L)


def _reduced(u, period):
    """``u = j·period + r`` with r in [−period/2, period/2]; returns (j, r)."""
    j = np.round(u / period)
    return j, u - j * period


def _jacobi_rates_Pp(sol: _Jacobi, t):
    """Body rates in P' (T, 3) and the continuous amplitude am(u) (T,)."""
    u = sol.p * t + sol.u0
    j, r = _reduced(u, 4.0 * sol.K)  # sn, cn, dn have period 4K (DLMF 22.4); reduce for accuracy
    sn, cn, dn, _ = ellipj(r, sol.m)
    am = np.arctan2(sn, cn) + 2.0 * np.pi * j  # am(r) in [−π, π] for r in [−2K, 2K]
    a1, a2, a3 = sol.a
    w = np.stack([a1 * cn, sol.sigma * a2 * sn, sol.s3 * a3 * dn], axis=-1)
    return w, am, sn, cn


def jacobi_body_rates(moments, w0_B, t_s):
    """Torque-free body angular velocity from Jacobi elliptic functions (three distinct moments).

    Solves Euler's equations ``I ω̇ + ω × (I ω) = 0`` in a principal frame, any initial condition off
    the separatrix. Relabel the axes (1, 2, 3) so that 2 is the intermediate axis and 3 the *polar*
    axis — the largest moment when ``2 E I2 < L²``, the smallest when ``2 E I2 > L²`` — keeping the
    frame right-handed. Then (L. D. Landau & E. M. Lifshitz, *Mechanics*, 3rd ed., §37)::

        ω1 = a1 cn u,   ω2 = σ a2 sn u,   ω3 = s3 a3 dn u,   u = p t + u0
        a1² = (2E I3 − L²) / (I1 (I3 − I1)),   a2² = (2E I3 − L²) / (I2 (I3 − I2))
        a3² = (L² − 2E I1) / (I3 (I3 − I1)),   p² = (I3 − I2)(L² − 2E I1) / (I1 I2 I3)
        k² = (I2 − I1)(2E I3 − L²) / ((I3 − I2)(L² − 2E I1))

    with ``s3 = sign ω3(0)`` (ω3 never vanishes) and ``σ = s3 sign(I3 − I2)`` (substituting into
    Euler's equations fixes it). The phase follows from ``am(u0) = atan2(σ ω2(0)/a2, ω1(0)/a1)`` and
    ``u0 = F(am(u0) | k²)`` (incomplete elliptic integral, ``scipy.special.ellipkinc``), which covers
    all sign combinations (octants) of ω(0).

    Parameters: ``moments`` (3,) principal moments, kg m², in any order, pairwise distinct; ``w0_B`` (3,)
    initial angular velocity in the principal body frame (inertia = diag(moments)), rad/s; ``t_s`` (T,) s.
    Returns ``w_B`` (T, 3), the angular velocity in the same principal body frame, rad/s; constant for a
    spin exactly about one principal axis (two zero components).
    Raises ValueError for non-positive or equal moments, or an initial condition on the separatrix
    ``2 E I_mid = L²`` (see SEPARATRIX_REL_TOL).
    """
    I = _vec3("moments", moments)
    if np.any(I <= 0.0):
        raise ValueError(f"moments must be positive, got {I.tolist()}")
    Is = np.sort(I)
    if np.min(np.diff(Is)) <= EQUAL_MOMENTS_REL_TOL * Is[2]:
        raise ValueError(f"moments must be pairwise distinct, got {I.tolist()} - use axisymmetric_top")
    w0 = _vec3("w0_B", w0_B)
    t = _times(t_s)
    sol = _jacobi_setup(I, w0)
    if sol is None:
        return np.broadcast_to(w0, (t.size, 3)).copy()
    w_Pp, _, _, _ = _jacobi_rates_Pp(sol, t)
    return w_Pp @ sol.perm.T


def _jacobi_attitude(sol: _Jacobi, t, w_Pp, am, sn, cn):
    """Orientation ``q_LP'`` (T, 4) of P' relative to the world-fixed frame L (z along L_W).

    ZXZ Euler angles ``R_LP' = Rz(ψ) Rx(θ) Rz(χ)`` (:func:`torque_free_asymmetric`).
    """
    I1, I2, I3 = sol.I
    d31, d32, d21 = I3 - I1, I3 - I2, I2 - I1
    Lp = w_Pp * sol.I
    theta = np.arctan2(np.hypot(Lp[:, 0], Lp[:, 1]), Lp[:, 2])
    # χ = atan2(I1 ω1, I2 ω2) = atan2(a cn, σ b sn) = π/2 − σ μ, with μ = atan2(b sn, a cn) made
    # continuous in t: μ = am + atan2((b − a) sn cn, a cn² + b sn²) (the denominator is > 0).
    a_, b_ = I1 * sol.a[0], I2 * sol.a[1]
    mu = am + np.arctan2((b_ - a_) * sn * cn, a_ * cn * cn + b_ * sn * sn)
    chi = 0.5 * np.pi - sol.sigma * mu
    # ψ(t) = (L/I1) [t + (c2/p) (S(u) − S(u0))], n, c2 and S as in torque_free_asymmetric's docstring
    n = -I3 * d21 / (I1 * d32)
    c2 = (I1 - I2) * d31 / (I1 * d32)
    S_K = elliprj(0.0, 1.0 - sol.m, 1.0, 1.0 - n) / 3.0

    def S(u):
        j, r = _reduced(u, 2.0 * sol.K)
        s_, c_, d_, _ = ellipj(r, sol.m)
        return 2.0 * j * S_K + s_ ** 3 * elliprj(c_ * c_, d_ * d_, 1.0, 1.0 - n * s_ * s_) / 3.0

    u = sol.p * t + sol.u0
    psi = (sol.L / I1) * (t + (c2 / sol.p) * (S(u) - S(np.array([sol.u0]))))
    return quat_mul(_qz(psi), quat_mul(_qx(theta), _qz(chi)))


def torque_free_asymmetric(inertia_B, q0_WB, w0_W, t_s):
    """Torque-free motion of a body with three distinct principal moments, any initial condition.

    Body rates from :func:`jacobi_body_rates` (Landau & Lifshitz, *Mechanics*, §37). Orientation: the
    world angular momentum ``L_W`` is constant. In the world-fixed frame L whose z axis is along
    ``L_W`` the principal frame P' (axes relabelled so that 3 is the polar axis, see
    :func:`jacobi_body_rates`) has ZXZ Euler angles ``R_LP' = Rz(ψ) Rx(θ) Rz(χ)``; θ and χ follow
    from ``L_P'(t)/|L| = (sinθ sinχ, sinθ cosχ, cosθ)`` (never singular: ``L_P'`` is never along axis 3
    unless ω is), and the body angular velocity ``ω = ψ̇ l + θ̇ Rz(−χ) e_x + χ̇ e_z`` gives
    (Landau & Lifshitz §37)::

        ψ̇ = |L| (I1 ω1² + I2 ω2²) / (I1² ω1² + I2² ω2²) = (|L|/I1) [1 + c2 sn²u / (1 − n sn²u)]

    ``n = −I3 (I2 − I1) / (I1 (I3 − I2))``, ``c2 = (I1 − I2)(I3 − I1) / (I1 (I3 − I2))``. Its integral is
    closed form, ``ψ(t) = (|L|/I1) [t + (c2/p)(S(u) − S(u0))]`` with
    ``S(u) = ∫₀ᵘ sn²/(1 − n sn²) = ⅓ sn³u R_J(cn²u, dn²u, 1, 1 − n sn²u)`` on |u| <= K extended by
    ``S(u + 2K) = S(u) + 2 S(K)`` (the elliptic integral of the third kind in Carlson form, DLMF
    §19.25(i); B. C. Carlson, Numer. Algorithms 10 (1995) 13). No quadrature: the attitude is exact
    up to round-off in the phase (~ε |ω| t). ψ(0) = 0 fixes L's frame from ``q0_WB``.

    Parameters and returns: those of :func:`axisymmetric_top`, with three distinct principal moments.
    Raises ValueError when two moments are equal (use :func:`axisymmetric_top`), or ω(0) is on the separatrix.
    """
    moments, R_BP = _principal(inertia_B)
    if np.min(np.diff(moments)) <= EQUAL_MOMENTS_REL_TOL * moments[2]:
        raise ValueError(
            f"torque_free_asymmetric needs three distinct principal moments, got {moments.tolist()} "
            "- use axisymmetric_top (or torque_free, which chooses)"
        )
    q0 = _quat("q0_WB", q0_WB)
    w0 = _vec3("w0_W", w0_W)
    t = _times(t_s)
    w0_P = R_BP.T @ rotate(quat_conj(q0), w0)
    sol = _jacobi_setup(moments, w0_P)
    if sol is None:  # exact spin about a principal axis
        return constant_spin(q0, w0, t)
    w_Pp, am, sn, cn = _jacobi_rates_Pp(sol, t)
    q_BPp = quat_from_matrix(R_BP @ sol.perm)
    q_LPp = _jacobi_attitude(sol, t, w_Pp, am, sn, cn)
    # World-fixed L frame chosen so that ψ(0) = 0: q_WL = q_WP'(0) q_LP'(0)⁻¹.
    zero = np.zeros(1)
    q_LPp_0 = _jacobi_attitude(sol, zero, *_jacobi_rates_Pp(sol, zero))[0]
    q_WL = quat_mul(quat_mul(q0, q_BPp), quat_conj(q_LPp_0))
    q_WPp = quat_mul(q_WL, q_LPp)
    q_WB = quat_mul(q_WPp, quat_conj(q_BPp))
    w_W = rotate(q_WPp, w_Pp)
    return q_WB, w_W


def torque_free(inertia_B, q0_WB, w0_W, t_s):
    """Torque-free motion of a free rigid body: the closed form that applies.

    * isotropic inertia, or ω(0) along a principal axis (PRINCIPAL_AXIS_REL_TOL) → :func:`constant_spin`;
    * two principal moments equal (EQUAL_MOMENTS_REL_TOL) → :func:`axisymmetric_top`;
    * otherwise → :func:`torque_free_asymmetric`.

    Parameters and returns: those of :func:`axisymmetric_top`, with any body-frame inertia.
    """
    kind = _torque_free_kind(inertia_B, q0_WB, w0_W)
    if kind == "constant_spin":
        return constant_spin(q0_WB, w0_W, t_s)
    if kind == "axisymmetric_top":
        return axisymmetric_top(inertia_B, q0_WB, w0_W, t_s)
    return torque_free_asymmetric(inertia_B, q0_WB, w0_W, t_s)


def _torque_free_kind(inertia_B, q0_WB, w0_W) -> str:
    """Name of the closed form :func:`torque_free` uses for this body and initial state."""
    moments, R_BP = _principal(inertia_B)
    q0 = _quat("q0_WB", q0_WB)
    w0 = _vec3("w0_W", w0_W)
    tol = EQUAL_MOMENTS_REL_TOL * moments[2]
    if moments[2] - moments[0] <= tol:
        return "constant_spin"
    w_P = R_BP.T @ rotate(quat_conj(q0), w0)
    w_norm = float(np.linalg.norm(w_P))
    for i in range(3):
        perp = np.delete(w_P, i)
        if np.linalg.norm(perp) <= PRINCIPAL_AXIS_REL_TOL * w_norm:
            return "constant_spin"
    if moments[1] - moments[0] <= tol or moments[2] - moments[1] <= tol:
        return "axisymmetric_top"
    return "torque_free_asymmetric"


# --- discretisation error of the course scheme -------------------------------------------------------

def symplectic_euler_gravity_error(g_W, t_s, dt_s):
    """Position error (m) of symplectic Euler under uniform gravity, at times ``t = n Δt``.

    The course's ``v ← v + Δt g; x ← x + Δt v`` gives ``x_n = x0 + n Δt v0 + g Δt² n(n+1)/2``; the
    parabola is ``x0 + n Δt v0 + g (n Δt)²/2``, so ``x_n − x(t_n) = g Δt² n/2`` and
    ``|error| = ½ |g| t Δt`` exactly (no higher-order terms; derived from docs/course_equations.md).

    Parameters: ``g_W`` (3,) gravity, world, m/s²; ``t_s`` (T,) times (multiples of ``dt_s``), s; ``dt_s``
    the step, s. Returns ``error_m`` (T,), the norm of the position error, m.
    """
    g = _vec3("g_W", g_W)
    return 0.5 * float(np.linalg.norm(g)) * _times(t_s) * float(dt_s)


def course_spin_phase_lag(w_W, t_s, dt_s):
    """Leading-order orientation error (rad) of the course quaternion update at constant ω.

    ``q ← (q + [0, Δt/2 ω] q)/|…|`` multiplies q by ``(1, Δt ω/2)/sqrt(1 + (Δt|ω|/2)²)``, a rotation
    about ω by ``2 atan(Δt|ω|/2)`` instead of ``Δt|ω|``. The lag per step is
    ``Δt|ω| − 2 atan(Δt|ω|/2) = (Δt|ω|)³/12 + O((Δt|ω|)⁵)``, so after ``t = nΔt``::

        lag ≈ t |ω|³ Δt² / 12

    (relative error of this form: ``0.15 (Δt|ω|)²``; :func:`course_spin_phase_lag_exact` has none).

    Parameters: ``w_W`` (3,) angular velocity, rad/s (any frame: only |ω| matters); ``t_s`` (T,) times, s;
    ``dt_s`` the step, s. Returns ``lag_rad`` (T,), the geodesic angle between the course orientation and
    the exact constant spin, rad.
    """
    w = float(np.linalg.norm(_vec3("w_W", w_W)))
    return _times(t_s) * w ** 3 * float(dt_s) ** 2 / 12.0


def course_spin_phase_lag_exact(w_W, n_steps, dt_s):
    """Exact orientation lag (rad) of the course quaternion update after ``n_steps`` at constant ω.

    ``n (Δt|ω| − 2 atan(Δt|ω|/2))`` (see :func:`course_spin_phase_lag`); ``y − atan y`` with
    ``y = Δt|ω|/2`` is summed as its alternating series ``Σ (−1)^{j+1} y^{2j+1}/(2j+1)`` (j >= 1) for
    y < 0.25 so the result keeps full relative precision (the direct difference loses ~3 ε / y²).
    As a geodesic angle it is meaningful while below π.

    Parameters: ``w_W`` (3,) angular velocity, rad/s; ``n_steps`` int or (T,) ints, steps taken; ``dt_s``
    the step, s. Returns ``lag_rad``, float or (T,), rad.
    """
    y = 0.5 * float(dt_s) * float(np.linalg.norm(_vec3("w_W", w_W)))
    if y < 0.25:
        y2, term, acc = y * y, y, 0.0
        for j in range(1, 30):  # 0.25^61 / 61 ≈ 3e-39: truncation far below round-off
            term *= y2
            acc += (-1.0) ** (j + 1) * term / (2 * j + 1)
        per_step = 2.0 * acc
    else:
        per_step = 2.0 * (y - np.arctan(y))
    return np.asarray(n_steps, dtype=float) * per_step
