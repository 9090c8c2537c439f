"""DART (``dartpy``) as an engine adapter (``dart:VARIANT``, float64); the interface is
cross_checks.engines.base.

One ``World`` per run holding one ``FreeJoint``/``BodyNode`` pair, its inertia ``Inertia(m, com_B = 0, I_B)``
(body origin = COM, the scenario's tensor as given), neutralised (:data:`JOINT_SETTINGS`, :func:`neutralise`).
State at the boundary: FreeJoint positions ``[r, x_W]`` (``r`` the rotation vector of R_WB) and velocities
``[ω_W, v_W]``, both in WORLD axes; the recorded quaternion is sign-continuous from the scenario's initial
one. The step is ``World::step`` (dart/simulation/World.cpp): semi-implicit Euler, explicit gyroscopic term,
exponential-map rotation — MuJoCo Euler's scheme, DART's only integrator. Forces: before every step (DART
clears them) the harness's world force at the COM minus the weight ``m g``, then the world torque
(``setExtForce`` replaces the whole wrench), from the start-of-step state; the decay before the step
(base.apply_decay_prestep). Divergence: DART goes on after a blow-up, so the state is checked after every
step and the first bad one (non-finite or beyond BLOWUP_LIMIT) ends the run.
Conventions, defaults neutralised and what pins them: docs/engine_conventions.md, "DART 6.x".
"""
from __future__ import annotations

import math

import numpy as np

from cross_checks.engines import base
from cross_checks.engines.base import EngineError, ModuleAdapter, Variant
from cross_checks.engines.step_floats import bad_floats, harness_fn
from reference_sim.quaternion import quat_exp, quat_log, same_side, sign_continuous
from reference_sim.simulate import Run, blowup_words, diverged

dart, _IMPORT_ERROR = base.optional_import("dartpy")

__all__ = ["ENGINE", "VARIANTS", "JOINT_SETTINGS", "EngineError", "version", "simulate", "one_step",
           "DartBody", "DartAdapter", "neutralise", "to_dart_state", "from_dart_state",
           ]

ENGINE = "dart"
#: DART's one integrator (``World::step``): semi-implicit Euler, first order.
VARIANTS = {
    "semi_implicit_euler": Variant(1,
                                   "DART World::step: semi-implicit Euler, explicit "
                                   "gyroscopic term (its own articulated-body dynamics), "
                                   "exponential-map rotation update with the new ω",
                                   traits=base.SYMPLECTIC_EULER_EXPLICIT_GYRO),
}

#: FreeJoint settings every body gets, set explicitly so that no release's default changes the physics:
#: (dartpy Joint setter, value for each of the 6 DOFs).
JOINT_SETTINGS = (
    ("setDampingCoefficient", 0.0),
    ("setSpringStiffness", 0.0),
    ("setRestPosition", 0.0),
    ("setCoulombFriction", 0.0),
    ("setPositionLowerLimit", -math.inf), ("setPositionUpperLimit", math.inf),
    ("setVelocityLowerLimit", -math.inf), ("setVelocityUpperLimit", math.inf),
    ("setAccelerationLowerLimit", -math.inf), ("setAccelerationUpperLimit", math.inf),
    ("setForceLowerLimit", -math.inf), ("setForceUpperLimit", math.inf),
)

_ZERO3 = np.zeros(3)


def _require():
    base.require(dart, _IMPORT_ERROR, "dartpy", hint="pip install 'rbcheck[dart]'")


def version() -> str:
    """The installed dartpy distribution's version (EngineNotInstalled when it is absent)."""
    _require()
    return base.release("dartpy")


# --- state conversion (the boundary) --------------------------------------------------------------------

def to_dart_state(y):
    """Packed states (..., 13) ``[x_W, v_W, q_WB (w x y z), ω_W]`` -> DART's FreeJoint ``[r, x_W, ω_W, v_W]``
    (..., 12), ``r`` the rotation vector of q_WB (rad)."""
    y = np.asarray(y, dtype=float)
    return np.concatenate([quat_log(y[..., 6:10]), y[..., 0:3], y[..., 10:13], y[..., 3:6]], axis=-1)


