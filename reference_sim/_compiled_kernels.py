"""numba transcription of reference_sim.integrators for N members (imported by reference_sim.compiled only).

Each function is the definition's function of the same name, written on the floats of one member, with
the operations in the definition's order (``a + b + c`` is ``(a + b) + c`` in NumPy and here) and
``fastmath`` off (no reassociation, no fused multiply-add), so that a state it writes equals the
definition's (tests/reference_sim/test_compiled.py). ``P`` is the tuple of reference_sim.compiled.parameters:
(sc (N, 7) [h, m, c, γ_v, γ_ω, k_v, k_ω], I_B, I_B⁻¹ (N, 3, 3), m g_W, f_W at the COM, τ_W, τ_B (N, 3),
springs (N, S, 8)
[anchor_W, attach_B, k, L0], world point forces (N, P, 6) [f_W, r_B], body point forces (N, B, 6) [f_B, r_B],
the principal moments (N, 3) kg m² and axes (N, 3, 3) (columns, body axes) of I_B: ``np.linalg.eigh``).

``run`` steps the members of :func:`lane_members` (a course-type variant; no springs or point forces in the
batch, no drag on the member) LANES at a time (``_run_lanes``): each member's step is the same scalar
arithmetic, the loop over the members vectorised by LLVM (lanes are independent, so that changes no bit), its
terms without state dependence (``h (f / m)``) computed once per member with the definition's operations.
Every other member is stepped alone.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from reference_sim.compiled import cache_wanted
from reference_sim.quaternion import SINC_SERIES_BELOW_RAD

# fastmath stays off: no reassociation, no contraction into fused multiply-adds; numba's on-disk cache unless
# its folder proved unusable (reference_sim.compiled.load_compiled: then compiled in memory)
_JIT = dict(cache=cache_wanted(), nogil=True, error_model="numpy")
_INLINE = dict(_JIT, inline="always")   # the pieces of a step: inlined into it (no call per piece)


@njit(**_JIT)
def _rot(qw, qx, qy, qz):
    """reference_sim.quaternion.matrix_from_quat, row by row."""
    return (1.0 - 2.0 * (qy * qy + qz * qz), 2.0 * (qx * qy - qw * qz), 2.0 * (qx * qz + qw * qy),
            2.0 * (qx * qy + qw * qz), 1.0 - 2.0 * (qx * qx + qz * qz), 2.0 * (qy * qz - qw * qx),
            2.0 * (qx * qz - qw * qy), 2.0 * (qy * qz + qw * qx), 1.0 - 2.0 * (qx * qx + qy * qy))


@njit(**_JIT)
def _mv(R, a0, a1, a2):
    return (R[0] * a0 + R[1] * a1 + R[2] * a2, R[3] * a0 + R[4] * a1 + R[5] * a2,
            R[6] * a0 + R[7] * a1 + R[8] * a2)


@njit(**_JIT)
def _mtv(R, a0, a1, a2):
    return (R[0] * a0 + R[3] * a1 + R[6] * a2, R[1] * a0 + R[4] * a1 + R[7] * a2,
            R[2] * a0 + R[5] * a1 + R[8] * a2)


@njit(**_INLINE)
def _force_torque(i, y, R, P):
    """Members.force_torque of member i."""
    sc, mg, fW, tW, tB, springs, wp, bp = P[0], P[3], P[4], P[5], P[6], P[7], P[8], P[9]
    fx, fy, fz = mg[i, 0] + fW[i, 0], mg[i, 1] + fW[i, 1], mg[i, 2] + fW[i, 2]
    tx, ty, tz = tW[i, 0], tW[i, 1], tW[i, 2]
    c = sc[i, 2]
    if c != 0.0:
        fx, fy, fz = fx - c * y[3], fy - c * y[4], fz - c * y[5]
    for j in range(springs.shape[1]):
        s = springs[i, j]
        rx, ry, rz = _mv(R, s[3], s[4], s[5])
        dx, dy, dz = y[0] + rx - s[0], y[1] + ry - s[1], y[2] + rz - s[2]
        L = math.sqrt(dx * dx + dy * dy + dz * dz)
        k = -s[6] * (L - s[7]) / L if L > 0.0 else 0.0
        gx, gy, gz = k * dx, k * dy, k * dz
        fx, fy, fz = fx + gx, fy + gy, fz + gz
        tx, ty, tz = tx + (ry * gz - rz * gy), ty + (rz * gx - rx * gz), tz + (rx * gy - ry * gx)
    for j in range(wp.shape[1]):
        p = wp[i, j]
        gx, gy, gz = p[0], p[1], p[2]
        rx, ry, rz = _mv(R, p[3], p[4], p[5])
        fx, fy, fz = fx + gx, fy + gy, fz + gz
        tx, ty, tz = tx + (ry * gz - rz * gy), ty + (rz * gx - rx * gz), tz + (rx * gy - ry * gx)
    for j in range(bp.shape[1]):
        p = bp[i, j]
        gx, gy, gz = _mv(R, p[0], p[1], p[2])
        rx, ry, rz = _mv(R, p[3], p[4], p[5])
        fx, fy, fz = fx + gx, fy + gy, fz + gz
        tx, ty, tz = tx + (ry * gz - rz * gy), ty + (rz * gx - rx * gz), tz + (rx * gy - ry * gx)
    if tB[i, 0] != 0.0 or tB[i, 1] != 0.0 or tB[i, 2] != 0.0:
        bx, by, bz = _mv(R, tB[i, 0], tB[i, 1], tB[i, 2])
        tx, ty, tz = tx + bx, ty + by, tz + bz
    return fx, fy, fz, tx, ty, tz


@njit(**_INLINE)
def _angular_acceleration(i, R, wx, wy, wz, tx, ty, tz, gyro, P):
    """Members.angular_acceleration of member i."""
    I, J = P[1][i], P[2][i]
    bx, by, bz = _mtv(R, tx, ty, tz)
    if gyro:
        ox, oy, oz = _mtv(R, wx, wy, wz)
        lx = I[0, 0] * ox + I[0, 1] * oy + I[0, 2] * oz
        ly = I[1, 0] * ox + I[1, 1] * oy + I[1, 2] * oz
        lz = I[2, 0] * ox + I[2, 1] * oy + I[2, 2] * oz
        bx, by, bz = bx - (oy * lz - oz * ly), by - (oz * lx - ox * lz), bz - (ox * ly - oy * lx)
    ax = J[0, 0] * bx + J[0, 1] * by + J[0, 2] * bz
    ay = J[1, 0] * bx + J[1, 1] * by + J[1, 2] * bz
    az = J[2, 0] * bx + J[2, 1] * by + J[2, 2] * bz
    return _mv(R, ax, ay, az)


@njit(**_JIT)
def _omega_times(wx, wy, wz, qw, qx, qy, qz):
    """[0, ω] ⊗ q (integrators.omega_times)."""
    return (-(wx * qx + wy * qy + wz * qz), wx * qw + wy * qz - wz * qy, wy * qw + wz * qx - wx * qz,
            wz * qw + wx * qy - wy * qx)


@njit(**_INLINE)
def _half_angle_sinc(th, sin_half):
    """sin(θ/2)/θ (quaternion.half_angle_sinc, its numba twin: equal to the last bit, tests/reference_sim),
    given ``sin_half`` = sin(θ/2) (the lanes make their libm calls in a loop of their own)."""
    if th < SINC_SERIES_BELOW_RAD:
        t2 = th * th
        return 0.5 - t2 / 48.0 + t2 * t2 / 3840.0
    return sin_half / th


@njit(**_JIT)
def _exp_map_times(h, wx, wy, wz, qw, qx, qy, qz):
    """exp(h ω) ⊗ q (integrators.exp_map_times)."""
    th = h * math.sqrt(wx * wx + wy * wy + wz * wz)
    s = h * _half_angle_sinc(th, math.sin(0.5 * th))
    ew, ex, ey, ez = math.cos(0.5 * th), s * wx, s * wy, s * wz
    return (ew * qw - ex * qx - ey * qy - ez * qz, ew * qx + ex * qw + ey * qz - ez * qy,
            ew * qy + ey * qw + ez * qx - ex * qz, ew * qz + ez * qw + ex * qy - ey * qx)


@njit(**_JIT)
def _normalize(y):
    n = math.sqrt(y[6] * y[6] + y[7] * y[7] + y[8] * y[8] + y[9] * y[9])
    y[6], y[7], y[8], y[9] = y[6] / n, y[7] / n, y[8] / n, y[9] / n


@njit(**_INLINE)
def _symplectic_end(y, h, vx, vy, vz, nw, nx, ny, nz, wx, wy, wz, out):
    """The end of a symplectic Euler step: x + h v⁺, v⁺, the new attitude normalised, ω⁺."""
    out[0], out[1], out[2] = y[0] + h * vx, y[1] + h * vy, y[2] + h * vz
    out[3], out[4], out[5] = vx, vy, vz
    out[6], out[7], out[8], out[9] = nw, nx, ny, nz
    _normalize(out)
    out[10], out[11], out[12] = wx, wy, wz


@njit(**_INLINE)
def _rhs(i, y, out, P):
    """integrators.rhs of member i."""
    sc = P[0]
    qw, qx, qy, qz = y[6], y[7], y[8], y[9]
    n = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
    R = _rot(qw / n, qx / n, qy / n, qz / n)
    fx, fy, fz, tx, ty, tz = _force_torque(i, y, R, P)
    m = sc[i, 1]
    dvx, dvy, dvz = fx / m, fy / m, fz / m
    ax, ay, az = _angular_acceleration(i, R, y[10], y[11], y[12], tx, ty, tz, True, P)
    kv, kw = sc[i, 5], sc[i, 6]
    if kv != 0.0 or kw != 0.0:
        dvx, dvy, dvz = dvx - kv * y[3], dvy - kv * y[4], dvz - kv * y[5]
        ax, ay, az = ax - kw * y[10], ay - kw * y[11], az - kw * y[12]
    dw, dx, dy, dz = _omega_times(y[10], y[11], y[12], qw, qx, qy, qz)
    out[0], out[1], out[2], out[3], out[4], out[5] = y[3], y[4], y[5], dvx, dvy, dvz
    out[6], out[7], out[8], out[9] = 0.5 * dw, 0.5 * dx, 0.5 * dy, 0.5 * dz
    out[10], out[11], out[12] = ax, ay, az


@njit(**_INLINE)
def _start_symplectic(i, y, P):
    """The start of member i's symplectic steps (integrators.course_type, _engine_gyro_step): R(q_WB), the
    world torque (N m) and the new velocity v' = gv (v + h f/m) (m/s, world)."""
    sc = P[0]
    h, m, gv = sc[i, 0], sc[i, 1], sc[i, 3]
    R = _rot(y[6], y[7], y[8], y[9])
    fx, fy, fz, tx, ty, tz = _force_torque(i, y, R, P)
    return R, tx, ty, tz, gv * (y[3] + h * (fx / m)), gv * (y[4] + h * (fy / m)), gv * (y[5] + h * (fz / m))


