"""mjx:rk4 on tennis_racket: orientation converges at order 4 (declared) over Δt = 0.01, 0.005, 0.0025, 0.00125, 0.000625 s? Reference: analytic.
Written by rbcheck 0.1.0 (rbcheck repro mjx:rk4 tennis_racket --claim order orientation); needs only numpy and mujoco-mjx, mujoco, jax.
Exit 1 while the defect holds, 0 when it does not. The code: rbcheck's engines/worlds/mujoco.py, engines/worlds/mjx.py, sweep/repro_measure.py, compacted."""
import importlib.metadata, platform, sys
import jax, mujoco, numpy as np
from mujoco import mjx

def build_model(bodies, gravity_W, variant, dt_s, name="rbcheck"):
    spec = mujoco.MjSpec()
    spec.modelname, spec.option.timestep = name, float(dt_s)
    spec.option.gravity = np.asarray(gravity_W, dtype=float)
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
    return spec.compile()
def _inertial(b, mass_kg, moments, q_BP, com_B):
    b.explicitinertial, b.mass, b.iquat, b.inertia = True, float(mass_kg), q_BP, moments
    b.ipos = [float(v) for v in com_B]
def _cross(a, b):
    a0, a1, a2, b0, b1, b2 = a[..., 0], a[..., 1], a[..., 2], b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)
def rotate(q, v):
    s, u = q[..., :1], q[..., 1:]
    t = 2.0 * _cross(u, v)
    return v + s * t + _cross(u, t)
def to_qpos_qvel(y):
    y = np.asarray(y, dtype=float)
    w_B = rotate(y[..., 6:10] * np.array([1.0, -1.0, -1.0, -1.0]), y[..., 10:13])
    return np.concatenate([y[..., 0:3], y[..., 6:10]], axis=-1), np.concatenate([y[..., 3:6], w_B], axis=-1)
def to_packed(qpos, qvel):
    q = qpos[..., 3:7]
    return np.concatenate([qpos[..., 0:3], qvel[..., 0:3], q, rotate(q, qvel[..., 3:6])], axis=-1)
jax.config.update("jax_enable_x64", True)
def step_one(m, d, gain, f):
    d = d.replace(qvel=d.qvel * gain, xfrc_applied=d.xfrc_applied.at[1].set(f))
    return mjx.step(m, d)
class Bodies:
    def __init__(self, model):
        self.m = mjx.put_model(model)
        self.d = mjx.put_data(model, mujoco.MjData(model))
        self.f, self.gain, self._step = np.zeros(6), np.ones(6), jax.jit(step_one)
    def set_state(self, y):
        qpos, qvel = to_qpos_qvel(y)
        self.d = self.d.replace(qpos=jax.numpy.asarray(qpos[0]), qvel=jax.numpy.asarray(qvel[0]))
    def apply(self, f_W, tau_W):
        self.f = np.concatenate([np.asarray(f_W, dtype=float)[0], np.asarray(tau_W, dtype=float)[0]])
    def step(self):
        self.d = self._step(self.m, self.d, self.gain, self.f)
    def read(self):
        return np.concatenate([np.asarray(self.d.qpos), np.asarray(self.d.qvel)])[None]
    def packed(self, raw):
        raw = np.asarray(raw, dtype=float)
        return to_packed(raw[..., 0:7], raw[..., 7:13])
def world(bodies, gravity_W, variant, dt_s):
    return Bodies(build_model(bodies, gravity_W, variant, dt_s))
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
def error(quantity, y, y_ref):
    a, b = y_ref[6:10] / np.linalg.norm(y_ref[6:10]), y[6:10] / np.linalg.norm(y[6:10])
    w = a[0] * b[0] + a[1:] @ b[1:]
    v = a[0] * b[1:] - b[0] * a[1:] - np.cross(a[1:], b[1:])
    return float(2.0 * np.arctan2(np.linalg.norm(v), abs(w)))
def fitted_order(dt_s, errors, floors, resolved):
    use = [i for i, (e, f) in enumerate(zip(errors, floors)) if np.isfinite(e) and e > resolved * f]
    if len(use) < 2:
        return None
    x, y = np.log([dt_s[i] for i in use]), np.log([errors[i] for i in use])
    return float(np.sum((x - x.mean()) * (y - y.mean())) / np.sum((x - x.mean()) ** 2))
def diverged_at(y, dt_s):
    bad = np.nonzero(~np.all(np.isfinite(y), axis=1) | (np.abs(y).max(axis=1) > 1e8))[0]
    return None if len(bad) == 0 else float(bad[0] * dt_s)
def main_order(world, s):
    versions(s["DIST"])
    errors, blown = [], []
    for h, n, r, f in zip(s["DT_S"], s["STEPS"], s["Y_REF"], s["FLOORS"]):
        y = run(world, s, h, n)
        errors.append(error(s["QUANTITY"], y[-1], np.array(r)))
        blown.append(t := diverged_at(y, h))
        print(f"dt = {h:g} s: " + (f"{s['QUANTITY']} error {errors[-1]:.3e} (round-off floor {f:.1e})"
                                   if t is None else f"the state diverged at t = {t:.4g} s"))
    k = sum(t is not None for t in blown)
    p = None if k else fitted_order(s["DT_S"], errors, s["FLOORS"], s["RESOLVED"])
    holds = k > 0 or (p is not None and p < s["DECLARED"] - s["ORDER_TOL"])
    print(f"{s['VARIANT']} {s['QUANTITY']} order: " + (
        f"the run diverged at {k} of {len(blown)} Δt, expected order {s['DECLARED']:g}" if k else "measured "
        + ("at round-off (exact)" if p is None else f"{p:.2f}") + f", expected {s['DECLARED']:g} (defect "
        f"when below {s['DECLARED'] - s['ORDER_TOL']:g})") + (": DEFECT" if holds else ": no defect"))
    return int(holds)

# the scenario (SI units; states [x_W, v_W, q_WB (w x y z), ω_W]) and the reference values
DIST, VARIANT, BODIES = ('mujoco-mjx', 'mujoco', 'jax'), 'rk4', [(1.0, [1.0, 2.0, 3.0], [1.0, 0.0, 0.0, 0.0])]
GRAVITY_W, Y0 = [0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.01, 2.0, 0.01]
F_W, TAU_W, QUANTITY = [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], 'orientation'
DT_S, STEPS = [0.01, 0.005, 0.0025, 0.00125, 0.000625], [1000, 2000, 4000, 8000, 16000]
Y_REF = [[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -0.012931118997544178, 0.9985483074461181, -0.0066656724317143215, -0.05186166859056298, -0.014116769655821641, 1.99991335660909, 0.0295913753400584]] * 5
FLOORS = [3.388118376433995e-13, 4.232233327369145e-13, 5.425992139183532e-13, 7.114222041053831e-13, 9.501739664682605e-13]
DECLARED, ORDER_TOL, RESOLVED = 4.0, 0.3, 10.0
if __name__ == "__main__": sys.exit(main_order(world, globals()))
