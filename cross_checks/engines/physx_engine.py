"""NVIDIA PhysX 5 (CPU, through SAPIEN's ``sapien.physx``) as an engine (``physx:VARIANT``, float32): a world
of bodies for rbcheck's loop (cross_checks.engines.world, cross_checks.engines.loop).

A ``sapien.Scene`` with a ``PhysxCpuSystem`` (PhysX 5.3.1 in SAPIEN 3.0.3, on the calling thread) per Δt and
float32 gravity; a ``PhysxRigidDynamicComponent`` per run, no shape, the tensor as principal moments and mass
frame R_BP (the actor frame stays the body frame), neutralised (:data:`BODY_SETTINGS`). At the boundary: the
actor pose ``Pose(p, q (w x y z))``, the COM's velocity, ω in WORLD axes, one ``pack()`` per step; forces
before every step (PhysX clears them). Conventions, defaults neutralised and what pins them:
docs/engine_conventions.md, "PhysX 5.3.1 (SAPIEN 3.0.3)".
"""
from __future__ import annotations

import dataclasses
import functools
import importlib.util
import re
import threading
import warnings
from pathlib import Path

import numpy as np

from cross_checks.engines import install
from cross_checks.engines.base import EngineError, Traits, Variant
from cross_checks.engines.install import installed_version
from cross_checks.engines.world import World, WorldEngine
from reference_sim.quaternion import quat_from_matrix
from reference_sim.simulate import BLOWUP_LIMIT

__all__ = ["ENGINE", "VARIANTS", "BODY_SETTINGS", "PACK_TO_PACKED", "EngineError", "version", "simulate",
           "simulate_many", "one_step", "PhysxWorld", "neutralise", "PhysxAdapter"]

ENGINE = "physx"
_DIST = "sapien"

#: PhysX's rigid-body step: the renormalisation keeps |L| exactly while the rotational energy drifts at first
#: order, either sign (docs/verdicts.md §3). TGS keeps ω in √I space and converts it back with two float32 3×3
#: products every step: four ordinary steps' rounding (docs/verdicts.md, ``rounding_factor``).
_TRAITS = Traits(gyroscopic_term=True, translation_drift=0, rotation_drift="momentum", rotation_sign=None,
                 precision="float32")
VARIANTS = {
    # sapien's default solver (PhysxSceneConfig.enable_tgs = True)
    "tgs": Variant(1, "PhysX 5 TGS (SAPIEN's default): semi-implicit Euler, explicit gyroscopic term "
                      "renormalised to |L|, exponential-map attitude; float32; ω kept in sqrt-inertia space",
                   traits=dataclasses.replace(_TRAITS, rounding_factor=4.0)),
    "pgs": Variant(1, "PhysX 5 PGS: semi-implicit Euler, explicit gyroscopic term renormalised to |L|, "
                      "exponential-map attitude; float32", traits=_TRAITS),
}

#: Rigid-dynamic settings every body gets, each set explicitly: (sapien setter, value). The velocity limits:
#: |v|² must stay finite in float32 (PhysX stores the square); a zero sleep threshold resets the wake counter
#: every step (DySleep.cpp).
BODY_SETTINGS = (("set_linear_damping", 0.0), ("set_angular_damping", 0.0), ("set_max_linear_velocity", 1e16),
                 ("set_max_angular_velocity", 1e16), ("set_max_depenetration_velocity", 1e16),
                 ("set_max_contact_impulse", 1e16), ("set_sleep_threshold", 0.0),
                 ("set_solver_position_iterations", 1), ("set_solver_velocity_iterations", 1),
                 ("set_disable_gravity", False), ("set_kinematic", False))

#: Columns of one body's ``pack()`` row ``[q (w x y z), p, v, ω]`` in rbcheck's packed order [x, v, q, ω].
PACK_TO_PACKED = np.array([4, 5, 6, 7, 8, 9, 0, 1, 2, 3, 10, 11, 12])
_REST = np.eye(1, 13, 6)[0]   # where a body whose run blew up is parked: at rest at the origin
_LOCK = threading.RLock()


def version() -> str:
    """SAPIEN's version and the PhysX release it bundles, e.g. ``3.0.3 (PhysX 5.3.1)``, without importing
    sapien (its import starts a thread; the sweep forks): EngineNotInstalled, or ImportError if not found."""
    if installed_version(_DIST) is None:
        raise install.EngineNotInstalled("sapien is not installed (pip install 'rbcheck[physx]')")
    if importlib.util.find_spec("sapien") is None:
        raise ImportError(f"sapien {installed_version(_DIST)} is installed but cannot be imported: "
                          "no module named 'sapien'")
    return _dist_version()


@functools.lru_cache(maxsize=1)
def _dist_version() -> str:
    """The release, with PhysX's from the header SAPIEN ships (found by import spec), "unknown" without it."""
    root = Path(importlib.util.find_spec("sapien").origin or "").parent
    header = root / "include" / "physx" / "include" / "foundation" / "PxPhysicsVersion.h"
    text = header.read_text(errors="replace") if header.is_file() else ""
    parts = re.findall(r"#define PX_PHYSICS_VERSION_(?:MAJOR|MINOR|BUGFIX)\s+(\d+)", text)
    return f"{installed_version(_DIST)} (PhysX {'.'.join(parts) if len(parts) == 3 else 'unknown'})"


@functools.lru_cache(maxsize=1)
def _engine():
    """``(sapien, sapien.physx)``, imported once after :func:`version`'s checks; SAPIEN's warning at import
    ("Failed to find system libvulkan": no rendering here) silenced."""
    version()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import sapien
        import sapien.physx as px
    return sapien, px


