"""Rapier (``rapier3d``, dimforge's Python bindings, 3D, float32) as an engine (``rapier:VARIANT``): the
bodies of cross_checks.engines.worlds.rapier for rbcheck's loop. Conventions, defaults neutralised, the
scheme of each variant and what pins them: docs/engine_conventions.md, "Rapier 0.36.1".
"""
from __future__ import annotations

import functools
import math

import numpy as np

from cross_checks.engines import install, world
from cross_checks.engines.base import EngineError, Traits, Variant
from cross_checks.engines.world import World, WorldEngine

rapier, _IMPORT_ERROR, rpw = install.optional_world("rapier3d", "rapier", "Bodies")

__all__ = ["ENGINE", "DIST", "VARIANTS", "EngineError", "version", "simulate", "simulate_many", "one_step",
           "RapierWorld", "RapierAdapter"]

ENGINE = "rapier"
DIST = "rapier3d"

#: Rapier's one integrator, its gyroscopic forces on (its default, first) and off.
VARIANTS = {
    "symplectic_euler": Variant(1, "Rapier's step (gyroscopic forces on, its default): semi-implicit Euler "
                                   "in float32, explicit gyroscopic step in the principal frame rescaled to "
                                   "keep |L|, linearised normalised quaternion update with the new ω",
                                traits=Traits(rotation_drift="momentum", rotation_sign=None,
                                              precision="float32")),
    "symplectic_euler_no_gyro": Variant(1, "Rapier's step with gyroscopic_forces(False): semi-implicit Euler "
                                           "in float32 without the gyroscopic term (ω_W changes only by the "
                                           "torque)",
                                        traits=Traits(gyroscopic_term=False, precision="float32")),
}


def _decode(blobs: bytes, n: int, layout) -> np.ndarray:
    """``n`` bodies' serialisations of one length (``blobs``, joined) as packed rows (n, 13) in float64:
    ``[x_W, v_W, q (w x y z), ω_W]``, the quaternion normalised as ``Rotation3.to_tuple`` normalises it (in
    float32: q / sqrt((x² + z²) + (y² + w²)))."""
    length, cols = layout
    raw = np.frombuffer(blobs, dtype=np.uint8).reshape(n, length)[:, cols]
    v = np.ascontiguousarray(raw).view("<f4")                      # x, y, z, vx, vy, vz, qx, qy, qz, qw, ω
    qx, qy, qz, qw = v[:, 6], v[:, 7], v[:, 8], v[:, 9]
    norm = np.sqrt((qx * qx + qz * qz) + (qy * qy + qw * qw))
    out = v[:, [0, 1, 2, 3, 4, 5, 9, 6, 7, 8, 10, 11, 12]].astype(float)
    out[:, 6:10] = v[:, [9, 6, 7, 8]] / norm[:, None]   # (w, x, y, z), each divided in float32
    return out


@functools.lru_cache(maxsize=1)
@np.errstate(all="ignore")   # a layout that is wrong decodes garbage: refused, not warned about
def state_bytes_layout():
    """Where a body's state sits in ``RigidBody.to_bytes()`` (rapier3d's own serialisation): ``(length,
    byte columns of [x, v, q (x y z w), ω] as float32)``, found on a probe body given distinct values (each
    component's first place); None unless :func:`_decode` of 256 bodies' serialisations (random states
    stepped under random torques) is what the getters return, bit for bit (another rapier3d may lay its
    bodies out otherwise: a value not found, another length): the getters then, per body."""
    try:
        n = 256
        rng = np.random.default_rng(20260)
        y = rng.normal(size=(n, 13)) * 5.0   # (Rotation3 normalises the quaternion)
        check = rpw.Bodies([(1.0, np.array([1.0, 2.0, 3.0]), np.array([1.0, 0.0, 0.0, 0.0]))] * n,
                           (0.0, 0.0, -9.81), "symplectic_euler", 1e-2)
        check.set_state(y)
        rb = check.bodies[0]   # the probe, its state distinct values
        rb.position = rapier.Isometry3((1.25, 2.375, 3.5), rapier.Rotation3(0.9, 0.1, -0.2, 0.3))
        rb.linvel, rb.angvel = (4.625, 5.75, 6.875), (7.125, 8.25, 9.375)
        rot = rb.rotation.to_bytes()
        want = np.float32([1.25, 2.375, 3.5, 4.625, 5.75, 6.875, 0, 0, 0, 0, 7.125, 8.25, 9.375])
        want[6:10] = np.frombuffer(rot[len(rot) - 16:], dtype="<f4")   # the rotation as kept: x, y, z, w
        blob = rb.to_bytes()
        offsets = [blob.find(c.tobytes()) for c in want]   # one not found (-1) reads garbage: refused below
        layout = (len(blob), np.concatenate([np.arange(o, o + 4) for o in offsets]))
        for _ in range(4):
            check.apply(np.zeros((n, 3)), rng.normal(size=(n, 3)))
            got = _decode(b"".join([b.to_bytes() for b in check.bodies]), n, layout)
            if not np.array_equal(got, np.asarray(rpw.Bodies.read(check), dtype=float)):
                return None
            check.step()
        return layout
    except Exception:  # noqa: BLE001 - an unexpected serialisation: the getters are always right
        return None


