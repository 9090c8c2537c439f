"""The classic mistakes of a course-style rigid-body step, as step functions ``rbcheck check`` can try.

Each :class:`Mistake` is the course's semi-implicit step (``v += Δt f/m; x += Δt v; ω += Δt α;
q += ½Δt [0, ω] q; q /= |q|``, with or without the gyroscopic torque −ω × (I ω), velocity decay as
``e^{−kΔt}``) with ONE thing done wrong, written from the equations (not from the reference
integrators): the checker compares a user's step with each of them from the user's own states, and
names the mistake whose steps explain the trajectory (see cross_checks.gates.check). Batched over rows: states
``y`` (N, 13) packed [x_W, v_W, q_WB (w x y z), w_W]; ``h`` (s) a scalar or (N,).
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from reference_sim.quaternion import matrix_from_quat, quat_mul
from reference_sim.state import Q, V, W, X
from reference_sim.vec import cross3

__all__ = ["Knobs", "Mistake", "CATALOG", "applicable_mistakes", "course_step", "BASES"]


@dataclass(frozen=True)
class Knobs:
    """How a course-style step computes each piece (defaults: the correct step with gyroscopic term).

    gyro : coefficient c of ω × (I ω) in the torque (−1 correct, 0 missing as in the course, +1 flipped).
    inertia : "world" (I_W = R I_B Rᵀ), "body" (I_B used with world vectors), "transposed" (Rᵀ I_B R).
    quat : "left_world" ([0, ω_W] ⊗ q), "right_world" (q ⊗ [0, ω_W]), "left_body" ([0, Rᵀω_W] ⊗ q).
    quat_half : the factor of Δt in the quaternion update (½ correct).
    normalise : renormalise q after the update.
    torque_sign : τ = torque_sign · (r × f) for forces at body points.
    lever_rotated : r_W = R r_B (False: the body-coordinates lever r_B used as world).
    point_torque : include the torques of forces at body points and springs.
    frames_swapped : body-frame torques/forces applied in world axes and world ones in body axes.
    attach_rotated : spring attachment at x + R r_B (False: x + r_B).
    decay_power : velocity decay e^{−power k Δt} (1 correct, 2 applied twice, 0 missing).
    decay_per_step : apply the scenario's per-step factor γ whatever Δt is (frame-rate dependent).
    drag_sign : sign of the linear drag force (+1: f = −c v).
    gravity_axis : "" (as given) or "swap_yz" (a y-up / z-up mix-up).
    """

    gyro: float = -1.0
    inertia: str = "world"
    quat: str = "left_world"
    quat_half: float = 0.5
    normalise: bool = True
    torque_sign: float = 1.0
    lever_rotated: bool = True
    point_torque: bool = True
    frames_swapped: bool = False
    attach_rotated: bool = True
    decay_power: float = 1.0
    decay_per_step: bool = False
    drag_sign: float = 1.0
    gravity_axis: str = ""


#: The two correct bases a mistake is made on: the course's step with the gyroscopic term, and the
#: course's own step without it.
BASES = {"with the gyroscopic term": Knobs(), "without the gyroscopic term (the course's step)": Knobs(gyro=0.0)}


def _frame_vec(R, vec, frame, knobs):
    body = (frame == "body") != knobs.frames_swapped
    return np.einsum("...ij,j->...i", R, vec) if body else np.broadcast_to(np.asarray(vec, float), R.shape[:-1])


def _lever(R, r_B, knobs):
    return np.einsum("...ij,j->...i", R, r_B) if knobs.lever_rotated else np.broadcast_to(r_B, R.shape[:-1])


def _gravity(g, knobs):
    g = np.asarray(g, dtype=float)
    return g[[0, 2, 1]] if knobs.gravity_axis == "swap_yz" else g


def forces(scenario, knobs: Knobs, x, v, R):
    """World force (N) at the COM and world torque (N m) about it, with the knobs' mistakes."""
    p = scenario.problem
    fm, m = p.forces, p.body.mass_kg
    f = np.broadcast_to(m * _gravity(fm.gravity_W, knobs), x.shape).copy()
    tau = np.zeros_like(f)
    if fm.linear_drag_N_s_per_m:
        f -= knobs.drag_sign * fm.linear_drag_N_s_per_m * v
    for s in fm.springs:
        attach = np.einsum("...ij,j->...i", R, s.attach_B) if knobs.attach_rotated else s.attach_B
        d = x + attach - s.anchor_W
        L = np.linalg.norm(d, axis=-1, keepdims=True)
        with np.errstate(invalid="ignore", divide="ignore"):
            fs = np.where(L > 0.0, -s.stiffness_N_per_m * (L - s.rest_length_m) * d / L, 0.0)
        f += fs
        if knobs.point_torque and np.any(s.attach_B != 0):
            tau += knobs.torque_sign * cross3(_lever(R, s.attach_B, knobs), fs)
    for pf in fm.point_forces:
        fp = _frame_vec(R, pf.force, pf.frame, knobs)
        f += fp
        if knobs.point_torque and np.any(pf.point_B != 0):
            tau += knobs.torque_sign * cross3(_lever(R, pf.point_B, knobs), fp)
    for t in fm.torques:
        tau += _frame_vec(R, t.torque, t.frame, knobs)
    return f, tau