@njit(**_INLINE)
def _course_type(i, y, out, gyro, expmap, P):
    """integrators.course_type of member i."""
    h, gw = P[0][i, 0], P[0][i, 4]
    qw, qx, qy, qz = y[6], y[7], y[8], y[9]
    R, tx, ty, tz, vx, vy, vz = _start_symplectic(i, y, P)
    ax, ay, az = _angular_acceleration(i, R, y[10], y[11], y[12], tx, ty, tz, gyro, P)
    wx, wy, wz = gw * (y[10] + h * ax), gw * (y[11] + h * ay), gw * (y[12] + h * az)
    if expmap:
        nw, nx, ny, nz = _exp_map_times(h, wx, wy, wz, qw, qx, qy, qz)
    else:
        half = 0.5 * h
        dw, dx, dy, dz = _omega_times(half * wx, half * wy, half * wz, qw, qx, qy, qz)
        nw, nx, ny, nz = qw + dw, qx + dx, qy + dy, qz + dz
    _symplectic_end(y, h, vx, vy, vz, nw, nx, ny, nz, wx, wy, wz, out)


@njit(**_JIT)
def _axpy(y, a, k, out):
    for j in range(13):
        out[j] = y[j] + a * k[j]


@njit(**_INLINE)
def _rk(i, y, out, order, k1, k2, k3, k4, tmp, P):
    """integrators.step_explicit_euler (order 1), step_midpoint (2), step_rk4 (4) of member i."""
    h = P[0][i, 0]
    _rhs(i, y, k1, P)
    if order == 1:
        _axpy(y, h, k1, out)
    elif order == 2:
        _axpy(y, 0.5 * h, k1, tmp)
        _rhs(i, tmp, k2, P)
        _axpy(y, h, k2, out)
    else:
        _axpy(y, 0.5 * h, k1, tmp)
        _rhs(i, tmp, k2, P)
        _axpy(y, 0.5 * h, k2, tmp)
        _rhs(i, tmp, k3, P)
        _axpy(y, h, k3, tmp)
        _rhs(i, tmp, k4, P)
        h6 = h / 6.0
        for j in range(13):
            out[j] = y[j] + h6 * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j])
    _normalize(out)