def body_spec(body) -> tuple:
    """``(mass_kg, principal moments (3,), q_BP (w x y z))`` as Rapier takes them, COM at the origin
    (world.principal_spec; the identity q_BP for a diagonal tensor)."""
    return world.principal_spec(body, diagonal=np.array([1.0, 0.0, 0.0, 0.0]))


class RapierWorld(rpw.Bodies, World):
    """The bodies of ``requests`` in one ``PhysicsWorld`` at ``dt_s`` under the first request's gravity
    (:class:`cross_checks.engines.worlds.rapier.Bodies`, what ``rbcheck repro`` embeds). Raw rows are packed
    states (float32 values). A body Rapier quarantines, or whose run is over, is dead from then on."""

    def __init__(self, requests, variant: str, dt_s: float):
        World.__init__(self)
        rpw.Bodies.__init__(self, world.body_specs(requests, body_spec),
                            requests[0].scenario.problem.forces.gravity_W, variant, dt_s)
        self.ends = [int(r.n_steps) for r in requests]
        self.layout = state_bytes_layout() if len(requests) > world.MANY_BODIES else None
        # a few bodies: the harness's rows and the reads (packed rows already) in plain floats, no arrays
        self.float_rows = self.float_reads = len(requests) <= world.MANY_BODIES
        self._to_bytes = [rb.to_bytes for rb in self.bodies]

    def set_state(self, y):
        rpw.Bodies.set_state(self, y)
        self.n, self.live, self._next_end = 0, [True] * len(self.bodies), min(self.ends, default=math.inf)
        self._given = None   # many bodies: the (f_W, τ_W) last given to the bodies (Rapier keeps them)

    def packed_row(self, raw):   # a read is packed rows already (plain floats, or many bodies' decoded array)
        return raw

    def apply(self, f_W, tau_W):
        """Many bodies: :meth:`Bodies.apply`'s replacement, made only where a body's force or torque
        changed, bit for bit, since the last (Rapier keeps them; the same Python floats reach it)."""
        if self.layout is None:
            return rpw.Bodies.apply(self, f_W, tau_W)
        given, self._given = self._given, (np.array(f_W, dtype=float), np.array(tau_W, dtype=float))
        for j, (reset, add) in enumerate((("reset_forces", "add_force"), ("reset_torques", "add_torque"))):
            a = self._given[j]
            new = (np.ones(len(a), dtype=bool) if given is None
                   else (a.view(np.uint64) != given[j].view(np.uint64)).any(axis=1))
            for k, v in zip(np.flatnonzero(new).tolist(), a[new].tolist()):
                if k not in self.dead:
                    getattr(self.bodies[k], reset)(False)
                    getattr(self.bodies[k], add)(tuple(v), False)

    def decay(self, g_v, g_w):   # Bodies.decay of the last read, many bodies' (an array) as plain floats
        if isinstance(self.last, np.ndarray):
            self.last = self.last.tolist()
        rpw.Bodies.decay(self, g_v, g_w)

    def first(self, y0):   # the scenario's own first row, not its float32 round trip
        return y0

    def step(self):   # a body Rapier quarantines (rolled back, disabled) is dead, with Rapier's words
        self.world.step()
        self.n += 1
        bad = self.world.quarantine.bodies
        for k in [k for k, h in enumerate(self.handles) if h in bad] if bad else ():
            self.dead.add(k)
            self.live[k] = False
            self.warnings.append((k, self.n, "Rapier quarantined the body"))

    def read(self):
        """The packed rows (a dead body's non-finite): up to world.MANY_BODIES bodies' through the getters,
        more from one serialisation each, decoded for all at once (the getters' numbers, bit for bit:
        :func:`state_bytes_layout`). A body whose run is over (its last step, or its state blown up:
        world.blown_up) is dead from then on: disabled, no force, no decay."""
        if self.layout is None:
            rows = rpw.Bodies.read(self)
        else:
            rows = self.last = _decode(b"".join([f() for f in self._to_bytes]), len(self.bodies), self.layout)
            if self.dead:
                rows[sorted(self.dead)] = math.nan
        over = world.blown_up(rows, self.live)
        if self.n >= self._next_end:   # some runs end at this step
            over += [k for k, end in enumerate(self.ends) if end <= self.n and self.live[k]]
            self._next_end = min([end for end in self.ends if end > self.n], default=math.inf)
        for k in over:
            self.live[k] = False
            self.dead.add(k)
            self.bodies[k].is_enabled = False
        return rows


class RapierEngine(WorldEngine):
    """``rapier:VARIANT`` — registered under the entry-point group ``rbcheck.engines``; optional."""

    name, variants, world, distribution, extra = ENGINE, VARIANTS, RapierWorld, DIST, "rapier"
    imported = "rapier"
    keeps_forces = True
    sign_continuity = True
    any_length = True   # one world per Δt and float32 gravity, whatever the runs' lengths

_ENGINE, version, simulate, simulate_many, one_step = RapierEngine.exported()
RapierAdapter = RapierEngine
