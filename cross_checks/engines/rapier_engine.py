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

import math

import numpy as np

from cross_checks.engines import install
from cross_checks.engines.base import EngineError, Traits, Variant
from cross_checks.engines.step_floats import bad_floats
from cross_checks.engines.world import World, WorldEngine
from reference_sim.quaternion import quat_from_matrix

rapier, _IMPORT_ERROR = install.optional_import("rapier3d")

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

#: IntegrationParameters set on every world: (attribute, value). Rapier 0.36.1's defaults are 4, 400, 1, 1.0.
WORLD_SETTINGS = (
    ("num_solver_iterations", 1),                         # substeps per step (default 4)
    ("normalized_max_linear_velocity", math.inf),         # linear speed cap (default 400 m/s)
    ("max_ccd_substeps", 0),                              # continuous collision detection (default 1)
    ("length_unit", 1.0),                                 # scales the speed cap and the contact tolerances
)
#: RigidBodyBuilder settings every body gets (builder method, value); the gyroscopic flag is the variant's.
BODY_SETTINGS = (
    ("can_sleep", False),                  # default True: asleep after 0.5 s below 0.05 m/s and 0.05 rad/s
    ("allow_fast_rotation", True),         # default False: |ω| capped at (π/4)/Δt
    ("linear_damping", 0.0), ("angular_damping", 0.0), ("gravity_scale", 1.0), ("ccd_enabled", False),
    ("additional_solver_iterations", 0),   # extra substeps for this body's island
)


def _mass_properties(body):
    """``rapier3d.MassProperties`` of an rbcheck RigidBody: COM at the origin, the principal moments and the
    rotation of the principal axes in body coordinates (identity for a diagonal tensor)."""
    if body.is_diagonal():
        moments, q_BP = np.diag(body.inertia_B).copy(), np.array([1.0, 0.0, 0.0, 0.0])
    else:
        moments, R_BP = body.principal_axes()
        q_BP = quat_from_matrix(R_BP)
    return rapier.MassProperties(local_com=(0.0, 0.0, 0.0), mass=float(body.mass_kg),
                                 principal_inertia=tuple(float(m) for m in moments),
                                 principal_inertia_local_frame=rapier.Rotation3(*(float(c) for c in q_BP)))


class RapierWorld(World):
    """The bodies of ``requests`` (``bodies``: live ``RigidBody`` views) in one ``PhysicsWorld`` at ``dt_s``
    under the first request's gravity. Raw rows are packed states (float32 values)."""

    def __init__(self, requests, variant: str, dt_s: float):
        super().__init__()
        self.world = w = rapier.PhysicsWorld(
            gravity=tuple(float(g) for g in requests[0].scenario.problem.forces.gravity_W))
        w.set_num_threads(1)
        for attr, value in (("dt", float(dt_s)), *WORLD_SETTINGS):
            setattr(w.integration_parameters, attr, value)      # a live view: modified in place
        self.handles, self.bodies = [], []
        for r in requests:
            mp = _mass_properties(r.scenario.problem.body)
            b = rapier.RigidBody.dynamic().additional_mass_properties(mp)
            for method, value in BODY_SETTINGS:
                b = getattr(b, method)(value)
            self.handles.append(w.add_body(b.gyroscopic_forces(VARIANTS[variant].traits.gyroscopic_term)))
            self.bodies.append(w.rigid_bodies[self.handles[-1]])
        self.ends = [int(r.n_steps) for r in requests]
        self.n, self.dead, self.last = 0, set(), []

    def set_state(self, y):
        """Put the bodies at packed states ``y`` (B, 13) (rounded to float32 by Rapier), every one enabled."""
        self.last = np.asarray(y, dtype=float).tolist()     # the velocities the next decay scales
        for rb, r in zip(self.bodies, self.last):
            rb.is_enabled = True
            rb.position = rapier.Isometry3((r[0], r[1], r[2]), rapier.Rotation3(r[6], r[7], r[8], r[9]))
            rb.linvel, rb.angvel = (r[3], r[4], r[5]), (r[10], r[11], r[12])
        self.n, self.dead = 0, set()

    def first(self, y0):   # the scenario's own first row, not its float32 round trip
        return y0

    def apply(self, f_W, tau_W):
        """Replace the user forces (world, at the COM, N) and torques (world, N m): Rapier keeps them."""
        for k, (rb, f, tau) in enumerate(zip(self.bodies, f_W.tolist(), tau_W.tolist())):
            if k not in self.dead:
                rb.reset_forces(False)
                rb.reset_torques(False)
                rb.add_force(tuple(f), False)
                rb.add_torque(tuple(tau), False)

    def decay(self, g_v, g_w):   # the velocities last read (or set), scaled: no pose reset (q renormalised)
        for k, (rb, r, gv, gw) in enumerate(zip(self.bodies, self.last, g_v.tolist(), g_w.tolist())):
            if k not in self.dead:
                rb.linvel = (gv * r[3], gv * r[4], gv * r[5])
                rb.angvel = (gw * r[10], gw * r[11], gw * r[12])

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
        rows = []
        for k, rb in enumerate(self.bodies):
            qx, qy, qz, qw = rb.rotation.to_tuple()
            x, v, w = rb.translation.to_tuple(), rb.linvel.to_tuple(), rb.angvel.to_tuple()
            rows.append([math.nan] * 13 if k in self.dead else [*x, *v, qw, qx, qy, qz, *w])
            if k not in self.dead and (self.n >= self.ends[k] or bad_floats(rows[-1])):
                self.dead.add(k)
                rb.is_enabled = False
        self.last = rows
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
