"""PyBullet as an engine (``pybullet:VARIANT``, float64): the bodies of cross_checks.engines.worlds.pybullet
(one ``DIRECT`` client per process, its world reset for each world of bodies; a ``createMultiBody`` per body,
maximal coordinates for ``maximal``; the inertial frame P as the base pose: ``q_WP = q_WB ⊗ q_BP`` in,
``q_WB = q_WP ⊗ q_BP⁻¹`` out) for rbcheck's loop. Forces: the loop's (the weight taken off), before every
step (PyBullet clears them); a torque fixed in body axes is PyBullet's own (``takes_body_torque``).
Conventions, defaults neutralised and what pins them: docs/engine_conventions.md, "PyBullet 3.2.7".
"""
from __future__ import annotations

import dataclasses
import functools
import os
import threading

import numpy as np

from cross_checks.engines import base, install, world
from cross_checks.engines.base import EngineError, Variant
from cross_checks.engines.world import World, WorldEngine
from reference_sim.quaternion import quat_conj

# (pybullet prints its build time at import)
p, _IMPORT_ERROR, pbw = install.optional_world("pybullet", "pybullet", "Bodies", quiet_stderr=True)
if _IMPORT_ERROR is None:
    from cross_checks.engines.worlds.pybullet import DYNAMICS_SETTINGS

__all__ = ["ENGINE", "VARIANTS", "EngineError", "version", "simulate",
           "simulate_many", "one_step", "DYNAMICS_SETTINGS"]

ENGINE = "pybullet"
#: The engine's invariance finding (docs/engine_conventions.md, "Invariance"): measured on tennis_racket (k =
#: 0.01: μ = 0.02 drops the term, μ = 0.05 keeps it) and on six catalog scenarios at k = μ = 0.01.
SMALL_BODY_GYROSCOPIC_FINDING = base.InvarianceFinding(
    "scale", (("k", 0.01, 0.01), ("mu", 0.01, 0.02)),
    "the engine's: Bullet's implicit gyroscopic step (btRigidBody::computeGyroscopicImpulseImplicit_Body) "
    "solves its 3×3 system with btMatrix3x3::solve33, which divides by the determinant only when |det| > "
    "SIMD_EPSILON (2.2e-16 in PyBullet's double build); a body scaled to k = μ = 0.01 has moments ~1e-6 "
    "kg m² (det ~6e-18), so the gyroscopic term is dropped and ω stays at its initial value (measured "
    "0.81–3.12 rad in orientation on six catalog scenarios; on tennis_racket at k = 0.01 μ = 0.02 drops it, "
    "0.05 keeps it)")
#: Both modes are semi-implicit Euler: explicit gyroscopic term in multibody, implicit in maximal coordinates.
VARIANTS = {
    "multibody": Variant(1, "PyBullet Featherstone multibody (default): semi-implicit Euler, explicit "
                            "gyroscopic term", traits=base.SYMPLECTIC_EULER_EXPLICIT_GYRO),
    "maximal": Variant(1, "PyBullet maximal coordinates (btRigidBody): semi-implicit Euler, implicit "
                          "gyroscopic term",
                       traits=dataclasses.replace(base.SYMPLECTIC_EULER_IMPLICIT_GYRO,
                                                  invariance_findings=(SMALL_BODY_GYROSCOPIC_FINDING,))),
}

LOCK = threading.RLock()
_client: int | None = None
_client_pid: int | None = None


def _connect() -> int:
    """The process's DIRECT client (reconnected after a fork or if it was closed)."""
    global _client, _client_pid
    _ENGINE.require_installed()
    if _client is not None and _client_pid == os.getpid() and p.isConnected(physicsClientId=_client):
        return _client
    cid = p.connect(p.DIRECT)
    if cid < 0:
        raise EngineError("pybullet.connect(DIRECT) failed")
    _client, _client_pid = cid, os.getpid()
    return cid


def body_spec(body) -> tuple:
    """``(mass_kg, principal moments (3,), q_BP (w x y z) or None)``: PyBullet takes a diagonal inertia
    (world.principal_spec: None, no frame rotation, for a diagonal tensor)."""
    return world.principal_spec(body)


def body_entry(scenario) -> tuple:
    """The scenario's body as worlds.pybullet's ``add_body`` takes it (world.body_entry: its COM, where the
    base's inertial frame is)."""
    return world.body_entry(scenario, body_spec)