@njit(**_JIT)
def _change(new, old, lo, hi):
    """max over j in [lo, hi) of |new − old| / (1 + |new|) (integrators._change)."""
    worst = 0.0
    for j in range(lo, hi):
        e = abs(new[j] - old[j]) / (1.0 + abs(new[j]))
        if not e <= worst:
            worst = e
            if e != e:   # a NaN wins, as in np.max
                return e
    return worst


@njit(**_INLINE)
def _leapfrog(i, y, out, d, u, u_new, tol, max_iter, P):
    """integrators.step_leapfrog of member i; False when the half kick does not converge (not routine)."""
    h = P[0][i, 0]
    half = 0.5 * h
    _rhs(i, y, d, P)
    for j in range(3):
        u[j], u[3 + j] = y[3 + j] + half * d[3 + j], y[10 + j] + half * d[10 + j]
    for j in range(13):
        out[j] = y[j]
    converged = False
    for _ in range(max_iter):
        for j in range(3):
            out[3 + j], out[10 + j] = u[j], u[3 + j]
        _rhs(i, out, d, P)
        for j in range(3):
            u_new[j], u_new[3 + j] = y[3 + j] + half * d[3 + j], y[10 + j] + half * d[10 + j]
        worst = _change(u_new, u, 0, 6)
        for j in range(6):
            u[j] = u_new[j]
        if worst <= tol:
            converged = True
            break
    if not converged:
        return False
    for j in range(3):
        out[3 + j], out[10 + j] = u[j], u[3 + j]
        out[j] = y[j] + h * u[j]
    nw, nx, ny, nz = _exp_map_times(h, u[3], u[4], u[5], y[6], y[7], y[8], y[9])
    out[6], out[7], out[8], out[9] = nw, nx, ny, nz
    _normalize(out)
    _rhs(i, out, d, P)
    for j in range(3):
        out[3 + j], out[10 + j] = u[j] + half * d[3 + j], u[3 + j] + half * d[10 + j]
    return True


@njit(**_INLINE)
def _implicit_euler(i, y, out, d, z, tol, max_iter, P):
    """integrators.step_implicit_euler's fixed point for member i; False when it stops contracting or runs
    out of iterations (not routine: the definition then solves the step with Newton's method)."""
    h = P[0][i, 0]
    _rhs(i, y, d, P)
    _axpy(y, h, d, z)
    prev = np.inf
    for _ in range(max_iter):
        _rhs(i, z, d, P)
        _axpy(y, h, d, out)
        worst = _change(out, z, 0, 13)
        for j in range(13):
            z[j] = out[j]
        if worst <= tol:
            _normalize(out)
            return True
        if not worst < 0.9 * prev:
            return False
        prev = worst
    return False


# --- the gyroscopic variants (integrators: the engines' steps and the Strang steps) ------------------------
# 3x3 matrices are row-major 9-tuples; every formula is the definition's helper of the same name.

@njit(**_JIT)
def _m9(M):
    """A (3, 3) array as a row-major 9-tuple."""
    return (M[0, 0], M[0, 1], M[0, 2], M[1, 0], M[1, 1], M[1, 2], M[2, 0], M[2, 1], M[2, 2])


@njit(**_JIT)
def _tr(A):
    return (A[0], A[3], A[6], A[1], A[4], A[7], A[2], A[5], A[8])


@njit(**_JIT)
def _mm(A, B):
    """integrators._matmul3."""
    return (A[0] * B[0] + A[1] * B[3] + A[2] * B[6], A[0] * B[1] + A[1] * B[4] + A[2] * B[7],
            A[0] * B[2] + A[1] * B[5] + A[2] * B[8],
            A[3] * B[0] + A[4] * B[3] + A[5] * B[6], A[3] * B[1] + A[4] * B[4] + A[5] * B[7],
            A[3] * B[2] + A[4] * B[5] + A[5] * B[8],
            A[6] * B[0] + A[7] * B[3] + A[8] * B[6], A[6] * B[1] + A[7] * B[4] + A[8] * B[7],
            A[6] * B[2] + A[7] * B[5] + A[8] * B[8])


@njit(**_JIT)
def _cross(a0, a1, a2, b0, b1, b2):
    """reference_sim.vec.cross3."""
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


@njit(**_JIT)
def _dot(a0, a1, a2, b0, b1, b2):
    """integrators._dot3."""
    return a0 * b0 + a1 * b1 + a2 * b2


@njit(**_JIT)
def _skew(a0, a1, a2):
    """integrators._skew."""
    z = 0.0 * a0
    return (z, -a2, a1, a2, z, -a0, -a1, a0, z)


@njit(**_JIT)
def _skew_times(a0, a1, a2, M):
    """integrators._skew_times: column j is a × M[:, j]."""
    c00, c01, c02 = _cross(a0, a1, a2, M[0], M[3], M[6])
    c10, c11, c12 = _cross(a0, a1, a2, M[1], M[4], M[7])
    c20, c21, c22 = _cross(a0, a1, a2, M[2], M[5], M[8])
    return (c00, c10, c20, c01, c11, c21, c02, c12, c22)


@njit(**_JIT)
def _solve3(M, b0, b1, b2):
    """integrators._solve3 (Cramer's rule; NaN when det M = 0)."""
    r00, r01, r02 = _cross(M[1], M[4], M[7], M[2], M[5], M[8])
    r10, r11, r12 = _cross(M[2], M[5], M[8], M[0], M[3], M[6])
    r20, r21, r22 = _cross(M[0], M[3], M[6], M[1], M[4], M[7])
    det = _dot(M[0], M[3], M[6], r00, r01, r02)
    if not det != 0.0:
        return np.nan, np.nan, np.nan
    return (_dot(r00, r01, r02, b0, b1, b2) / det, _dot(r10, r11, r12, b0, b1, b2) / det,
            _dot(r20, r21, r22, b0, b1, b2) / det)


@njit(**_JIT)
def _world_inertia(R, I9):
    """integrators._world_inertia: (R I_B) Rᵀ."""
    return _mm(_mm(R, I9), _tr(R))


@njit(**_JIT)
def _world_inv_inertia_times(R, J9, a0, a1, a2):
    """integrators._world_inv_inertia_times: R I_B⁻¹ Rᵀ a."""
    b0, b1, b2 = _mtv(R, a0, a1, a2)
    c0, c1, c2 = _mv(J9, b0, b1, b2)
    return _mv(R, c0, c1, c2)


