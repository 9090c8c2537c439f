"""MuJoCo's world of free bodies (numpy and mujoco only: ``rbcheck repro`` embeds this file's code).

One MjSpec body per body, with a free joint on the body frame and the mass and inertia exactly as given
(alignfree, inertiafromgeom, balanceinertia, boundmass and boundinertia neutralised; no auto-reset).
MuJoCo's state is ``qpos = [x_W, q_WB (w x y z)]``, ``qvel = [v_W, ω_B (BODY axes)]``; forces go into
``xfrc_applied`` (world force at the COM, world torque; MuJoCo keeps them), a torque fixed in body axes into
``qfrc_applied`` (a free joint's rotational DOFs are body axes). A body whose frame origin is off its COM, or
of welded parts, is :class:`FormBodies`' (:func:`form_world`): qpos/qvel are then the frame origin's, and a
world force at the COM is shared among the parts. docs/engine_conventions.md.
"""
import mujoco
import numpy as np

from .com import com_state, origin_state


def build_model(bodies, gravity_W, variant, dt_s, name="rbcheck"):
    """The compiled MjModel of ``bodies`` ((mass_kg, moments (3,), q_BP (w x y z)) each; optionally also the
    COM in the body frame (m, from its origin) and welded parts, each (mass_kg, moments, q_BP, com (m)): the
    first part the jointed body's inertial, the others child bodies without a joint) for the integrator
    ``variant`` ("euler", "rk4", "implicit", "implicitfast", "discrete") at step ``dt_s`` (s)."""
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
        parts = body[4] if len(body) > 4 else [(*body[:3], body[3] if len(body) > 3 else (0.0, 0.0, 0.0))]
        _inertial(b, *parts[0])
        for j, part in enumerate(parts[1:], 1):
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


class Form:
    """Per body (:func:`build_model`'s items), its COM in its frame (``com_B`` (B, 3), m from the origin) and
    the rows of xfrc_applied its parts are (the first its jointed body) with their shares of its mass.
    MuJoCo's qpos/qvel are the body frame origin's (x_o, v_o), and xfrc_applied acts at each MuJoCo body's
    own COM: the world force f at the composite COM is shared by mass (Σ (m_i/m) f at the parts' COMs has no
    torque about their composite COM), the torque goes to the jointed body."""

    def __init__(self, bodies):
        self.com_B = np.array([np.zeros(3) if len(b) < 4 else np.asarray(b[3], dtype=float)
                               for b in bodies])
        self.rows, row = [], 0
        for b in bodies:
            m = [part[0] for part in b[4]] if len(b) > 4 else [b[0]]
            self.rows.append((list(range(row, row + len(m))), np.array(m) / sum(m)))
            row += len(m)

    def com_rows(self, raw):
        """Raw rows ``[qpos (7), qvel (6)]`` (..., B, 13) -> packed COM states (..., B, 13)."""
        return com_state(to_packed(raw[..., 0:7], raw[..., 7:13]), self.com_B)

    def origin_rows(self, y):
        """Packed COM states (B, 13) -> qpos (B, 7), qvel (B, 6) of the body frame origins."""
        return to_qpos_qvel(origin_state(y, self.com_B))

    def write(self, xfrc, f_W, tau_W):
        """World forces ``f_W`` and torques ``tau_W`` (B, 3) at the bodies' COMs into ``xfrc`` (the world's
        rows of xfrc_applied, from its first body's)."""
        f_W, tau_W = np.asarray(f_W, dtype=float), np.asarray(tau_W, dtype=float)
        for (rows, share), f, tau in zip(self.rows, f_W, tau_W):
            for i, w in zip(rows, share):
                xfrc[i, 0:3] = w * f
                xfrc[i, 3:6] = tau if i == rows[0] else 0.0

    def span(self, k) -> slice:
        """Body ``k``'s rows of xfrc_applied (from the world's first body's)."""
        return slice(self.rows[k][0][0], self.rows[k][0][-1] + 1)


class FormBodies(Bodies):
    """:class:`Bodies` some of which have their frame origin off their COM or are welded parts (``form``, a
    :class:`Form`): the state set and read is the COM's, the forces shared among the parts."""

    def __init__(self, model, form):
        super().__init__(model)
        self.form = form

    def set_state(self, y):
        self.data.time = 0.0
        self.qpos[:], self.qvel[:] = self.form.origin_rows(y)

    def apply(self, f_W, tau_W):
        self.form.write(self.xfrc, f_W, tau_W)

    def packed(self, raw):
        return self.form.com_rows(np.asarray(raw, dtype=float))


def form_world(bodies, gravity_W, variant, dt_s):
    """:func:`world` of bodies that may have a COM off their frame origin or welded parts
    (:func:`build_model`'s fourth and fifth items)."""
    model = build_model(bodies, gravity_W, variant, dt_s)
    if all(len(b) < 4 for b in bodies):
        return Bodies(model)
    return FormBodies(model, Form(bodies))
