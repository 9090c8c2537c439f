"""rapier:symplectic_euler on long_major_axis_spin: does a torque-free run of 62832 steps of 0.05 s keep its energy, |L| and its separatrix distance δ = (2E I₂ − |L|²)/|L|²?
Written by rbcheck 0.1.0 (rbcheck repro rapier:symplectic_euler long_major_axis_spin --claim drift); needs only numpy and rapier3d.
Exit 1 while the defect holds, 0 when it does not. The code: rbcheck's engines/worlds/rapier.py, sweep/repro_measure.py, compacted."""
import importlib.metadata, math, platform, sys
import numpy as np, rapier3d as rapier

GYROSCOPIC = {"symplectic_euler": True, "symplectic_euler_no_gyro": False}
WORLD_SETTINGS = (
    ("num_solver_iterations", 1),
    ("normalized_max_linear_velocity", math.inf),
    ("max_ccd_substeps", 0),
    ("length_unit", 1.0),
)
OWN_POOL_ABOVE = 64
BODY_SETTINGS = (
    ("can_sleep", False),
    ("allow_fast_rotation", True),
    ("linear_damping", 0.0), ("angular_damping", 0.0), ("gravity_scale", 1.0), ("ccd_enabled", False),
    ("additional_solver_iterations", 0),
)
def mass_properties(mass_kg, moments, q_BP):
    return rapier.MassProperties(local_com=(0.0, 0.0, 0.0), mass=float(mass_kg),
                                 principal_inertia=tuple(float(m) for m in moments),
                                 principal_inertia_local_frame=rapier.Rotation3(*(float(c) for c in q_BP)))
class Bodies:
    def __init__(self, bodies, gravity_W, variant, dt_s):
        self.world = w = rapier.PhysicsWorld(gravity=tuple(float(g) for g in gravity_W))
        w.set_num_threads(1 if len(bodies) > OWN_POOL_ABOVE else None)
        for attr, value in (("dt", float(dt_s)), *WORLD_SETTINGS):
            setattr(w.integration_parameters, attr, value)
        self.handles, self.bodies, self.dead, self.last = [], [], set(), []
        for mass_kg, moments, q_BP in bodies:
            b = rapier.RigidBody.dynamic().additional_mass_properties(mass_properties(mass_kg, moments, q_BP))
            for method, value in BODY_SETTINGS:
                b = getattr(b, method)(value)
            self.handles.append(w.add_body(b.gyroscopic_forces(GYROSCOPIC[variant])))
            self.bodies.append(w.rigid_bodies[self.handles[-1]])
    def set_state(self, y):
        self.last = np.asarray(y, dtype=float).tolist()
        for rb, r in zip(self.bodies, self.last):
            rb.is_enabled = True
            rb.position = rapier.Isometry3((r[0], r[1], r[2]), rapier.Rotation3(r[6], r[7], r[8], r[9]))
            rb.linvel, rb.angvel = (r[3], r[4], r[5]), (r[10], r[11], r[12])
        self.dead = set()
    def apply(self, f_W, tau_W):
        if isinstance(f_W, np.ndarray) or isinstance(tau_W, np.ndarray):
            f_W, tau_W = np.asarray(f_W, dtype=float).tolist(), np.asarray(tau_W, dtype=float).tolist()
        for k, (rb, f, tau) in enumerate(zip(self.bodies, f_W, tau_W)):
            if k not in self.dead:
                rb.reset_forces(False)
                rb.reset_torques(False)
                rb.add_force(tuple(f), False)
                rb.add_torque(tuple(tau), False)
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
DIST, VARIANT, BODIES = ('rapier3d',), 'symplectic_euler', [(1.0, [1.0, 2.0, 3.0], [1.0, 0.0, 0.0, 0.0])]
GRAVITY_W, Y0 = [0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.02, 0.02, 2.0]
F_W, TAU_W, DT, N = [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], 0.05, 62832
INERTIA_B, I2, END_FRACTION, MIN_CHANGE = [[1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 3.0]], 2.0, 0.05, 0.02
TREND_TO_SCATTER = 3.0
if __name__ == "__main__": sys.exit(main_drift(world, globals()))
