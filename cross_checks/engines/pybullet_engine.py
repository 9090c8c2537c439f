"""PyBullet as an engine adapter (``pybullet:VARIANT``); the interface is cross_checks.engines.base.

One ``DIRECT`` connection per process (module-level, created on first use; ``resetSimulation``
between runs). Every run sets gravity and ``fixedTimeStep`` from the scenario, ``numSubSteps = 0``,
and creates one body with ``createMultiBody`` (no collision shape, ``useMaximalCoordinates`` False for
``multibody``, True for ``maximal``), then ``changeDynamics(mass=m, localInertiaDiagonal=moments)``
with damping zeroed (multibody defaults to 0.04 linear + quadratic), ``maxJointVelocity`` raised
(multibody clamps every velocity component to ±100 by default) and sleeping disabled.

Body frames (docs/engine_conventions.md): PyBullet takes only a diagonal inertia, and what it reports as the
base pose is the inertial (principal) frame P. The adapter therefore gives PyBullet the principal
frame as the body (``baseInertialFrameOrientation`` identity) and rotates at the boundary:
``q_WP = q_WB ⊗ q_BP`` in, ``q_WB = q_WP ⊗ q_BP⁻¹`` out, with ``R_BP`` from
``RigidBody.principal_axes()`` (identity, with no rotation at all, when the inertia is diagonal).
Position and linear velocity are the COM's in world axes, ``getBaseVelocity``'s angular velocity is
WORLD axes; quaternions are (x, y, z, w) in PyBullet and converted at the boundary.

Forces (harness semantics of base.py): PyBullet clears external forces after every
``stepSimulation``, so each step applies ``harness_force_torque − m g`` (PyBullet applies gravity
itself) with ``applyExternalForce`` (WORLD_FRAME, at the COM's world position) and
``applyExternalTorque`` (WORLD_FRAME), evaluated from the start-of-step state. Velocity decay
``e^{−kΔt}`` is applied before the step with ``resetBaseVelocity`` (base.apply_decay_prestep), that
step's force and torque scaled alike.

Maximal-coordinate bodies: ``resetBasePositionAndOrientation`` zeroes their velocity, so the velocity
is always reset after the pose. PyBullet is reported to use a stale world inertia in the first step after a
pose reset or ``changeDynamics``; every pose reset is primed with one zero-velocity step at that pose,
then reset again. (With this adapter's call order no effect of the priming was measurable in 3.2.7 —
primed and unprimed runs agree bit for bit — it is kept as cheap insurance.)
"""
from __future__ import annotations

import os
import threading

import numpy as np

from reference_sim.quaternion import quat_conj, quat_from_matrix, quat_mul
from reference_sim.simulate import Run, bad_rows, blowup_words, diverged

from cross_checks.engines.base import (EngineAdapter, EngineError, Variant, apply_decay_prestep, decay_factors,
                                       harness_force_torque, optional_import, require)

p, _IMPORT_ERROR = optional_import("pybullet", quiet_stderr=True)   # it prints its build time at import

__all__ = ["ENGINE", "VARIANTS", "EngineError", "version", "simulate", "one_step", "DYNAMICS_SETTINGS"]

ENGINE = "pybullet"
#: The variants with their declared global orders: both modes are semi-implicit Euler (explicit
#: gyroscopic term in multibody, implicit in maximal coordinates): 1.
VARIANTS = {
    "multibody": Variant(1, "PyBullet Featherstone multibody (default): semi-implicit Euler, explicit gyroscopic term"),
    "maximal": Variant(1, "PyBullet maximal coordinates (btRigidBody): semi-implicit Euler, implicit gyroscopic term"),
}

#: changeDynamics settings every body gets (besides mass and inertia); see the module docstring.
#: maxJointVelocity far above BLOWUP_LIMIT (1e8): a lower clamp would cap a blow-up (e.g. at 1e6 rad/s)
#: and hide the divergence from the harness.
DYNAMICS_SETTINGS = {"linearDamping": 0.0, "angularDamping": 0.0, "maxJointVelocity": 1e12}

#: Steps between divergence checks of a free-running simulation (checked vectorised per chunk).
_CHUNK = 128

_LOCK = threading.RLock()
_client: int | None = None
_client_pid: int | None = None




def _require():
    require(p, _IMPORT_ERROR, "pybullet")


def version() -> str:
    _require()
    from importlib.metadata import PackageNotFoundError, version as dist_version
    try:
        v = dist_version("pybullet")
    except PackageNotFoundError:  # pragma: no cover - a source build without metadata
        v = "unknown"
    return v


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