def neutralise(c) -> None:   # every setting of BODY_SETTINGS on the rigid dynamic c, whatever it was
    for setter, value in BODY_SETTINGS:
        getattr(c, setter)(value)


class PhysxWorld(World):
    """The bodies of ``requests`` (``comps``: their rigid dynamics) in one scene of ``variant``'s solver at
    ``dt_s`` under the first request's gravity. Raw rows are packed states (float32 values)."""

    def __init__(self, requests, variant: str, dt_s: float):
        super().__init__()
        sapien, px = _engine()
        self.Pose = sapien.Pose
        cfg = px.PhysxSceneConfig()
        cfg.gravity = np.float32(requests[0].scenario.problem.forces.gravity_W)
        cfg.enable_tgs = variant == "tgs"
        with _LOCK:   # the scene config is SAPIEN's process-global default, read when the system is made
            before = px.get_scene_config()
            px.set_scene_config(cfg)
            try:
                self.system = px.PhysxCpuSystem()
            finally:      # SAPIEN's default left as it was for any other user of sapien in the process
                px.set_scene_config(before)
        self.scene = sapien.Scene(systems=[self.system])
        self.system.set_timestep(float(dt_s))
        self.comps = []
        for r in requests:
            moments, R_BP = r.scenario.problem.body.principal_axes()
            entity, c = sapien.Entity(), px.PhysxRigidDynamicComponent()
            entity.add_component(c)
            try:
                c.set_mass(float(r.scenario.problem.body.mass_kg))
                c.set_inertia(np.float32(moments))
                c.set_cmass_local_pose(sapien.Pose(np.float32([0, 0, 0]), np.float32(quat_from_matrix(R_BP))))
            except Exception as exc:  # noqa: BLE001 - PhysX/SAPIEN refuses the mass properties: its words
                raise EngineError(f"PhysX (sapien {installed_version(_DIST)}) refuses the body: "
                                  f"{type(exc).__name__}: {exc}") from None
            neutralise(c)
            self.scene.add_entity(entity)
            self.comps.append(c)
        self.always = np.array([r.scenario.problem.forces.state_dependent for r in requests], dtype=bool)

    def _put(self, k: int, y) -> None:   # body k at the packed state y (13,): pose, COM velocity, world ω
        c = self.comps[k]
        c.set_entity_pose(self.Pose(np.float32(y[0:3]), np.float32(y[6:10])))
        c.set_linear_velocity(np.float32(y[3:6]))
        c.set_angular_velocity(np.float32(y[10:13]))

    def set_state(self, y):
        for k, row in enumerate(np.asarray(y, dtype=float)):
            self._put(k, row)
        self.alive, self.raw = np.ones(len(self.comps), dtype=bool), self._pack()

    def first(self, y0):   # the scenario's own first row, not its float32 round trip
        return y0

    def apply(self, f_W, tau_W):   # world forces at the COMs (N) and world torques (N m), float32
        F, T = np.float32(f_W), np.float32(tau_W)
        for k in np.flatnonzero(self.alive & (self.always | F.any(axis=1) | T.any(axis=1))):
            self.comps[k].add_force_torque(F[k], T[k])

    def decay(self, g_v, g_w):   # the float32 velocities last read, scaled in float32
        for k, (c, gv, gw) in enumerate(zip(self.comps, g_v.tolist(), g_w.tolist())):
            if self.alive[k]:
                c.set_linear_velocity(self.raw[k, 7:10] * np.float32(gv))
                c.set_angular_velocity(self.raw[k, 10:13] * np.float32(gw))

    def step(self):
        self.system.step()

    def read(self):
        """The packed rows; a body whose state is non-finite or beyond BLOWUP_LIMIT is parked at rest once
        read (so that PhysX never steps a NaN), with no force and no decay from then on."""
        self.raw = raw = self._pack()
        fine = np.abs(raw).max() <= BLOWUP_LIMIT          # (NaN compares False)
        for k in () if fine else np.flatnonzero(self.alive & ~(np.abs(raw).max(axis=1) <= BLOWUP_LIMIT)):
            self.alive[k] = False
            self._put(k, _REST)
        return raw[:, PACK_TO_PACKED]

    def _pack(self):   # every body's ``pack()`` row [q (w x y z), p, v, ω] (B, 13) float32, a copy
        return np.frombuffer(self.system.pack(), dtype=np.float32).reshape(len(self.comps), 13).copy()


class PhysxEngine(WorldEngine):
    """``physx:VARIANT`` — registered under the entry-point group ``rbcheck.engines``; optional."""

    name, variants, distribution = ENGINE, VARIANTS, _DIST
    sign_continuity = True

    version = staticmethod(version)   # the module's: sapien is not imported

    def build(self, requests, variant, dt_s):
        return PhysxWorld(requests, variant, dt_s)

    def group_key(self, request) -> tuple:   # one scene per Δt and float32 gravity; runs of any length
        return (float(request.dt_s), np.float32(request.scenario.problem.forces.gravity_W).tobytes())

    def engine_files(self) -> list:   # SAPIEN's compiled module and library (PhysX linked in), not imported
        return [*install.package_files("sapien", pattern="pysapien*.so"),
                *install.package_files("sapien", "../sapien.libs", pattern="libsapien*")]


_ENGINE = PhysxEngine()
#: The module's functions (tests and scripts call them): the engine's, through the host loop.
simulate, simulate_many, one_step = _ENGINE.simulate, _ENGINE.simulate_many, _ENGINE.one_step
PhysxAdapter = PhysxEngine
