"""DART's world (``dartpy``, float64): numpy and dartpy only (``rbcheck repro`` embeds this file's code).

Each body alone in a DART ``World`` of its own: one ``FreeJoint``/``BodyNode`` pair, ``Inertia(m, com_B = 0,
I_B)`` (the full tensor as given), every joint default neutralised (:data:`JOINT_SETTINGS`,
:func:`neutralise`).
FreeJoint positions ``[r, x_W]`` (``r`` the rotation vector of R_WB) and velocities ``[ω_W, v_W]``, world
axes. Forces are cleared after every step (``apply`` before each one); a torque fixed in body axes is given
once (``apply_body_torque``) and set by ``apply`` before every step in the body's own axes
(``setExtTorque(τ_B, isLocal=True)``: DART turns it itself). A body whose origin is off its COM, or of
welded parts, is a :class:`FormBody` (:func:`form_world`): DART's x and v are then the origin's.
docs/engine_conventions.md, "DART".
"""
import math

import dartpy as dart
import numpy as np

from .com import com_state, origin_state

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


def quat_exp(rotvec):
    """Unit quaternions (w, x, y, z) of rotation vectors (..., 3) (rad); a series near zero."""
    rotvec = np.asarray(rotvec, dtype=float)
    theta = np.linalg.norm(rotvec, axis=-1)
    half = 0.5 * theta
    small = theta < 1e-4
    t2 = theta * theta
    sinc_half = np.where(small, 0.5 - t2 / 48.0 + t2 * t2 / 3840.0,
                         np.sin(half) / np.where(small, 1.0, theta))
    return np.concatenate([np.cos(half)[..., None], sinc_half[..., None] * rotvec], axis=-1)


def quat_log(q):
    """Rotation vectors θ u (rad, θ in [0, π]) of quaternions (..., 4) (w, x, y, z), q and −q alike."""
    q = np.asarray(q, dtype=float)
    n = np.linalg.norm(q, axis=-1)
    if np.any(~(n > 0.0)):
        raise ValueError("cannot normalise a zero (or non-finite) quaternion")
    q = q / n[..., None]
    first = np.argmax(q != 0.0, axis=-1)      # the sign making the first non-zero component positive
    lead = np.take_along_axis(q, first[..., None], axis=-1)[..., 0]
    q = q * np.where(lead < 0.0, -1.0, 1.0)[..., None]
    v = q[..., 1:]
    s = np.linalg.norm(v, axis=-1)
    angle = 2.0 * np.arctan2(s, q[..., 0])
    safe = s > 0.0
    axis = np.where(safe[..., None], v / np.where(safe, s, 1.0)[..., None], np.array([1.0, 0.0, 0.0]))
    return axis * angle[..., None]


def to_dart_state(y):
    """Packed states (..., 13) -> DART's FreeJoint ``[r, x_W, ω_W, v_W]`` (..., 12)."""
    y = np.asarray(y, dtype=float)
    return np.concatenate([quat_log(y[..., 6:10]), y[..., 0:3], y[..., 10:13], y[..., 3:6]], axis=-1)


def from_dart_state(s):
    """DART's FreeJoint states (..., 12) ``[r, x_W, ω_W, v_W]`` -> packed (..., 13) (w ≥ 0)."""
    s = np.asarray(s, dtype=float)
    return np.concatenate([s[..., 3:6], s[..., 9:12], quat_exp(s[..., 0:3]), s[..., 6:9]], axis=-1)


def neutralise(world, joint, node):
    """Every default of DART that is not the physics set to its neutral value, whatever it was: each of
    JOINT_SETTINGS on the 6 DOFs of ``joint``, its limit enforcement off, ``node`` not collidable, and the
    ``world``'s deactivation (sleeping) off."""
    for setter, value in JOINT_SETTINGS:
        for i in range(6):
            getattr(joint, setter)(i, value)
    joint.setLimitEnforcement(False)
    node.setCollidable(False)
    sleep = world.getDeactivationOptions()
    sleep.mEnabled = False
    world.setDeactivationOptions(sleep)


