"""Rapier (``rapier3d``, dimforge's Python bindings, 3D, float32) as an engine (``rapier:VARIANT``): a world
of bodies for rbcheck's loop (cross_checks.engines.world, cross_checks.engines.loop).

One ``PhysicsWorld`` per Δt and gravity, a dynamic ``RigidBody`` per run, no collider, mass properties about
the COM (body origin = COM, the scenario's body frame; principal moments and frame R_BP); defaults neutralised
(:data:`WORLD_SETTINGS`, :data:`BODY_SETTINGS`, one thread). At the boundary: COM position and velocity, ω in
WORLD axes, ``Rotation3`` built (w, x, y, z) but read (x, y, z, w); user forces ACCUMULATE and are kept (the
loop's replace them); the decay sets the velocities last read, scaled. Conventions, defaults neutralised and
what pins them: docs/engine_conventions.md, "Rapier 0.36.1".
"""
from __future__ import annotations

import types

import numpy as np

from cross_checks.engines import install
from cross_checks.engines.base import EngineError, Traits, Variant
from cross_checks.engines.step_floats import bad_floats
from cross_checks.engines.world import World, WorldEngine
from reference_sim.quaternion import quat_from_matrix

rapier, _IMPORT_ERROR = install.optional_import("rapier3d")
if _IMPORT_ERROR is None:   # the world (what rbcheck repro embeds) imports the engine itself
    from cross_checks.engines.worlds import rapier as rpw
    from cross_checks.engines.worlds.rapier import BODY_SETTINGS, WORLD_SETTINGS
else:   # not installed: the adapter still loads, and says so when used
    rpw = types.SimpleNamespace(Bodies=type("Bodies", (), {}))

__all__ = ["ENGINE", "DIST", "VARIANTS", "WORLD_SETTINGS", "BODY_SETTINGS", "EngineError", "version",
           "simulate", "simulate_many", "one_step", "RapierWorld", "RapierAdapter"]

ENGINE = "rapier"
DIST = "rapier3d"

#: Rapier's one integrator (symplectic Euler: rigid_body_components.rs, ``integrate_forces_and_velocities``),
#: its gyroscopic forces on (its default, first: |L| kept exactly, the energy drifting towards the separatrix,
#: either sign) and off (ω_W changes only by the torque: constant without one).
VARIANTS = {
    "symplectic_euler": Variant(1, "Rapier's step (gyroscopic forces on, its default): semi-implicit Euler "
                                   "in float32, explicit gyroscopic step in the principal frame rescaled to "
                                   "keep |L|, linearised normalised quaternion update with the new ω",
                                traits=Traits(gyroscopic_term=True, translation_drift=0, rotation_sign=None,
                                              rotation_drift="momentum", precision="float32")),
    "symplectic_euler_no_gyro": Variant(1, "Rapier's step with gyroscopic_forces(False): semi-implicit Euler "
                                           "in float32 without the gyroscopic term (ω_W changes only by the "
                                           "torque)",
                                        traits=Traits(gyroscopic_term=False, translation_drift=0,
                                                      rotation_drift="none", rotation_sign=0,
                                                      precision="float32")),
}

def body_spec(body) -> tuple:
    """``(mass_kg, principal moments (3,), q_BP (w x y z))`` of an rbcheck RigidBody as Rapier takes it: COM
    at the origin, the rotation of the principal axes in body coordinates (identity for a diagonal tensor)."""
    if body.is_diagonal():
        return float(body.mass_kg), np.diag(body.inertia_B).copy(), np.array([1.0, 0.0, 0.0, 0.0])
    moments, R_BP = body.principal_axes()
    return float(body.mass_kg), moments, quat_from_matrix(R_BP)


class RapierWorld(rpw.Bodies, World):
    """The bodies of ``requests`` in one ``PhysicsWorld`` at ``dt_s`` under the first request's gravity
    (:class:`cross_checks.engines.worlds.rapier.Bodies`, what ``rbcheck repro`` embeds). Raw rows are packed
    states (float32 values). A body Rapier quarantines, or whose run is over, is dead from then on."""

    def __init__(self, requests, variant: str, dt_s: float):
        World.__init__(self)
        rpw.Bodies.__init__(self, [body_spec(r.scenario.problem.body) for r in requests],
                            requests[0].scenario.problem.forces.gravity_W, variant, dt_s)
        self.ends = [int(r.n_steps) for r in requests]
        self.n = 0

    def set_state(self, y):
        rpw.Bodies.set_state(self, y)
        self.n = 0

    def first(self, y0):   # the scenario's own first row, not its float32 round trip
        return y0

    def step(self):
        """One step; a body Rapier quarantines (rolled back, disabled) is dead, with Rapier's words."""
        self.world.step()
        self.n += 1
        bad = self.world.quarantine.bodies
        for k in [k for k, h in enumerate(self.handles) if h in bad] if bad else ():
            self.dead.add(k)
            self.warnings.append((k, self.n, "Rapier quarantined the body"))

    def read(self):
        """The packed rows (a dead body's non-finite). A body whose run is over (its last step, or a state
        non-finite or beyond BLOWUP_LIMIT) is dead from then on: disabled, no force, no decay."""
        rows = rpw.Bodies.read(self)
        for k, rb in enumerate(self.bodies):
            if k not in self.dead and (self.n >= self.ends[k] or bad_floats(rows[k])):
                self.dead.add(k)
                rb.is_enabled = False
        return rows


class RapierEngine(WorldEngine):
    """``rapier:VARIANT`` — registered under the entry-point group ``rbcheck.engines``; optional."""

    name = ENGINE
    variants = VARIANTS
    distribution = DIST
    keeps_forces = True
    sign_continuity = True

    def _installed(self):
        install.require(rapier, _IMPORT_ERROR, DIST, hint="pip install 'rbcheck[rapier]'")

    def build(self, requests, variant, dt_s):
        self._installed()
        return RapierWorld(requests, variant, dt_s)

    def group_key(self, request) -> tuple:   # one world per Δt and gravity; runs of any length share it
        return (float(request.dt_s), tuple(float(g) for g in request.scenario.problem.forces.gravity_W))

    def engine_files(self) -> list:   # rapier3d's compiled module (a rebuilt wheel is a new engine)
        return [] if rapier is None else install.library_files(getattr(rapier, "_rapier3d", None))


_ENGINE = RapierEngine()
#: The module's functions (tests and scripts call them): the engine's, through the host loop.
version, simulate, simulate_many, one_step = (_ENGINE.version, _ENGINE.simulate, _ENGINE.simulate_many,
                                              _ENGINE.one_step)
RapierAdapter = RapierEngine
