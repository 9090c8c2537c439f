"""PyBullet's world of free bodies (numpy and pybullet only: ``rbcheck repro`` embeds this file's code).

A body is a ``createMultiBody`` without collision shape (maximal coordinates for ``maximal``), damping zeroed,
no velocity clamp, sleeping disabled (:data:`DYNAMICS_SETTINGS`). PyBullet takes a diagonal inertia and
reports the inertial (principal) frame P as the base pose, so the boundary rotates: ``q_WP = q_WB ⊗ q_BP``
in, ``q_WB = q_WP ⊗ q_BP⁻¹`` out (PyBullet's quaternions are (x, y, z, w)); position and velocity are the
COM's, ω in WORLD axes. Forces are cleared after every step (``apply`` before each one); a torque fixed in
body axes is given once (``apply_body_torque``) and re-applied by ``apply`` in the base's own axes
(``LINK_FRAME``: the inertial frame P's, so ``τ_P = R_BPᵀ τ_B``), turned by Bullet itself. A world resets the
client's simulation. docs/engine_conventions.md, "PyBullet".
"""

import numpy as np
import pybullet as p

#: changeDynamics settings every body gets (besides mass and inertia): damping zeroed, and maxJointVelocity
#: far above 1e8 so that no clamp hides a blow-up.
DYNAMICS_SETTINGS = {"linearDamping": 0.0, "angularDamping": 0.0, "maxJointVelocity": 1e12}


def _xyzw(q):
    return [float(q[1]), float(q[2]), float(q[3]), float(q[0])]


def qmul(a, b):
    """Hamilton product of two quaternions (w, x, y, z) of 4 floats each."""
    s1, x1, y1, z1 = a
    s2, x2, y2, z2 = b
    return [s1 * s2 - (x1 * x2 + y1 * y2 + z1 * z2),
            s1 * x2 + s2 * x1 + (y1 * z2 - z1 * y2),
            s1 * y2 + s2 * y1 + (z1 * x2 - x1 * z2),
            s1 * z2 + s2 * z1 + (x1 * y2 - y1 * x2)]


def _qmul_rows(q1, q2):
    """Hamilton products of quaternion rows (..., 4) (w, x, y, z), with NumPy."""
    s1, v1, s2, v2 = q1[..., :1], q1[..., 1:], q2[..., :1], q2[..., 1:]
    c0, c1, c2 = v1[..., 0], v1[..., 1], v1[..., 2]
    d0, d1, d2 = v2[..., 0], v2[..., 1], v2[..., 2]
    cross = np.stack([c1 * d2 - c2 * d1, c2 * d0 - c0 * d2, c0 * d1 - c1 * d0], axis=-1)
    return np.concatenate([s1 * s2 - np.sum(v1 * v2, axis=-1, keepdims=True), s1 * v2 + s2 * v1 + cross],
                          axis=-1)


