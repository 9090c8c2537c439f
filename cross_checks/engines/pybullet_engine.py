"""PyBullet as an engine adapter (``pybullet:VARIANT``, float64); the interface is cross_checks.engines.base.

One ``DIRECT`` client per process, the world reset between runs; the body is a ``createMultiBody`` without
collision shape (maximal coordinates for ``maximal``), neutralised (:data:`DYNAMICS_SETTINGS`, sleeping
disabled). PyBullet takes a diagonal inertia and reports the inertial (principal) frame P as the base pose,
so the boundary rotates: ``q_WP = q_WB ⊗ q_BP`` in, ``q_WB = q_WP ⊗ q_BP⁻¹`` out (quaternions (x, y, z, w)
in PyBullet); position and velocity are the COM's, ω in WORLD axes. Forces: before every step (PyBullet
clears them) the harness's world force at the COM minus the weight ``m g`` and world torque, from the
start-of-step state; the decay before the step (base.apply_decay_prestep). :func:`simulate_many` runs a
scenario's requests on one kept body. Divergence: the first bad state (reference_sim.simulate.bad_rows)
ends the run. Conventions, defaults neutralised and what pins them: docs/engine_conventions.md,
"PyBullet 3.2.7".
"""
from __future__ import annotations

import os
import threading

import numpy as np

from cross_checks.engines import base
from cross_checks.engines.base import EngineError, ModuleAdapter, Variant, decay_factors
from cross_checks.engines.step_floats import harness_fn, quat_mul_floats
from reference_sim.quaternion import quat_conj, quat_from_matrix, quat_mul
from reference_sim.simulate import Run, bad_rows, blowup_words, diverged

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

#: Steps between divergence checks of a free-running simulation (checked vectorised per chunk).
_CHUNK = 1024

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


