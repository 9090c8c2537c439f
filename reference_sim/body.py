"""Rigid body mass properties: mass (kg) and body-frame inertia about the COM (kg m²)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["RigidBody", "BodyPart", "compose_parts", "inertia_from_particles", "check_inertia",
           "principal_axes", "origin_state", "com_state"]

# Relative tolerance for symmetry and the triangle inequality of an inertia tensor: a few ulps of
# the largest moment, so tensors typed with ~15 significant digits pass and real violations do not.
_INERTIA_REL_TOL = 1e-12
# Largest inertia entry accepted: sums and products of moments and angular velocities must stay far
# from float overflow (1.8e308); 1e150 kg m² is ~1e100 times any physical body (a galaxy is ~1e70).
_INERTIA_MAX = 1e150
# Smallest/largest principal moment accepted: below 1e-12 the inverse inertia keeps < 4 significant
# digits in double precision (condition number 1e12), so no integrator result would mean anything.
_INERTIA_MIN_RATIO = 1e-12


def check_inertia(inertia_B) -> np.ndarray:
    """Validate a body-frame inertia (3 principal moments or a 3×3 tensor, kg m²); return the 3×3 tensor.

    Raises ValueError naming the reason: wrong shape, non-finite, not symmetric, not positive
    definite, or principal moments violating the triangle inequality ``A + B >= C``.
    """
    I = np.asarray(inertia_B, dtype=float)
    if I.shape == (3,):
        I = np.diag(I)
    elif I.shape != (3, 3):
        raise ValueError(f"must be 3 principal moments or a 3x3 tensor, got shape {I.shape}")
    if not np.all(np.isfinite(I)):
        raise ValueError("must be finite numbers")
    scale = float(np.max(np.abs(I)))
    if scale == 0.0:
        raise ValueError("is zero; must be positive definite")
    if scale > _INERTIA_MAX:
        raise ValueError(f"has an entry of magnitude {scale:g} kg m^2, "
                         f"beyond {_INERTIA_MAX:g} (overflow range)")
    if np.max(np.abs(I - I.T)) > _INERTIA_REL_TOL * scale:
        raise ValueError("is not symmetric")
    moments = np.linalg.eigvalsh(0.5 * (I + I.T))
    if moments[0] <= 0.0:
        raise ValueError(f"is not positive definite (principal moments {moments.tolist()})")
    if moments[0] < _INERTIA_MIN_RATIO * moments[-1] or moments[0] < 1.0 / _INERTIA_MAX:
        raise ValueError(f"is ill-conditioned: smallest principal moment {moments[0]:g} is "
                         f"below {_INERTIA_MIN_RATIO:g} x the largest {moments[-1]:g} (or "
                         f"below {1.0 / _INERTIA_MAX:g}); its inverse would lose all digits")
    a, b, c = np.sort(moments)
    if a + b < c * (1.0 - _INERTIA_REL_TOL):
        raise ValueError(
            f"violates the triangle inequality: principal moments {a:g} + {b:g} < {c:g} "
            "(no physical body has these)"
        )
    return 0.5 * (I + I.T)


def principal_axes(inertia_B):
    """Principal moments ``(3,)`` ascending (kg m²) and ``R_BP`` (3, 3), det +1, of a symmetric (3, 3)
    inertia: ``inertia_B = R_BP diag(moments) R_BPᵀ`` (columns: principal axes in body coordinates)."""
    moments, R = np.linalg.eigh(inertia_B)
    if np.linalg.det(R) < 0:
        R[:, 2] *= -1.0
    return moments, R


def inertia_from_particles(masses_kg, points_B_m):
    """Mass, COM and inertia of point masses ``masses_kg`` (K,) at ``points_B_m`` (K, 3) (body coordinates,
    m), as the course defines them: ``(mass_kg, com_B_m (3,) m in the given coordinates, inertia_B (3, 3)
    kg m²)`` with ``I_ref = Σ m_i [(r_iᵀ r_i) I₃ − r_i r_iᵀ]`` about the COM,
    ``r_i = points_B_m[i] − com_B_m``.
    """
    m = np.asarray(masses_kg, dtype=float)
    p = np.asarray(points_B_m, dtype=float)
    mass = float(np.sum(m))
    com = (m[:, None] * p).sum(axis=0) / mass
    r = p - com
    I = np.einsum("k,kij->ij", m,
                  np.einsum("ki,ki->k", r, r)[:, None, None] * np.eye(3) - r[:, :, None] * r[:, None, :])
    return mass, com, I


@dataclass(frozen=True, eq=False)
class RigidBody:
    """Mass properties of one rigid body whose body frame has its origin at the COM: ``mass_kg`` (kg),
    ``inertia_B`` (3, 3) about the COM in body axes, kg m² (symmetric, positive definite), and, for a body
    built from particles, ``particles`` (K, 4) ``[m, x, y, z]`` (body coordinates from the COM, m).
    """

    mass_kg: float
    inertia_B: np.ndarray
    particles: np.ndarray | None = None

    def __post_init__(self):
        if not (np.isfinite(self.mass_kg) and self.mass_kg > 0.0):
            raise ValueError(f"mass must be a positive finite number, got {self.mass_kg!r}")
        object.__setattr__(self, "inertia_B", check_inertia(self.inertia_B))
        inv = np.linalg.inv(self.inertia_B)
        object.__setattr__(self, "inertia_inv_B", 0.5 * (inv + inv.T))

    @classmethod
    def from_particles(cls, particles):
        """Body from point masses ``[[m, x, y, z], ...]`` (kg, m, body coordinates).

        Returns ``(body, com_B_m)``: the body's frame is moved to the COM, and ``com_B_m`` says where
        that COM was in the coordinates the particles were given in.
        """
        P = np.asarray(particles, dtype=float)
        if P.ndim != 2 or P.shape[1] != 4 or P.shape[0] < 1:
            raise ValueError(f"particles must be a list of [m, x, y, z], got shape {P.shape}")
        if np.any(~(P[:, 0] > 0.0)):
            raise ValueError("every particle mass must be positive")
        mass, com, I = inertia_from_particles(P[:, 0], P[:, 1:])
        rel = P.copy()
        rel[:, 1:] -= com
        return cls(mass, I, rel), com

    def principal_axes(self):
        """:func:`principal_axes` of this body's inertia."""
        return principal_axes(self.inertia_B)

    def is_diagonal(self) -> bool:
        off = self.inertia_B - np.diag(np.diag(self.inertia_B))
        return bool(np.all(off == 0.0))

    def gyroscopic_torque_vanishes(self, q_WB, w_W) -> bool:
        """True when ``ω × (I ω) = 0`` to round-off (relative 1e-12): ω along a principal axis, an
        isotropic inertia, or ω = 0. Then a torque-free body keeps spinning about that axis."""
        from reference_sim.quaternion import quat_conj, rotate
        w_B = rotate(quat_conj(q_WB), w_W)
        L_B = self.inertia_B @ w_B
        scale = float(np.linalg.norm(w_B) * np.linalg.norm(L_B))
        return scale == 0.0 or float(np.linalg.norm(np.cross(w_B, L_B))) <= 1e-12 * scale

    def world_inertia(self, R_WB):
        """World-frame inertia ``R I_B Rᵀ`` (kg m²) for rotations ``R_WB`` (..., 3, 3)."""
        return R_WB @ self.inertia_B @ np.swapaxes(R_WB, -1, -2)


