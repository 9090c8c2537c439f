"""The classic mistakes of a course-style rigid-body step, as step functions ``rbcheck check`` can try.

Each :class:`Mistake` is the course's semi-implicit step
(``v += Δt f/m; x += Δt v; ω += Δt α; q += ½Δt [0, ω] q; q /= |q|``, with or without the gyroscopic
torque −ω × (I ω), velocity decay as ``e^{−kΔt}``) with ONE thing done wrong: the definition's course-type
step (reference_sim.integrators.course_type) with its knobs, or its parameters changed. The checker compares a
user's step with each of them from the user's own states, and names the mistake whose steps explain the
trajectory (see cross_checks.gates.check). Batched over rows: states ``y`` (N, 13) packed
[x_W, v_W, q_WB (w x y z), w_W]; ``h`` (s) a scalar or (N,).
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from reference_sim.integrators import course_type

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
BASES = {"with the gyroscopic term": Knobs(),
         "without the gyroscopic term (the course's step)": Knobs(gyro=0.0)}


def _members(problem, knobs: Knobs, h, n_rows: int):
    """The problem's parameters with the knobs' parameter mistakes: gravity's axes, the drag's sign, body and
    world frames swapped, the decay factor's power and (per step) its step."""
    m = problem.members
    change: dict = {}
    if knobs.gravity_axis == "swap_yz":
        change["weight_W"] = m.weight_W[:, [0, 2, 1]]
    if knobs.drag_sign != 1.0:
        change["drag"] = knobs.drag_sign * m.drag
    if knobs.frames_swapped:
        at_com = np.concatenate([m.force_W[:, None, :], np.zeros((len(m), 1, 3))], axis=-1)   # r_B = 0
        change.update(world_points=m.body_points,
                      body_points=np.concatenate([at_com, m.world_points], axis=1), force_W=0.0 * m.force_W,
                      torque_W=m.torque_B, torque_B=m.torque_W)
    if knobs.gyro == 1.0:   # only the gyroscopic term ω × I ω uses I_B itself (with q renormalised)
        if not knobs.normalise:
            raise ValueError("the gyroscopic sign is flipped through I_B, "
                             "which a world-axes solve does not allow")
        change["inertia_B"] = -m.inertia_B
    if knobs.decay_power != 1.0:
        change["decay_gamma"] = m.decay_gamma ** knobs.decay_power
    m = dataclasses.replace(m, **change) if change else m
    if knobs.decay_per_step:   # γ whatever the step: the factors' own step is each row's step
        m = m.take(np.zeros(n_rows, dtype=int)) if np.ndim(h) else m
        m = dataclasses.replace(m, decay_dt_s=np.broadcast_to(np.asarray(h, dtype=float).reshape(-1, 1),
                                                              m.decay_dt_s.shape).copy())
    return m


def course_step(scenario, y, h, knobs: Knobs = Knobs()):
    """One course-style step of ``h`` from each row of ``y`` (N, 13), computed as ``knobs`` say: the
    definition's course-type step (reference_sim.integrators.course_type) with its knobs set."""
    quat = {"left_world": "left", "right_world": "right", "left_body": "left_body"}[knobs.quat]
    return course_type(_members(scenario.problem, knobs, h, len(y)), np.asarray(y, dtype=float), h,
                       gyro=knobs.gyro != 0.0, expmap=False, quat=quat, quat_half=knobs.quat_half,
                       normalise=knobs.normalise, inertia=knobs.inertia, lever_rotated=knobs.lever_rotated,
                       attach_rotated=knobs.attach_rotated,
                       torque_sign=knobs.torque_sign if knobs.point_torque else 0.0)


# --- the catalog ------------------------------------------------------------------------------------

