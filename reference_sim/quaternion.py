"""Unit quaternions in scalar-first order ``(w, x, y, z)``.

Every function here takes arrays whose LAST axis holds the 4 quaternion components
``(w, x, y, z)`` (or the 3 vector components), so any leading batch shape ``(...)`` works.
This is the only quaternion order used inside rbcheck; engine adapters convert at their boundary.

Conventions (docs/course_equations.md):

* ``q_WB`` maps body coordinates to world coordinates: ``p_W = R(q_WB) @ p_B``.
* Product ``q1 q2 = [s1 s2 - v1.v2, s1 v2 + s2 v1 + v1 x v2]``.
* ``q`` and ``-q`` are the same rotation.
"""
from __future__ import annotations

import numpy as np

from reference_sim.vec import cross3, floating

__all__ = [
    "quat_mul",
    "quat_conj",
    "quat_norm",
    "quat_normalize",
    "quat_from_axis_angle",
    "axis_angle_from_quat",
    "matrix_from_quat",
    "quat_from_matrix",
    "quat_exp",
    "quat_log",
    "rotate",
    "geodesic_angle",
    "quat_canonical",
    "sign_continuous",
    "same_side",
    "euler_zxy_from_quat",
    "quat_from_euler_zxy",
]

def quat_mul(q1, q2):
    """Hamilton product ``q1 q2`` of quaternions ``(..., 4)`` in (w, x, y, z) order."""
    q1 = np.asarray(q1, dtype=float)
    q2 = np.asarray(q2, dtype=float)
    s1, v1 = q1[..., :1], q1[..., 1:]
    s2, v2 = q2[..., :1], q2[..., 1:]
    s = s1 * s2 - np.sum(v1 * v2, axis=-1, keepdims=True)
    v = s1 * v2 + s2 * v1 + cross3(v1, v2)
    return np.concatenate([s, v], axis=-1)


def quat_conj(q):
    """Conjugate ``[s, -v]`` of ``(..., 4)`` quaternions (w, x, y, z); the inverse of a unit one."""
    q = np.asarray(q, dtype=float)
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def quat_norm(q):
    """Euclidean norm ``sqrt(w² + x² + y² + z²)``, shape ``(...)``."""
    return np.linalg.norm(np.asarray(q, dtype=float), axis=-1)


def quat_normalize(q):
    """Unit quaternion ``q / |q|`` (w, x, y, z). Raises ValueError for a zero quaternion."""
    q = np.asarray(q, dtype=float)
    n = quat_norm(q)
    if np.any(~(n > 0.0)):
        raise ValueError("cannot normalise a zero (or non-finite) quaternion")
    return q / n[..., None]


def quat_from_axis_angle(axis, angle_rad):
    """``[cos(θ/2), u sin(θ/2)]`` for axis ``(..., 3)`` (normalised here) and angle θ (rad)."""
    axis = np.asarray(axis, dtype=float)
    angle_rad = np.asarray(angle_rad, dtype=float)
    u = axis / np.linalg.norm(axis, axis=-1, keepdims=True)
    half = 0.5 * angle_rad[..., None]
    return np.concatenate([np.cos(half), u * np.sin(half)], axis=-1)


def axis_angle_from_quat(q):
    """Unit axis ``(..., 3)`` and angle in [0, π] (rad) of unit quaternions ``(..., 4)`` (w, x, y, z).

    For the identity the axis is arbitrary and returned as (1, 0, 0).
    """
    q = quat_canonical(quat_normalize(q))
    v = q[..., 1:]
    s = np.linalg.norm(v, axis=-1)
    angle = 2.0 * np.arctan2(s, q[..., 0])
    safe = s > 0.0
    axis = np.where(safe[..., None], v / np.where(safe, s, 1.0)[..., None], np.array([1.0, 0.0, 0.0]))
    return axis, angle


def matrix_from_quat(q):
    """Rotation matrix ``R`` ``(..., 3, 3)`` of unit quaternions ``(..., 4)`` (w, x, y, z).

    Uses the course's formula (docs/course_equations.md); ``p_W = R @ p_B`` for ``q = q_WB``.
    """
    q = floating(q)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    R = np.empty(q.shape[:-1] + (3, 3), dtype=q.dtype)
    R[..., 0, 0] = 1.0 - 2.0 * (y * y + z * z)
    R[..., 0, 1] = 2.0 * (x * y - w * z)
    R[..., 0, 2] = 2.0 * (x * z + w * y)
    R[..., 1, 0] = 2.0 * (x * y + w * z)
    R[..., 1, 1] = 1.0 - 2.0 * (x * x + z * z)
    R[..., 1, 2] = 2.0 * (y * z - w * x)
    R[..., 2, 0] = 2.0 * (x * z - w * y)
    R[..., 2, 1] = 2.0 * (y * z + w * x)
    R[..., 2, 2] = 1.0 - 2.0 * (x * x + y * y)
    return R


