"""mujoco:implicitfast on long_tennis_racket: does a torque-free run of 62832 steps of 0.05 s keep its energy, |L| and its separatrix distance δ = (2E I₂ − |L|²)/|L|²?
Written by rbcheck 0.1.0 (rbcheck repro mujoco:implicitfast long_tennis_racket --claim drift); needs only numpy and mujoco.
Exit 1 while the defect holds, 0 when it does not. The code: rbcheck's engines/worlds/mujoco.py, sweep/repro_measure.py, compacted."""
import importlib.metadata, platform, sys
import mujoco, numpy as np

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
class Bodies:
    def __init__(self, model):
        self.model, self.data = model, mujoco.MjData(model)
        self.B = model.nq // 7
        self.qpos, self.qvel = self.data.qpos.reshape(self.B, 7), self.data.qvel.reshape(self.B, 6)
        self.xfrc = self.data.xfrc_applied[1:]
    def set_state(self, y):
        self.data.time = 0.0
        self.qpos[:], self.qvel[:] = to_qpos_qvel(y)
    def apply(self, f_W, tau_W):
        self.xfrc[:, 0:3], self.xfrc[:, 3:6] = f_W, tau_W
    def step(self):
        mujoco.mj_step(self.model, self.data)
    def read(self):
        return np.concatenate((self.qpos, self.qvel), axis=1)
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
def diverged_at(y, dt_s):
    bad = np.nonzero(~np.all(np.isfinite(y), axis=1) | (np.abs(y).max(axis=1) > 1e8))[0]
    return None if len(bad) == 0 else float(bad[0] * dt_s)
def invariants(y, inertia_B, I2):
    q = y[:, 6:10] / np.linalg.norm(y[:, 6:10], axis=-1, keepdims=True)
    w0, x, yy, z = q.T
    R = np.stack([1 - 2 * (yy * yy + z * z), 2 * (x * yy - w0 * z), 2 * (x * z + w0 * yy),
                  2 * (x * yy + w0 * z), 1 - 2 * (x * x + z * z), 2 * (yy * z - w0 * x),
                  2 * (x * z - w0 * yy), 2 * (yy * z + w0 * x), 1 - 2 * (x * x + yy * yy)], -1)
    R = R.reshape(-1, 3, 3)
    L = np.einsum("nij,nj->ni", R @ np.asarray(inertia_B) @ np.swapaxes(R, -1, -2), y[:, 10:13])
    E, Lm = 0.5 * np.sum(y[:, 10:13] * L, axis=-1), np.linalg.norm(L, axis=-1)
    return E, Lm, (2.0 * E * I2 - Lm ** 2) / Lm ** 2
def main_drift(world, s):
    versions(s["DIST"])
    y = run(world, s, s["DT"], s["N"])
    t = diverged_at(y, s["DT"])
    if t is not None:
        print(f"{s['N']} steps of {s['DT']:g} s: the state diverged at t = {t:.4g} s; "
              "expected the energy, |L| and δ conserved: DEFECT")
        return 1
    E, Lm, d = invariants(y, s["INERTIA_B"], s["I2"])
    k = max(1, int(len(d) * s["END_FRACTION"]))
    end, scatter = float(np.mean(d[-k:])), 2.0 * float(np.std(np.abs(d[-k:])))
    change = abs(d[0]) - float(np.mean(np.abs(d[-k:])))
    moved = abs(end - d[0])
    holds = bool(moved >= s["MIN_CHANGE"] * abs(d[0]) and moved >= s["TREND_TO_SCATTER"] * scatter)
    what = ("crosses the separatrix" if np.sign(end) != np.sign(d[0]) and holds else
            "drifts toward the intermediate axis" if holds and change > 0 else
            "drifts away from the intermediate axis" if holds else "keeps δ")
    print(f"{s['N']} steps of {s['DT']:g} s: energy {E[-1] / E[0] - 1:+.3e}, |L| {Lm[-1] / Lm[0] - 1:+.3e} "
          f"(relative, expected 0: both conserved)")
    print(f"separatrix distance δ: measured {d[0]:.4g} -> {end:.4g} (mean of the last {k} states), expected "
          f"{d[0]:.4g} -> {d[0]:.4g}: {what}: " + ("DEFECT" if holds else "no defect"))
    return int(holds)

# the scenario (SI units; states [x_W, v_W, q_WB (w x y z), ω_W]) and the reference values
DIST, VARIANT, BODIES = ('mujoco',), 'implicitfast', [(1.0, [1.0, 2.0, 3.0], [1.0, 0.0, 0.0, 0.0])]
GRAVITY_W, Y0 = [0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.02, 2.0, 0.02]
F_W, TAU_W, DT, N = [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], 0.05, 62832
INERTIA_B, I2, END_FRACTION, MIN_CHANGE = [[1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 3.0]], 2.0, 0.05, 0.02
TREND_TO_SCATTER = 3.0
if __name__ == "__main__": sys.exit(main_drift(world, globals()))
