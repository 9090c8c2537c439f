"""Forces on a free rigid body, each giving a world force and a world torque about the COM.

Every force is evaluated from a state ``(x_W, v_W, q_WB)`` with any leading batch shape ``(...)``;
the torque of a force ``f_W`` applied at body point ``r_B`` is ``τ_W = (R r_B) × f_W`` (course).
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from reference_sim.body import RigidBody
from reference_sim.quaternion import matrix_from_quat, rotate
from reference_sim.vec import cross3, mat_t_vec3, matvec3

__all__ = ["Spring", "PointForce", "Torque", "ForceModel", "FRAMES", "Members"]

#: The axes a point force or torque may be given in.
FRAMES = ("world", "body")


@dataclass(frozen=True, eq=False)
class Spring:
    """Hookean spring between world anchor ``anchor_W`` (m) and body point ``attach_B`` (m, from COM).

    ``f_W = −k (L − L0) d/L`` on the body at the attachment point, ``d = x + R attach_B − anchor_W``,
    ``L = |d|``; zero when ``L == 0`` (direction undefined). Potential ``½ k (L − L0)²`` (J).
    """

    anchor_W: np.ndarray
    attach_B: np.ndarray
    stiffness_N_per_m: float
    rest_length_m: float = 0.0


@dataclass(frozen=True, eq=False)
class PointForce:
    """Constant force ``force`` (N) at body point ``point_B`` (m, from COM), in ``frame`` axes:
    "world" (fixed direction) or "body" (rotates with the body)."""

    force: np.ndarray
    point_B: np.ndarray
    frame: str = "world"


@dataclass(frozen=True, eq=False)
class Torque:
    """Constant pure torque ``torque`` (N m) in ``frame`` axes ("world" or "body")."""

    torque: np.ndarray
    frame: str = "world"


@dataclass(frozen=True, eq=False)
class ForceModel:
    """All forces of a scenario.

    gravity_W : (3,) m/s², uniform: acts at the COM, no torque.
    linear_drag_N_s_per_m : c in ``f = −c v_W`` at the COM.
    velocity_decay, angular_velocity_decay : the course's per-step factors γ on v and ω (1 = off),
        given at the step ``decay_dt_s``.
    decay_dt_s : s, the step at which the factors are the course's (the scenario's dt); required when
        a factor is not 1. The factors are the damping rates :meth:`decay_rates_per_s`
        (docs/semantics.md, "Velocity decay").
    springs, point_forces, torques : tuples of the above.
    """

    gravity_W: np.ndarray = field(default_factory=lambda: np.zeros(3))
    linear_drag_N_s_per_m: float = 0.0
    velocity_decay: float = 1.0
    angular_velocity_decay: float = 1.0
    decay_dt_s: float | None = None
    springs: tuple = ()
    point_forces: tuple = ()
    torques: tuple = ()

    def __post_init__(self):
        for name in ("velocity_decay", "angular_velocity_decay"):
            g = getattr(self, name)
            if not 0.0 < g <= 1.0:
                raise ValueError(f"{name} must be in (0, 1] (a per-step factor; 1 = off), got {g!r}")
        if self.has_decay and not (self.decay_dt_s is not None and self.decay_dt_s > 0.0):
            raise ValueError("decay_dt_s (the step at which the decay factors are given) must be > 0 when a "
                             f"decay factor is not 1, got {self.decay_dt_s!r}")

    # -- velocity decay: the course's per-step factor, as a rate ------------------------------------
    def decay_rates_per_s(self):
        """``(k_v, k_ω)`` (1/s): the continuous damping rates ``k = −ln γ / decay_dt_s`` (0 when off)."""
        if not self.has_decay:
            return 0.0, 0.0
        return (-math.log(self.velocity_decay) / self.decay_dt_s,
                -math.log(self.angular_velocity_decay) / self.decay_dt_s)

    def decay_factors(self, dt_s):
        """``(γ_v, γ_ω)`` per step of ``dt_s`` (s; a float or an array): ``e^{−k Δt} = γ^(Δt / decay_dt_s)``.

        At ``dt_s == decay_dt_s`` these are exactly the course's factors (bit for bit), so the course
        variants at the scenario's own step are the course's simulator.
        """
        if not self.has_decay:
            return 1.0, 1.0
        if np.ndim(dt_s) == 0 and float(dt_s) == self.decay_dt_s:
            return self.velocity_decay, self.angular_velocity_decay
        ratio = np.asarray(dt_s, dtype=float) / self.decay_dt_s
        gv = self.velocity_decay ** ratio if self.velocity_decay != 1.0 else 1.0
        gw = self.angular_velocity_decay ** ratio if self.angular_velocity_decay != 1.0 else 1.0
        if np.ndim(dt_s) == 0:
            return float(gv), float(gw)
        return gv, gw

    # -- classification used to pick references and engine force paths ---------------------------
    @property
    def has_decay(self) -> bool:
        return self.velocity_decay != 1.0 or self.angular_velocity_decay != 1.0

    @property
    def state_dependent(self) -> bool:
        """True when force or torque depends on the state (so it changes within a step)."""
        return bool(
            self.linear_drag_N_s_per_m != 0.0
            or self.springs
            or any(np.any(p.point_B != 0) or p.frame == "body" for p in self.point_forces)
            or any(t.frame == "body" for t in self.torques)
        )

    @property
    def torque_free(self) -> bool:
        """True when no force or torque produces a torque about the COM in any state."""
        return (
            not self.torques
            and all(np.all(s.attach_B == 0) for s in self.springs)
            and all(np.all(p.point_B == 0) for p in self.point_forces)
        )

    # -- evaluation ---------------------------------------------------------------------------------
    def force_torque(self, body: RigidBody, x_W, v_W, q_WB, R_WB=None):
        """Total world force (N) at the COM and world torque about the COM (N m), each ``(..., 3)``:
        :meth:`Members.force_torque` of this one body (the rotation of ``q_WB`` unless ``R_WB`` is given)."""
        shape = np.broadcast_shapes(np.shape(x_W), np.shape(v_W), np.shape(q_WB)[:-1] + (3,))
        R = matrix_from_quat(q_WB) if R_WB is None else np.asarray(R_WB, dtype=float)
        flat = [np.broadcast_to(np.asarray(a, dtype=float), shape).reshape(-1, 3) for a in (x_W, v_W)]
        R = np.broadcast_to(R, shape + (3,)).reshape(-1, 3, 3)
        f, tau = Members.stack([(body, self)]).force_torque(*flat, R)
        return f.reshape(shape).copy(), tau.reshape(shape).copy()

    def potential_energy_J(self, body: RigidBody, x_W, q_WB):
        """Gravity ``−m g·x`` plus spring ``½ k (L − L0)²`` potential energy (J), shape ``(...)``.

        Constant point forces and torques are not conservative in general and are left out; energy
        drift is reported only for scenarios where they are absent.
        """
        x_W = np.asarray(x_W, dtype=float)
        U = -body.mass_kg * (x_W @ np.asarray(self.gravity_W, dtype=float))
        for s in self.springs:
            d = x_W + rotate(q_WB, s.attach_B) - s.anchor_W
            L = np.linalg.norm(d, axis=-1)
            U = U + 0.5 * s.stiffness_N_per_m * (L - s.rest_length_m) ** 2
        return U

    @property
    def conservative(self) -> bool:
        """True when total energy (kinetic + gravity + springs) is a conserved quantity of the ODE."""
        return (self.linear_drag_N_s_per_m == 0.0 and not self.has_decay
                and not self.point_forces and not self.torques)


def _entries(lists, width: int) -> np.ndarray:
    """Per member a list of rows of ``width`` numbers -> (N, E, width), E the longest list; missing rows are
    zero (a zero spring, force or torque adds an exact 0)."""
    out = np.zeros((len(lists), max((len(e) for e in lists), default=0), width))
    for i, rows in enumerate(lists):
        for j, row in enumerate(rows):
            out[i, j] = np.concatenate([np.ravel(np.asarray(a, dtype=float)) for a in row])
    return out


@dataclass(frozen=True, eq=False)
class Members:
    """The parameters of N free-body problems, one row per member, so that N different problems (bodies,
    forces, decay) advance together through one evaluation of the equations (reference_sim.integrators).

    Arrays (N = number of members; a quantity of shape (N, 1) broadcasts against (N, 3) vectors):
    mass_kg (N, 1); inertia_B, inertia_inv_B (N, 3, 3) kg m², kg⁻¹ m⁻²; weight_W (N, 3) m g_W, N; force_W
    (N, 3) the sum of the world point forces applied at the COM, N;
    drag (N, 1) c, N s/m; decay_rates (N, 2) (k_v, k_ω), 1/s; decay_gamma (N, 2) the per-step factors γ
    given at decay_dt_s (N, 1) s; springs (N, S, 8) [anchor_W (m), attach_B (m), k (N/m), L0 (m)];
    world_points (N, P, 6) [f_W (N), r_B (m)] (the others); body_points (N, B, 6) [f_B (N), r_B (m)];
    torque_W, torque_B (N, 3) N m, the sums of the world- and body-axes torques. Shorter lists are padded
    with zero entries. With N = 1 every array broadcasts against states of any leading shape (one problem,
    many states).
    """

    mass_kg: np.ndarray
    inertia_B: np.ndarray
    inertia_inv_B: np.ndarray
    weight_W: np.ndarray
    force_W: np.ndarray
    drag: np.ndarray
    decay_rates: np.ndarray
    decay_gamma: np.ndarray
    decay_dt_s: np.ndarray
    springs: np.ndarray
    world_points: np.ndarray
    body_points: np.ndarray
    torque_W: np.ndarray
    torque_B: np.ndarray

    @classmethod
    def stack(cls, pairs) -> Members:
        """The members of ``pairs``, a sequence of ``(RigidBody, ForceModel)`` (or of Problems)."""
        pairs = [(p.body, p.forces) if hasattr(p, "forces") else p for p in pairs]
        bodies, fms = [b for b, _ in pairs], [f for _, f in pairs]
        col = lambda values: np.array(values, dtype=float).reshape(len(pairs), -1)  # noqa: E731
        torques = [[np.sum([t.torque for t in f.torques if t.frame == fr] or [np.zeros(3)], axis=0)
                    for f in fms] for fr in FRAMES]
        return cls(
            col([b.mass_kg for b in bodies]),
            np.array([b.inertia_B for b in bodies], dtype=float),
            np.array([b.inertia_inv_B for b in bodies], dtype=float),
            col([b.mass_kg * np.asarray(f.gravity_W, dtype=float) for b, f in pairs]),
            col([np.sum([p.force for p in f.point_forces if p.frame == "world" and not np.any(p.point_B)]
                        or [np.zeros(3)], axis=0) for f in fms]),
            col([f.linear_drag_N_s_per_m for f in fms]), col([f.decay_rates_per_s() for f in fms]),
            col([(f.velocity_decay, f.angular_velocity_decay) for f in fms]),
            col([f.decay_dt_s if f.has_decay else 1.0 for f in fms]),
            _entries([[(s.anchor_W, s.attach_B, s.stiffness_N_per_m, s.rest_length_m) for s in f.springs]
                      for f in fms], 8),
            _entries([[(p.force, p.point_B)
                       for p in f.point_forces if p.frame == "world" and np.any(p.point_B)]
                      for f in fms], 6),
            _entries([[(p.force, p.point_B) for p in f.point_forces if p.frame == "body"] for f in fms], 6),
            col(torques[0]), col(torques[1]))

    def __len__(self) -> int:
        return len(self.mass_kg)

    def take(self, idx) -> Members:
        """The members ``idx`` (an index array or list), in that order."""
        idx = np.atleast_1d(np.asarray(idx, dtype=int))
        return type(self)(*(getattr(self, f.name)[idx] for f in dataclasses.fields(self)))

    def decay_factors(self, h):
        """``(γ_v, γ_ω)`` per member (or per row, for one member and a step per row), each (N, 1), for a step
        ``h`` (s; a float or (N,)): ``γ^(h / decay_dt_s)``, exactly γ where ``h == decay_dt_s`` (as
        :meth:`ForceModel.decay_factors`); ``(1.0, 1.0)`` when no member decays."""
        if np.all(self.decay_gamma == 1.0):
            return 1.0, 1.0
        hs = np.asarray(h, dtype=float).reshape(-1)
        n = max(len(self), len(hs))
        rows = zip(np.broadcast_to(self.decay_gamma, (n, 2)).tolist(), np.broadcast_to(hs, (n,)).tolist(),
                   np.broadcast_to(self.decay_dt_s[:, 0], (n,)).tolist())
        # row by row in Python floats (libm's pow): NumPy's vectorised power may round differently with the
        # array's length, and a member's factors must not depend on the batch it is in
        g = np.array([[1.0 if c == 1.0 else c if hi == d else c ** (hi / d) for c in gamma]
                      for gamma, hi, d in rows])
        return g[:, 0:1], g[:, 1:2]

    def force_torque(self, x_W, v_W, R_WB, *, lever_rotated: bool = True, attach_rotated: bool = True,
                     torque_sign: float = 1.0):
        """World force (N) at the COM and world torque (N m) about it, each (N, 3) or (..., 3), at
        positions ``x_W``, velocities ``v_W`` and rotations ``R_WB`` (..., 3, 3). Sums, in this order:
        the weight plus the world forces at the COM, the drag ``−c v``, each spring
        ``f = −k (L − L0) d / L`` (``d = x + R r_B − anchor``, zero when ``L = 0``) with torque
        ``(R r_B) × f``, each world point force, each body point force ``R f_B`` (torque
        ``(R r_B) × f``), then the world torque and the body torque ``R τ_B``.

        The keywords compute a piece wrongly, for the catalog of classic mistakes
        (cross_checks.gates.check.mistakes): the lever arms ``r_B`` unrotated, the spring
        attachment at ``x + r_B``, the torques of springs and point forces times
        ``torque_sign`` (−1: ``f × r``, 0: none)."""
        shape = np.broadcast_shapes(self.weight_W.shape, np.shape(x_W), np.shape(R_WB)[:-1])
        f = np.broadcast_to(self.weight_W + self.force_W, shape)
        tau = np.broadcast_to(self.torque_W, shape)
        if np.any(self.drag):
            f = f - self.drag * v_W
        def lever(r_B):
            return matvec3(R_WB, r_B) if lever_rotated else r_B

        def moment(r, g):
            t = cross3(r, g)
            return t if torque_sign == 1.0 else torque_sign * t

        for j in range(self.springs.shape[1]):
            s = self.springs[:, j]
            r = matvec3(R_WB, s[:, 3:6])
            d = x_W + (r if attach_rotated else s[:, 3:6]) - s[:, 0:3]
            L = np.sqrt(d[..., 0:1] * d[..., 0:1] + d[..., 1:2] * d[..., 1:2] + d[..., 2:3] * d[..., 2:3])
            with np.errstate(invalid="ignore", divide="ignore"):
                fs = np.where(L > 0.0, -s[:, 6:7] * (L - s[:, 7:8]) / L, 0.0) * d
            f = f + fs
            tau = tau + moment(r if lever_rotated else s[:, 3:6], fs)
        for j in range(self.world_points.shape[1]):
            p = self.world_points[:, j]
            f = f + p[:, 0:3]
            tau = tau + moment(lever(p[:, 3:6]), p[:, 0:3])
        for j in range(self.body_points.shape[1]):
            p = self.body_points[:, j]
            g = matvec3(R_WB, p[:, 0:3])
            f = f + g
            tau = tau + moment(lever(p[:, 3:6]), g)
        if np.any(self.torque_B):
            tau = tau + matvec3(R_WB, self.torque_B)
        return f, tau

    def angular_acceleration(self, R_WB, w_W, tau_W, *, gyro: bool = True, world_solve: bool = False):
        """``I_W⁻¹ (τ − ω × I_W ω)`` (world axes, rad/s²) with ``I_W = R I_B Rᵀ``, computed in body axes where
        I_B is constant: ``R I_B⁻¹ (Rᵀτ − ω_B × I_B ω_B)`` with ``ω_B = Rᵀω`` (without the gyroscopic term
        when not ``gyro``). ``world_solve``: formed in world axes and solved, which differs when ``R`` is not
        a rotation (a step that does not renormalise q; cross_checks.gates.check.mistakes)."""
        if world_solve:
            I_W = R_WB @ self.inertia_B @ np.swapaxes(R_WB, -1, -2)
            b = tau_W - cross3(w_W, matvec3(I_W, w_W)) if gyro else tau_W
            return np.linalg.solve(I_W, b[..., None])[..., 0]
        tau_B = mat_t_vec3(R_WB, tau_W)
        if gyro:
            w_B = mat_t_vec3(R_WB, w_W)
            tau_B = tau_B - cross3(w_B, matvec3(self.inertia_B, w_B))
        return matvec3(R_WB, matvec3(self.inertia_inv_B, tau_B))
