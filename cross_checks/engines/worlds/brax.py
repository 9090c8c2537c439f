"""Brax's world (JAX, float64): numpy, jax and brax only (``rbcheck repro`` embeds this file's code).

The body as MJCF loaded by ``brax.io.mjcf.loads`` (:func:`mjcf_text`), every damping, scale and the
approximate inverse neutralised (:data:`NEUTRAL_SYSTEM`, :data:`NEUTRAL_DOF`); the generalized pipeline takes
the applied force and torque through six actuators on the free joint (:func:`six_dof_actuator`: ``act =
[f_W − m g, R_WBᵀ τ_W]``, brax adds the weight), the positional and spring pipelines gravity only.
State: ``q = [x_W, q_WB (w x y z)]``, ``qd = [v_W, ω_B]`` in, ``x.pos, xd.vel, x.rot, xd.ang`` (world axes)
out.
docs/engine_conventions.md, "Brax".
"""
import jax
import jax.numpy as jp
import numpy as np
from brax import math as bmath
from brax.base import Actuator
from brax.generalized import pipeline as generalized
from brax.io import mjcf
from brax.positional import pipeline as positional
from brax.spring import pipeline as spring

jax.config.update("jax_enable_x64", True)   # float64 (process-global)

PIPELINES = {"generalized": generalized, "positional": positional, "spring": spring}
#: System fields set on every model (``System.replace``), each brax 0.14.2's MJCF default except
#: matrix_inv_iterations (default 10: an approximate inverse), set so that no default can change the physics.
NEUTRAL_SYSTEM = (("vel_damping", 0.0), ("ang_damping", 0.0), ("spring_mass_scale", 0.0),
                  ("spring_inertia_scale", 0.0), ("matrix_inv_iterations", 0))
#: DoF fields (per DOF of the free joint): joint damping and armature, both 0 by default.
NEUTRAL_DOF = (("damping", 0.0), ("armature", 0.0))


def _num(v):
    return repr(float(v))


def inertial(mass_kg, inertia_B):
    """The body's MJCF ``<inertial>`` (at the body origin = COM): the full tensor (``fullinertia``), which
    MuJoCo's compiler decomposes itself, except for a non-diagonal tensor whose principal moments lie on the
    triangle inequality's boundary A + B = C (within 8 ε of C: a flat body in a turned body frame, e.g.
    tennis_racket's 1, 2, 3 kg m²): MuJoCo's decomposition leaves it ~1e-15 beyond and refuses it
    (balanceinertia off), so it is given as its principal moments (``diaginertia``, C put back on the
    boundary) and the principal frame's quaternion (``quat``, w x y z), as rbcheck's MuJoCo adapter does
    (mujoco_engine.on_the_triangle)."""
    I = np.asarray(inertia_B, dtype=float)
    mass = _num(mass_kg)
    if I[0, 1] != 0.0 or I[0, 2] != 0.0 or I[1, 2] != 0.0:
        moments, R = np.linalg.eigh(I)
        if abs(moments[2] - moments[0] - moments[1]) <= 8 * np.finfo(float).eps * moments[2]:
            import mujoco
            if np.linalg.det(R) < 0:
                R[:, 2] *= -1.0
            moments[2] = min(moments[2], moments[0] + moments[1])
            quat = np.zeros(4)
            mujoco.mju_mat2Quat(quat, R.reshape(-1))
            return (f'<inertial pos="0 0 0" quat="{" ".join(_num(v) for v in quat)}" mass="{mass}" '
                    f'diaginertia="{" ".join(_num(v) for v in moments)}"/>')
    full = " ".join(_num(v) for v in (I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2]))
    return f'<inertial pos="0 0 0" mass="{mass}" fullinertia="{full}"/>'


def mjcf_text(mass_kg, inertia_B, gravity_W, dt_s, actuators):
    """The free body (mass kg, inertia kg m² (3, 3) about the COM in body axes) as MJCF (full precision)."""
    g = " ".join(_num(v) for v in gravity_W)
    motors = ""
    if actuators:
        gears = ["1 0 0 0 0 0", "0 1 0 0 0 0", "0 0 1 0 0 0", "0 0 0 1 0 0", "0 0 0 0 1 0", "0 0 0 0 0 1"]
        motors = "".join(f'<motor joint="free" gear="{gr}" ctrllimited="false"/>' for gr in gears)
        motors = f"<actuator>{motors}</actuator>"
    return (f'<mujoco model="rbcheck"><compiler alignfree="false" inertiafromgeom="false" '
            f'balanceinertia="false" boundmass="0" boundinertia="0"/>'
            f'<option timestep="{_num(dt_s)}" gravity="{g}" viscosity="0" density="0" integrator="Euler"/>'
            f'<worldbody><body name="body"><freejoint name="free"/>'
            f'{inertial(mass_kg, inertia_B)}'
            f'<geom type="sphere" size="0.01" contype="0" conaffinity="0" mass="0"/>'
            f'</body></worldbody>{motors}</mujoco>')