class BulletBody:
    """One scenario body in the (reset) PyBullet world, with the boundary conversions."""

    def __init__(self, scenario, variant: str, dt_s: float, y0):
        """The body in the adapter's world, reset first."""
        base.check_variant(ENGINE, VARIANTS, variant)
        self.c = c = _connect()
        self.maximal = variant == "maximal"
        body = scenario.problem.body
        forces = scenario.problem.forces
        if body.is_diagonal():
            moments, self.q_BP = np.diag(body.inertia_B).copy(), None
        else:
            moments, R_BP = body.principal_axes()
            self.q_BP = quat_from_matrix(R_BP)
        self.weight = body.mass_kg * np.asarray(forces.gravity_W, dtype=float)
        _KEPT.clear()   # the reset removes the kept body
        try:
            p.resetSimulation(physicsClientId=c)
            p.setGravity(*[float(g) for g in forces.gravity_W], physicsClientId=c)
            p.setPhysicsEngineParameter(fixedTimeStep=float(dt_s), numSubSteps=0, physicsClientId=c)
            x0, q0 = self._pose_in(y0)
            self.b = p.createMultiBody(baseMass=float(body.mass_kg), baseCollisionShapeIndex=-1,
                                       baseVisualShapeIndex=-1, basePosition=x0, baseOrientation=q0,
                                       useMaximalCoordinates=self.maximal, physicsClientId=c)
            if self.b < 0:
                raise EngineError(f"pybullet.createMultiBody failed for scenario {scenario.name!r}")
            p.changeDynamics(self.b, -1, mass=float(body.mass_kg),
                             localInertiaDiagonal=[float(v) for v in moments],
                             activationState=p.ACTIVATION_STATE_DISABLE_SLEEPING,
                             physicsClientId=c, **DYNAMICS_SETTINGS)
        except p.error as exc:
            raise EngineError(f"PyBullet rejected the model of scenario {scenario.name!r}: {exc}") from None

    # -- boundary conversions ------------------------------------------------------------------
    def _pose_in(self, y):
        q_WB = [float(v) for v in y[6:10]]
        q_WP = q_WB if self.q_BP is None else quat_mul_floats(q_WB, self.q_BP.tolist())
        return [float(v) for v in y[0:3]], _xyzw(q_WP)

    def set_state(self, y):
        """Put the body at packed state ``y`` (13,). Maximal coordinates: the pose reset zeroes the velocity,
        so it is set last, and every pose reset is primed with one zero-velocity step (a stale world inertia
        reported in the first step after a reset; docs/engine_conventions.md)."""
        c, b = self.c, self.b
        pos, orn = self._pose_in(y)
        p.resetBasePositionAndOrientation(b, pos, orn, physicsClientId=c)
        if self.maximal:
            p.resetBaseVelocity(b, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], physicsClientId=c)
            p.stepSimulation(physicsClientId=c)
            p.resetBasePositionAndOrientation(b, pos, orn, physicsClientId=c)
        p.resetBaseVelocity(b, [float(v) for v in y[3:6]], [float(v) for v in y[10:13]], physicsClientId=c)

    def read_raw(self):
        """[pos, lin vel, q_WP (x, y, z, w), ang vel (world)] as a flat list of 13 floats."""
        pos, orn = p.getBasePositionAndOrientation(self.b, physicsClientId=self.c)
        lin, ang = p.getBaseVelocity(self.b, physicsClientId=self.c)
        return [*pos, *lin, *orn, *ang]

    def raw_to_packed(self, raw):
        """Raw rows (..., 13) from read_raw -> packed states (..., 13) of the SCENARIO body frame."""
        raw = np.asarray(raw, dtype=float)
        y = raw.copy()
        q_WP = np.concatenate([raw[..., 9:10], raw[..., 6:9]], axis=-1)
        y[..., 6:10] = q_WP if self.q_BP is None else quat_mul(q_WP, quat_conj(self.q_BP))
        return y

    def packer(self):
        """A function: one raw row (13 floats, :meth:`read_raw`'s order) -> the packed state of the SCENARIO
        body frame, 13 floats: :meth:`raw_to_packed` of that row bit for bit (the quaternion product in
        step_floats.quat_mul_floats), for the loops that evaluate the forces every step."""
        if self.q_BP is None:
            def packed(raw):
                x0, x1, x2, v0, v1, v2, qx, qy, qz, qw, w0, w1, w2 = raw
                return [x0, x1, x2, v0, v1, v2, qw, qx, qy, qz, w0, w1, w2]
            return packed
        q_PB = [float(v) for v in quat_conj(self.q_BP)]

        def packed_rotated(raw):
            x0, x1, x2, v0, v1, v2, qx, qy, qz, qw, w0, w1, w2 = raw
            return [x0, x1, x2, v0, v1, v2, *quat_mul_floats((qw, qx, qy, qz), q_PB), w0, w1, w2]
        return packed_rotated

    def apply(self, f_W, tau_W, x_W):
        """External world force ``f_W`` at the COM (at ``x_W``) and world torque ``tau_W`` (3 floats each, any
        sequence), for the next step only. A zero force or torque is not applied (PyBullet clears them after
        every step: the same step)."""
        c, b = self.c, self.b
        if f_W[0] != 0.0 or f_W[1] != 0.0 or f_W[2] != 0.0:
            p.applyExternalForce(b, -1, f_W, x_W, p.WORLD_FRAME, physicsClientId=c)
        if tau_W[0] != 0.0 or tau_W[1] != 0.0 or tau_W[2] != 0.0:
            p.applyExternalTorque(b, -1, tau_W, p.WORLD_FRAME, physicsClientId=c)


def simulate(scenario, variant: str, dt_s: float, n_steps: int) -> Run:
    """Free run of ``n_steps`` steps of ``dt_s`` from the scenario's initial state, every step recorded."""
    y0 = scenario.problem.initial_packed()
    with LOCK, np.errstate(all="ignore"):
        return _free_run(BulletBody(scenario, variant, dt_s, y0), scenario, y0, dt_s, n_steps)


