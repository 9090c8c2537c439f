"""Genesis's world (``genesis-world`` on the CPU, float64): numpy and genesis only (``rbcheck repro`` embeds
this file as it is).

One MJCF body (:func:`mjcf_text`: a free joint, an inertial at the body origin so that body origin = COM,
``fullinertia`` the tensor in BODY axes, the compiler told to keep both as given) loaded with ``align=False``
into a scene of ``n_envs`` environments (0: unbatched) whose defaults are neutralised (:func:`scene_options`:
one substep, collision, joint limits, constraints and hibernation off; the free joint's DOF settings
:data:`NEUTRAL_DOFS` checked after the build). State: ``qpos = [x_W, q_WB (w x y z)]``, DOF velocity
``[v_W, ω_B]`` (ω in BODY axes). The force (the weight off: Genesis applies gravity) and torque are written
into the link's wrench accumulators before every step, as ``apply_links_external_wrench(ref="link_com",
local=False)`` writes them. docs/engine_conventions.md, "Genesis 1.4.5".
"""
import numpy as np

#: DOF settings of the free joint, each checked after the build (Genesis getter suffix, neutral value).
NEUTRAL_DOFS = (("armature", 0.0), ("damping", 0.0), ("stiffness", 0.0), ("frictionloss", 0.0))


class NotNeutral(ValueError):
    """Genesis left a setting of the free joint that is not the physics at another value than neutral."""


def init():
    """The ``genesis`` module, initialised (once per process: ``gs.init`` is process-global) on the CPU in
    float64."""
    import genesis as gs
    if not gs._initialized:
        gs.init(backend=gs.cpu, precision="64", logging_level="warning")
    return gs


def mjcf_text(mass_kg, inertia_B, dt_s=0.01):
    """The body as MJCF: a free joint, an inertial at the body origin (mass, kg; ``fullinertia`` = Ixx Iyy Izz
    Ixy Ixz Iyz, kg m², body axes), the compiler told to keep frame and inertia as given (no free-joint
    alignment, inertia from geoms, balancing, bounds); the joint's limit time constant (none acts) raised from
    MuJoCo's 0.02 s to 2Δt where Genesis would, with a warning, at Δt > 0.01 s."""
    J = np.asarray(inertia_B, dtype=float)
    full = " ".join(repr(float(v)) for v in (J[0, 0], J[1, 1], J[2, 2], J[0, 1], J[0, 2], J[1, 2]))
    timeconst = max(0.02, 2.0 * float(dt_s))   # s
    return ('<mujoco model="rbcheck"><compiler alignfree="false" inertiafromgeom="false" '
            'balanceinertia="false" boundmass="0" boundinertia="0"/>'
            f'<default><joint solreflimit="{timeconst!r} 1"/></default>'
            '<worldbody><body name="body"><joint type="free" name="free"/>'
            f'<inertial pos="0 0 0" mass="{float(mass_kg)!r}" fullinertia="{full}"/>'
            '</body></worldbody></mujoco>')


def scene_options(variant, dt_s, gravity_W):
    """``(SimOptions, RigidOptions)`` of a scene: the run's step and gravity, one substep, the variant's
    ``gs.integrator`` (``Euler`` for euler), collision, joint limits, constraints and hibernation off."""
    gs = init()
    sim = gs.options.SimOptions(dt=float(dt_s), substeps=1, gravity=tuple(float(g) for g in gravity_W))
    rigid = gs.options.RigidOptions(
        integrator=getattr(gs.integrator, "Euler" if variant == "euler" else variant), enable_collision=False,
        enable_joint_limit=False, use_hibernation=False, disable_constraint=True)
    return sim, rigid


def _cross(a, b):
    a0, a1, a2, b0, b1, b2 = a[..., 0], a[..., 1], a[..., 2], b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def rotate(q, v):
    """``R(q) v`` for quaternions q (..., 4) (w, x, y, z) and vectors v (..., 3)."""
    s, u = q[..., :1], q[..., 1:]
    t = 2.0 * _cross(u, v)
    return v + s * t + _cross(u, t)


def to_qpos_vel(y):
    """Packed states (..., 13) ``[x_W, v_W, q_WB (w x y z), ω_W]`` -> qpos (..., 7) ``[x_W, q_WB]``, DOF
    velocity (..., 6) ``[v_W, ω_B]`` (ω in BODY axes)."""
    y = np.asarray(y, dtype=float)
    q = y[..., 6:10]
    return (np.concatenate([y[..., 0:3], q], axis=-1),
            np.concatenate([y[..., 3:6], rotate(q * np.array([1.0, -1.0, -1.0, -1.0]), y[..., 10:13])],
                           axis=-1))