def neutralise(sys):
    """``sys`` with every NEUTRAL_SYSTEM and NEUTRAL_DOF field set (whatever it was)."""
    dof = sys.dof
    for field, value in NEUTRAL_DOF:
        dof = dof.replace(**{field: jp.full_like(getattr(dof, field), value)})
    return sys.replace(dof=dof, **{k: v for k, v in NEUTRAL_SYSTEM})


def six_dof_actuator(sys):
    """``sys`` with its actuator set to one motor per DOF of the free joint (DOFs 0..5), gear 1, gain 1, no
    bias, no control or force limit: ``act`` is then the generalized force ``[f_W, τ_B]``."""
    inf = jp.full((6, 2), jp.inf) * jp.array([-1.0, 1.0])
    act = Actuator(q_id=jp.arange(6), qd_id=jp.arange(6), ctrl_range=inf, force_range=inf,
                   gain=jp.ones(6), gear=jp.ones(6), bias_q=jp.zeros(6), bias_qd=jp.zeros(6))
    return sys.replace(actuator=act)


def system(mass_kg, inertia_B, gravity_W, variant):
    """The neutralised brax System of the body for the pipeline ``variant`` (its step set per run)."""
    gen = variant == "generalized"
    sys = neutralise(mjcf.loads(mjcf_text(mass_kg, inertia_B, gravity_W, 0.01, actuators=gen)))
    return six_dof_actuator(sys) if gen else sys


def act(sys, state, f, tau, variant):
    """The generalized pipeline's actuation ``[f_W − m g, R_WBᵀ τ_W]`` (``f`` the force less the weight), or
    none (the other pipelines take no applied force)."""
    if variant != "generalized":
        return jp.zeros(sys.act_size())
    return jp.concatenate([f, bmath.inv_rotate(tau, state.x.rot[0])])


def to_q_qd(y):
    """Packed states (..., 13) -> ``q`` (..., 7), ``qd = [v_W, ω_B]`` (..., 6)."""
    y = np.asarray(y, dtype=float)
    s, u, w = y[..., 6:7], -y[..., 7:10], y[..., 10:13]
    u0, u1, u2, w0, w1, w2 = u[..., 0], u[..., 1], u[..., 2], w[..., 0], w[..., 1], w[..., 2]
    t = 2.0 * np.stack([u1 * w2 - u2 * w1, u2 * w0 - u0 * w2, u0 * w1 - u1 * w0], axis=-1)
    t0, t1, t2 = t[..., 0], t[..., 1], t[..., 2]
    w_B = w + s * t + np.stack([u1 * t2 - u2 * t1, u2 * t0 - u0 * t2, u0 * t1 - u1 * t0], axis=-1)
    return np.concatenate([y[..., 0:3], y[..., 6:10]], axis=-1), np.concatenate([y[..., 3:6], w_B], axis=-1)


def packed(state):
    """A brax state (one body) -> the packed state (13,): x.pos, xd.vel, x.rot (w x y z), xd.ang."""
    return jp.concatenate([state.x.pos[0], state.xd.vel[0], state.x.rot[0], state.xd.ang[0]])


class Bodies:
    """One body in a brax pipeline at step ``dt_s``; raw rows are packed states."""

    def __init__(self, mass_kg, inertia_B, gravity_W, variant, dt_s):
        sys = system(mass_kg, inertia_B, gravity_W, variant).replace(mj_model=None)
        self.sys = sys.replace(opt=sys.opt.replace(timestep=jp.asarray(float(dt_s))))
        self.variant, self.P, self.f = variant, PIPELINES[variant], (np.zeros(3), np.zeros(3))
        P, v = self.P, variant
        self._step = jax.jit(lambda sys, state, f, tau: P.step(sys, state, act(sys, state, f, tau, v)))

    def set_state(self, y):
        q, qd = to_q_qd(np.asarray(y, dtype=float)[0])
        self.state = self.P.init(self.sys, jp.asarray(q), jp.asarray(qd))

    def apply(self, f_W, tau_W):
        self.f = (np.asarray(f_W, dtype=float)[0], np.asarray(tau_W, dtype=float)[0])

    def step(self):
        self.state = self._step(self.sys, self.state, *self.f)

    def read(self):
        return np.asarray(packed(self.state))[None]

    def packed(self, raw):
        return np.asarray(raw, dtype=float)


def world(bodies, gravity_W, variant, dt_s):
    (mass_kg, inertia_B, _), = bodies
    return Bodies(mass_kg, inertia_B, gravity_W, variant, dt_s)