@njit(**_INLINE)
def _gyro_newton_step(M, w0, w1, w2, h):
    """The one Newton step of the implicit gyroscopic update in the axes of the inertia ``M`` (9,):
    (M + h([ω]× M − [M ω]×))⁻¹ h ω × M ω, which the update subtracts from ω."""
    l0, l1, l2 = _mv(M, w0, w1, w2)
    A, S = _skew_times(w0, w1, w2, M), _skew(l0, l1, l2)
    J = (M[0] + h * (A[0] - S[0]), M[1] + h * (A[1] - S[1]), M[2] + h * (A[2] - S[2]),
         M[3] + h * (A[3] - S[3]), M[4] + h * (A[4] - S[4]), M[5] + h * (A[5] - S[5]),
         M[6] + h * (A[6] - S[6]), M[7] + h * (A[7] - S[7]), M[8] + h * (A[8] - S[8]))
    c0, c1, c2 = _cross(w0, w1, w2, l0, l1, l2)
    return _solve3(J, h * c0, h * c1, h * c2)


@njit(**_JIT)
def _gyro_update(kind, R, wx, wy, wz, h, I9, J9, max_torque):
    """The engines' gyroscopic updates G(ω) of integrators: 0 _gyro_implicit_body, 1 _gyro_implicit_world,
    2 _gyro_explicit_clamped (``max_torque``: BULLET_MAX_GYROSCOPIC_TORQUE), 3 _gyro_momentum_clamped."""
    if kind == 0:
        b0, b1, b2 = _mtv(R, wx, wy, wz)
        s0, s1, s2 = _gyro_newton_step(I9, b0, b1, b2, h)
        return _mv(R, b0 - s0, b1 - s1, b2 - s2)
    if kind == 1:
        s0, s1, s2 = _gyro_newton_step(_world_inertia(R, I9), wx, wy, wz, h)
        return wx - s0, wy - s1, wz - s2
    if kind == 2:
        l0, l1, l2 = _mv(_world_inertia(R, I9), wx, wy, wz)
        g0, g1, g2 = _cross(wx, wy, wz, l0, l1, l2)
        n2 = _dot(g0, g1, g2, g0, g1, g2)
        if n2 > max_torque * max_torque:
            f = 1.0 / math.sqrt(n2) * max_torque
            g0, g1, g2 = g0 * f, g1 * f, g2 * f
        a0, a1, a2 = _world_inv_inertia_times(R, J9, g0, g1, g2)
        return wx - h * a0, wy - h * a1, wz - h * a2
    b0, b1, b2 = _mtv(R, wx, wy, wz)
    l0, l1, l2 = _mv(I9, b0, b1, b2)
    c0, c1, c2 = _cross(b0, b1, b2, l0, l1, l2)
    n0, n1, n2 = l0 - h * c0, l1 - h * c1, l2 - h * c2
    nn = _dot(n0, n1, n2, n0, n1, n2)
    if nn > 0.0:
        f = math.sqrt(_dot(l0, l1, l2, l0, l1, l2) / nn)
        n0, n1, n2 = n0 * f, n1 * f, n2 * f
    else:
        n0, n1, n2 = 0.0, 0.0, 0.0
    a0, a1, a2 = _mv(J9, n0, n1, n2)
    return _mv(R, a0, a1, a2)


# The two steps below are called from run, not inlined into it: inlined, they lengthen run's compilation and
# make the sweep no faster.
@njit(**_JIT)
def _engine_gyro_step(i, y, out, kind, max_torque, P):
    """integrators._engine_gyro_step of member i with the gyroscopic update ``kind``
    (:func:`_gyro_update`)."""
    h, gw = P[0][i, 0], P[0][i, 4]
    qw, qx, qy, qz = y[6], y[7], y[8], y[9]
    R, tx, ty, tz, vx, vy, vz = _start_symplectic(i, y, P)
    G0, G1, G2 = _gyro_update(kind, R, y[10], y[11], y[12], h, _m9(P[1][i]), _m9(P[2][i]), max_torque)
    ax, ay, az = _angular_acceleration(i, R, y[10], y[11], y[12], tx, ty, tz, False, P)
    wx, wy, wz = gw * (G0 + h * ax), gw * (G1 + h * ay), gw * (G2 + h * az)
    nw, nx, ny, nz = _exp_map_times(h, wx, wy, wz, qw, qx, qy, qz)
    _symplectic_end(y, h, vx, vy, vz, nw, nx, ny, nz, wx, wy, wz, out)


@njit(**_JIT)
def _unit(qw, qx, qy, qz):
    """q / |q| (integrators._norm: summed left to right)."""
    n = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
    return qw / n, qx / n, qy / n, qz / n


@njit(**_JIT)
def _one_plus_times(ax, ay, az, qw, qx, qy, qz):
    """[1, a] ⊗ q (integrators._times with aw = 1.0)."""
    return (1.0 * qw - ax * qx - ay * qy - az * qz, 1.0 * qx + ax * qw + ay * qz - az * qy,
            1.0 * qy + ay * qw + az * qx - ax * qz, 1.0 * qz + az * qw + ax * qy - ay * qx)


@njit(**_JIT)
def _omega_of_momentum(R1, I9, J9, L0, L1, L2, wx, wy, wz):
    """integrators._omega_of_momentum: w + I_W(R₁)⁻¹ (L − I_W(R₁) w)."""
    l0, l1, l2 = _mv(_world_inertia(R1, I9), wx, wy, wz)
    a0, a1, a2 = _world_inv_inertia_times(R1, J9, L0 - l0, L1 - l1, L2 - l2)
    return wx + a0, wy + a1, wz + a2


@njit(**_JIT)
def _change3(n0, n1, n2, o0, o1, o2):
    """integrators._change of 3-vectors: the largest |new − old| / (1 + |new|), NaN if any is NaN."""
    e0 = abs(n0 - o0) / (1.0 + abs(n0))
    e1 = abs(n1 - o1) / (1.0 + abs(n1))
    e2 = abs(n2 - o2) / (1.0 + abs(n2))
    if e0 != e0 or e1 != e1 or e2 != e2:
        return np.nan
    return max(e0, e1, e2)