class Bodies:
    """The bodies in PyBullet client ``client``'s (reset) world. Raw rows: ``[x_W (COM), v_W, q_WP (x, y, z,
    w), ω_W]`` as PyBullet reports them (P: the inertial frame)."""

    def __init__(self, client, gravity_W, variant, dt_s):
        self.c = c = client
        self.maximal = variant == "maximal"
        self.q_BP, self.bodies, self.last = [], [], []
        self.torque_P = []          # per body: the body-axes torque in P's axes (3 floats), or None
        self._plan_of = self._tau_of = None   # the (f_W, tau_W) arrays the plan below was made for
        self._plan = []             # per body: its force and torque calls for those arrays
        p.resetSimulation(physicsClientId=c)
        p.setGravity(*[float(g) for g in gravity_W], physicsClientId=c)
        p.setPhysicsEngineParameter(fixedTimeStep=float(dt_s), numSubSteps=0, physicsClientId=c)

    def add_body(self, mass_kg, moments, q_BP, y0, com_B=None):
        """A body of principal ``moments`` about the frame ``q_BP`` (w, x, y, z; None: the body frame), put at
        packed state ``y0`` (its COM's); ``com_B``: the COM in the body frame (m) when the body frame origin
        is off it (the base's inertial frame there: PyBullet's base state is that frame's). False when
        PyBullet refuses it."""
        self.q_BP.append(q_BP)
        x0, q0 = self._pose_in(y0, len(self.bodies))
        inertial = {}
        if com_B is not None:
            inertial = {"baseInertialFramePosition": [float(v) for v in com_B],
                        "baseInertialFrameOrientation": [0.0, 0.0, 0.0, 1.0] if q_BP is None else _xyzw(q_BP)}
        b = p.createMultiBody(baseMass=float(mass_kg), baseCollisionShapeIndex=-1, baseVisualShapeIndex=-1,
                              basePosition=x0, baseOrientation=q0, useMaximalCoordinates=self.maximal,
                              physicsClientId=self.c, **inertial)
        if b < 0:
            return False
        p.changeDynamics(b, -1, mass=float(mass_kg), localInertiaDiagonal=[float(v) for v in moments],
                         activationState=p.ACTIVATION_STATE_DISABLE_SLEEPING, physicsClientId=self.c,
                         **DYNAMICS_SETTINGS)
        self.bodies.append(b)
        self.torque_P.append(None)
        return True

    def _pose_in(self, y, k):
        q_WB = [float(v) for v in y[6:10]]
        q_BP = self.q_BP[k]
        q_WP = q_WB if q_BP is None else qmul(q_WB, [float(v) for v in q_BP])
        return [float(v) for v in y[0:3]], _xyzw(q_WP)

    def set_state(self, y):
        """Put the bodies at packed states ``y`` (B, 13). Maximal coordinates: the pose reset zeroes the
        velocity, so it is set last, and every pose reset is primed with one zero-velocity step (a stale world
        inertia is reported in the first step after a reset)."""
        c = self.c
        self.last = np.asarray(y, dtype=float).tolist()   # where forces apply until the next read
        poses = [self._pose_in(row, k) for k, row in enumerate(y)]
        for b, (pos, orn) in zip(self.bodies, poses):
            p.resetBasePositionAndOrientation(b, pos, orn, physicsClientId=c)
        if self.maximal:
            for b in self.bodies:
                p.resetBaseVelocity(b, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], physicsClientId=c)
            p.stepSimulation(physicsClientId=c)
            for b, (pos, orn) in zip(self.bodies, poses):
                p.resetBasePositionAndOrientation(b, pos, orn, physicsClientId=c)
        for b, row in zip(self.bodies, y):
            p.resetBaseVelocity(b, [float(v) for v in row[3:6]], [float(v) for v in row[10:13]],
                                physicsClientId=c)

    def read(self):
        c, pose, vel = self.c, p.getBasePositionAndOrientation, p.getBaseVelocity
        rows = []
        for b in self.bodies:
            ps, orn = pose(b, c)   # (bodyUniqueId, physicsClientId)
            lin, ang = vel(b, c)
            rows.append(ps + lin + orn + ang)
        self.last = rows
        return rows

    def packed(self, raw):
        """Raw rows (..., B, 13) -> packed states (..., B, 13) of the body frame."""
        raw = np.asarray(raw, dtype=float)
        y = raw.copy()
        y[..., 6:10] = np.concatenate([raw[..., 9:10], raw[..., 6:9]], axis=-1)
        for k, q_BP in enumerate(self.q_BP):
            if q_BP is not None:
                y[..., k, 6:10] = _qmul_rows(y[..., k, 6:10], np.asarray(q_BP, dtype=float) * [1, -1, -1, -1])
        return y

    def decay(self, g_v, g_w):
        """The velocities last read, scaled (no pose reset: it would prime a maximal body again)."""
        for b, prev, gv, gw in zip(self.bodies, self.last, g_v.tolist(), g_w.tolist()):
            p.resetBaseVelocity(b, (prev[3] * gv, prev[4] * gv, prev[5] * gv),
                                (prev[10] * gw, prev[11] * gw, prev[12] * gw), physicsClientId=self.c)

    def apply_body_torque(self, tau_B):
        """Torques fixed in body axes (B, 3) (N m), applied with every following ``apply`` (Bullet clears
        forces after each step): in the base's own axes (``LINK_FRAME``), P's, so ``τ_P = R_BPᵀ τ_B``; a zero
        torque is not applied."""
        self.torque_P = []
        for tau, q_BP in zip(np.asarray(tau_B, dtype=float), self.q_BP):
            if q_BP is not None:
                q = np.asarray(q_BP, dtype=float)
                s, u = q[0], -q[1:]                       # R_BPᵀ = R(q_BP⁻¹)
                t = 2.0 * np.cross(u, tau)
                tau = tau + s * t + np.cross(u, t)
            self.torque_P.append(tuple(float(v) for v in tau) if np.any(tau != 0.0) else None)
        self._plan_of = None

    def apply(self, f_W, tau_W):
        """World forces at the COMs (at their last read positions, N) and world torques (N m), (B, 3), for the
        next step only, and the body-axes torques given by ``apply_body_torque``. A zero force or torque is
        not applied (the same step). The calls are planned once for the arrays given (the host loop gives
        the same arrays every step when the forces are constant)."""
        if f_W is not self._plan_of or tau_W is not self._tau_of:
            self._plan_of, self._tau_of = f_W, tau_W
            self._plan = [(b, f if (f[0] != 0.0 or f[1] != 0.0 or f[2] != 0.0) else None,
                           tau if (tau[0] != 0.0 or tau[1] != 0.0 or tau[2] != 0.0) else None, tau_P, k)
                          for k, (b, f, tau, tau_P) in enumerate(zip(
                              self.bodies, np.asarray(f_W, dtype=float).tolist(),
                              np.asarray(tau_W, dtype=float).tolist(), self.torque_P))]
        c, last = self.c, self.last
        for b, f, tau, tau_P, k in self._plan:
            if f is not None:
                p.applyExternalForce(b, -1, f, last[k][0:3], p.WORLD_FRAME, physicsClientId=c)
            if tau is not None:
                p.applyExternalTorque(b, -1, tau, p.WORLD_FRAME, physicsClientId=c)
            if tau_P is not None:
                p.applyExternalTorque(b, -1, tau_P, p.LINK_FRAME, physicsClientId=c)


    def step(self):
        p.stepSimulation(physicsClientId=self.c)


_CLIENT = []


def world(bodies, gravity_W, variant, dt_s):
    """A world in this process's DIRECT client (connected once); ``bodies`` start at rest at the origin."""
    if not _CLIENT:
        _CLIENT.append(p.connect(p.DIRECT))
    w = Bodies(_CLIENT[0], gravity_W, variant, dt_s)
    for mass_kg, moments, q_BP in bodies:
        w.add_body(mass_kg, moments, q_BP, [0.0] * 6 + [1.0, 0.0, 0.0, 0.0] + [0.0] * 3)
    return w


def form_world(bodies, gravity_W, variant, dt_s):
    """:func:`world` of bodies that may also give their COM (m, body axes from the frame origin; None: at it)
    as a fourth item: the base's inertial frame there (PyBullet's base state is that frame's, the COM's)."""
    w = world([], gravity_W, variant, dt_s)
    for body in bodies:
        w.add_body(*body[:3], [0.0] * 6 + [1.0, 0.0, 0.0, 0.0] + [0.0] * 3, *body[3:4])
    return w