#: The body :func:`simulate_many` and :func:`one_step` last built in this process's world:
#: ``(pid, scenario, variant, BulletBody.__init__, body)``, the scenario matched by identity. The next run of
#: the same scenario and variant keeps that body, its step and gravity set again, and puts it at its start
#: state (the numbers of a new body in a reset world, tested).
_KEPT: list = []


def _kept_body(scenario, variant: str, dt_s: float, y0):
    """The kept body when it was built for ``scenario`` and ``variant`` in this process's world, its step set
    to ``dt_s``; else a new one (reset world), kept. The caller holds ``LOCK``."""
    k = _KEPT[0] if _KEPT else None
    if (k is not None and k[0] == os.getpid() and k[1] is scenario and k[2] == variant
            and k[3] is BulletBody.__init__ and k[4].c == _client):
        c = k[4].c
        p.setGravity(*[float(g) for g in scenario.problem.forces.gravity_W], physicsClientId=c)
        p.setPhysicsEngineParameter(fixedTimeStep=float(dt_s), numSubSteps=0, physicsClientId=c)
        return k[4]
    _KEPT.clear()
    B = BulletBody(scenario, variant, dt_s, y0)
    _KEPT.append((os.getpid(), scenario, variant, BulletBody.__init__, B))
    return B


def simulate_many(variant: str, requests) -> list:
    """The runs of ``requests`` (``base.RunRequest``), a scenario's runs one after the other on its kept body
    (:func:`_kept_body`): each element :func:`simulate`'s Run bit for bit (tested), or its EngineError. A
    run that blows up is run again through :func:`simulate` (a new body: its divergence time and message)."""
    out: list = [None] * len(requests)
    first: dict = {}
    for j, r in enumerate(requests):
        first.setdefault(id(r.scenario), j)
    for j in sorted(range(len(requests)), key=lambda j: (first[id(requests[j].scenario)], j)):
        sc, h, n = requests[j].scenario, float(requests[j].dt_s), int(requests[j].n_steps)
        try:
            y0 = sc.problem.initial_packed()
            with LOCK, np.errstate(all="ignore"):
                run = _free_run(_kept_body(sc, variant, h, y0), sc, y0, h, n)
            out[j] = run if run.diverged_at_s is None else simulate(sc, variant, h, n)
        except EngineError as exc:
            out[j] = exc
    return out


def _free_run(B, scenario, y0, dt_s: float, n_steps: int) -> Run:
    """The free run of body ``B`` (a new ``BulletBody`` of ``scenario``, or one kept from a run of the same
    scenario and variant with its step set to ``dt_s``) from ``y0``: put at ``y0``, then stepped
    ``n_steps`` times with the harness's forces. The caller holds ``LOCK``."""
    B.set_state(y0)
    raw = np.empty((n_steps + 1, 13))
    raw[0] = B.read_raw()
    return _run_steps(B, scenario, y0, raw, dt_s, n_steps)


