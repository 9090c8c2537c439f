"""brax:spring on tennis_racket: does the torque-free spin near the intermediate axis flip (at t = 6.06 s, analytic)?
Written by rbcheck 0.1.0 (rbcheck repro brax:spring tennis_racket --claim gyroscopic); needs only numpy and brax, jax, mujoco.
Exit 1 while the defect holds, 0 when it does not. The code: rbcheck's engines/worlds/brax.py, sweep/repro_measure.py, compacted."""
import importlib.metadata, platform, sys
import jax, jax.numpy as jp, numpy as np
from brax import math as bmath
from brax.base import Actuator
from brax.generalized import pipeline as generalized
from brax.io import mjcf
from brax.positional import pipeline as positional
from brax.spring import pipeline as spring

jax.config.update("jax_enable_x64", True)
PIPELINES = {"generalized": generalized, "positional": positional, "spring": spring}
NEUTRAL_SYSTEM = (("vel_damping", 0.0), ("ang_damping", 0.0), ("spring_mass_scale", 0.0),
                  ("spring_inertia_scale", 0.0), ("matrix_inv_iterations", 0))
NEUTRAL_DOF = (("damping", 0.0), ("armature", 0.0))
def _num(v):
    return repr(float(v))
def inertial(mass_kg, inertia_B):
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
    g = " ".join(_num(v) for v in gravity_W)
    motors = ""
    return (f'<mujoco model="rbcheck"><compiler alignfree="false" inertiafromgeom="false" '
            f'balanceinertia="false" boundmass="0" boundinertia="0"/>'
            f'<option timestep="{_num(dt_s)}" gravity="{g}" viscosity="0" density="0" integrator="Euler"/>'
            f'<worldbody><body name="body"><freejoint name="free"/>'
            f'{inertial(mass_kg, inertia_B)}'
            f'<geom type="sphere" size="0.01" contype="0" conaffinity="0" mass="0"/>'
            f'</body></worldbody>{motors}</mujoco>')
def neutralise(sys):
    dof = sys.dof
    for field, value in NEUTRAL_DOF:
        dof = dof.replace(**{field: jp.full_like(getattr(dof, field), value)})
    return sys.replace(dof=dof, **{k: v for k, v in NEUTRAL_SYSTEM})
def six_dof_actuator(sys):
    inf = jp.full((6, 2), jp.inf) * jp.array([-1.0, 1.0])
    act = Actuator(q_id=jp.arange(6), qd_id=jp.arange(6), ctrl_range=inf, force_range=inf,
                   gain=jp.ones(6), gear=jp.ones(6), bias_q=jp.zeros(6), bias_qd=jp.zeros(6))
    return sys.replace(actuator=act)
def system(mass_kg, inertia_B, gravity_W, variant):
    gen = variant == "generalized"
    sys = neutralise(mjcf.loads(mjcf_text(mass_kg, inertia_B, gravity_W, 0.01, actuators=gen)))
    return six_dof_actuator(sys) if gen else sys
def act(sys, state, f, tau, variant):
    if variant != "generalized":
        return jp.zeros(sys.act_size())
    return jp.concatenate([f, bmath.inv_rotate(tau, state.x.rot[0])])
def to_q_qd(y):
    y = np.asarray(y, dtype=float)
    s, u, w = y[..., 6:7], -y[..., 7:10], y[..., 10:13]
    u0, u1, u2, w0, w1, w2 = u[..., 0], u[..., 1], u[..., 2], w[..., 0], w[..., 1], w[..., 2]
    t = 2.0 * np.stack([u1 * w2 - u2 * w1, u2 * w0 - u0 * w2, u0 * w1 - u1 * w0], axis=-1)
    t0, t1, t2 = t[..., 0], t[..., 1], t[..., 2]
    w_B = w + s * t + np.stack([u1 * t2 - u2 * t1, u2 * t0 - u0 * t2, u0 * t1 - u1 * t0], axis=-1)
    return np.concatenate([y[..., 0:3], y[..., 6:10]], axis=-1), np.concatenate([y[..., 3:6], w_B], axis=-1)
def packed(state):
    return jp.concatenate([state.x.pos[0], state.xd.vel[0], state.x.rot[0], state.xd.ang[0]])
class Bodies:
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
def versions(dists):
    print(", ".join(f"{d} {importlib.metadata.version(d)}" for d in dists)
          + f", numpy {np.__version__}, Python {platform.python_version()}, {platform.platform()}")
def run(world, s, dt_s, n_steps):
    w = world(s["BODIES"], s["GRAVITY_W"], s["VARIANT"], dt_s)
    w.set_state(np.array([s["Y0"]], dtype=float))
    f, tau = np.array([s["F_W"]], dtype=float), np.array([s["TAU_W"]], dtype=float)
    raw = [np.array(s["Y0"], dtype=float)]
    w.read()
    for _ in range(n_steps):
        w.apply(f, tau)
        w.step()
        raw.append(w.packed(np.asarray(w.read(), dtype=float)[None])[0, 0])
    return np.array(raw)
def first_flip_s(y, q_BP, axis, dt_s):
    q = y[:, 6:10] / np.linalg.norm(y[:, 6:10], axis=-1, keepdims=True)
    qc = q * np.array([1.0, -1.0, -1.0, -1.0])
    p = np.asarray(q_BP, dtype=float)
    w = y[:, 10:13]
    for qq in (qc, np.broadcast_to(p * np.array([1.0, -1.0, -1.0, -1.0]), qc.shape)):
        t = 2.0 * np.cross(qq[:, 1:], w)
        w = w + qq[:, :1] * t + np.cross(qq[:, 1:], t)
    s = np.sign(w[:, axis])
    flips = np.nonzero(s[1:] * s[0] < 0)[0]
    return None if len(flips) == 0 else float((flips[0] + 1) * dt_s)
def main_gyroscopic(world, s):
    versions(s["DIST"])
    t = first_flip_s(run(world, s, s["DT"], s["N"]), s["Q_BP"], s["AXIS"], s["DT"])
    print(f"{s['N']} steps of {s['DT']:g} s: ω about the intermediate axis (body) first reverses at "
          + ("no time (no flip)" if t is None else f"t = {t:.4g} s")
          + f", expected t = {s['FLIP_S']:.4g} s (the torque-free flip): "
          + ("DEFECT" if t is None else "no defect"))
    return int(t is None)

# the scenario (SI units; states [x_W, v_W, q_WB (w x y z), ω_W]) and the reference values
DIST, VARIANT = ('brax', 'jax', 'mujoco'), 'spring'
BODIES, GRAVITY_W = [(1.0, [[1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 3.0]], None)], [0.0, 0.0, 0.0]
Y0, F_W = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.01, 2.0, 0.01], [0.0, 0.0, 0.0]
TAU_W, DT, N, Q_BP, AXIS, FLIP_S = [0.0, 0.0, 0.0], 0.001, 10000, [1.0, 0.0, 0.0, 0.0], 1, 6.0600000000000005
if __name__ == "__main__": sys.exit(main_gyroscopic(world, globals()))
