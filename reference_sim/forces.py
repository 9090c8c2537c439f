"""Forces on a free rigid body, each giving a world force and a world torque about the COM.

Every force is evaluated from a state ``(x_W, v_W, q_WB)`` with any leading batch shape ``(...)``;
the torque of a force ``f_W`` applied at body point ``r_B`` is ``τ_W = (R r_B) × f_W`` (course).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from reference_sim.body import RigidBody
from reference_sim.quaternion import matrix_from_quat, rotate
from reference_sim.vec import cross3

__all__ = ["Spring", "PointForce", "Torque", "ForceModel", "FRAMES"]

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

    Attributes
    ----------
    gravity_W : (3,) m/s², uniform: acts at the COM, no torque.
    linear_drag_N_s_per_m : c in ``f = −c v_W`` at the COM.
    velocity_decay, angular_velocity_decay : the course's per-step factors γ on v and ω (1 = off),
        given at the step ``decay_dt_s``.
    decay_dt_s : s, the step at which the factors are the course's (the scenario's dt); required when
        a factor is not 1. Physically the factors are exponential damping at the rates
        ``k = −ln γ / decay_dt_s`` (1/s): ``v̇ = f/m − k_v v``, ``ω̇ = … − k_ω ω`` (see
        :meth:`decay_rates_per_s`); a scheme with step Δt applies :meth:`decay_factors` ``(Δt)`` per
        step, or puts the rates in its right-hand side.
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
        """Total world force (N) at the COM and world torque about the COM (N m), each ``(..., 3)``."""
        x_W = np.asarray(x_W, dtype=float)
        v_W = np.asarray(v_W, dtype=float)
        shape = np.broadcast_shapes(x_W.shape, v_W.shape, np.shape(q_WB)[:-1] + (3,))
        if R_WB is None:
            R_WB = matrix_from_quat(q_WB)
        f_W = np.broadcast_to(body.mass_kg * np.asarray(self.gravity_W, dtype=float), shape).copy()
        tau_W = np.zeros(shape)
        if self.linear_drag_N_s_per_m != 0.0:
            f_W -= self.linear_drag_N_s_per_m * v_W
        for s in self.springs:
            r_W = R_WB @ s.attach_B
            d = x_W + r_W - s.anchor_W
            L = np.linalg.norm(d, axis=-1, keepdims=True)
            with np.errstate(invalid="ignore", divide="ignore"):
                fs = np.where(L > 0.0, -s.stiffness_N_per_m * (L - s.rest_length_m) * d / L, 0.0)
            f_W += fs
            tau_W += cross3(r_W, fs)
        for p in self.point_forces:
            fp = (R_WB @ p.force) if p.frame == "body" else np.broadcast_to(p.force, shape)
            f_W += fp
            if np.any(p.point_B != 0):
                tau_W += cross3(R_WB @ p.point_B, fp)
        for t in self.torques:
            tau_W += (R_WB @ t.torque) if t.frame == "body" else t.torque
        return f_W, tau_W

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
        return self.linear_drag_N_s_per_m == 0.0 and not self.has_decay and not self.point_forces and not self.torques