@njit(**_JIT)
def _free_explicit(kind, q, R, w, h, I9, J9, moments, axes):
    """_free_buss (kind 0) or _free_dlm (kind 1: ``moments``, ``axes``, eigh of I_B) of integrators, from
    attitude ``q`` (its rotation ``R``) and world ω ``w`` (rad/s) over ``h`` (s): (q₁ (4), world ω₁ (3))."""
    qw, qx, qy, qz = q
    wx, wy, wz = w
    L0, L1, L2 = _mv(_world_inertia(R, I9), wx, wy, wz)
    if kind == 0:
        c0, c1, c2 = _cross(wx, wy, wz, L0, L1, L2)
        a0, a1, a2 = _world_inv_inertia_times(R, J9, c0, c1, c2)
        a0, a1, a2 = -a0, -a1, -a2
        hh, h12 = 0.5 * h, h * h / 12.0
        d0, d1, d2 = _cross(a0, a1, a2, wx, wy, wz)
        b0, b1, b2 = wx + hh * a0 + h12 * d0, wy + hh * a1 + h12 * d1, wz + hh * a2 + h12 * d2
        nw, nx, ny, nz = _unit(*_exp_map_times(h, b0, b1, b2, qw, qx, qy, qz))
    else:
        nw, nx, ny, nz = qw, qx, qy, qz
        for j in range(5):
            k = (0, 1, 2, 1, 0)[j]
            frac = (0.5, 0.5, 1.0, 0.5, 0.5)[j]
            a0, a1, a2 = _mv(_rot(nw, nx, ny, nz), axes[0, k], axes[1, k], axes[2, k])
            phi = (frac * h) * _dot(a0, a1, a2, L0, L1, L2) / moments[k]
            nw, nx, ny, nz = _exp_map_times(1.0, phi * a0, phi * a1, phi * a2, nw, nx, ny, nz)
        nw, nx, ny, nz = _unit(nw, nx, ny, nz)
    o0, o1, o2 = _omega_of_momentum(_rot(nw, nx, ny, nz), I9, J9, L0, L1, L2, wx, wy, wz)
    return (nw, nx, ny, nz), (o0, o1, o2)


@njit(**_JIT)
def _newton_system(kind, x0, x1, x2, P0, P1, P2, h, I9, J9):
    """The Jacobian (9, row-major) and residual (3) at iterate ``x`` of the Newton solve of _free_midpoint
    (kind 2: G(Π_m) = Π_m − Π − h/2 Π_m × I⁻¹Π_m) or of _free_moser_veselov (kind 3), ``P`` = Π (body)."""
    hh = 0.5 * h
    if kind == 2:
        m0, m1, m2 = _mv(J9, x0, x1, x2)
        c0, c1, c2 = _cross(x0, x1, x2, m0, m1, m2)
        r0, r1, r2 = x0 - P0 - hh * c0, x1 - P1 - hh * c1, x2 - P2 - hh * c2
        A, S = _skew_times(x0, x1, x2, J9), _skew(m0, m1, m2)
        J = (1.0 - hh * (A[0] - S[0]), 0.0 - hh * (A[1] - S[1]), 0.0 - hh * (A[2] - S[2]),
             0.0 - hh * (A[3] - S[3]), 1.0 - hh * (A[4] - S[4]), 0.0 - hh * (A[5] - S[5]),
             0.0 - hh * (A[6] - S[6]), 0.0 - hh * (A[7] - S[7]), 1.0 - hh * (A[8] - S[8]))
        return J, (r0, r1, r2)
    n = 1.0 + _dot(x0, x1, x2, x0, x1, x2)
    f0, f1, f2 = _mv(I9, x0, x1, x2)
    c0, c1, c2 = _cross(x0, x1, x2, f0, f1, f2)
    u0, u1, u2 = f0 + c0, f1 + c1, f2 + c2
    c = 2.0 / n
    e = 4.0 / (n * n)
    A, S = _skew_times(x0, x1, x2, I9), _skew(f0, f1, f2)
    J = (c * (I9[0] + A[0] - S[0]) - e * (u0 * x0), c * (I9[1] + A[1] - S[1]) - e * (u0 * x1),
         c * (I9[2] + A[2] - S[2]) - e * (u0 * x2), c * (I9[3] + A[3] - S[3]) - e * (u1 * x0),
         c * (I9[4] + A[4] - S[4]) - e * (u1 * x1), c * (I9[5] + A[5] - S[5]) - e * (u1 * x2),
         c * (I9[6] + A[6] - S[6]) - e * (u2 * x0), c * (I9[7] + A[7] - S[7]) - e * (u2 * x1),
         c * (I9[8] + A[8] - S[8]) - e * (u2 * x2))
    return J, (c * u0 - h * P0, c * u1 - h * P1, c * u2 - h * P2)


@njit(**_JIT)
def _free_map(kind, q, R, w, h, I9, J9, moments, axes, tol, max_iter):
    """The free rigid-body maps of integrators, from attitude ``q`` (its rotation ``R``) and world ω ``w``
    (rad/s) over ``h`` (s): 0 _free_buss, 1 _free_dlm (``moments``, ``axes``: eigh of I_B), 2 _free_midpoint,
    3 _free_moser_veselov. Returns (routine, q₁ (4), world ω₁ (3) rad/s); not routine when the Newton
    iteration of 2 or 3 meets a non-finite update or does not reach ``tol`` in ``max_iter`` (the definition
    then takes the step)."""
    if kind <= 1:
        q1, w1 = _free_explicit(kind, q, R, w, h, I9, J9, moments, axes)
        return True, q1, w1
    qw, qx, qy, qz = q
    wx, wy, wz = w
    b0, b1, b2 = _mtv(R, wx, wy, wz)
    P0, P1, P2 = _mv(I9, b0, b1, b2)
    hh = 0.5 * h
    if kind == 2:
        x0, x1, x2 = P0, P1, P2
    else:
        x0, x1, x2 = hh * b0, hh * b1, hh * b2
    converged = False
    for _ in range(max_iter):
        J, (r0, r1, r2) = _newton_system(kind, x0, x1, x2, P0, P1, P2, h, I9, J9)
        s0, s1, s2 = _solve3(J, r0, r1, r2)
        y0, y1, y2 = x0 - s0, x1 - s1, x2 - s2
        d = _change3(y0, y1, y2, x0, x1, x2)
        x0, x1, x2 = y0, y1, y2
        if d <= tol:
            converged = True
            break
        if not abs(d) < np.inf:   # a non-finite row: the definition gives its non-finite state
            break
    if not converged:
        return False, (qw, qx, qy, qz), (wx, wy, wz)
    if kind == 2:
        m0, m1, m2 = _mv(J9, x0, x1, x2)
        a0, a1, a2 = _mv(R, m0, m1, m2)
        a0, a1, a2 = hh * a0, hh * a1, hh * a2
    else:
        a0, a1, a2 = _mv(R, x0, x1, x2)
    nw, nx, ny, nz = _unit(*_one_plus_times(a0, a1, a2, qw, qx, qy, qz))
    R1 = _rot(nw, nx, ny, nz)
    if kind == 2:
        L0, L1, L2 = _mv(R1, 2.0 * x0 - P0, 2.0 * x1 - P1, 2.0 * x2 - P2)
    else:
        L0, L1, L2 = _mv(R, P0, P1, P2)
    o0, o1, o2 = _omega_of_momentum(R1, I9, J9, L0, L1, L2, wx, wy, wz)
    return True, (nw, nx, ny, nz), (o0, o1, o2)


