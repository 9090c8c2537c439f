"""MuJoCo's world of free bodies (numpy and mujoco only: ``rbcheck repro`` embeds this file's code).

One MjSpec body per body, with a free joint on the body frame and the mass and inertia exactly as given
(alignfree, inertiafromgeom, balanceinertia, boundmass and boundinertia neutralised; no auto-reset).
MuJoCo's state is ``qpos = [x_W, q_WB (w x y z)]``, ``qvel = [v_W, ω_B (BODY axes)]``; forces go into
``xfrc_applied`` (world force at the COM, world torque; MuJoCo keeps them), a torque fixed in body axes into
``qfrc_applied`` (a free joint's rotational DOFs are body axes). docs/engine_conventions.md.
"""
import mujoco
import numpy as np


def build_model(bodies, gravity_W, variant, dt_s, name="rbcheck"):
    """The compiled MjModel of ``bodies`` ((mass_kg, moments (3,), q_BP (w x y z)) each; optionally also the
    COM in the body frame (m) and welded parts: child bodies without a joint, each (mass_kg, moments, q_BP,
    com)) for the integrator ``variant`` ("euler", "rk4", "implicit", "implicitfast", "discrete") at step
    ``dt_s`` (s)."""
    spec = mujoco.MjSpec()
    spec.modelname, spec.option.timestep = name, float(dt_s)
    spec.option.gravity = np.asarray(gravity_W, dtype=float)
    # keep the joint (= qpos) on the body frame, not the inertial frame; never alter the inertia silently
    spec.compiler.alignfree = spec.compiler.balanceinertia = False
    spec.compiler.inertiafromgeom = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_FALSE
    spec.compiler.boundmass = spec.compiler.boundinertia = 0.0
    spec.option.integrator = getattr(mujoco.mjtIntegrator, f"mjINT_{variant.upper()}")
    spec.option.disableflags |= mujoco.mjtDisableBit.mjDSBL_AUTORESET
    for k, body in enumerate(bodies):
        b = spec.worldbody.add_body(name="body" if k == 0 else f"body{k}")
        b.add_freejoint()
        _inertial(b, *body[:3], body[3] if len(body) > 3 else (0.0, 0.0, 0.0))
        for j, part in enumerate(body[4] if len(body) > 4 else (), 1):
            child = b.add_body()           # no joint: welded to the body, its frame the body frame
            child.name = f"{b.name}_part{j}"
            child.pos = [0.0, 0.0, 0.0]
            _inertial(child, *part)
    return spec.compile()


def _inertial(b, mass_kg, moments, q_BP, com_B):
    # explicit, ipos set (unset, NaN, would let geoms override it); iquat: the principal frame P in body axes
    b.explicitinertial, b.mass, b.iquat, b.inertia = True, float(mass_kg), q_BP, moments
    b.ipos = [float(v) for v in com_B]


def _cross(a, b):
    a0, a1, a2, b0, b1, b2 = a[..., 0], a[..., 1], a[..., 2], b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def rotate(q, v):
    """``R(q) v`` for quaternions q (..., 4) (w, x, y, z) and vectors v (..., 3)."""
    s, u = q[..., :1], q[..., 1:]
    t = 2.0 * _cross(u, v)
    return v + s * t + _cross(u, t)


def to_qpos_qvel(y):
    """Packed states (..., 13) -> qpos (..., 7), qvel (..., 6) with ω in BODY axes."""
    y = np.asarray(y, dtype=float)
    w_B = rotate(y[..., 6:10] * np.array([1.0, -1.0, -1.0, -1.0]), y[..., 10:13])   # R(q)ᵀ ω_W
    return np.concatenate([y[..., 0:3], y[..., 6:10]], axis=-1), np.concatenate([y[..., 3:6], w_B], axis=-1)


def to_packed(qpos, qvel):
    """qpos (..., 7), qvel (..., 6) -> packed states (..., 13) with ω in WORLD axes."""
    q = qpos[..., 3:7]
    return np.concatenate([qpos[..., 0:3], qvel[..., 0:3], q, rotate(q, qvel[..., 3:6])], axis=-1)


class Bodies:
    """B free bodies in one MjModel (one kinematic tree each: they never interact) and one MjData. Raw rows:
    ``[qpos (7), qvel (6)]`` per body."""

    def __init__(self, model):
        self.model, self.data = model, mujoco.MjData(model)
        self.B = model.nq // 7             # free bodies (welded parts have no joint)
        self.qpos, self.qvel = self.data.qpos.reshape(self.B, 7), self.data.qvel.reshape(self.B, 6)
        self.xfrc = self.data.xfrc_applied[1:]

    def set_state(self, y):
        self.data.time = 0.0
        self.qpos[:], self.qvel[:] = to_qpos_qvel(y)

    def apply(self, f_W, tau_W):   # world force at the COM (N; MuJoCo adds the weight), world torque (N m)
        self.xfrc[:, 0:3], self.xfrc[:, 3:6] = f_W, tau_W

    def apply_body_torque(self, tau_B):   # torques fixed in body axes (N m, (B, 3)), kept by MuJoCo
        self.data.qfrc_applied.reshape(self.B, 6)[:, 3:6] = tau_B

    def decay(self, g_v, g_w):
        self.qvel[:, 0:3] *= g_v[:, None]
        self.qvel[:, 3:6] *= g_w[:, None]

    def step(self):
        mujoco.mj_step(self.model, self.data)

    def read(self):
        return np.concatenate((self.qpos, self.qvel), axis=1)

    def packed(self, raw):
        raw = np.asarray(raw, dtype=float)
        return to_packed(raw[..., 0:7], raw[..., 7:13])


def world(bodies, gravity_W, variant, dt_s):
    return Bodies(build_model(bodies, gravity_W, variant, dt_s))