def _inertia(body, R, knobs):
    """(I, I⁻¹) as the knobs compute them, (..., 3, 3); I⁻¹ by inversion, as a student's code does (R
    need not be orthogonal when q is not normalised)."""
    I_B = body.inertia_B
    Rt = np.swapaxes(R, -1, -2)
    if knobs.inertia == "body":
        return np.broadcast_to(I_B, R.shape), np.broadcast_to(body.inertia_inv_B, R.shape)
    I = Rt @ I_B @ R if knobs.inertia == "transposed" else R @ I_B @ Rt
    return I, np.linalg.inv(I)


def _decay_factors(scenario, knobs, h):
    fm = scenario.problem.forces
    if knobs.decay_per_step:
        return fm.velocity_decay ** knobs.decay_power, fm.angular_velocity_decay ** knobs.decay_power
    k_v, k_w = scenario.problem.forces.decay_rates_per_s()
    return np.exp(-knobs.decay_power * k_v * h), np.exp(-knobs.decay_power * k_w * h)


def course_step(scenario, y, h, knobs: Knobs = Knobs()):
    """One course-style step of ``h`` from each row of ``y`` (N, 13), computed as ``knobs`` say."""
    body = scenario.problem.body
    hh = np.asarray(h, dtype=float)[..., None] if np.ndim(h) else float(h)
    x, v, q, w = y[..., X], y[..., V], y[..., Q], y[..., W]
    # a step that never normalises also builds R from the stored, non-unit q (the course formula)
    R = matrix_from_quat(q / np.linalg.norm(q, axis=-1, keepdims=True) if knobs.normalise else q)
    f, tau = forces(scenario, knobs, x, v, R)
    gv, gw = _decay_factors(scenario, knobs, hh)
    v1 = gv * (v + hh * f / body.mass_kg)
    x1 = x + hh * v1
    I, I_inv = _inertia(body, R, knobs)
    L = np.einsum("...ij,...j->...i", I, w)
    alpha = np.einsum("...ij,...j->...i", I_inv, tau + knobs.gyro * cross3(w, L))
    w1 = gw * (w + hh * alpha)
    if knobs.quat == "left_body":
        w_used = np.einsum("...ji,...j->...i", R, w1)
    else:
        w_used = w1
    omega = np.concatenate([np.zeros(w1.shape[:-1] + (1,)), knobs.quat_half * hh * w_used], axis=-1)
    q1 = q + (quat_mul(q, omega) if knobs.quat == "right_world" else quat_mul(omega, q))
    if knobs.normalise:
        q1 = q1 / np.linalg.norm(q1, axis=-1, keepdims=True)
    return np.concatenate([x1, v1, q1, w1], axis=-1)


# --- the catalog ------------------------------------------------------------------------------------

def _off_com(sc):
    fm = sc.problem.forces
    return any(np.any(p.point_B != 0) for p in fm.point_forces) or any(np.any(s.attach_B != 0) for s in fm.springs)


def _anisotropic(sc):
    m = np.linalg.eigvalsh(sc.problem.body.inertia_B)
    return bool(m[-1] - m[0] > 1e-12 * m[-1])


def _rotates(sc):
    p = sc.problem
    return bool(np.any(p.initial.w_W != 0) or p.forces.torques or _off_com(sc))


def _decay(sc):
    fm = sc.problem.forces
    return fm.velocity_decay != 1.0 or fm.angular_velocity_decay != 1.0


@dataclass(frozen=True)
class Mistake:
    """One classic mistake: a short name, the sentence said to the user, the knobs, and when it can
    show at all (``applies(scenario, h)``)."""

    name: str
    sentence: str
    knobs: dict
    applies: object
    with_bases: bool = True

    def variants(self):
        """``[(label, Knobs)]``: the mistake on each correct base (or alone when it sets the gyro)."""
        if not self.with_bases:
            return [(self.name, dataclasses.replace(Knobs(), **self.knobs))]
        return [(f"{self.name} ({b})", dataclasses.replace(k, **self.knobs)) for b, k in BASES.items()]