def from_dart_state(s):
    """DART's FreeJoint states (..., 12) ``[r, x_W, ω_W, v_W]`` -> packed (..., 13); the quaternion is
    ``quat_exp(r)`` (w ≥ 0: see :func:`reference_sim.quaternion.sign_continuous`)."""
    s = np.asarray(s, dtype=float)
    return np.concatenate([s[..., 3:6], s[..., 9:12], quat_exp(s[..., 0:3]), s[..., 6:9]], axis=-1)



def neutralise(world, joint, node) -> None:
    """Set every default of DART that is not the scenario's physics to its neutral value, whatever it was:
    each of JOINT_SETTINGS on the 6 DOFs of ``joint``, its limit enforcement off, ``node`` not collidable,
    and the ``world``'s deactivation (sleeping) off."""
    for setter, value in JOINT_SETTINGS:
        for i in range(6):
            getattr(joint, setter)(i, value)
    joint.setLimitEnforcement(False)
    node.setCollidable(False)
    sleep = world.getDeactivationOptions()
    sleep.mEnabled = False
    world.setDeactivationOptions(sleep)


def _packed_floats(row) -> list:
    """One DART state (12 floats ``[r, x_W, ω_W, v_W]``) -> the packed state (13 floats) for the force
    evaluation of the next step: :func:`from_dart_state` in plain floats (the quaternion's sign does not
    matter to a force)."""
    r0, r1, r2, x0, x1, x2, w0, w1, w2, v0, v1, v2 = row
    theta = math.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
    if theta < 1e-4:     # sin(θ/2)/θ by its series, as reference_sim.quaternion.quat_exp
        t2 = theta * theta
        s = 0.5 - t2 / 48.0 + t2 * t2 / 3840.0
    else:
        s = math.sin(0.5 * theta) / theta
    return [x0, x1, x2, v0, v1, v2, math.cos(0.5 * theta), s * r0, s * r1, s * r2, w0, w1, w2]


class DartBody:
    """A scenario's free body alone in a DART world stepping at ``dt_s``; ``set_state``/``read`` at the
    boundary."""

    def __init__(self, scenario, dt_s: float):
        _require()
        p = scenario.problem
        body = p.body
        world = dart.simulation.World()
        skeleton = dart.dynamics.Skeleton("body")
        joint, node = skeleton.createFreeJointAndBodyNodePair()
        inertia = dart.dynamics.Inertia(float(body.mass_kg), _ZERO3, np.asarray(body.inertia_B, dtype=float))
        if not inertia.verify():
            raise EngineError(f"DART {version()} rejects the inertia of scenario "
                              f"{scenario.name!r} (dart::dynamics::Inertia::verify "
                              "is false: a mass or moment that is not positive)")
        node.setInertia(inertia)
        world.addSkeleton(skeleton)
        # the world's gravity reaches its skeletons
        world.setGravity(np.asarray(p.forces.gravity_W, dtype=float))
        world.setTimeStep(float(dt_s))
        neutralise(world, joint, node)
        self.world, self.skeleton, self.joint, self.node = world, skeleton, joint, node
        self.weight = (body.mass_kg * np.asarray(p.forces.gravity_W, dtype=float)).tolist()

    def set_state(self, y) -> None:
        """Put the body at the packed state ``y`` (13,)."""
        s = to_dart_state(y)
        self.skeleton.setPositions(s[0:6])
        self.skeleton.setVelocities(s[6:12])

    def read(self) -> list:
        """DART's state ``[r, x_W, ω_W, v_W]`` as 12 floats."""
        return self.skeleton.getPositions().tolist() + self.skeleton.getVelocities().tolist()

    def apply(self, f_W, tau_W) -> None:
        """World force ``f_W`` (N) at the COM and world torque ``tau_W`` (N m), for the next step only (DART
        clears them after it). ``setExtForce`` first: it replaces the whole external wrench."""
        self.node.setExtForce(f_W, _ZERO3, False, True)
        self.node.setExtTorque(tau_W, False)