def quat_from_matrix(R):
    """Unit quaternion (w, x, y, z), ``w >= 0``, of rotation matrices ``(..., 3, 3)``.

    Shepperd's method: picks the largest of w², x², y², z² to stay well conditioned.
    """
    R = np.asarray(R, dtype=float)
    m00, m11, m22 = R[..., 0, 0], R[..., 1, 1], R[..., 2, 2]
    d21, d02, d10 = R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]
    s01, s02, s12 = R[..., 0, 1] + R[..., 1, 0], R[..., 0, 2] + R[..., 2, 0], R[..., 1, 2] + R[..., 2, 1]
    four_sq = np.stack([1.0 + m00 + m11 + m22, 1.0 + m00 - m11 - m22,
                        1.0 - m00 + m11 - m22, 1.0 - m00 - m11 + m22], axis=-1)  # 4w², 4x², 4y², 4z²
    k = np.argmax(four_sq, axis=-1)[..., None, None]
    r = 2.0 * np.sqrt(np.maximum(np.take_along_axis(four_sq, k[..., 0], axis=-1), 0.0))  # 4·|largest|
    # Row i: the quaternion times 4·q_i, built from the case where q_i is the largest component.
    cands = np.stack([
        np.stack([r[..., 0] * r[..., 0] / 4.0, d21, d02, d10], axis=-1),
        np.stack([d21, r[..., 0] * r[..., 0] / 4.0, s01, s02], axis=-1),
        np.stack([d02, s01, r[..., 0] * r[..., 0] / 4.0, s12], axis=-1),
        np.stack([d10, s02, s12, r[..., 0] * r[..., 0] / 4.0], axis=-1),
    ], axis=-2)
    q = np.take_along_axis(cands, k, axis=-2)[..., 0, :]
    return quat_canonical(q / np.linalg.norm(q, axis=-1, keepdims=True))


#: Below this angle (rad) ``sin(θ/2)/θ`` comes from its series ``1/2 − θ²/48 + θ⁴/3840``: the first term left
#: out, θ⁶/645120, is < 2e-30 there (relative 3e-30), while sin(θ/2)/θ itself would lose digits to
#: the division as θ → 0 and is 0/0 at 0.
SINC_SERIES_BELOW_RAD = 1e-4


def half_angle_sinc(theta):
    """``sin(θ/2)/θ`` of angles ``θ ≥ 0`` (rad; array or scalar), from its Taylor series below
    SINC_SERIES_BELOW_RAD (1/2 at θ = 0): the one definition of the exponential map's coefficient
    (:func:`quat_exp`, integrators.exp_map_times; its numba twin is
    ``reference_sim._compiled_kernels._half_angle_sinc``, equal to the last bit: tests/reference_sim)."""
    theta = np.asarray(theta, dtype=float)
    small = theta < SINC_SERIES_BELOW_RAD
    t2 = theta * theta
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(small, 0.5 - t2 / 48.0 + t2 * t2 / 3840.0,
                        np.sin(0.5 * theta) / np.where(small, 1.0, theta))


def quat_exp(rotvec):
    """Exponential map: unit quaternion (w, x, y, z) of rotation vectors ``(..., 3)`` (rad).

    ``quat_exp(θ u) = [cos(θ/2), u sin(θ/2)]``, ``sin(θ/2)/θ`` by :func:`half_angle_sinc` (a Taylor series
    near zero, so it is exact to round-off for tiny angles).
    """
    rotvec = np.asarray(rotvec, dtype=float)
    theta = np.linalg.norm(rotvec, axis=-1)
    half = 0.5 * theta
    return np.concatenate([np.cos(half)[..., None], half_angle_sinc(theta)[..., None] * rotvec], axis=-1)


def quat_log(q):
    """Rotation vector ``θ u`` (rad, ``(..., 3)``) of unit quaternions; θ in [0, π] (q and −q alike)."""
    axis, angle = axis_angle_from_quat(q)
    return axis * angle[..., None]


def rotate(q, v):
    """Rotate vectors ``v`` ``(..., 3)`` by unit quaternions ``q`` (w, x, y, z): ``R(q) @ v``."""
    q = np.asarray(q, dtype=float)
    v = np.asarray(v, dtype=float)
    s, u = q[..., :1], q[..., 1:]
    t = 2.0 * cross3(u, v)
    return v + s * t + cross3(u, t)


def quat_canonical(q):
    """The representative of ``±q`` with ``w >= 0`` (ties broken on the first non-zero component)."""
    q = np.asarray(q, dtype=float)
    nz = q != 0.0
    first = np.argmax(nz, axis=-1)
    lead = np.take_along_axis(q, first[..., None], axis=-1)[..., 0]
    sign = np.where(lead < 0.0, -1.0, 1.0)
    return q * sign[..., None]


