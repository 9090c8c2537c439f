"""DART (``dartpy``) as an engine (``dart:VARIANT``, float64): a world of free bodies for rbcheck's loop
(cross_checks.engines.world, cross_checks.engines.loop).

Each body alone in a DART ``World`` of its own (:class:`DartBody`): one ``FreeJoint``/``BodyNode`` pair, its
inertia ``Inertia(m, com_B = 0, I_B)`` (body origin = COM, the scenario's tensor as given), neutralised
(:data:`JOINT_SETTINGS`, :func:`neutralise`). State at the boundary: FreeJoint positions ``[r, x_W]`` (``r``
the rotation vector of R_WB) and velocities ``[ω_W, v_W]``, both in WORLD axes; the recorded quaternion is
sign-continuous from the scenario's initial one, recorded as given (the rotation vector's round trip is not
exact). The step is ``World::step`` (dart/simulation/World.cpp): semi-implicit Euler, explicit gyroscopic
term, exponential-map rotation — MuJoCo Euler's scheme, DART's only integrator. Forces: the loop's, set
before every step (DART clears them): the world force at the COM minus the weight ``m g``, then the world
torque (``setExtForce`` replaces the whole wrench); the decay by setting the velocities last read, scaled.
Divergence: the loop's (DART goes on after a blow-up).
Conventions, defaults neutralised and what pins them: docs/engine_conventions.md, "DART 6.x".
"""
from __future__ import annotations

import math

import numpy as np

from cross_checks.engines import base
from cross_checks.engines.base import EngineError, Variant
from cross_checks.engines.step_floats import bad_floats
from cross_checks.engines.world import World, WorldEngine
from reference_sim.quaternion import quat_exp, quat_log

dart, _IMPORT_ERROR = base.optional_import("dartpy")

__all__ = ["ENGINE", "VARIANTS", "JOINT_SETTINGS", "EngineError", "version", "simulate", "simulate_many",
           "one_step", "DartBody", "DartWorld", "DartAdapter", "neutralise", "to_dart_state",
           "from_dart_state"]

ENGINE = "dart"
#: DART's one integrator (``World::step``): semi-implicit Euler, first order.
VARIANTS = {
    "semi_implicit_euler": Variant(1, "DART World::step: semi-implicit Euler, explicit gyroscopic term (its "
                                      "own articulated-body dynamics), exponential-map rotation update with "
                                      "the new ω", traits=base.SYMPLECTIC_EULER_EXPLICIT_GYRO),
}

