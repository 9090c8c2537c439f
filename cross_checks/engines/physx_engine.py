"""NVIDIA PhysX 5 (CPU, through SAPIEN's ``sapien.physx``) as an engine (``physx:VARIANT``, float32): the
bodies of cross_checks.engines.worlds.physx for rbcheck's loop. Conventions, defaults neutralised, the
scheme of each variant and what pins them: docs/engine_conventions.md, "PhysX 5.3.1 (SAPIEN 3.0.3)".
"""
from __future__ import annotations

import dataclasses
import functools
import importlib.util
import math
import operator
import re
import struct
import threading
import warnings
from pathlib import Path

import numpy as np

from cross_checks.engines import install, world
from cross_checks.engines.base import EngineError, Traits, Variant
from cross_checks.engines.world import World, WorldEngine
from reference_sim.quaternion import quat_from_matrix
from reference_sim.simulate import BLOWUP_LIMIT

__all__ = ["ENGINE", "VARIANTS", "EngineError", "version", "simulate", "simulate_many", "one_step",
           "PhysxWorld", "PhysxAdapter"]

ENGINE = "physx"
_DIST = "sapien"

#: What each variant's step does and why it declares these traits: docs/engine_conventions.md, "PhysX".
_TRAITS = Traits(rotation_drift="momentum", rotation_sign=None, precision="float32")
VARIANTS = {
    "tgs": Variant(1, "PhysX 5 TGS (SAPIEN's default): semi-implicit Euler, explicit gyroscopic term "
                      "renormalised to |L|, exponential-map attitude; float32; ω kept in sqrt-inertia space",
                   traits=dataclasses.replace(_TRAITS, rounding_factor=4.0)),
    "pgs": Variant(1, "PhysX 5 PGS: semi-implicit Euler, explicit gyroscopic term renormalised to |L|, "
                      "exponential-map attitude; float32", traits=_TRAITS),
}

_LOCK = threading.RLock()


def version() -> str:
    """SAPIEN's version and the PhysX release it bundles, e.g. ``3.0.3 (PhysX 5.3.1)``, without importing
    sapien (its import starts a thread; the sweep forks): install.check_installed's errors."""
    install.check_installed(_DIST, "pip install 'rbcheck[physx]'", (("sapien", _DIST),))
    return _dist_version()


@functools.lru_cache(maxsize=1)
def _dist_version() -> str:
    """The release, with PhysX's from the header SAPIEN ships (found by import spec), "unknown" without it."""
    root = Path(importlib.util.find_spec("sapien").origin or "").parent
    header = root / "include" / "physx" / "include" / "foundation" / "PxPhysicsVersion.h"
    text = header.read_text(errors="replace") if header.is_file() else ""
    parts = re.findall(r"#define PX_PHYSICS_VERSION_(?:MAJOR|MINOR|BUGFIX)\s+(\d+)", text)
    return f"{install.installed_version(_DIST)} (PhysX {'.'.join(parts) if len(parts) == 3 else 'unknown'})"


def body_spec(body) -> tuple:
    """``(mass_kg, principal moments (3,), q_BP (w x y z))`` as PhysX takes them (its principal axes always:
    reference_sim.body.principal_axes, a diagonal tensor's too)."""
    moments, R_BP = body.principal_axes()
    return float(body.mass_kg), moments, quat_from_matrix(R_BP)


