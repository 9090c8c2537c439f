"""numba transcription of reference_sim.integrators for N members (imported by reference_sim.compiled only).

Each function is the definition's function of the same name, written on the floats of one member, with
the operations in the definition's order (``a + b + c`` is ``(a + b) + c`` in NumPy and here) and
``fastmath`` off (no reassociation, no fused multiply-add), so that a state it writes equals the
definition's (tests/reference_sim/test_compiled.py). ``P`` is the tuple of reference_sim.compiled.parameters:
(sc (N, 7) [h, m, c, γ_v, γ_ω, k_v, k_ω], I_B, I_B⁻¹ (N, 3, 3), m g_W, f_W at the COM, τ_W, τ_B (N, 3),
springs (N, S, 8)
[anchor_W, attach_B, k, L0], world point forces (N, P, 6) [f_W, r_B], body point forces (N, B, 6) [f_B, r_B]).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

# fastmath stays off: no reassociation, no contraction into fused multiply-adds
_JIT = dict(cache=True, nogil=True, error_model="numpy")
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


@njit(**_JIT)
def _exp_map_times(h, wx, wy, wz, qw, qx, qy, qz):
    """exp(h ω) ⊗ q (integrators.exp_map_times)."""
    th = h * math.sqrt(wx * wx + wy * wy + wz * wz)
    t2 = th * th
    s = h * (0.5 - t2 / 48.0 + t2 * t2 / 3840.0) if th < 1e-4 else h * (math.sin(0.5 * th) / th)
    ew, ex, ey, ez = math.cos(0.5 * th), s * wx, s * wy, s * wz
    return (ew * qw - ex * qx - ey * qy - ez * qz, ew * qx + ex * qw + ey * qz - ez * qy,
            ew * qy + ey * qw + ez * qx - ex * qz, ew * qz + ez * qw + ex * qy - ey * qx)


@njit(**_JIT)
def _normalize(y):
    n = math.sqrt(y[6] * y[6] + y[7] * y[7] + y[8] * y[8] + y[9] * y[9])
    y[6], y[7], y[8], y[9] = y[6] / n, y[7] / n, y[8] / n, y[9] / n


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
def _course_type(i, y, out, gyro, expmap, P):
    """integrators.course_type of member i."""
    sc = P[0]
    h, m, gv, gw = sc[i, 0], sc[i, 1], sc[i, 3], sc[i, 4]
    qw, qx, qy, qz = y[6], y[7], y[8], y[9]
    R = _rot(qw, qx, qy, qz)
    fx, fy, fz, tx, ty, tz = _force_torque(i, y, R, P)
    vx, vy, vz = gv * (y[3] + h * (fx / m)), gv * (y[4] + h * (fy / m)), gv * (y[5] + h * (fz / m))
    ax, ay, az = _angular_acceleration(i, R, y[10], y[11], y[12], tx, ty, tz, gyro, P)
    wx, wy, wz = gw * (y[10] + h * ax), gw * (y[11] + h * ay), gw * (y[12] + h * az)
    if expmap:
        nw, nx, ny, nz = _exp_map_times(h, wx, wy, wz, qw, qx, qy, qz)
    else:
        half = 0.5 * h
        dw, dx, dy, dz = _omega_times(half * wx, half * wy, half * wz, qw, qx, qy, qz)
        nw, nx, ny, nz = qw + dw, qx + dx, qy + dy, qz + dz
    out[0], out[1], out[2] = y[0] + h * vx, y[1] + h * vy, y[2] + h * vz
    out[3], out[4], out[5] = vx, vy, vz
    out[6], out[7], out[8], out[9] = nw, nx, ny, nz
    _normalize(out)
    out[10], out[11], out[12] = wx, wy, wz


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


@njit(**_JIT)
def run(code, rows, offsets, pos, stop, limit, tol, max_iter, sc, I, J, mg, fW, tW, tB, springs, wp, bp):
    """For each member i: step ``rows[offsets[i] + pos[i]]`` on, writing the next rows, until ``pos[i]`` is
    ``stop[i]`` or the next step is not routine (a solve this loop does not finish, or a new state with a
    component that is non-finite or beyond ``limit``). ``pos`` is updated in place."""
    P = (sc, I, J, mg, fW, tW, tB, springs, wp, bp)
    k1, k2, k3, k4, tmp = np.empty(13), np.empty(13), np.empty(13), np.empty(13), np.empty(13)
    u, u_new = np.empty(6), np.empty(6)
    for i in range(offsets.shape[0]):
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
            else:
                ok = _implicit_euler(i, y, out, k1, tmp, tol, max_iter, P)
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
def force_torque_at(y, stage, sc, I, J, mg, fW, tW, tB, springs, wp, bp):
    """Members.force_torque of member 0 at state ``y`` (13,), the rotation from q/|q|: 6 floats. With
    ``stage``, the decay as forces too: ``−m k_v v`` and ``−k_ω I_W ω`` (``I_W ω = R I_B Rᵀ ω``)."""
    n = math.sqrt(y[6] * y[6] + y[7] * y[7] + y[8] * y[8] + y[9] * y[9])
    R = _rot(y[6] / n, y[7] / n, y[8] / n, y[9] / n)
    fx, fy, fz, tx, ty, tz = _force_torque(0, y, R, (sc, I, J, mg, fW, tW, tB, springs, wp, bp))
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