@njit(**_JIT)
def _strang(i, y, out, kind, tmp, tol, max_iter, P):
    """integrators._strang of member i around the free map ``kind`` (:func:`_free_map`); False when that map's
    step is not routine."""
    sc = P[0]
    h, m = sc[i, 0], sc[i, 1]
    s = 0.5 * h
    lam_v = sc[i, 2] / m + sc[i, 5]
    k_w = sc[i, 6]
    R = _rot(y[6], y[7], y[8], y[9])
    for j in range(13):
        tmp[j] = y[j]
    tmp[3], tmp[4], tmp[5] = 0.0 * y[3], 0.0 * y[4], 0.0 * y[5]
    fx, fy, fz, tx, ty, tz = _force_torque(i, tmp, R, P)
    d = 1.0 + s * lam_v
    vx, vy, vz = (y[3] + s * (fx / m)) / d, (y[4] + s * (fy / m)) / d, (y[5] + s * (fz / m)) / d
    ax, ay, az = _angular_acceleration(i, R, y[10], y[11], y[12], tx, ty, tz, False, P)
    d = 1.0 + s * k_w
    wx, wy, wz = (y[10] + s * ax) / d, (y[11] + s * ay) / d, (y[12] + s * az) / d
    x0, x1, x2 = y[0] + h * vx, y[1] + h * vy, y[2] + h * vz
    ok, q1, w1 = _free_map(kind, (y[6], y[7], y[8], y[9]), R, (wx, wy, wz), h, _m9(P[1][i]), _m9(P[2][i]),
                           P[10][i], P[11][i], tol, max_iter)
    if not ok:
        return False
    R1 = _rot(q1[0], q1[1], q1[2], q1[3])
    tmp[0], tmp[1], tmp[2] = x0, x1, x2
    tmp[3], tmp[4], tmp[5] = 0.0 * vx, 0.0 * vy, 0.0 * vz
    fx, fy, fz, tx, ty, tz = _force_torque(i, tmp, R1, P)
    out[0], out[1], out[2] = x0, x1, x2
    out[3], out[4], out[5] = (vx + s * (fx / m - lam_v * vx), vy + s * (fy / m - lam_v * vy),
                              vz + s * (fz / m - lam_v * vz))
    out[6], out[7], out[8], out[9] = q1
    ax, ay, az = _angular_acceleration(i, R1, w1[0], w1[1], w1[2], tx, ty, tz, False, P)
    out[10], out[11], out[12] = (w1[0] + s * (ax - k_w * w1[0]), w1[1] + s * (ay - k_w * w1[1]),
                                 w1[2] + s * (az - k_w * w1[2]))
    return True


# --- the course-type steps of members whose forces do not depend on the state, LANES members at a time -----
# A lane holds one member: its state in column k of S (13 rows of LANES), its constants in column k of Pm
# (_LANE_PARAMS rows of LANES). One call of a lane step advances every lane in use by one step, each lane with
# the scalar arithmetic of _course_type in its order; the lanes are independent, so LLVM vectorises the loop
# over them (LLVM leaves a loop of fewer than 16 iterations that needs alias checks scalar: hence 16 lanes).
# Pm rows: 0 h, 1 γ_v, 2 γ_ω, 3–5 h (f / m) with f = m g + f_W, 6–8 τ_W, 9–11 τ_B, 12 τ_B ≠ 0 (1.0 or 0.0),
# 13–21 I_B⁻¹, 22–30 I_B (row-major).
LANES = 16
_LANE_PARAMS = 31