def _off_com(sc):
    fm = sc.problem.forces
    return (any(np.any(p.point_B != 0) for p in fm.point_forces)
            or any(np.any(s.attach_B != 0) for s in fm.springs))


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
    Mistake("gyroscopic term sign",
            "the gyroscopic term has the wrong sign: +ω × (Iω) where Euler's equations "
            "have −ω × (Iω)", {"gyro": 1.0}, lambda sc, h: _anisotropic(sc) and _rotates(sc),
            with_bases=False),
    Mistake("quaternion product order", "the quaternion update multiplies on the wrong side: q ⊗ [0, ω] with "
            "world ω (a world angular velocity needs [0, ω] ⊗ q)", {"quat": "right_world"},
            lambda sc, h: _rotates(sc)),
    Mistake("angular velocity frame", "ω is taken in the wrong frame: body-axes ω in the world-frame update "
            "[0, ω] ⊗ q", {"quat": "left_body"}, lambda sc, h: _rotates(sc)),
    Mistake("inertia not rotated",
            "the inertia is not rotated into world axes: I_body is used with world ω and "
            "τ (needs I = R I_body Rᵀ)", {"inertia": "body"},
            lambda sc, h: _anisotropic(sc) and _rotates(sc)),
    Mistake("inertia rotated backwards", "the inertia is rotated the wrong way: Rᵀ I_body R instead of "
            "R I_body Rᵀ", {"inertia": "transposed"}, lambda sc, h: _anisotropic(sc) and _rotates(sc)),
    Mistake("torque cross product order",
            "the torque is f × r instead of r × f (every applied torque has the "
            "wrong sign)", {"torque_sign": -1.0}, lambda sc, h: _off_com(sc)),
    Mistake("lever arm not rotated", "the lever arm is not rotated: τ = r_body × f instead of (R r_body) × f",
            {"lever_rotated": False}, lambda sc, h: _off_com(sc)),
    Mistake("torque of point forces missing", "forces applied at a point off the centre of mass produce no "
            "torque (τ = r × f left out)", {"point_torque": False}, lambda sc, h: _off_com(sc)),
    Mistake("force or torque frame", "body-frame torques or forces are applied in world axes (or world ones "
            "in body axes)", {"frames_swapped": True},
            lambda sc, h: bool(sc.problem.forces.torques
                               or any(p.frame == "body" for p in sc.problem.forces.point_forces))),
    Mistake("spring attachment not rotated", "the spring's attachment point is not rotated with the body "
            "(x + r_body instead of x + R r_body)", {"attach_rotated": False},
            lambda sc, h: any(np.any(s.attach_B != 0) for s in sc.problem.forces.springs)),
    Mistake("missing ½ in the quaternion update",
            "the quaternion update lacks the ½: q + Δt [0, ω] q turns the "
            "body twice as fast (q̇ = ½ [0, ω] q)", {"quat_half": 1.0}, lambda sc, h: _rotates(sc)),
    Mistake("quaternion not normalised",
            "the quaternion is not renormalised after the update: |q| drifts from 1", {"normalise": False},
            lambda sc, h: _rotates(sc)),
    Mistake("decay applied twice", "the velocity decay is applied twice per step", {"decay_power": 2.0},
            lambda sc, h: _decay(sc)),
    Mistake("decay missing", "the velocity decay is not applied",
            {"decay_power": 0.0}, lambda sc, h: _decay(sc)),
    Mistake("decay per step at another Δt", "the per-step decay factor γ is applied at a Δt other than the "
            "scenario's: γ is frame-rate dependent (use e^(−kΔt) with k = −ln γ / dt)",
            {"decay_per_step": True},
            lambda sc, h: _decay(sc) and not math.isclose(float(np.max(h)), sc.dt_s, rel_tol=1e-9)),
    Mistake("drag sign", "the linear drag pushes along the velocity (f = +c v instead of −c v)",
            {"drag_sign": -1.0}, lambda sc, h: sc.problem.forces.linear_drag_N_s_per_m != 0.0),
    Mistake("gravity axis", "gravity acts along the wrong axis (a y-up / z-up mix-up)",
            {"gravity_axis": "swap_yz"},
            lambda sc, h: bool(np.asarray(sc.problem.forces.gravity_W)[1]
                               != np.asarray(sc.problem.forces.gravity_W)[2])),
)


def applicable_mistakes(scenario, h):
    """The catalog entries that can show on ``scenario`` at step ``h`` (s)."""
    return [m for m in CATALOG if m.applies(scenario, h)]