@dataclass(frozen=True, eq=False)
class BodyPart:
    """One of the rigidly joined (welded) parts of a body: ``mass_kg`` (kg), ``com_B_m`` (3,) its COM in the
    body's own frame, from the body frame's origin (m, body axes), and ``inertia_B`` (3, 3) about its own COM
    in body axes (kg m²)."""

    mass_kg: float
    com_B_m: np.ndarray
    inertia_B: np.ndarray

    def __post_init__(self):
        if not (np.isfinite(self.mass_kg) and self.mass_kg > 0.0):
            raise ValueError(f"mass must be a positive finite number, got {self.mass_kg!r}")
        object.__setattr__(self, "com_B_m", np.asarray(self.com_B_m, dtype=float).reshape(3))
        object.__setattr__(self, "inertia_B", check_inertia(self.inertia_B))


def compose_parts(parts) -> tuple:
    """The rigid body the welded ``parts`` (BodyPart) make: ``(mass_kg, com_B_m (3,) from the body frame's
    origin, inertia_B (3, 3) about that COM in body axes)``; each part's inertia moved to the common COM by
    the parallel-axis theorem, ``I = Σ [I_i + m_i ((d_iᵀ d_i) I₃ − d_i d_iᵀ)]``, ``d_i = com_i − com``."""
    m = np.array([p.mass_kg for p in parts], dtype=float)
    c = np.array([p.com_B_m for p in parts], dtype=float)
    mass = float(m.sum())
    com = (m[:, None] * c).sum(axis=0) / mass
    d = c - com
    shift = np.einsum("ki,ki->k", d, d)[:, None, None] * np.eye(3) - d[:, :, None] * d[:, None, :]
    inertia = sum(p.inertia_B for p in parts) + np.einsum("k,kij->ij", m, shift)
    return mass, com, 0.5 * (inertia + inertia.T)


def origin_state(y, com_B_m):
    """The body frame origin's position ``x_o = x − R c`` (m, world) and velocity ``v_o = v − ω × R c``
    (m/s, world) of packed COM states ``y`` (..., 13) of a body whose COM is at ``com_B_m`` (3,) in its own
    frame (m, body axes): ``(x_o, v_o)``, each (..., 3)."""
    from reference_sim.quaternion import rotate
    y = np.asarray(y, dtype=float)
    r_W = rotate(y[..., 6:10], np.broadcast_to(np.asarray(com_B_m, dtype=float), y[..., 0:3].shape))
    return y[..., 0:3] - r_W, y[..., 3:6] - np.cross(y[..., 10:13], r_W)


def com_state(x_o_W, v_o_W, q_WB, w_W, com_B_m):
    """Packed COM states (..., 13) of a body whose frame origin is at ``x_o_W`` (m, world) moving at
    ``v_o_W`` (m/s, world), oriented ``q_WB`` (w, x, y, z) and turning at ``w_W`` (rad/s, world), with its COM
    at ``com_B_m`` (3,) in its own frame: ``x = x_o + R c``, ``v = v_o + ω × R c``."""
    from reference_sim.quaternion import rotate
    x_o, v_o = np.asarray(x_o_W, dtype=float), np.asarray(v_o_W, dtype=float)
    q, w = np.asarray(q_WB, dtype=float), np.asarray(w_W, dtype=float)
    r_W = rotate(q, np.broadcast_to(np.asarray(com_B_m, dtype=float), x_o.shape))
    return np.concatenate([x_o + r_W, v_o + np.cross(w, r_W), q, w], axis=-1)