#: FreeJoint settings every body gets, set explicitly so that no release's default changes the physics:
#: (dartpy Joint setter, value for each of the 6 DOFs).
JOINT_SETTINGS = (
    ("setDampingCoefficient", 0.0), ("setSpringStiffness", 0.0), ("setRestPosition", 0.0),
    ("setCoulombFriction", 0.0), ("setPositionLowerLimit", -math.inf), ("setPositionUpperLimit", math.inf),
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
        p, body, world = scenario.problem, scenario.problem.body, dart.simulation.World()
        skeleton = dart.dynamics.Skeleton("body")
        joint, node = skeleton.createFreeJointAndBodyNodePair()
        c = getattr(scenario, "body_com_B_m", None)
        self.com_B = None if c is None else np.asarray(c, dtype=float)   # the body origin off the COM
        parts = getattr(scenario, "body_parts", ())
        inertias = ([(p_.mass_kg, p_.com_B_m, p_.inertia_B) for p_ in parts] if parts else
                    [(body.mass_kg, _ZERO3 if c is None else self.com_B, body.inertia_B)])
        nodes = [node]
        for _ in inertias[1:]:   # welded parts: WeldJoint children at the body frame itself
            _, child = skeleton.createWeldJointAndBodyNodePair(node)
            nodes.append(child)
        for n, (m, com, I) in zip(nodes, inertias):
            inertia = dart.dynamics.Inertia(float(m), np.asarray(com, dtype=float),
                                            np.asarray(I, dtype=float))
            if not inertia.verify():
                raise EngineError(f"DART {version()} rejects the inertia of scenario "
                                  f"{scenario.name!r} (dart::dynamics::Inertia::verify "
                                  "is false: a mass or moment that is not positive)")
            n.setInertia(inertia)
        world.addSkeleton(skeleton)
        world.setGravity(np.asarray(p.forces.gravity_W, dtype=float))   # the world's reaches its skeletons
        world.setTimeStep(float(dt_s))
        neutralise(world, joint, node)
        for child in nodes[1:]:
            child.setCollidable(False)
        self.world, self.skeleton, self.joint, self.node = world, skeleton, joint, node

    def set_state(self, y) -> None:
        """Put the body at the packed state ``y`` (13,)."""
        if self.com_B is not None:   # DART's state is the body origin's: x − R c, v − ω × R c
            from reference_sim.body import origin_state
            y = np.array(y, dtype=float)
            y[0:3], y[3:6] = origin_state(y, self.com_B)
        s = to_dart_state(y)
        self.skeleton.setPositions(s[0:6])
        self.skeleton.setVelocities(s[6:12])

    def read(self) -> list:
        """DART's state ``[r, x_W, ω_W, v_W]`` as 12 floats."""
        return self.skeleton.getPositions().tolist() + self.skeleton.getVelocities().tolist()

    def apply(self, f_W, tau_W) -> None:
        """World force ``f_W`` (N) at the COM and world torque ``tau_W`` (N m), for the next step only (DART
        clears them after it). ``setExtForce`` first: it replaces the whole external wrench."""
        if self.com_B is None:
            self.node.setExtForce(f_W, _ZERO3, False, True)
            self.node.setExtTorque(tau_W, False)
            return
        # the body origin off the COM: setExtTorque replaces the wrench's whole moment about the origin, the
        # one setExtForce's offset made too, so the force at the origin and the moment of f at the COM added
        r_W = self.node.getWorldTransform().rotation() @ self.com_B
        self.node.setExtForce(f_W, _ZERO3, False, True)
        self.node.setExtTorque(np.asarray(tau_W, dtype=float) + np.cross(r_W, np.asarray(f_W, dtype=float)),
                               False)


class DartWorld(World):
    """B bodies, each a :class:`DartBody`, stepped in turn. Raw rows: DART's ``[r, x_W, ω_W, v_W]`` (12). A
    body whose state blew up is not stepped again (DART would go on, warning on stderr; the loop ends its
    run)."""

    exact_start = True

    def __init__(self, requests, dt_s: float):
        super().__init__()
        self.bodies = [DartBody(r.scenario, dt_s) for r in requests]
        self.always = [r.scenario.problem.forces.state_dependent for r in requests]

    def set_state(self, y):
        for b, row in zip(self.bodies, y):
            b.set_state(row)
        self.live = [True] * len(self.bodies)

    def read(self):
        self.last = [b.read() for b in self.bodies]
        self.live = [not bad_floats(row) for row in self.last]   # DART's |r| ≤ π: the packed state's verdict
        return self.last

    def packed(self, raw):
        y = from_dart_state(raw)
        for k, b in enumerate(self.bodies):
            if b.com_B is not None:   # the COM's x and v from the body origin's
                from reference_sim.body import com_state
                yk = y[..., k, :]
                y[..., k, :] = com_state(yk[..., 0:3], yk[..., 3:6], yk[..., 6:10], yk[..., 10:13], b.com_B)
        return y

    def packed_row(self, raw):
        if any(b.com_B is not None for b in self.bodies):
            return self.packed(np.asarray(raw, dtype=float)[None])[0].tolist()
        return [_packed_floats(r) for r in np.asarray(raw).tolist()]

    def decay(self, g_v, g_w):
        """The velocities last read, scaled (the pose is not set again: its round trip is not exact); a body
        whose origin is off its COM: the COM's v and ω scaled, the origin's v = v − ω × R c set."""
        y_all = None
        for k, (b, prev, gv, gw) in enumerate(zip(self.bodies, self.last, g_v.tolist(), g_w.tolist())):
            if b.com_B is not None:
                if y_all is None:
                    y_all = self.packed(np.asarray(self.last, dtype=float)[None])[0]
                y = y_all[k]
                r_W = y[0:3] - np.asarray(prev[3:6])
                w, v = gw * y[10:13], gv * y[3:6]
                b.skeleton.setVelocities(np.concatenate([w, v - np.cross(w, r_W)]))
                continue
            b.skeleton.setVelocities(np.array(prev[6:12]) * (gw, gw, gw, gv, gv, gv))

    def apply(self, f_W, tau_W):
        """A zero wrench of state-independent forces is not set (DART clears them after every step)."""
        for b, live, always, f, tau in zip(self.bodies, self.live, self.always, f_W, tau_W):
            if live and (always or f.any() or tau.any()):
                b.apply(f, tau)

    def step(self):
        for b, live in zip(self.bodies, self.live):
            if live:
                b.world.step()


class DartEngine(WorldEngine):
    """``dart:VARIANT`` — registered under the entry-point group ``rbcheck.engines``; optional
    (``pip install 'rbcheck[dart]'``)."""

    name, variants = ENGINE, VARIANTS
    distribution, module, extra = "dartpy", "dartpy", "dart"
    #: the COM off the body origin (Inertia's local COM); welded parts (WeldJoint children)
    body_forms = frozenset({"com_offset", "welded_parts"})
    sign_continuity = True

    def version(self) -> str:
        return version()

    def build(self, requests, variant, dt_s):
        _require()
        return DartWorld(requests, dt_s)


_ENGINE = DartEngine()
simulate, simulate_many, one_step = _ENGINE.simulate, _ENGINE.simulate_many, _ENGINE.one_step
DartAdapter = DartEngine