@njit(**_INLINE)
def _course_lanes(nl, S, Pm, T, OK, limit, gyro, expmap):
    """_course_type of the first ``nl`` lanes, in place; ``OK[k]``: lane k's new state is within ``limit``
    (finite). ``T``: scratch (4 LANES) for the exponential map's sine and cosine, taken by libm lane by
    lane."""
    K = LANES
    for k in range(nl):
        h, gv, gw = Pm[k], Pm[K + k], Pm[2 * K + k]
        qw, qx, qy, qz = S[6 * K + k], S[7 * K + k], S[8 * K + k], S[9 * K + k]
        w0, w1, w2 = S[10 * K + k], S[11 * K + k], S[12 * K + k]
        R0, R1, R2 = 1.0 - 2.0 * (qy * qy + qz * qz), 2.0 * (qx * qy - qw * qz), 2.0 * (qx * qz + qw * qy)
        R3, R4, R5 = 2.0 * (qx * qy + qw * qz), 1.0 - 2.0 * (qx * qx + qz * qz), 2.0 * (qy * qz - qw * qx)
        R6, R7, R8 = 2.0 * (qx * qz - qw * qy), 2.0 * (qy * qz + qw * qx), 1.0 - 2.0 * (qx * qx + qy * qy)
        tx, ty, tz = Pm[6 * K + k], Pm[7 * K + k], Pm[8 * K + k]
        bx, by, bz = Pm[9 * K + k], Pm[10 * K + k], Pm[11 * K + k]
        ux = tx + (R0 * bx + R1 * by + R2 * bz)
        uy = ty + (R3 * bx + R4 * by + R5 * bz)
        uz = tz + (R6 * bx + R7 * by + R8 * bz)
        if Pm[12 * K + k] != 0.0:   # _force_torque adds R τ_B only where τ_B is not zero
            tx, ty, tz = ux, uy, uz
        vx, vy, vz = gv * (S[3 * K + k] + Pm[3 * K + k]), gv * (S[4 * K + k] + Pm[4 * K + k]), \
            gv * (S[5 * K + k] + Pm[5 * K + k])
        cx, cy, cz = R0 * tx + R3 * ty + R6 * tz, R1 * tx + R4 * ty + R7 * tz, R2 * tx + R5 * ty + R8 * tz
        if gyro:
            ox, oy, oz = R0 * w0 + R3 * w1 + R6 * w2, R1 * w0 + R4 * w1 + R7 * w2, R2 * w0 + R5 * w1 + R8 * w2
            lx = Pm[22 * K + k] * ox + Pm[23 * K + k] * oy + Pm[24 * K + k] * oz
            ly = Pm[25 * K + k] * ox + Pm[26 * K + k] * oy + Pm[27 * K + k] * oz
            lz = Pm[28 * K + k] * ox + Pm[29 * K + k] * oy + Pm[30 * K + k] * oz
            cx, cy, cz = cx - (oy * lz - oz * ly), cy - (oz * lx - ox * lz), cz - (ox * ly - oy * lx)
        ax = Pm[13 * K + k] * cx + Pm[14 * K + k] * cy + Pm[15 * K + k] * cz
        ay = Pm[16 * K + k] * cx + Pm[17 * K + k] * cy + Pm[18 * K + k] * cz
        az = Pm[19 * K + k] * cx + Pm[20 * K + k] * cy + Pm[21 * K + k] * cz
        ex, ey, ez = R0 * ax + R1 * ay + R2 * az, R3 * ax + R4 * ay + R5 * az, R6 * ax + R7 * ay + R8 * az
        n0, n1, n2 = gw * (w0 + h * ex), gw * (w1 + h * ey), gw * (w2 + h * ez)
        S[k], S[K + k], S[2 * K + k] = S[k] + h * vx, S[K + k] + h * vy, S[2 * K + k] + h * vz
        S[3 * K + k], S[4 * K + k], S[5 * K + k] = vx, vy, vz
        S[10 * K + k], S[11 * K + k], S[12 * K + k] = n0, n1, n2
        if expmap:
            th = h * math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
            T[k], T[K + k] = 0.5 * th, th
        else:
            half = 0.5 * h
            a0, a1, a2 = half * n0, half * n1, half * n2
            pw, px = qw + -(a0 * qx + a1 * qy + a2 * qz), qx + (a0 * qw + a1 * qz - a2 * qy)
            py, pz = qy + (a1 * qw + a2 * qx - a0 * qz), qz + (a2 * qw + a0 * qy - a1 * qx)
            nn = math.sqrt(pw * pw + px * px + py * py + pz * pz)
            S[6 * K + k], S[7 * K + k], S[8 * K + k], S[9 * K + k] = pw / nn, px / nn, py / nn, pz / nn
    if expmap:   # _exp_map_times: the libm calls in a loop of their own, the rest vectorised around them
        for k in range(nl):
            T[2 * K + k], T[3 * K + k] = math.sin(T[k]), math.cos(T[k])
        for k in range(nl):
            h, th = Pm[k], T[K + k]
            qw, qx, qy, qz = S[6 * K + k], S[7 * K + k], S[8 * K + k], S[9 * K + k]
            s = h * _half_angle_sinc(th, T[2 * K + k])
            ew, ex, ey, ez = T[3 * K + k], s * S[10 * K + k], s * S[11 * K + k], s * S[12 * K + k]
            pw, px = ew * qw - ex * qx - ey * qy - ez * qz, ew * qx + ex * qw + ey * qz - ez * qy
            py, pz = ew * qy + ey * qw + ez * qx - ex * qz, ew * qz + ez * qw + ex * qy - ey * qx
            nn = math.sqrt(pw * pw + px * px + py * py + pz * pz)
            S[6 * K + k], S[7 * K + k], S[8 * K + k], S[9 * K + k] = pw / nn, px / nn, py / nn, pz / nn
    for k in range(nl):
        ok = True
        for j in range(13):
            ok = ok & (abs(S[j * K + k]) <= limit)   # NaN compares false: simulate.bad_rows
        OK[k] = ok


@njit(**_JIT)
def _course_lanes_0(nl, S, Pm, T, OK, limit):
    _course_lanes(nl, S, Pm, T, OK, limit, False, False)


@njit(**_JIT)
def _course_lanes_1(nl, S, Pm, T, OK, limit):
    _course_lanes(nl, S, Pm, T, OK, limit, True, False)


@njit(**_JIT)
def _course_lanes_2(nl, S, Pm, T, OK, limit):
    _course_lanes(nl, S, Pm, T, OK, limit, True, True)


@njit(**_JIT)
def _lane_load(S, Pm, k, i, y, sc, I, J, mg, fW, tW, tB):
    """Lane k: member i at state ``y``, with its constants as _course_type computes them."""
    K = LANES
    for j in range(13):
        S[j * K + k] = y[j]
    h, m = sc[i, 0], sc[i, 1]
    Pm[k], Pm[K + k], Pm[2 * K + k] = h, sc[i, 3], sc[i, 4]
    for j in range(3):
        Pm[(3 + j) * K + k] = h * ((mg[i, j] + fW[i, j]) / m)
        Pm[(6 + j) * K + k], Pm[(9 + j) * K + k] = tW[i, j], tB[i, j]
    Pm[12 * K + k] = 1.0 if tB[i, 0] != 0.0 or tB[i, 1] != 0.0 or tB[i, 2] != 0.0 else 0.0
    for a in range(3):
        for b in range(3):
            Pm[(13 + 3 * a + b) * K + k], Pm[(22 + 3 * a + b) * K + k] = J[i, a, b], I[i, a, b]


@njit(**_JIT)
def _lane_move(S, Pm, src, dst):
    """Lane ``src``'s state and constants into lane ``dst``."""
    K = LANES
    for j in range(13):
        S[j * K + dst] = S[j * K + src]
    for j in range(_LANE_PARAMS):
        Pm[j * K + dst] = Pm[j * K + src]


@njit(**_JIT)
def _run_lanes(code, rows, offsets, pos, stop, limit, order, sc, I, J, mg, fW, tW, tB):
    """``run`` for the members ``order`` (longest run first) of a course-type variant (code 0, 1, 2) whose
    forces do not depend on the state (no drag, springs or point forces): LANES members at a time, a lane
    taking the next member when its member reaches ``stop`` or meets a step that is not routine."""
    K = LANES
    S, Pm, T = np.zeros(13 * K), np.zeros(_LANE_PARAMS * K), np.zeros(4 * K)
    OK = np.zeros(K, dtype=np.bool_)
    member, n_at = np.zeros(K, dtype=np.int64), np.zeros(K, dtype=np.int64)
    nl, nxt = 0, 0
    while True:
        while nl < K and nxt < order.shape[0]:   # fill the free lanes
            i = order[nxt]
            nxt += 1
            if pos[i] < stop[i]:
                member[nl], n_at[nl] = i, pos[i]
                _lane_load(S, Pm, nl, i, rows[offsets[i] + pos[i]], sc, I, J, mg, fW, tW, tB)
                nl += 1
        if nl == 0:
            return
        if code == 0:
            _course_lanes_0(nl, S, Pm, T, OK, limit)
        elif code == 1:
            _course_lanes_1(nl, S, Pm, T, OK, limit)
        else:
            _course_lanes_2(nl, S, Pm, T, OK, limit)
        k = 0
        while k < nl:
            i, n = member[k], n_at[k]
            if OK[k]:
                out = rows[offsets[i] + n + 1]
                for j in range(13):
                    out[j] = S[j * K + k]
                n += 1
                n_at[k] = n
            if OK[k] and n < stop[i]:
                k += 1
                continue
            # done, or its next step is not routine: the lane is free, and the last lane moves into it
            pos[i] = n
            nl -= 1
            if k < nl:
                _lane_move(S, Pm, nl, k)
                member[k], n_at[k], OK[k] = member[nl], n_at[nl], OK[nl]