class Body:
    """A free body (mass kg, inertia kg m² (3, 3) in body axes about the COM) alone in a DART world under
    ``gravity_W`` at ``dt_s``; ``ok`` False when DART's ``Inertia::verify`` refuses the inertia."""

    def __init__(self, mass_kg, inertia_B, gravity_W, dt_s):
        world = dart.simulation.World()
        skeleton = dart.dynamics.Skeleton("body")
        joint, node = skeleton.createFreeJointAndBodyNodePair()
        inertia = dart.dynamics.Inertia(float(mass_kg), _ZERO3, np.asarray(inertia_B, dtype=float))
        self.ok = inertia.verify()
        node.setInertia(inertia)
        world.addSkeleton(skeleton)
        world.setGravity(np.asarray(gravity_W, dtype=float))   # the world's reaches its skeletons
        world.setTimeStep(float(dt_s))
        neutralise(world, joint, node)
        self.world, self.skeleton, self.joint, self.node = world, skeleton, joint, node

    def set_state(self, y):
        """Put the body at the packed state ``y`` (13,)."""
        s = to_dart_state(y)
        self.skeleton.setPositions(s[0:6])
        self.skeleton.setVelocities(s[6:12])

    def read(self):
        """DART's state ``[r, x_W, ω_W, v_W]`` as 12 floats."""
        return self.skeleton.getPositions().tolist() + self.skeleton.getVelocities().tolist()

    def apply(self, f_W, tau_W):
        """World force (N) at the COM and world torque (N m), for the next step only (DART clears them).
        ``setExtForce`` first: it replaces the whole external wrench."""
        self.node.setExtForce(f_W, _ZERO3, False, True)
        self.node.setExtTorque(tau_W, False)


class Bodies:
    """Bodies (each a :class:`Body`) stepped in turn; raw rows DART's ``[r, x_W, ω_W, v_W]`` (12)."""

    def __init__(self, bodies):
        self.bodies, self.always, self.live = bodies, [False] * len(bodies), [True] * len(bodies)
        self.torque_B = [None] * len(bodies)   # per body: its body-axes torque (N m), or None
        self._plan_of = self._tau_of = None     # the (f_W, tau_W) arrays the plan was made for
        self._plan = []
        # bound once: the per-step calls (a step of one body costs DART about 2 µs)
        self._steps = [b.world.step for b in bodies]
        self._reads = [(b.skeleton.getPositions, b.skeleton.getVelocities) for b in bodies]

    def set_state(self, y):
        for b, row in zip(self.bodies, y):
            b.set_state(row)
        self.live = [True] * len(self.bodies)

    def read(self):
        self.last = [pos().tolist() + vel().tolist() for pos, vel in self._reads]
        return self.last

    def packed(self, raw):
        return from_dart_state(raw)

    def decay(self, g_v, g_w):
        """The velocities last read, scaled (the pose is not set again: its round trip is not exact)."""
        for b, prev, gv, gw in zip(self.bodies, self.last, g_v.tolist(), g_w.tolist()):
            b.skeleton.setVelocities(np.array(prev[6:12]) * (gw, gw, gw, gv, gv, gv))

    def apply_body_torque(self, tau_B):
        """Torques fixed in body axes (B, 3) (N m), set with every following ``apply`` in the body's own
        axes (DART clears them after every step); a zero torque is not set."""
        self.torque_B = [np.array(t, dtype=float) if np.any(t != 0.0) else None
                         for t in np.asarray(tau_B, dtype=float)]
        self._plan_of = None

    def apply(self, f_W, tau_W):
        """World forces at the COMs (N) and world torques (N m), (B, 3), and the body-axes torques of
        ``apply_body_torque``, for the next step only. A zero wrench of state-independent forces is not set
        (DART clears them after every step). Planned once for the arrays given (the host loop gives the same
        arrays every step when the forces are constant)."""
        if f_W is not self._plan_of or tau_W is not self._tau_of:
            self._plan_of, self._tau_of = f_W, tau_W
            self._plan = []
            for k, (b, always, f, tau) in enumerate(zip(self.bodies, self.always,
                                                        np.asarray(f_W, dtype=float),
                                                        np.asarray(tau_W, dtype=float))):
                world = always or f.any() or tau.any()
                self._plan.append((k, b if world else None, f, tau, self.torque_B[k], b.node))
        live = self.live
        for k, b, f, tau, tau_B, node in self._plan:
            if live[k]:
                if b is not None:
                    b.apply(f, tau)
                    if tau_B is not None:
                        node.addExtTorque(tau_B, True)
                elif tau_B is not None:
                    node.setExtTorque(tau_B, True)

    def step(self):
        for step, live in zip(self._steps, self.live):
            if live:
                step()


