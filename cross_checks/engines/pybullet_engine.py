"""PyBullet as an engine (``pybullet:VARIANT``, float64): a world of bodies for rbcheck's loop
(cross_checks.engines.world, cross_checks.engines.loop).

One ``DIRECT`` client per process, its world reset for each world of bodies; a body is a ``createMultiBody``
without collision shape (maximal coordinates for ``maximal``), neutralised (:data:`DYNAMICS_SETTINGS`,
sleeping disabled). PyBullet takes a diagonal inertia and reports the inertial (principal) frame P as the base
pose, so the boundary rotates: ``q_WP = q_WB ⊗ q_BP`` in, ``q_WB = q_WP ⊗ q_BP⁻¹`` out (quaternions (x, y, z,
w) in PyBullet); position and velocity are the COM's, ω in WORLD axes. Forces: the loop's, applied before
every step (PyBullet clears them), the weight ``m g`` taken off; the decay by setting the velocities last
read, scaled. Conventions, defaults neutralised and what pins them: docs/engine_conventions.md, "PyBullet
3.2.7".
"""
from __future__ import annotations

import os
import threading

import numpy as np

from cross_checks.engines import base
from cross_checks.engines.base import EngineError, Variant
from cross_checks.engines.step_floats import quat_mul_floats
from cross_checks.engines.world import World, WorldEngine
from reference_sim.quaternion import quat_conj, quat_from_matrix, quat_mul
from reference_sim.simulate import Run

p, _IMPORT_ERROR = base.optional_import("pybullet", quiet_stderr=True)   # it prints its build time at import

__all__ = ["ENGINE", "VARIANTS", "EngineError", "version", "simulate",
           "simulate_many", "one_step", "DYNAMICS_SETTINGS"]

ENGINE = "pybullet"
#: Both modes are semi-implicit Euler: explicit gyroscopic term in multibody, implicit in maximal coordinates.
VARIANTS = {
    "multibody": Variant(1,
                         "PyBullet Featherstone multibody (default): "
                         "semi-implicit Euler, explicit gyroscopic term",
                         traits=base.SYMPLECTIC_EULER_EXPLICIT_GYRO),
    "maximal": Variant(1,
                       "PyBullet maximal coordinates (btRigidBody): "
                       "semi-implicit Euler, implicit gyroscopic term",
                       traits=base.SYMPLECTIC_EULER_IMPLICIT_GYRO),
}

#: changeDynamics settings every body gets (besides mass and inertia): damping zeroed, and maxJointVelocity
#: far above BLOWUP_LIMIT (1e8) so that no clamp hides a blow-up from the harness.
DYNAMICS_SETTINGS = {"linearDamping": 0.0, "angularDamping": 0.0, "maxJointVelocity": 1e12}

LOCK = threading.RLock()
_client: int | None = None
_client_pid: int | None = None


def _require():
    base.require(p, _IMPORT_ERROR, "pybullet")


def version() -> str:
    """The installed pybullet distribution's version (read from its metadata once per process)."""
    _require()
    return base.release("pybullet")


def _connect() -> int:
    """The process's DIRECT client (reconnected after a fork or if it was closed)."""
    global _client, _client_pid
    _require()
    if _client is not None and _client_pid == os.getpid() and p.isConnected(physicsClientId=_client):
        return _client
    cid = p.connect(p.DIRECT)
    if cid < 0:
        raise EngineError("pybullet.connect(DIRECT) failed")
    _client, _client_pid = cid, os.getpid()
    return cid


def _xyzw(q):
    return [float(q[1]), float(q[2]), float(q[3]), float(q[0])]