@njit(**_JIT)
def lane_members(code, sc, springs, wp, bp):
    """The members (N,) bool that ``run`` steps in lanes (_run_lanes): a course-type variant (code 0, 1, 2),
    a batch without springs or point forces, a member without drag."""
    if 0 <= code <= 2 and springs.shape[1] == 0 and wp.shape[1] == 0 and bp.shape[1] == 0:
        return sc[:, 2] == 0.0
    return np.zeros(sc.shape[0], dtype=np.bool_)


@njit(**_JIT)
def run(code, rows, offsets, pos, stop, limit, tol, max_iter, max_torque, sc, I, J, mg, fW, tW, tB, springs,
        wp, bp, moments, axes):
    """For each member i: step ``rows[offsets[i] + pos[i]]`` on, writing the next rows, until ``pos[i]`` is
    ``stop[i]`` or the next step is not routine (a solve this loop does not finish, or a new state with a
    component that is non-finite or beyond ``limit``). ``pos`` is updated in place. ``code``: the variant
    (reference_sim.compiled.VARIANT_CODES); ``max_torque``: integrators.BULLET_MAX_GYROSCOPIC_TORQUE."""
    P = (sc, I, J, mg, fW, tW, tB, springs, wp, bp, moments, axes)
    in_lanes = lane_members(code, sc, springs, wp, bp)
    if in_lanes.any():
        free = np.flatnonzero(in_lanes)
        order = free[np.argsort(pos[free] - stop[free], kind="mergesort")]
        _run_lanes(code, rows, offsets, pos, stop, limit, order, sc, I, J, mg, fW, tW, tB)
    k1, k2, k3, k4, tmp = np.empty(13), np.empty(13), np.empty(13), np.empty(13), np.empty(13)
    u, u_new = np.empty(6), np.empty(6)
    for i in range(offsets.shape[0]):
        if in_lanes[i]:
            continue
        n = pos[i]
        while n < stop[i]:
            y, out = rows[offsets[i] + n], rows[offsets[i] + n + 1]
            ok = True
            if code <= 2:
                _course_type(i, y, out, code >= 1, code == 2, P)
            elif code <= 5:
                _rk(i, y, out, (1, 2, 4)[code - 3], k1, k2, k3, k4, tmp, P)
            elif code == 6:
                ok = _leapfrog(i, y, out, k1, u, u_new, tol, max_iter, P)
            elif code == 7:
                ok = _implicit_euler(i, y, out, k1, tmp, tol, max_iter, P)
            elif code <= 11:
                _engine_gyro_step(i, y, out, code - 8, max_torque, P)
            else:
                ok = _strang(i, y, out, code - 12, tmp, tol, max_iter, P)
            if not ok:
                break
            for j in range(13):
                if not abs(out[j]) <= limit:  # non-finite (NaN compares false) or blown up: simulate.bad_rows
                    ok = False
            if not ok:
                break
            n += 1
        pos[i] = n


@njit(**_JIT)
def force_torque_rows(Y, out, sc, I, J, mg, fW, tW, tB, springs, wp, bp, moments, axes):
    """Members.force_torque of member i at state ``Y[i]`` (N, 13), the rotation from q/|q|, for every i, into
    ``out`` (N, 6): force_torque_at's arithmetic (without the stage decay), member by member."""
    P = (sc, I, J, mg, fW, tW, tB, springs, wp, bp, moments, axes)
    for i in range(Y.shape[0]):
        y = Y[i]
        n = math.sqrt(y[6] * y[6] + y[7] * y[7] + y[8] * y[8] + y[9] * y[9])
        R = _rot(y[6] / n, y[7] / n, y[8] / n, y[9] / n)
        fx, fy, fz, tx, ty, tz = _force_torque(i, y, R, P)
        out[i, 0], out[i, 1], out[i, 2], out[i, 3], out[i, 4], out[i, 5] = fx, fy, fz, tx, ty, tz


@njit(**_JIT)
def force_torque_at(y, stage, sc, I, J, mg, fW, tW, tB, springs, wp, bp, moments, axes):
    """Members.force_torque of member 0 at state ``y`` (13,), the rotation from q/|q|: 6 floats. With
    ``stage``, the decay as forces too: ``−m k_v v`` and ``−k_ω I_W ω`` (``I_W ω = R I_B Rᵀ ω``)."""
    n = math.sqrt(y[6] * y[6] + y[7] * y[7] + y[8] * y[8] + y[9] * y[9])
    R = _rot(y[6] / n, y[7] / n, y[8] / n, y[9] / n)
    P = (sc, I, J, mg, fW, tW, tB, springs, wp, bp, moments, axes)
    fx, fy, fz, tx, ty, tz = _force_torque(0, y, R, P)
    kv, kw, m = sc[0, 5], sc[0, 6], sc[0, 1]
    if stage and kv != 0.0:
        fx, fy, fz = fx - m * kv * y[3], fy - m * kv * y[4], fz - m * kv * y[5]
    if stage and kw != 0.0:
        ox, oy, oz = _mtv(R, y[10], y[11], y[12])
        Ib = I[0]
        lx, ly, lz = _mv(R, Ib[0, 0] * ox + Ib[0, 1] * oy + Ib[0, 2] * oz,
                         Ib[1, 0] * ox + Ib[1, 1] * oy + Ib[1, 2] * oz,
                         Ib[2, 0] * ox + Ib[2, 1] * oy + Ib[2, 2] * oz)
        tx, ty, tz = tx - kw * lx, ty - kw * ly, tz - kw * lz
    return fx, fy, fz, tx, ty, tz