def sign_continuous(q, first=None):
    """Quaternion rows ``q`` (N, 4) with each row's sign chosen to follow the row before (``q`` and ``−q`` are
    the same orientation: a jump between them is no motion), the first row's to follow ``first`` when given:
    the same rotations as one continuous curve. A row whose dot product is not finite keeps its sign."""
    q = np.array(q, dtype=float, copy=True)
    if not len(q):
        return q
    with np.errstate(invalid="ignore"):
        dots = np.einsum("ij,ij->i", q[1:], q[:-1])
        head = -1.0 if first is not None and float(np.dot(q[0], np.asarray(first, dtype=float))) < 0 else 1.0
    step = np.where(dots < 0, -1.0, 1.0)
    return q * np.cumprod(np.concatenate([[head], step]))[:, None]


def same_side(q, q_ref):
    """Quaternions ``q`` (..., 4), each with the sign that makes its dot product with ``q_ref``'s (same shape)
    non-negative: after one step from ``q_ref``, which turns by less than π, the representative of ±q on
    ``q_ref``'s side. A row whose dot product is not finite keeps its sign."""
    q = np.asarray(q, dtype=float)
    with np.errstate(invalid="ignore", over="ignore"):
        dots = np.einsum("...i,...i->...", q, np.asarray(q_ref, dtype=float))
    return q * np.where(dots < 0.0, -1.0, 1.0)[..., None]


def geodesic_angle(q_ref, q):
    """Geodesic angle (rad, in [0, π]) between unit quaternions: ``2 atan2(|vec(q_ref⁻¹ q)|, |scalar|)``.

    Sign-invariant (``q`` and ``-q`` give the same angle), as docs/results.md defines the orientation error.
    """
    d = quat_mul(quat_conj(q_ref), q)
    return 2.0 * np.arctan2(np.linalg.norm(d[..., 1:], axis=-1), np.abs(d[..., 0]))


def quat_from_euler_zxy(angles_deg):
    """Quaternion (w, x, y, z) of Unity Euler angles ``(..., 3)`` = (x, y, z) in DEGREES.

    Unity applies the rotations in the order Z, then X, then Y about the fixed (world) axes, i.e.
    ``R = R_y(y) R_x(x) R_z(z)`` acting on column vectors, so ``q = q_y q_x q_z``.
    """
    a = np.deg2rad(np.asarray(angles_deg, dtype=float))
    ex = np.array([1.0, 0.0, 0.0])
    ey = np.array([0.0, 1.0, 0.0])
    ez = np.array([0.0, 0.0, 1.0])
    qx = quat_from_axis_angle(np.broadcast_to(ex, a.shape), a[..., 0])
    qy = quat_from_axis_angle(np.broadcast_to(ey, a.shape), a[..., 1])
    qz = quat_from_axis_angle(np.broadcast_to(ez, a.shape), a[..., 2])
    return quat_mul(qy, quat_mul(qx, qz))


def euler_zxy_from_quat(q, *, gimbal_tol=1e-9):
    """Unity Euler angles (x, y, z) in DEGREES of unit quaternions (w, x, y, z), and a gimbal-lock flag.

    Returns ``(angles_deg (..., 3), locked (...) bool)``. With ``R = R_y R_x R_z``: ``R[1, 2] = -sin x`` and
    ``hypot(R[0,2], R[2,2]) = cos x``, so x is in [-90°, 90°]. When ``|cos x| < gimbal_tol`` (pitch ±90°)
    the y and z rotations act about the same axis; then z is set to 0, y absorbs the whole remaining
    rotation, and ``locked`` is True.
    """
    R = matrix_from_quat(quat_normalize(q))
    # cos x from the row that carries it (hypot stays accurate near ±90°, where asin would not).
    cx = np.hypot(R[..., 0, 2], R[..., 2, 2])
    x = np.arctan2(-R[..., 1, 2], cx)
    locked = cx < gimbal_tol
    # Regular case: R[0,2] = sin y cos x, R[2,2] = cos y cos x; R[1,0] = cos x sin z, R[1,1] = cos x cos z.
    y = np.arctan2(R[..., 0, 2], R[..., 2, 2])
    z = np.arctan2(R[..., 1, 0], R[..., 1, 1])
    # Locked: z := 0, R = R_y R_x; with x = ±90°: R[0,0] = cos y, R[0,1] = ±sin y ... solve from row 0/2.
    y_locked = np.arctan2(-R[..., 2, 0], R[..., 0, 0])
    y = np.where(locked, y_locked, y)
    z = np.where(locked, 0.0, z)
    return np.rad2deg(np.stack([x, y, z], axis=-1)), locked
