"""physx:pgs on long_major_axis_spin: does a torque-free run of 62832 steps of 0.05 s keep its energy, |L| and its separatrix distance δ = (2E I₂ − |L|²)/|L|²?
Written by rbcheck 0.1.0 (rbcheck repro physx:pgs long_major_axis_spin --claim drift); needs only numpy and sapien.
Exit 1 while the defect holds, 0 when it does not. The code: rbcheck's engines/worlds/physx.py, sweep/repro_measure.py, compacted."""
import importlib.metadata, platform, sys
import numpy as np, sapien, sapien.physx as px

BODY_SETTINGS = (("set_linear_damping", 0.0), ("set_angular_damping", 0.0), ("set_max_linear_velocity", 1e16),
                 ("set_max_angular_velocity", 1e16), ("set_max_depenetration_velocity", 1e16),
                 ("set_max_contact_impulse", 1e16), ("set_sleep_threshold", 0.0),
                 ("set_solver_position_iterations", 1), ("set_solver_velocity_iterations", 1),
                 ("set_disable_gravity", False), ("set_kinematic", False))
PACK_TO_PACKED = np.array([4, 5, 6, 7, 8, 9, 0, 1, 2, 3, 10, 11, 12])
def neutralise(c):
    for setter, value in BODY_SETTINGS:
        getattr(c, setter)(value)
class Bodies:
    def __init__(self, gravity_W, variant, dt_s):
        cfg = px.PhysxSceneConfig()
        cfg.gravity = np.float32(gravity_W)
        cfg.enable_tgs = variant == "tgs"
        before = px.get_scene_config()
        px.set_scene_config(cfg)
        try:
            self.system = px.PhysxCpuSystem()
        finally:
            px.set_scene_config(before)
        self.scene = sapien.Scene(systems=[self.system])
        self.system.set_timestep(float(dt_s))
        self.comps, self.always = [], np.zeros(0, dtype=bool)
        self._add = []
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
    def _put(self, k, y):
        c = self.comps[k]
        c.set_entity_pose(sapien.Pose(np.float32(y[0:3]), np.float32(y[6:10])))
        c.set_linear_velocity(np.float32(y[3:6]))
        c.set_angular_velocity(np.float32(y[10:13]))
    def set_state(self, y):
        for k, row in enumerate(np.asarray(y, dtype=float)):
            self._put(k, row)
        self.alive, self.raw = np.ones(len(self.comps), dtype=bool), self._pack()
    def apply(self, f_W, tau_W):
        alive, always, add = self.alive, self.always, self._add
        for k, f, t in zip(range(len(add)), np.asarray(f_W, dtype=float).tolist(),
                           np.asarray(tau_W, dtype=float).tolist()):
            if alive[k] and (always[k] or f[0] or f[1] or f[2] or t[0] or t[1] or t[2]):
                add[k](f, t)
    def read(self):
        self.raw = self._pack()
        return self.raw[:, PACK_TO_PACKED]
    def packed(self, raw):
        return np.asarray(raw, dtype=float)
    def _pack(self):
        return np.frombuffer(self.system.pack(), dtype=np.float32).reshape(len(self.comps), 13).copy()
def world(bodies, gravity_W, variant, dt_s):
    w = Bodies(gravity_W, variant, dt_s)
    for mass_kg, moments, q_BP in bodies:
        w.add_body(mass_kg, moments, q_BP)
    return w
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
DIST, VARIANT, BODIES = ('sapien',), 'pgs', [(1.0, [1.0, 2.0, 3.0], [1.0, 0.0, 0.0, 0.0])]
GRAVITY_W, Y0 = [0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.02, 0.02, 2.0]
F_W, TAU_W, DT, N = [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], 0.05, 62832
INERTIA_B, I2, END_FRACTION, MIN_CHANGE = [[1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 3.0]], 2.0, 0.05, 0.02
TREND_TO_SCATTER = 3.0
if __name__ == "__main__": sys.exit(main_drift(world, globals()))
