"""PhysX 5's world (CPU, through SAPIEN's ``sapien.physx``, float32): numpy and sapien only (``rbcheck repro``
embeds this file's code).

A ``sapien.Scene`` with a ``PhysxCpuSystem`` of the variant's solver ("tgs": SAPIEN's default, or "pgs") at
``dt_s`` and float32 gravity; a ``PhysxRigidDynamicComponent`` per body, no shape, its principal moments and
mass frame ``q_BP`` (the actor frame stays the body frame), neutralised (:data:`BODY_SETTINGS`). The actor
pose ``Pose(p, q (w x y z))``, the COM's velocity, ω in WORLD axes; one ``pack()`` per read; forces before
every step (PhysX clears them). docs/engine_conventions.md, "PhysX".
"""
import numpy as np
import sapien
import sapien.physx as px

#: Rigid-dynamic settings every body gets, each set explicitly: (sapien setter, value). The velocity limits:
#: |v|² must stay finite in float32 (PhysX stores the square); a zero sleep threshold resets the wake counter
#: every step (DySleep.cpp).
BODY_SETTINGS = (("set_linear_damping", 0.0), ("set_angular_damping", 0.0), ("set_max_linear_velocity", 1e16),
                 ("set_max_angular_velocity", 1e16), ("set_max_depenetration_velocity", 1e16),
                 ("set_max_contact_impulse", 1e16), ("set_sleep_threshold", 0.0),
                 ("set_solver_position_iterations", 1), ("set_solver_velocity_iterations", 1),
                 ("set_disable_gravity", False), ("set_kinematic", False))
#: Columns of one body's ``pack()`` row ``[q (w x y z), p, v, ω]`` in the packed order [x, v, q, ω].
PACK_TO_PACKED = np.array([4, 5, 6, 7, 8, 9, 0, 1, 2, 3, 10, 11, 12])


def neutralise(c):   # every setting of BODY_SETTINGS on the rigid dynamic c, whatever it was
    for setter, value in BODY_SETTINGS:
        getattr(c, setter)(value)


class Bodies:
    """Rigid dynamics (``comps``) in one scene; raw rows are packed states (float32 values). A body not
    ``alive`` gets no force nor decay; one in ``always`` gets its force even when zero."""

    def __init__(self, gravity_W, variant, dt_s):
        cfg = px.PhysxSceneConfig()
        cfg.gravity = np.float32(gravity_W)
        cfg.enable_tgs = variant == "tgs"
        before = px.get_scene_config()   # SAPIEN's process-global default, read when the system is made
        px.set_scene_config(cfg)
        try:
            self.system = px.PhysxCpuSystem()
        finally:
            px.set_scene_config(before)
        self.scene = sapien.Scene(systems=[self.system])
        self.system.set_timestep(float(dt_s))
        self.comps, self.always = [], np.zeros(0, dtype=bool)
        self._add = []   # each body's add_force_torque, bound once
        self.step = self.system.step

    def add_body(self, mass_kg, moments, q_BP):
        entity, c = sapien.Entity(), px.PhysxRigidDynamicComponent()
        entity.add_component(c)
        c.set_mass(float(mass_kg))
        c.set_inertia(np.float32(moments))
        c.set_cmass_local_pose(sapien.Pose(np.float32([0, 0, 0]), np.float32(q_BP)))
        neutralise(c)
        self.scene.add_entity(entity)
        self.comps.append(c)
        self._add.append(c.add_force_torque)
        self.always = np.zeros(len(self.comps), dtype=bool)

    def _put(self, k, y):   # body k at the packed state y (13,): pose, COM velocity, world ω
        c = self.comps[k]
        c.set_entity_pose(sapien.Pose(np.float32(y[0:3]), np.float32(y[6:10])))
        c.set_linear_velocity(np.float32(y[3:6]))
        c.set_angular_velocity(np.float32(y[10:13]))

    def set_state(self, y):
        for k, row in enumerate(np.asarray(y, dtype=float)):
            self._put(k, row)
        self.alive, self.raw = np.ones(len(self.comps), dtype=bool), self._pack()

    def apply(self, f_W, tau_W):
        """World forces at the COMs (N) and world torques (N m), (B, 3), for the next step only; SAPIEN
        rounds them to float32. A body not ``alive`` gets none; a zero wrench is not added unless the body
        is in ``always``. Per body in plain floats (a few small NumPy operations cost more than the step)."""
        alive, always, add = self.alive, self.always, self._add
        for k, f, t in zip(range(len(add)), np.asarray(f_W, dtype=float).tolist(),
                           np.asarray(tau_W, dtype=float).tolist()):
            if alive[k] and (always[k] or f[0] or f[1] or f[2] or t[0] or t[1] or t[2]):
                add[k](f, t)

    def decay(self, g_v, g_w):   # the float32 velocities last read, scaled in float32
        for k, (c, gv, gw) in enumerate(zip(self.comps, g_v.tolist(), g_w.tolist())):
            if self.alive[k]:
                c.set_linear_velocity(self.raw[k, 7:10] * np.float32(gv))
                c.set_angular_velocity(self.raw[k, 10:13] * np.float32(gw))

    def read(self):
        self.raw = self._pack()
        return self.raw[:, PACK_TO_PACKED]

    def packed(self, raw):
        return np.asarray(raw, dtype=float)

    def packed_row(self, raw):   # one read's rows as plain floats (float32 values, exactly)
        return raw.tolist()

    def _pack(self):   # every body's ``pack()`` row [q (w x y z), p, v, ω] (B, 13) float32, a copy
        return np.frombuffer(self.system.pack(), dtype=np.float32).reshape(len(self.comps), 13).copy()


def world(bodies, gravity_W, variant, dt_s):
    w = Bodies(gravity_W, variant, dt_s)
    for mass_kg, moments, q_BP in bodies:
        w.add_body(mass_kg, moments, q_BP)
    return w