class BulletWorld(pbw.Bodies, World):
    """The bodies of one run group in the process's (reset) PyBullet world (worlds.pybullet.Bodies). Raw rows:
    ``[x_W (COM), v_W, q_WP (x, y, z, w), ω_W]`` as PyBullet reports them (P: the inertial frame)."""

    float_reads = True

    def __init__(self, requests, variant: str, dt_s: float):
        """The bodies in the adapter's world, reset first; the caller holds ``LOCK``."""
        World.__init__(self)
        r = requests[0]
        try:
            pbw.Bodies.__init__(self, _connect(), r.scenario.problem.forces.gravity_W, variant, dt_s)
            for r in requests:
                self._add(r.scenario)
        except p.error as exc:
            raise EngineError(f"PyBullet rejected the model of scenario {r.scenario.name!r}: {exc}") from None
        self.step = functools.partial(p.stepSimulation, self.c)   # Bodies.step's call, no Python frame
        if len(self.bodies) == 1:   # Bodies.read of one body, its calls bound
            b, c, pose, vel = self.bodies[0], self.c, p.getBasePositionAndOrientation, p.getBaseVelocity

            def read():
                ps, orn = pose(b, c)
                lin, ang = vel(b, c)
                self.last = [ps + lin + orn + ang]
                return self.last
            self.read = read

    def applier(self, f_W, tau_W):
        """:meth:`apply` of constant forces as the engine's own calls, arguments bound (one: no Python frame
        a step), or None; world forces at the COM go through :meth:`apply` (at the COM last read)."""
        f_rows = np.asarray(f_W, dtype=float).tolist()
        if any(f[0] != 0.0 or f[1] != 0.0 or f[2] != 0.0 for f in f_rows):
            return functools.partial(self.apply, f_W, tau_W)
        calls = []
        for b, tau, tau_P in zip(self.bodies, np.asarray(tau_W, dtype=float).tolist(), self.torque_P):
            if tau[0] != 0.0 or tau[1] != 0.0 or tau[2] != 0.0:   # apply's calls, in its order
                calls.append(functools.partial(p.applyExternalTorque, b, -1, tau, p.WORLD_FRAME, self.c))
            if tau_P is not None:
                calls.append(functools.partial(p.applyExternalTorque, b, -1, tau_P, p.LINK_FRAME, self.c))
        if len(calls) < 2:
            return calls[0] if calls else None

        def again():
            for call in calls:
                call()
        return again

    def _add(self, scenario):
        entry = body_entry(scenario)
        if not self.add_body(*entry[:3], scenario.problem.initial_packed(), *entry[3:4]):
            raise EngineError(f"pybullet.createMultiBody failed for scenario {scenario.name!r}")

    def packed_row(self, raw):
        """:meth:`packed` of one read in plain floats (the world's quaternion product)."""
        out = []
        for r, q_BP in zip(raw if isinstance(raw, list) else np.asarray(raw).tolist(), self.q_BP):
            x0, x1, x2, v0, v1, v2, qx, qy, qz, qw, w0, w1, w2 = r
            q = ([qw, qx, qy, qz] if q_BP is None
                 else pbw.qmul((qw, qx, qy, qz), quat_conj(q_BP).tolist()))
            out.append([x0, x1, x2, v0, v1, v2, *q, w0, w1, w2])
        return out

    def close(self):
        LOCK.release()


class PybulletEngine(WorldEngine):
    """``pybullet:VARIANT`` — registered under the entry-point group ``rbcheck.engines``."""

    name, variants, distribution, imported = ENGINE, VARIANTS, "pybullet", "p"
    #: applyExternalTorque(LINK_FRAME) takes a torque in the base's (inertial frame's) axes and Bullet turns
    #: it with the body: the world re-applies the bodies' body-axes torques before every step, no harness
    #: evaluation (pinned: tests/cross_checks/engines/test_pybullet_engine.py)
    takes_body_torque = True
    #: a body frame off the COM: the base's inertial frame (its pose is what PyBullet's base state is)
    body_forms = frozenset({"com_offset"})

    def build(self, requests, variant, dt_s):
        self.require_installed()
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


_ENGINE, version, simulate, simulate_many, one_step = PybulletEngine.exported()
PybulletAdapter = PybulletEngine
