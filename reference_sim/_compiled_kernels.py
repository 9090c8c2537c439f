"""numba transcription of reference_sim.scalar's float steps (imported by reference_sim.compiled only).

Each function is the ScalarStepper method of the same name, operation for operation, in the same order
(Python evaluates ``a + b + c`` as ``(a + b) + c``; so does this code): with fastmath off, the results are
bit-identical (tests/reference_sim/test_compiled.py). ``P`` is the parameter tuple of
``reference_sim.compiled.parameters``: (scalars [h, m, c, gv, gw, kv, kw], flags [drag, body torque,
velocity decay, angular decay], I_B, I_B⁻¹, m g_W, fixed f_W, τ_W, τ_B, springs (n, 8) [anchor_W, attach_B,
k, L0], world point forces (n, 6) [f_W, r_B], body point forces (n, 6) [f_B, r_B]).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

# fastmath stays off: no reassociation, no contraction into fused multiply-adds (bit-identity)
_JIT = dict(cache=True, nogil=True, error_model="numpy")


@njit(**_JIT)
def _rot(qw, qx, qy, qz):
    xx, yy, zz = qx * qx, qy * qy, qz * qz
    xy, xz, yz, wx, wy, wz = qx * qy, qx * qz, qy * qz, qw * qx, qw * qy, qw * qz
    return (1.0 - 2.0 * (yy + zz), 2.0 * (xy - wz), 2.0 * (xz + wy),
            2.0 * (xy + wz), 1.0 - 2.0 * (xx + zz), 2.0 * (yz - wx),
            2.0 * (xz - wy), 2.0 * (yz + wx), 1.0 - 2.0 * (xx + yy))


@njit(**_JIT)
def _force_torque(y, R, P):
    sc, fl, _I, _J, mg, ff, tW, tB, springs, wp, bp = P
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = R
    fx, fy, fz = mg[0] + ff[0], mg[1] + ff[1], mg[2] + ff[2]
    tx, ty, tz = tW[0], tW[1], tW[2]
    if fl[0]:
        c = sc[2]
        fx = fx - c * y[3]
        fy = fy - c * y[4]
        fz = fz - c * y[5]
    for j in range(springs.shape[0]):
        a0, a1, a2 = springs[j, 3], springs[j, 4], springs[j, 5]
        k, L0 = springs[j, 6], springs[j, 7]
        rx = r00 * a0 + r01 * a1 + r02 * a2
        ry = r10 * a0 + r11 * a1 + r12 * a2
        rz = r20 * a0 + r21 * a1 + r22 * a2
        dx, dy, dz = y[0] + rx - springs[j, 0], y[1] + ry - springs[j, 1], y[2] + rz - springs[j, 2]
        L = math.sqrt(dx * dx + dy * dy + dz * dz)
        s = -k * (L - L0) / L if L > 0.0 else 0.0
        sx, sy, sz = s * dx, s * dy, s * dz
        fx = fx + sx
        fy = fy + sy
        fz = fz + sz
        tx = tx + (ry * sz - rz * sy)
        ty = ty + (rz * sx - rx * sz)
        tz = tz + (rx * sy - ry * sx)
    for j in range(wp.shape[0]):
        f0, f1, f2, p0, p1, p2 = wp[j, 0], wp[j, 1], wp[j, 2], wp[j, 3], wp[j, 4], wp[j, 5]
        rx = r00 * p0 + r01 * p1 + r02 * p2
        ry = r10 * p0 + r11 * p1 + r12 * p2
        rz = r20 * p0 + r21 * p1 + r22 * p2
        fx = fx + f0
        fy = fy + f1
        fz = fz + f2
        tx = tx + (ry * f2 - rz * f1)
        ty = ty + (rz * f0 - rx * f2)
        tz = tz + (rx * f1 - ry * f0)
    for j in range(bp.shape[0]):
        f0, f1, f2, p0, p1, p2 = bp[j, 0], bp[j, 1], bp[j, 2], bp[j, 3], bp[j, 4], bp[j, 5]
        gx = r00 * f0 + r01 * f1 + r02 * f2
        gy = r10 * f0 + r11 * f1 + r12 * f2
        gz = r20 * f0 + r21 * f1 + r22 * f2
        rx = r00 * p0 + r01 * p1 + r02 * p2
        ry = r10 * p0 + r11 * p1 + r12 * p2
        rz = r20 * p0 + r21 * p1 + r22 * p2
        fx = fx + gx
        fy = fy + gy
        fz = fz + gz
        tx = tx + (ry * gz - rz * gy)
        ty = ty + (rz * gx - rx * gz)
        tz = tz + (rx * gy - ry * gx)
    if fl[1]:
        tx = tx + (r00 * tB[0] + r01 * tB[1] + r02 * tB[2])
        ty = ty + (r10 * tB[0] + r11 * tB[1] + r12 * tB[2])
        tz = tz + (r20 * tB[0] + r21 * tB[1] + r22 * tB[2])
    return fx, fy, fz, tx, ty, tz


@njit(**_JIT)
def _ang_acc(R, wx, wy, wz, tx, ty, tz, gyro, P):
    I, J = P[2], P[3]
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = R
    bx = r00 * tx + r10 * ty + r20 * tz
    by = r01 * tx + r11 * ty + r21 * tz
    bz = r02 * tx + r12 * ty + r22 * tz
    if gyro:
        ox = r00 * wx + r10 * wy + r20 * wz
        oy = r01 * wx + r11 * wy + r21 * wz
        oz = r02 * wx + r12 * wy + r22 * wz
        lx = I[0, 0] * ox + I[0, 1] * oy + I[0, 2] * oz
        ly = I[1, 0] * ox + I[1, 1] * oy + I[1, 2] * oz
        lz = I[2, 0] * ox + I[2, 1] * oy + I[2, 2] * oz
        bx = bx - (oy * lz - oz * ly)
        by = by - (oz * lx - ox * lz)
        bz = bz - (ox * ly - oy * lx)
    ax = J[0, 0] * bx + J[0, 1] * by + J[0, 2] * bz
    ay = J[1, 0] * bx + J[1, 1] * by + J[1, 2] * bz
    az = J[2, 0] * bx + J[2, 1] * by + J[2, 2] * bz
    return (r00 * ax + r01 * ay + r02 * az, r10 * ax + r11 * ay + r12 * az, r20 * ax + r21 * ay + r22 * az)


@njit(**_JIT)
def _exp(h, wx, wy, wz):
    th = h * math.sqrt(wx * wx + wy * wy + wz * wz)
    t2 = th * th
    if th < 1e-4:
        s = h * (0.5 - t2 / 48.0 + t2 * t2 / 3840.0)
    else:
        s = h * (math.sin(0.5 * th) / th)
    return math.cos(0.5 * th), s * wx, s * wy, s * wz


@njit(**_JIT)
def _course(y, out, gyro, expmap, P):
    sc = P[0]
    h, m = sc[0], sc[1]
    qw, qx, qy, qz = y[6], y[7], y[8], y[9]
    wx, wy, wz = y[10], y[11], y[12]
    R = _rot(qw, qx, qy, qz)
    fx, fy, fz, tx, ty, tz = _force_torque(y, R, P)
    gv = sc[3]
    vx, vy, vz = gv * (y[3] + h * (fx / m)), gv * (y[4] + h * (fy / m)), gv * (y[5] + h * (fz / m))
    ax, ay, az = _ang_acc(R, wx, wy, wz, tx, ty, tz, gyro, P)
    gw = sc[4]
    wx, wy, wz = gw * (wx + h * ax), gw * (wy + h * ay), gw * (wz + h * az)
    if expmap:
        ew, ex, ey, ez = _exp(h, wx, wy, wz)
        nw = ew * qw - ex * qx - ey * qy - ez * qz
        nx = ew * qx + ex * qw + ey * qz - ez * qy
        ny = ew * qy + ey * qw + ez * qx - ex * qz
        nz = ew * qz + ez * qw + ex * qy - ey * qx
    else:
        hx, hy, hz = 0.5 * h * wx, 0.5 * h * wy, 0.5 * h * wz
        nw = qw - (hx * qx + hy * qy + hz * qz)
        nx = qx + (hx * qw + hy * qz - hz * qy)
        ny = qy + (hy * qw + hz * qx - hx * qz)
        nz = qz + (hz * qw + hx * qy - hy * qx)
    n = math.sqrt(nw * nw + nx * nx + ny * ny + nz * nz)
    out[0], out[1], out[2] = y[0] + h * vx, y[1] + h * vy, y[2] + h * vz
    out[3], out[4], out[5] = vx, vy, vz
    out[6], out[7], out[8], out[9] = nw / n, nx / n, ny / n, nz / n
    out[10], out[11], out[12] = wx, wy, wz


@njit(**_JIT)
def _rhs(y, out, P):
    sc, fl = P[0], P[1]
    qw, qx, qy, qz = y[6], y[7], y[8], y[9]
    n = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
    R = _rot(qw / n, qx / n, qy / n, qz / n)
    wx, wy, wz = y[10], y[11], y[12]
    fx, fy, fz, tx, ty, tz = _force_torque(y, R, P)
    ax, ay, az = _ang_acc(R, wx, wy, wz, tx, ty, tz, True, P)
    m = sc[1]
    dvx, dvy, dvz = fx / m, fy / m, fz / m
    if fl[2]:
        kv = sc[5]
        dvx, dvy, dvz = dvx - kv * y[3], dvy - kv * y[4], dvz - kv * y[5]
    if fl[3]:
        kw = sc[6]
        ax, ay, az = ax - kw * wx, ay - kw * wy, az - kw * wz
    out[0], out[1], out[2], out[3], out[4], out[5] = y[3], y[4], y[5], dvx, dvy, dvz
    out[6] = 0.5 * (-wx * qx - wy * qy - wz * qz)
    out[7] = 0.5 * (wx * qw + wy * qz - wz * qy)
    out[8] = 0.5 * (wy * qw + wz * qx - wx * qz)
    out[9] = 0.5 * (wz * qw + wx * qy - wy * qx)
    out[10], out[11], out[12] = ax, ay, az


@njit(**_JIT)
def _finish(y):
    n = math.sqrt(y[6] * y[6] + y[7] * y[7] + y[8] * y[8] + y[9] * y[9])
    y[6], y[7], y[8], y[9] = y[6] / n, y[7] / n, y[8] / n, y[9] / n


@njit(**_JIT)
def _explicit_euler(y, out, k1, P):
    h = P[0][0]
    _rhs(y, k1, P)
    for i in range(13):
        out[i] = y[i] + h * k1[i]
    _finish(out)


@njit(**_JIT)
def _midpoint(y, out, k1, k2, tmp, P):
    h = P[0][0]
    _rhs(y, k1, P)
    for i in range(13):
        tmp[i] = y[i] + 0.5 * h * k1[i]
    _rhs(tmp, k2, P)
    for i in range(13):
        out[i] = y[i] + h * k2[i]
    _finish(out)


@njit(**_JIT)
def _rk4(y, out, k1, k2, k3, k4, tmp, P):
    h = P[0][0]
    _rhs(y, k1, P)
    for i in range(13):
        tmp[i] = y[i] + (0.5 * h) * k1[i]
    _rhs(tmp, k2, P)
    for i in range(13):
        tmp[i] = y[i] + (0.5 * h) * k2[i]
    _rhs(tmp, k3, P)
    for i in range(13):
        tmp[i] = y[i] + h * k3[i]
    _rhs(tmp, k4, P)
    h6 = h / 6.0
    for i in range(13):
        out[i] = y[i] + h6 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
    _finish(out)


@njit(**_JIT)
def _leapfrog(y, out, d, u0, u, u_new, tol, max_iter, P):
    """False when the implicit half kick does not converge in ``max_iter`` iterations (the Python step raises)."""
    h = P[0][0]
    half = 0.5 * h
    for i in range(3):
        u0[i], u0[3 + i] = y[3 + i], y[10 + i]
    for i in range(13):
        out[i] = y[i]
    _rhs(y, d, P)
    for i in range(3):
        u[i], u[3 + i] = u0[i] + half * d[3 + i], u0[3 + i] + half * d[10 + i]
    converged = False
    for _ in range(max_iter):
        for i in range(3):
            out[3 + i], out[10 + i] = u[i], u[3 + i]
        _rhs(out, d, P)
        for i in range(3):
            u_new[i], u_new[3 + i] = u0[i] + half * d[3 + i], u0[3 + i] + half * d[10 + i]
        worst = abs((u_new[0] - u[0]) / (1.0 + abs(u_new[0])))   # Python's max(): a later item replaces on >
        for i in range(1, 6):
            e = abs((u_new[i] - u[i]) / (1.0 + abs(u_new[i])))
            if e > worst:
                worst = e
        for i in range(6):
            u[i] = u_new[i]
        if worst <= tol:
            converged = True
            break
    if not converged:
        return False
    for i in range(3):
        out[3 + i], out[10 + i] = u[i], u[3 + i]
    out[0], out[1], out[2] = y[0] + h * u[0], y[1] + h * u[1], y[2] + h * u[2]
    ew, ex, ey, ez = _exp(h, u[3], u[4], u[5])
    qw, qx, qy, qz = y[6], y[7], y[8], y[9]
    nw = ew * qw - ex * qx - ey * qy - ez * qz
    nx = ew * qx + ex * qw + ey * qz - ez * qy
    ny = ew * qy + ey * qw + ez * qx - ex * qz
    nz = ew * qz + ez * qw + ex * qy - ey * qx
    n = math.sqrt(nw * nw + nx * nx + ny * ny + nz * nz)
    out[6], out[7], out[8], out[9] = nw / n, nx / n, ny / n, nz / n
    _rhs(out, d, P)
    for i in range(3):
        out[3 + i] = u[i] + half * d[3 + i]
    for i in range(3):
        out[10 + i] = u[3 + i] + half * d[10 + i]
    return True


@njit(**_JIT)
def _implicit_euler(y, out, d, z, tol, max_iter, P):
    """The fixed point of ScalarStepper._implicit_euler; False when it stalls or runs out of iterations
    (the Python step then solves the step with Newton's method)."""
    h = P[0][0]
    _rhs(y, d, P)
    for i in range(13):
        z[i] = y[i] + h * d[i]
    prev = np.inf
    for _ in range(max_iter):
        _rhs(z, d, P)
        for i in range(13):
            out[i] = y[i] + h * d[i]
        worst = abs(out[0] - z[0]) / (1.0 + abs(out[0]))
        for i in range(1, 13):
            e = abs(out[i] - z[i]) / (1.0 + abs(out[i]))
            if e > worst:
                worst = e
        for i in range(13):
            z[i] = out[i]
        if worst <= tol:
            _finish(out)
            return True
        if not worst < 0.9 * prev:
            return False
        prev = worst
    return False


@njit(**_JIT)
def run(variant, rows, start, n_steps, limit, tol, max_iter, sc, fl, I, J, mg, ff, tW, tB, springs, wp, bp):
    """Step rows[start] → rows[start + 1] → … until n_steps, or until a step is not routine: a leapfrog or
    implicit Euler solve that the compiled iteration does not finish, or a new state with a component that
    is non-finite or beyond ``limit``. Returns the index of the last good state."""
    P = (sc, fl, I, J, mg, ff, tW, tB, springs, wp, bp)
    k1, k2, k3, k4, tmp = np.empty(13), np.empty(13), np.empty(13), np.empty(13), np.empty(13)
    u0, u, u_new = np.empty(6), np.empty(6), np.empty(6)
    for n in range(start, n_steps):
        y, out = rows[n], rows[n + 1]
        ok = True
        if variant <= 2:
            _course(y, out, variant >= 1, variant == 2, P)
        elif variant == 3:
            _explicit_euler(y, out, k1, P)
        elif variant == 4:
            _midpoint(y, out, k1, k2, tmp, P)
        elif variant == 5:
            _rk4(y, out, k1, k2, k3, k4, tmp, P)
        elif variant == 6:
            ok = _leapfrog(y, out, k1, u0, u, u_new, tol, max_iter, P)
        else:
            ok = _implicit_euler(y, out, k1, tmp, tol, max_iter, P)
        if not ok:
            return n
        for i in range(13):
            if not abs(out[i]) <= limit:   # non-finite (NaN compares false) or blown up: bad_rows
                return n
    return n_steps