def _model(scenario, variant: str, dt_s: float) -> DartBody:
    base.check_variant(ENGINE, VARIANTS, variant)
    return DartBody(scenario, dt_s)


def _recorded(rows, y0, dt_s: float, why: str = "") -> Run:
    """The Run of DART states ``rows`` (steps 1..n, 12 floats each) after the initial packed state ``y0``:
    the quaternions continuous from y0's; ``why`` non-empty: the run diverged in step n + 1."""
    y = np.empty((len(rows) + 1, 13))
    y[0] = y0
    if rows:
        y[1:] = from_dart_state(np.array(rows))
        y[1:, 6:10] = sign_continuous(y[1:, 6:10], first=y0[6:10])
    if why:
        return diverged(y, dt_s, why)
    return Run(dt_s * np.arange(len(y)), y)


def simulate(scenario, variant: str, dt_s: float, n_steps: int) -> Run:
    """Free run of ``n_steps`` steps of ``dt_s`` from the scenario's initial state, every step recorded."""
    B = _model(scenario, variant, dt_s)
    y0 = scenario.problem.initial_packed()
    B.set_state(y0)
    forces = scenario.problem.forces
    state_dependent, decay = forces.state_dependent, forces.has_decay
    harness = harness_fn(scenario, dt_s)
    gv, gw = (float(g) for g in base.decay_factors(scenario, dt_s))
    wx, wy, wz = B.weight
    fx, fy, fz, tx, ty, tz = harness([float(v) for v in y0])
    f, tau = np.array([fx - wx, fy - wy, fz - wz]), np.array([tx, ty, tz])
    applies = bool(np.any(f != 0.0) or np.any(tau != 0.0)) or state_dependent
    step, positions, velocities = B.world.step, B.skeleton.getPositions, B.skeleton.getVelocities
    set_velocities, apply = B.skeleton.setVelocities, B.apply
    rows: list = []
    prev = B.read()
    for _ in range(n_steps):
        if state_dependent and rows:
            fx, fy, fz, tx, ty, tz = harness(_packed_floats(prev))
            f, tau = np.array([fx - wx, fy - wy, fz - wz]), np.array([tx, ty, tz])
        if decay:
            set_velocities(np.array(prev[6:12]) * (gw, gw, gw, gv, gv, gv))
        if applies:
            apply(f, tau)
        step()
        prev = positions().tolist() + velocities().tolist()
        if bad_floats(prev):     # DART's state: its packed state's verdict (|r| ≤ π, |q| = 1 never exceed it)
            return _recorded(rows, y0, dt_s, f" ({blowup_words(prev)})")
        rows.append(prev)
    return _recorded(rows, y0, dt_s)


@base.on_rows
def one_step(scenario, variant: str, dt_s: float, y_start) -> np.ndarray:
    """One step of ``dt_s`` from each row of ``y_start`` (T, 13): the forces from the row, the pre-step
    decay, the state set per row. A row whose step blows up comes back as DART left it."""
    B = _model(scenario, variant, dt_s)
    y_dec = base.apply_decay_prestep(scenario, y_start, dt_s)
    harness = harness_fn(scenario, dt_s)
    wx, wy, wz = B.weight
    out = np.empty((len(y_start), 12))
    for i, y in enumerate(y_start.tolist()):
        fx, fy, fz, tx, ty, tz = harness(y)
        B.set_state(y_dec[i])
        B.apply(np.array([fx - wx, fy - wy, fz - wz]), np.array([tx, ty, tz]))
        B.world.step()
        out[i] = B.read()
    y = from_dart_state(out)
    y[:, 6:10] = same_side(y[:, 6:10], y_start[:, 6:10])
    return y


class DartAdapter(ModuleAdapter):
    """``dart:VARIANT`` — registered under the entry-point group ``rbcheck.engines``; optional
    (``pip install 'rbcheck[dart]'``)."""

    def engine_files(self) -> list:
        """dartpy's compiled module (a rebuilt or reinstalled dartpy is a new engine)."""
        return base.library_files(dart)