class BulletWorld(World):
    """The bodies of one run group in the process's (reset) PyBullet world, with the boundary conversions.
    Raw rows: ``[x_W (COM), v_W, q_WP (x, y, z, w), ω_W]`` as PyBullet reports them (P: the inertial
    frame)."""

    def __init__(self, requests, variant: str, dt_s: float):
        """The bodies in the adapter's world, reset first; the caller holds ``LOCK``."""
        super().__init__()
        self.c = c = _connect()
        self.maximal = variant == "maximal"
        self.q_BP: list = []
        self.bodies: list = []
        forces = requests[0].scenario.problem.forces
        try:
            p.resetSimulation(physicsClientId=c)
            p.setGravity(*[float(g) for g in forces.gravity_W], physicsClientId=c)
            p.setPhysicsEngineParameter(fixedTimeStep=float(dt_s), numSubSteps=0, physicsClientId=c)
            for r in requests:
                self._add(r.scenario)
        except p.error as exc:
            raise EngineError(f"PyBullet rejected the model of scenario {r.scenario.name!r}: {exc}") from None

    def _add(self, scenario):
        c, body = self.c, scenario.problem.body
        if body.is_diagonal():
            moments, q_BP = np.diag(body.inertia_B).copy(), None
        else:
            moments, R_BP = body.principal_axes()
            q_BP = quat_from_matrix(R_BP)
        self.q_BP.append(q_BP)
        x0, q0 = self._pose_in(scenario.problem.initial_packed(), len(self.bodies))
        inertial = {}
        com = getattr(scenario, "body_com_B_m", None)
        if com is not None:   # the body frame origin off the COM: the inertial frame pose in the link frame
            inertial = {"baseInertialFramePosition": [float(v) for v in com],
                        "baseInertialFrameOrientation": [0.0, 0.0, 0.0, 1.0] if q_BP is None else _xyzw(q_BP)}
        b = p.createMultiBody(baseMass=float(body.mass_kg), baseCollisionShapeIndex=-1,
                              baseVisualShapeIndex=-1, basePosition=x0, baseOrientation=q0,
                              useMaximalCoordinates=self.maximal, physicsClientId=c, **inertial)
        if b < 0:
            raise EngineError(f"pybullet.createMultiBody failed for scenario {scenario.name!r}")
        p.changeDynamics(b, -1, mass=float(body.mass_kg), localInertiaDiagonal=[float(v) for v in moments],
                         activationState=p.ACTIVATION_STATE_DISABLE_SLEEPING, physicsClientId=c,
                         **DYNAMICS_SETTINGS)
        self.bodies.append(b)

    # -- boundary conversions ------------------------------------------------------------------
    def _pose_in(self, y, k: int):
        q_WB = [float(v) for v in y[6:10]]
        q_BP = self.q_BP[k]
        q_WP = q_WB if q_BP is None else quat_mul_floats(q_WB, q_BP.tolist())
        return [float(v) for v in y[0:3]], _xyzw(q_WP)

    def set_state(self, y):
        """Put the bodies at packed states ``y`` (B, 13). Maximal coordinates: the pose reset zeroes the
        velocity, so it is set last, and every pose reset is primed with one zero-velocity step (a stale world
        inertia reported in the first step after a reset; docs/engine_conventions.md)."""
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
            ps, orn = pose(b, physicsClientId=c)
            lin, ang = vel(b, physicsClientId=c)
            rows.append(ps + lin + orn + ang)
        self.last = rows
        return rows

    def packed(self, raw):
        """Raw rows (..., B, 13) -> packed states (..., B, 13) of the SCENARIO body frame."""
        raw = np.asarray(raw, dtype=float)
        y = raw.copy()
        y[..., 6:10] = np.concatenate([raw[..., 9:10], raw[..., 6:9]], axis=-1)
        for k, q_BP in enumerate(self.q_BP):
            if q_BP is not None:
                y[..., k, 6:10] = quat_mul(y[..., k, 6:10], quat_conj(q_BP))
        return y

    def packed_row(self, raw):
        """:meth:`packed` of one read in plain floats (the quaternion product: quat_mul_floats)."""
        out = []
        for r, q_BP in zip(np.asarray(raw).tolist(), self.q_BP):
            x0, x1, x2, v0, v1, v2, qx, qy, qz, qw, w0, w1, w2 = r
            q = ([qw, qx, qy, qz] if q_BP is None
                 else quat_mul_floats((qw, qx, qy, qz), quat_conj(q_BP).tolist()))
            out.append([x0, x1, x2, v0, v1, v2, *q, w0, w1, w2])
        return out

    def decay(self, g_v, g_w):
        """The velocities last read, scaled (no pose reset: it would prime a maximal body again)."""
        c = self.c
        for b, prev, gv, gw in zip(self.bodies, self.last, g_v.tolist(), g_w.tolist()):
            p.resetBaseVelocity(b, (prev[3] * gv, prev[4] * gv, prev[5] * gv),
                                (prev[10] * gw, prev[11] * gw, prev[12] * gw), physicsClientId=c)

    def apply(self, f_W, tau_W):
        """External world forces at the COMs (at their last read positions) and world torques (B, 3), for
        the next step only. A zero force or torque is not applied (PyBullet clears them after every step: the
        same step)."""
        c = self.c
        for b, f, tau, prev in zip(self.bodies, f_W.tolist(), tau_W.tolist(), self.last):
            if f[0] != 0.0 or f[1] != 0.0 or f[2] != 0.0:
                p.applyExternalForce(b, -1, f, prev[0:3], p.WORLD_FRAME, physicsClientId=c)
            if tau[0] != 0.0 or tau[1] != 0.0 or tau[2] != 0.0:
                p.applyExternalTorque(b, -1, tau, p.WORLD_FRAME, physicsClientId=c)

    def step(self):
        p.stepSimulation(physicsClientId=self.c)

    def close(self):
        LOCK.release()


class PybulletEngine(WorldEngine):
    """``pybullet:VARIANT`` — registered under the entry-point group ``rbcheck.engines``."""

    name = ENGINE
    variants = VARIANTS
    distribution = "pybullet"
    #: a body frame off the COM: the base's inertial frame (its pose is what PyBullet's base state is)
    body_forms = frozenset({"com_offset"})

    def version(self) -> str:
        return version()

    def build(self, requests, variant, dt_s):
        _require()
        LOCK.acquire()
        try:
            return BulletWorld(requests, variant, dt_s)
        except BaseException:
            LOCK.release()
            raise

    def group_key(self, request) -> tuple:
        """One world per step, step count and gravity (PyBullet's world has one of each)."""
        return (float(request.dt_s), int(request.n_steps),
                tuple(float(g) for g in request.scenario.problem.forces.gravity_W))

    def engine_files(self) -> list:
        """PyBullet's compiled module."""
        return base.library_files(p)


_ENGINE = PybulletEngine()


def simulate(scenario, variant: str, dt_s: float, n_steps: int) -> Run:
    """Free run of ``n_steps`` steps of ``dt_s`` from the scenario's initial state (the host loop's)."""
    return _ENGINE.simulate(scenario, variant, dt_s, n_steps)


def simulate_many(variant: str, requests) -> list:
    return _ENGINE.simulate_many(variant, requests)


def one_step(scenario, variant: str, dt_s: float, y_start) -> np.ndarray:
    return _ENGINE.one_step(scenario, variant, dt_s, y_start)


PybulletAdapter = PybulletEngine