def to_packed(qpos, vel):
    """qpos (..., 7), DOF velocity (..., 6) -> packed states (..., 13) with ω in WORLD axes."""
    q = qpos[..., 3:7]
    return np.concatenate([qpos[..., 0:3], vel[..., 0:3], q, rotate(q, vel[..., 3:6])], axis=-1)


class Body:
    """The body of MJCF ``xml`` in a scene of ``n_envs`` environments (0: unbatched) stepping at ``dt_s``
    under ``gravity_W``; raw rows ``[qpos (7), DOF velocity (6)]`` (n = max(n_envs, 1), 13)."""

    def __init__(self, xml, variant, dt_s, gravity_W, n_envs=0):
        gs = init()
        sim, rigid = scene_options(variant, dt_s, gravity_W)
        scene = gs.Scene(sim_options=sim, rigid_options=rigid, show_viewer=False)
        entity = scene.add_entity(gs.morphs.MJCF(file=xml, default_armature=0.0, align=False))
        scene.build(n_envs=int(n_envs))
        scene.step()   # compiles (or loads) the step's kernels here; set_state puts the body back
        self.gs, self.scene, self.entity, self.solver = gs, scene, entity, scene.sim.rigid_solver
        self.n_envs, self.n, self.dt_s = int(n_envs), max(int(n_envs), 1), float(dt_s)
        self.link = entity.base_link_idx
        # zero-copy NumPy views (qd_to_torch(..., copy=False), as Genesis's getters) of qpos (n, 7), the DOF
        # velocity (n, 6), the body's wrench accumulators cfrc_applied_vel/_ang and COM arm i_pos (n, 3)
        from genesis.utils.misc import qd_to_torch
        s, links = self.solver, self.solver.dyn_state.links
        self._qpos = qd_to_torch(s.qpos, transpose=True, copy=False).numpy()
        self._vel = qd_to_torch(s.dyn_state.dofs.vel, transpose=True, copy=False).numpy()
        self._f_vel, self._f_ang, self._i_pos = (qd_to_torch(a, copy=False).numpy()[self.link] for a in (
            links.cfrc_applied_vel, links.cfrc_applied_ang, links.i_pos))
        for name, value in NEUTRAL_DOFS:
            if not np.all((got := getattr(entity, f"get_dofs_{name}")().numpy()) == value):
                raise NotNeutral(f"left the free joint's {name} at {got.tolist()}, not {value}")

    def set_state(self, y):
        """Every environment at packed state(s) ``y`` (n, 13) (or (13,))."""
        qpos, vel = to_qpos_vel(np.broadcast_to(np.asarray(y, dtype=float), (self.n, 13)))
        if self.n_envs == 0:
            qpos, vel = qpos[0], vel[0]
        self.entity.set_qpos(qpos, zero_velocity=False)
        self.entity.set_dofs_velocity(vel)

    def read(self):
        """``[qpos, vel]`` (n, 13): ``get_qpos()``'s and ``get_dofs_velocity()``'s numbers."""
        self.last = np.concatenate([self._qpos[:, 0:7], self._vel[:, 0:6]], axis=1)
        return self.last

    def packed(self, raw):
        raw = np.asarray(raw, dtype=float)
        return to_packed(raw[..., 0:7], raw[..., 7:13])

    def decay(self, g_v, g_w):
        """The DOF velocities last read, scaled, without a forward pass."""
        vel = self.last[:, 7:13] * np.repeat(np.stack([g_v, g_w], axis=1), 3, axis=1)
        self.entity.set_dofs_velocity(vel[0] if self.n_envs == 0 else vel, skip_forward=True)

    def apply(self, f_W, tau_W):
        """World force ``f_W`` (n, 3) (N) at the COM and world torque ``tau_W`` (N m), for the next step only,
        as ``apply_links_external_wrench(ref="link_com", local=False)``'s kernel (rigid/abd/misc.py) writes
        them (nothing when all are zero) into the accumulators the last step cleared: ``cfrc_applied_vel −=
        f``, ``cfrc_applied_ang −= τ + i_pos × f`` (i_pos: the COM's arm, 0 for a lone body)."""
        f = np.asarray(f_W, dtype=float).reshape(self.n, 3)
        t = np.asarray(tau_W, dtype=float).reshape(self.n, 3)
        if f.any() or t.any():
            self._f_vel -= f
            self._f_ang -= t + np.cross(self._i_pos, f)

    def step(self):
        self.scene.step()


def world(bodies, gravity_W, variant, dt_s):
    (mass_kg, inertia_B, _), = bodies
    return Body(mjcf_text(mass_kg, inertia_B, dt_s), variant, dt_s, gravity_W)
