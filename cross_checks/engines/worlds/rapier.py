"""Rapier's world of free bodies (numpy and rapier3d only: ``rbcheck repro`` embeds this file's code).

One ``PhysicsWorld`` (a few bodies stepped on the calling thread: :data:`OWN_POOL_ABOVE`), a dynamic
``RigidBody`` per body without a collider, its mass properties about the COM (body origin = COM; principal
moments and frame), Rapier's defaults neutralised (:data:`WORLD_SETTINGS`, :data:`BODY_SETTINGS`).
``Rotation3`` is built (w, x, y, z) but read (x, y, z, w); ω in WORLD axes; user forces accumulate and are
kept between steps (``apply`` replaces them). Rapier computes in float32. docs/engine_conventions.md,
"Rapier".
"""
import math

import numpy as np
import rapier3d as rapier

#: The variants: Rapier's one integrator with its gyroscopic forces on (its default) or off.
GYROSCOPIC = {"symplectic_euler": True, "symplectic_euler_no_gyro": False}
#: IntegrationParameters set on every world: (attribute, value). Rapier 0.36.1's defaults are 4, 400, 1, 1.0.
WORLD_SETTINGS = (
    ("num_solver_iterations", 1),                         # substeps per step (default 4)
    ("normalized_max_linear_velocity", math.inf),         # linear speed cap (default 400 m/s)
    ("max_ccd_substeps", 0),                              # continuous collision detection (default 1)
    ("length_unit", 1.0),                                 # scales the speed cap and the contact tolerances
)
#: A world of more bodies than this gets a pool of one worker of its own (``set_num_threads(1)``); up to it,
#: a world steps on the calling thread (``set_num_threads(None)``: rayon's global pool, which rapier3d 0.36.1
#: gives no work up to 256 free bodies, measured). A pool of its own hands every step to its worker and
#: back, 15-50 us per step (one body steps in ~3 us on the calling thread); the global pool gives a world of
#: over 256 bodies work on threads a forked process does not have (it hangs), and uses every core.
OWN_POOL_ABOVE = 64
#: RigidBodyBuilder settings every body gets (builder method, value); the gyroscopic flag is the variant's.
BODY_SETTINGS = (
    ("can_sleep", False),                  # default True: asleep after 0.5 s below 0.05 m/s and 0.05 rad/s
    ("allow_fast_rotation", True),         # default False: |ω| capped at (π/4)/Δt
    ("linear_damping", 0.0), ("angular_damping", 0.0), ("gravity_scale", 1.0), ("ccd_enabled", False),
    ("additional_solver_iterations", 0),   # extra substeps for this body's island
)


def mass_properties(mass_kg, moments, q_BP):
    """``rapier3d.MassProperties``: COM at the origin, the principal moments (kg m²) and the principal frame
    ``q_BP`` (w x y z) in body coordinates."""
    return rapier.MassProperties(local_com=(0.0, 0.0, 0.0), mass=float(mass_kg),
                                 principal_inertia=tuple(float(m) for m in moments),
                                 principal_inertia_local_frame=rapier.Rotation3(*(float(c) for c in q_BP)))


class Bodies:
    """The bodies (live ``RigidBody`` views) in one ``PhysicsWorld`` at ``dt_s`` under ``gravity_W``. Raw rows
    are packed states (float32 values); a body in ``dead`` gets no force nor decay and reads non-finite."""

    def __init__(self, bodies, gravity_W, variant, dt_s):
        self.world = w = rapier.PhysicsWorld(gravity=tuple(float(g) for g in gravity_W))
        w.set_num_threads(1 if len(bodies) > OWN_POOL_ABOVE else None)
        for attr, value in (("dt", float(dt_s)), *WORLD_SETTINGS):
            setattr(w.integration_parameters, attr, value)      # a live view: modified in place
        self.handles, self.bodies, self.dead, self.last = [], [], set(), []
        for mass_kg, moments, q_BP in bodies:
            b = rapier.RigidBody.dynamic().additional_mass_properties(mass_properties(mass_kg, moments, q_BP))
            for method, value in BODY_SETTINGS:
                b = getattr(b, method)(value)
            self.handles.append(w.add_body(b.gyroscopic_forces(GYROSCOPIC[variant])))
            self.bodies.append(w.rigid_bodies[self.handles[-1]])

    def set_state(self, y):
        """Put the bodies at packed states ``y`` (B, 13) (rounded to float32 by Rapier), every one enabled."""
        self.last = np.asarray(y, dtype=float).tolist()     # the velocities the next decay scales
        for rb, r in zip(self.bodies, self.last):
            rb.is_enabled = True
            rb.position = rapier.Isometry3((r[0], r[1], r[2]), rapier.Rotation3(r[6], r[7], r[8], r[9]))
            rb.linvel, rb.angvel = (r[3], r[4], r[5]), (r[10], r[11], r[12])
        self.dead = set()

    def apply(self, f_W, tau_W):
        """Replace the user forces (world, at the COM, N) and torques (world, N m), (B, 3) arrays or B rows
        of 3 plain floats: Rapier keeps them."""
        if isinstance(f_W, np.ndarray) or isinstance(tau_W, np.ndarray):
            f_W, tau_W = np.asarray(f_W, dtype=float).tolist(), np.asarray(tau_W, dtype=float).tolist()
        for k, (rb, f, tau) in enumerate(zip(self.bodies, f_W, tau_W)):
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
        self.world.step()

    def read(self):
        rows = []
        for k, rb in enumerate(self.bodies):
            qx, qy, qz, qw = rb.rotation.to_tuple()
            x, v, w = rb.translation.to_tuple(), rb.linvel.to_tuple(), rb.angvel.to_tuple()
            rows.append([math.nan] * 13 if k in self.dead else [*x, *v, qw, qx, qy, qz, *w])
        self.last = rows
        return rows

    def packed(self, raw):
        return np.asarray(raw, dtype=float)


def world(bodies, gravity_W, variant, dt_s):
    return Bodies(bodies, gravity_W, variant, dt_s)