def _run_steps(B, scenario, y0, raw, dt_s: float, n_steps: int) -> Run:
    """The free run's steps: the forces from ``y0`` (constant ones kept, state-dependent ones from every
    start-of-step state), the decayed velocity set with resetBaseVelocity when there is decay, the forces
    applied (none when zero: ``BulletBody.apply``). Per step in plain floats (the states as PyBullet's
    tuples, the harness through step_floats): the numbers of the NumPy formulas, bit for bit (tested)."""
    forces = scenario.problem.forces
    state_dependent, decay = forces.state_dependent, forces.has_decay   # properties: read once
    gv, gw = (float(g) for g in decay_factors(scenario, dt_s))
    harness = harness_fn(scenario, dt_s)
    packed = B.packer()
    wx, wy, wz = B.weight.tolist()
    fx, fy, fz, tx, ty, tz = harness([float(v) for v in y0])
    now = {"f": (fx - wx, fy - wy, fz - wz), "tau": (tx, ty, tz), "prev": raw[0].tolist()}

    def steps(start, stop):
        c, b, apply = B.c, B.b, B.apply
        step, pose, vel, reset_vel = (p.stepSimulation, p.getBasePositionAndOrientation,
                                      p.getBaseVelocity, p.resetBaseVelocity)
        f, tau, prev = now["f"], now["tau"], now["prev"]
        rows = []
        for n in range(start, stop):
            if state_dependent and n > 1:
                fx, fy, fz, tx, ty, tz = harness(packed(prev))
                f, tau = (fx - wx, fy - wy, fz - wz), (tx, ty, tz)
            if decay:
                reset_vel(b, (prev[3] * gv, prev[4] * gv, prev[5] * gv),
                          (prev[10] * gw, prev[11] * gw, prev[12] * gw), physicsClientId=c)
            apply(f, tau, prev[0:3])
            step(physicsClientId=c)
            ps, orn = pose(b, physicsClientId=c)
            lin, ang = vel(b, physicsClientId=c)
            prev = ps + lin + orn + ang
            rows.append(prev)
        now.update(f=f, tau=tau, prev=prev)
        return rows
    return _recorded(B, raw, dt_s, n_steps, steps)


def _recorded(B, raw, dt_s: float, n_steps: int, steps) -> Run:
    """The run whose steps ``start..stop-1`` ``steps(start, stop)`` takes, chunk by chunk, returning their
    raw states (tuples of 13 floats, stored in one assignment per chunk); divergence checked per chunk."""
    start = 1
    while start <= n_steps:
        stop = min(start + _CHUNK, n_steps + 1)
        raw[start:stop] = steps(start, stop)
        blown = _diverged_in(B, raw, start, stop, dt_s)
        if blown is not None:
            return blown
        start = stop
    return Run(dt_s * np.arange(n_steps + 1), B.raw_to_packed(raw))


def _diverged_in(B, raw, start: int, stop: int, dt_s: float):
    """The diverged Run when a recorded state of steps ``start..stop-1`` blew up, else None."""
    bad = bad_rows(raw[start:stop])
    if not bad.any():
        return None
    n_bad = start + int(np.argmax(bad))
    return diverged(B.raw_to_packed(raw[:n_bad]), dt_s, f" ({blowup_words(raw[n_bad])})")


@base.on_rows
def one_step(scenario, variant: str, dt_s: float, y_start) -> np.ndarray:
    """One step of ``dt_s`` from each row of ``y_start`` (T, 13) (state reset per row)."""
    if len(y_start) == 0:
        return np.empty_like(y_start)
    with LOCK, np.errstate(all="ignore"):
        return _one_steps(_kept_body(scenario, variant, dt_s, y_start[0]),
                          scenario, dt_s, y_start)


def _one_steps(B, scenario, dt_s: float, y_start) -> np.ndarray:
    """One step of ``dt_s`` of body ``B`` (as for :func:`_free_run`) from each row of ``y_start`` (T, 13):
    the forces from the row, the pre-step decay, the state reset per row. The caller holds ``LOCK``."""
    y_dec = base.apply_decay_prestep(scenario, y_start, dt_s)
    harness = harness_fn(scenario, dt_s)
    wx, wy, wz = B.weight.tolist()
    out = np.empty_like(y_start)
    for i, y in enumerate(y_start.tolist()):
        fx, fy, fz, tx, ty, tz = harness(y)
        B.set_state(y_dec[i])
        B.apply((fx - wx, fy - wy, fz - wz), (tx, ty, tz), y[0:3])
        p.stepSimulation(physicsClientId=B.c)
        out[i] = B.read_raw()
    return B.raw_to_packed(out)


class PybulletAdapter(ModuleAdapter):
    """``pybullet:VARIANT`` — registered under the entry-point group ``rbcheck.engines``."""

    def engine_files(self) -> list:
        """PyBullet's compiled module."""
        return base.library_files(p)