class _SceneLoop:
    """A PhysX world: the bodies of ``requests`` in one scene of ``variant``'s solver at ``dt_s`` under the
    first request's gravity (:func:`_world_class` puts it before worlds.physx's ``Bodies``, its ``W``). Raw
    rows are packed states (float32 values), up to world.MANY_BODIES bodies' as plain floats."""

    float_rows = True   # apply takes the harness's rows of plain floats (a few bodies)
    exact_start = True   # the scenario's own first row, not its float32 round trip

    def __init__(self, requests, variant: str, dt_s: float):
        World.__init__(self)
        with _LOCK:   # the scene config is SAPIEN's process-global default
            super().__init__(requests[0].scenario.problem.forces.gravity_W, variant, dt_s)
        for spec in world.body_specs(requests, body_spec):
            try:
                self.add_body(*spec)
            except Exception as exc:  # noqa: BLE001 - PhysX/SAPIEN refuses the mass properties
                raise EngineError(f"PhysX (sapien {install.installed_version(_DIST)}) refuses the body: "
                                  f"{type(exc).__name__}: {exc}") from None
        self.always = np.array([r.scenario.problem.forces.state_dependent for r in requests], dtype=bool)
        self.many = len(requests) > world.MANY_BODIES
        self.float_reads = not self.many
        # a few bodies: one pack() as plain floats, each body's packed row of it (PACK_TO_PACKED) in one call
        self._unpack = struct.Struct(f"{13 * len(self.comps)}f").unpack
        self._packed_of = [operator.itemgetter(*(13 * k + self.W.PACK_TO_PACKED).tolist())
                           for k in range(len(self.comps))]

    def read(self):
        """Every body's packed row: a few bodies' as 13 plain floats each from one ``pack()``, many bodies' as
        one float32 array (:meth:`Bodies.read`). A body whose state blew up (world.blown_up) is parked at rest
        at the origin once read (PhysX must never step a NaN), with no force and no decay from then on."""
        if self.many:
            rows = super().read()
            bad = world.blown_up(self.raw, self.alive)
        else:
            vals = self.last = self._unpack(self.system.pack())
            rows, self.raw = [g(vals) for g in self._packed_of], None   # raw: made by a decay of them
            bad = () if math.hypot(*vals) <= BLOWUP_LIMIT else world.blown_up(rows, self.alive)
        for k in bad:
            self.alive[k] = False
            self._put(k, np.eye(1, 13, 6)[0])   # x = 0, v = 0, q = (1, 0, 0, 0), ω = 0
        return rows

    def packed_row(self, raw):   # a read is packed rows already (a few: plain floats; many: float32)
        return raw

    def decay(self, g_v, g_w):   # the float32 velocities last read or set (Bodies.decay's raw), scaled
        if self.raw is None:
            self.raw = np.array(self.last, dtype=np.float32).reshape(len(self.comps), 13)
        super().decay(g_v, g_w)

    def apply(self, f_W, tau_W):
        """:meth:`Bodies.apply` of (B, 3) arrays, or of rows of plain floats as they are (the harness's).
        Many bodies' arrays: the same float32 numbers (rounded once for all by NumPy, as SAPIEN rounds each;
        both to nearest), the bodies that get one chosen in one vectorised pass, given float32 rows."""
        if self.many and isinstance(f_W, np.ndarray):
            get = self.alive & (self.always | f_W.any(axis=1) | tau_W.any(axis=1))
            f32, t32 = f_W.astype(np.float32), tau_W.astype(np.float32)
            for k in (range(len(self._add)) if get.all() else np.flatnonzero(get).tolist()):
                self._add[k](f32[k], t32[k])
            return
        if isinstance(f_W, np.ndarray):
            f_W, tau_W = f_W.tolist(), np.asarray(tau_W).tolist()
        alive, always, add = self.alive, self.always, self._add
        for k, f, t in zip(range(len(add)), f_W, tau_W):
            if alive[k] and (always[k] or f[0] or f[1] or f[2] or t[0] or t[1] or t[2]):
                add[k](f, t)

    def applier(self, f_W, tau_W):
        """:meth:`apply` of the constant forces as rows of plain floats (SAPIEN takes lists either way), made
        once, or None when no body gets any."""
        f, t = np.asarray(f_W, dtype=float).tolist(), np.asarray(tau_W, dtype=float).tolist()
        if self.always.any() or any(map(any, f)) or any(map(any, t)):
            return functools.partial(self.apply, f, t)
        return None


@functools.lru_cache(maxsize=1)
def _world_class():
    """The world's class, :class:`_SceneLoop` before ``W.Bodies``; ``W``: worlds.physx (what rbcheck repro
    embeds; it imports sapien), imported once after :func:`version`'s checks (install.first_import), SAPIEN's
    warning at import ("Failed to find system libvulkan") silenced."""
    version()
    with install.first_import(_DIST), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        from cross_checks.engines.worlds import physx as W
    return type("PhysxWorld", (_SceneLoop, W.Bodies, World), {"__doc__": _SceneLoop.__doc__, "W": W})


def PhysxWorld(requests, variant: str, dt_s: float):
    """A world of ``requests``, its class made once sapien is imported (the import starts a thread)."""
    return _world_class()(requests, variant, dt_s)


class PhysxEngine(WorldEngine):
    """``physx:VARIANT`` — registered under the entry-point group ``rbcheck.engines``; optional."""

    name, variants, distribution, extra = ENGINE, VARIANTS, _DIST, "physx"
    sign_continuity = True
    any_length = True   # one scene per Δt and float32 gravity, whatever the runs' lengths
    version = staticmethod(version)   # the module's: sapien is not imported
    require_installed = staticmethod(_world_class)   # version()'s checks and sapien's quiet import, once
    world = staticmethod(PhysxWorld)

    def engine_files(self) -> list:   # SAPIEN's compiled module and library (PhysX linked in), not imported
        return [*install.package_files("sapien", pattern="pysapien*.so"),
                *install.package_files("sapien", "../sapien.libs", pattern="libsapien*")]


_ENGINE, version, simulate, simulate_many, one_step = PhysxEngine.exported()
PhysxAdapter = PhysxEngine