class _Body:
    """One scenario body in the (reset) PyBullet world, with the boundary conversions."""

    def __init__(self, scenario, variant: str, dt_s: float, y0, client: int | None = None):
        """The body in the adapter's world, reset first; or, with ``client``, in that client's world, which
        must hold no other body (the fuzz keeps a world of its own and removes its previous body)."""
        if variant not in VARIANTS:
            raise ValueError(f"unknown pybullet variant {variant!r}; variants: {', '.join(VARIANTS)}")
        self.c = c = _connect() if client is None else client
        self.maximal = variant == "maximal"
        body = scenario.problem.body
        forces = scenario.problem.forces
        if body.is_diagonal():
            moments, self.q_BP = np.diag(body.inertia_B).copy(), None
        else:
            moments, R_BP = body.principal_axes()
            self.q_BP = quat_from_matrix(R_BP)
        self.weight = body.mass_kg * np.asarray(forces.gravity_W, dtype=float)
        try:
            if client is None:
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
        q_WB = np.asarray(y[6:10], dtype=float)
        q_WP = q_WB if self.q_BP is None else quat_mul(q_WB, self.q_BP)
        return [float(v) for v in y[0:3]], _xyzw(q_WP)

    def set_state(self, y):
        """Put the body at packed state ``y`` (13,) (maximal coordinates: primed, see module docstring)."""
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

    def apply(self, f_W, tau_W, x_W):
        """External world force at the COM (``x_W``) and world torque, for the next step only."""
        c, b = self.c, self.b
        if f_W[0] != 0.0 or f_W[1] != 0.0 or f_W[2] != 0.0:
            p.applyExternalForce(b, -1, f_W.tolist(), list(x_W), p.WORLD_FRAME, physicsClientId=c)
        if tau_W[0] != 0.0 or tau_W[1] != 0.0 or tau_W[2] != 0.0:
            p.applyExternalTorque(b, -1, tau_W.tolist(), p.WORLD_FRAME, physicsClientId=c)


def simulate(scenario, variant: str, dt_s: float, n_steps: int) -> Run:
    """Free run of ``n_steps`` steps of ``dt_s`` from the scenario's initial state, every step recorded."""
    forces = scenario.problem.forces
    y0 = scenario.problem.initial_packed()
    with _LOCK, np.errstate(all="ignore"):
        B = _Body(scenario, variant, dt_s, y0)
        B.set_state(y0)
        c, b = B.c, B.b
        decay = forces.has_decay
        gv, gw = decay_factors(scenario, dt_s)
        per_step = forces.state_dependent or decay
        if not forces.state_dependent:
            f_const, tau_const = harness_force_torque(scenario, y0, dt_s)
            f_const = f_const - B.weight
        raw = np.empty((n_steps + 1, 13))
        raw[0] = B.read_raw()
        if not per_step:
            return _run_constant(B, raw, f_const, tau_const, dt_s, n_steps)
        y_prev = y0
        step, read = p.stepSimulation, B.read_raw
        start = 1
        while start <= n_steps:  # per step: state-dependent forces and/or the pre-step decay
            stop = min(start + _CHUNK, n_steps + 1)
            for n in range(start, stop):
                row = raw[n - 1]
                if n > 1:
                    y_prev = B.raw_to_packed(row)
                if forces.state_dependent:
                    f, tau = harness_force_torque(scenario, y_prev, dt_s)
                    f = f - B.weight
                else:
                    f, tau = f_const, tau_const
                if decay:
                    p.resetBaseVelocity(b, (row[3:6] * gv).tolist(), (row[10:13] * gw).tolist(),
                                        physicsClientId=c)
                B.apply(f, tau, row[0:3])
                step(physicsClientId=c)
                raw[n] = read()
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


def _run_constant(B, raw, f_W, tau_W, dt_s: float, n_steps: int) -> Run:
    """The free run when the applied force and torque are constant and there is no decay (most of the
    catalog): the same calls as the general loop, with the per-step Python cut to the engine calls —
    nothing applied when force and torque are zero (PyBullet clears them after every step), and each
    chunk's states collected as tuples and stored in one assignment (the same floats, bit for bit)."""
    c, b = B.c, B.b
    step, pose, vel = p.stepSimulation, p.getBasePositionAndOrientation, p.getBaseVelocity
    applies = bool(np.any(f_W != 0.0) or np.any(tau_W != 0.0))
    start = 1
    while start <= n_steps:
        stop = min(start + _CHUNK, n_steps + 1)
        rows = []
        for n in range(start, stop):
            if applies:
                B.apply(f_W, tau_W, rows[-1][0:3] if rows else raw[n - 1, 0:3])
            step(physicsClientId=c)
            pos, orn = pose(b, physicsClientId=c)
            lin, ang = vel(b, physicsClientId=c)
            rows.append(pos + lin + orn + ang)
        raw[start:stop] = rows
        blown = _diverged_in(B, raw, start, stop, dt_s)
        if blown is not None:
            return blown
        start = stop
    return Run(dt_s * np.arange(n_steps + 1), B.raw_to_packed(raw))


def one_step(scenario, variant: str, dt_s: float, y_start) -> np.ndarray:
    """One step of ``dt_s`` from each row of ``y_start`` (T, 13) (state reset per row)."""
    shape = np.shape(y_start)
    y_start = np.asarray(y_start, dtype=float).reshape(-1, 13)
    y_dec = apply_decay_prestep(scenario, y_start, dt_s)
    out = np.empty_like(y_start)
    if len(y_start) == 0:
        return out.reshape(shape)
    with _LOCK, np.errstate(all="ignore"):
        B = _Body(scenario, variant, dt_s, y_start[0])
        for i in range(len(y_start)):
            f, tau = harness_force_torque(scenario, y_start[i], dt_s)
            B.set_state(y_dec[i])
            B.apply(f - B.weight, tau, y_start[i, 0:3])
            p.stepSimulation(physicsClientId=B.c)
            out[i] = B.read_raw()
        return B.raw_to_packed(out).reshape(shape)


class PybulletAdapter(EngineAdapter):
    """``pybullet:VARIANT`` — registered under the entry-point group ``rbcheck.engines``."""

    name = ENGINE
    variants = VARIANTS
    version = staticmethod(version)
    simulate = staticmethod(simulate)
    one_step = staticmethod(one_step)