CATALOG = (
    Mistake("gyroscopic term sign", "the gyroscopic term has the wrong sign: +ω × (Iω) where Euler's equations "
            "have −ω × (Iω)", {"gyro": 1.0}, lambda sc, h: _anisotropic(sc) and _rotates(sc), with_bases=False),
    Mistake("quaternion product order", "the quaternion update multiplies on the wrong side: q ⊗ [0, ω] with "
            "world ω (a world angular velocity needs [0, ω] ⊗ q)", {"quat": "right_world"}, lambda sc, h: _rotates(sc)),
    Mistake("angular velocity frame", "ω is taken in the wrong frame: body-axes ω in the world-frame update "
            "[0, ω] ⊗ q", {"quat": "left_body"}, lambda sc, h: _rotates(sc)),
    Mistake("inertia not rotated", "the inertia is not rotated into world axes: I_body is used with world ω and "
            "τ (needs I = R I_body Rᵀ)", {"inertia": "body"}, lambda sc, h: _anisotropic(sc) and _rotates(sc)),
    Mistake("inertia rotated backwards", "the inertia is rotated the wrong way: Rᵀ I_body R instead of "
            "R I_body Rᵀ", {"inertia": "transposed"}, lambda sc, h: _anisotropic(sc) and _rotates(sc)),
    Mistake("torque cross product order", "the torque is f × r instead of r × f (every applied torque has the "
            "wrong sign)", {"torque_sign": -1.0}, lambda sc, h: _off_com(sc)),
    Mistake("lever arm not rotated", "the lever arm is not rotated: τ = r_body × f instead of (R r_body) × f",
            {"lever_rotated": False}, lambda sc, h: _off_com(sc)),
    Mistake("torque of point forces missing", "forces applied at a point off the centre of mass produce no "
            "torque (τ = r × f left out)", {"point_torque": False}, lambda sc, h: _off_com(sc)),
    Mistake("force or torque frame", "body-frame torques or forces are applied in world axes (or world ones "
            "in body axes)", {"frames_swapped": True},
            lambda sc, h: bool(sc.problem.forces.torques or any(p.frame == "body" for p in sc.problem.forces.point_forces))),
    Mistake("spring attachment not rotated", "the spring's attachment point is not rotated with the body "
            "(x + r_body instead of x + R r_body)", {"attach_rotated": False},
            lambda sc, h: any(np.any(s.attach_B != 0) for s in sc.problem.forces.springs)),
    Mistake("missing ½ in the quaternion update", "the quaternion update lacks the ½: q + Δt [0, ω] q turns the "
            "body twice as fast (q̇ = ½ [0, ω] q)", {"quat_half": 1.0}, lambda sc, h: _rotates(sc)),
    Mistake("quaternion not normalised", "the quaternion is not renormalised after the update: |q| drifts from 1",
            {"normalise": False}, lambda sc, h: _rotates(sc)),
    Mistake("decay applied twice", "the velocity decay is applied twice per step", {"decay_power": 2.0},
            lambda sc, h: _decay(sc)),
    Mistake("decay missing", "the velocity decay is not applied", {"decay_power": 0.0}, lambda sc, h: _decay(sc)),
    Mistake("decay per step at another Δt", "the per-step decay factor γ is applied at a Δt other than the "
            "scenario's: γ is frame-rate dependent (use e^(−kΔt) with k = −ln γ / dt)", {"decay_per_step": True},
            lambda sc, h: _decay(sc) and not math.isclose(float(np.max(h)), sc.dt_s, rel_tol=1e-9)),
    Mistake("drag sign", "the linear drag pushes along the velocity (f = +c v instead of −c v)", {"drag_sign": -1.0},
            lambda sc, h: sc.problem.forces.linear_drag_N_s_per_m != 0.0),
    Mistake("gravity axis", "gravity acts along the wrong axis (a y-up / z-up mix-up)", {"gravity_axis": "swap_yz"},
            lambda sc, h: bool(np.asarray(sc.problem.forces.gravity_W)[1] != np.asarray(sc.problem.forces.gravity_W)[2])),
)


def applicable_mistakes(scenario, h):
    """The catalog entries that can show on ``scenario`` at step ``h`` (s)."""
    return [m for m in CATALOG if m.applies(scenario, h)]