def world(bodies, gravity_W, variant, dt_s):
    return Bodies([Body(mass_kg, inertia_B, gravity_W, dt_s) for mass_kg, inertia_B, _ in bodies])


class FormBody(Body):
    """:class:`Body` of ``body`` = ``(mass_kg, inertia_B (3, 3), None)`` that may also give its COM
    ``com_B`` (m, body axes from the body origin; None: at it) and welded parts (each ``(mass_kg, inertia_B,
    None, com_B)``: ``WeldJoint`` children at the body frame, each with its ``Inertia``'s local COM). DART's
    x and v are the origin's: the packed state's (the COM's) converted (worlds/com.py)."""

    def __init__(self, body, gravity_W, dt_s):
        super().__init__(body[0], body[1], gravity_W, dt_s)
        com = body[3] if len(body) > 3 else None
        self.com_B = None if com is None else np.asarray(com, dtype=float)
        parts = body[4] if len(body) > 4 else ()
        if parts or com is not None:
            inertias = [(p[0], p[3], p[1]) for p in parts] if parts else [(body[0], self.com_B, body[1])]
            nodes = [self.node]
            for _ in inertias[1:]:
                _, child = self.skeleton.createWeldJointAndBodyNodePair(self.node)
                child.setCollidable(False)
                nodes.append(child)
            for n, (m, c, inertia_B) in zip(nodes, inertias):
                inertia = dart.dynamics.Inertia(float(m), np.asarray(c, dtype=float),
                                                np.asarray(inertia_B, dtype=float))
                self.ok = self.ok and inertia.verify()
                n.setInertia(inertia)

    def set_state(self, y):
        """Put the body at the packed state ``y`` (13,) of its COM (DART's is the origin's)."""
        super().set_state(y if self.com_B is None else origin_state(y, self.com_B))

    def apply(self, f_W, tau_W):
        """World force ``f_W`` (N) at the COM and world torque ``tau_W`` (N m), for the next step only. With
        the origin off the COM, setExtTorque replaces the wrench's whole moment about the origin (the one
        setExtForce's offset made too), so the moment of f at the COM is added to it."""
        if self.com_B is None:
            super().apply(f_W, tau_W)
            return
        r_W = self.node.getWorldTransform().rotation() @ self.com_B
        self.node.setExtForce(f_W, _ZERO3, False, True)
        self.node.setExtTorque(np.asarray(tau_W, dtype=float) + np.cross(r_W, np.asarray(f_W, dtype=float)),
                               False)


class FormBodies(Bodies):
    """:class:`Bodies` of :class:`FormBody` (and :class:`Body`): a body whose origin is off its COM reads as
    its COM's state."""

    def packed(self, raw):
        y = from_dart_state(raw)
        for k, b in enumerate(self.bodies):
            if getattr(b, "com_B", None) is not None:
                y[..., k, :] = com_state(y[..., k, :], b.com_B)
        return y


def form_world(bodies, gravity_W, variant, dt_s):
    """:func:`world` of bodies that may have a COM off their origin or welded parts (:class:`FormBody`)."""
    return FormBodies([FormBody(b, gravity_W, dt_s) for b in bodies])
