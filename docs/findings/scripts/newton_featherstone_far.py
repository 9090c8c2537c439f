"""newton:featherstone on tumbling_box: the same physics written another way (translation 1e+04 m: transforms.py) must move the same once mapped back: judged as rbcheck sweep --invariance judges it at Δt = 0.001 s (and at 0.0005, 0.00025 s where it fails there)
Written by rbcheck 0.1.0 (rbcheck repro newton:featherstone tumbling_box --claim invariance translation 1e+04 m); needs only numpy and newton, warp-lang.
Exit 1 while the defect holds, 0 when it does not. The code: rbcheck's engines/worlds/newton.py, sweep/repro_measure.py, compacted."""
import importlib.metadata, platform, sys, warnings
import numpy as np

SOLVERS = {"semi_implicit": "SolverSemiImplicit", "xpbd": "SolverXPBD", "featherstone": "SolverFeatherstone",
           "mujoco_cpu": "SolverMuJoCo"}
SOLVER_SETTINGS = {
    "semi_implicit": {"angular_damping": 0.0},
    "xpbd": {"angular_damping": 0.0, "iterations": 2, "enable_restitution": False},
    "featherstone": {"angular_damping": 0.0, "update_mass_matrix_interval": 1},
    "mujoco_cpu": {"use_mujoco_cpu": True, "integrator": "implicitfast", "disable_contacts": True,
                   "kinematic_switchable_roots": False},
}
GENERALIZED = frozenset({"featherstone", "mujoco_cpu"})
ONE_BODY = frozenset({"mujoco_cpu"})
class Refused(Exception):
    def __init__(self, message, solver=False, backend=False):
        super().__init__(message)
        self.solver, self.backend = solver, backend
def engine():
    import warp as wp
    wp.config.log_level = wp.LOG_WARNING
    import newton
    return wp, newton
def build_model(variant, bodies):
    wp, newton = engine()
    builder = newton.ModelBuilder(gravity=(0.0, 0.0, 0.0))
    add = builder.add_body if variant in GENERALIZED else builder.add_link
    for mass, inertia, gravity in bodies:
        builder.begin_world(gravity=tuple(float(g) for g in gravity))
        add(xform=wp.transform(wp.vec3(0.0, 0.0, 0.0), wp.quat_identity()), com=wp.vec3(0.0, 0.0, 0.0),
            mass=float(mass), inertia=wp.mat33(*(float(v) for v in np.asarray(inertia, dtype=float).ravel())))
        builder.end_world()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", category=UserWarning)
            model = builder.finalize(device="cpu", skip_validation_inertia=True)
    except Exception as exc:
        raise Refused(f"refused the model: {type(exc).__name__}: {exc}") from None
    want_m = np.array([b[0] for b in bodies], dtype=np.float32)
    want_i = np.array([np.asarray(b[1], dtype=float) for b in bodies], dtype=np.float32)
    if not (np.array_equal(model.body_mass.numpy(), want_m)
            and np.array_equal(model.body_inertia.numpy(), want_i)):
        raise Refused("changed the body's mass or inertia when finalizing the model")
    return model
def make_solver(variant, model):
    _, newton = engine()
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="MuJoCo dependency version mismatch")
        try:
            solver = getattr(newton.solvers, SOLVERS[variant])(model, **SOLVER_SETTINGS[variant])
        except (ImportError, ValueError) as exc:
            raise Refused(f"{SOLVERS[variant]} refused the model: {type(exc).__name__}: {exc}",
                          solver=True, backend=isinstance(exc, ImportError)) from None
    if variant == "mujoco_cpu":
        import mujoco
        solver.mj_model.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_AUTORESET)
    return solver
def to_newton_rows(y):
    y = np.asarray(y, dtype=float).reshape(-1, 13)
    q = np.concatenate([y[:, 0:3], y[:, 7:10], y[:, 6:7]], axis=1)
    qd = np.concatenate([y[:, 3:6], y[:, 10:13]], axis=1)
    return q, qd
def from_newton_rows(q, qd):
    q = np.asarray(q, dtype=float)
    qd = np.asarray(qd, dtype=float)
    return np.concatenate([q[..., 0:3], qd[..., 0:3], q[..., 6:7], q[..., 3:6], qd[..., 3:6]], axis=-1)
class Batch:
    def __init__(self, variant, bodies):
        self.model = build_model(variant, bodies)
        self.solver = make_solver(variant, self.model)
        self.states = [self.model.state(), self.model.state()]
        q, qd = ("joint_q", "joint_qd") if variant in GENERALIZED else ("body_q", "body_qd")
        self.views = [(getattr(s, q).numpy().reshape(-1, 7), getattr(s, qd).numpy().reshape(-1, 6),
                       s.body_f.numpy()) for s in self.states]
    def step(self, dt_s):
        self.solver.step(self.states[0], self.states[1], None, None, dt_s)
        self.states.reverse()
        self.views.reverse()
class Bodies:
    def __init__(self, variant, bodies, dt_s, max_batch=256):
        self.dt_s, size = float(dt_s), 1 if variant in ONE_BODY else int(max_batch)
        self.parts = [(slice(s, s + size), Batch(variant, bodies[s:s + size]))
                      for s in range(0, len(bodies), size)]
    def set_state(self, y):
        q, qd = to_newton_rows(y)
        for part, b in self.parts:
            b.views[0][0][:], b.views[0][1][:] = q[part], qd[part]
    def apply(self, f_W, tau_W):
        for part, b in self.parts:
            f = b.views[0][2]
            f[:, 0:3], f[:, 3:6] = f_W[part], tau_W[part]
    def step(self):
        for _, b in self.parts:
            b.step(self.dt_s)
    def read(self):
        return np.concatenate([np.concatenate(b.views[0][0:2], axis=1) for _, b in self.parts]).astype(float)
    def packed(self, raw):
        raw = np.asarray(raw, dtype=float)
        return from_newton_rows(raw[..., 0:7], raw[..., 7:13])
def world(bodies, gravity_W, variant, dt_s):
    return Bodies(variant, [(mass_kg, inertia_B, gravity_W) for mass_kg, inertia_B, _ in bodies], dt_s)
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
def quat_mul(a, b):
    s = a[..., :1] * b[..., :1] - np.sum(a[..., 1:] * b[..., 1:], axis=-1, keepdims=True)
    return np.concatenate([s, a[..., :1] * b[..., 1:] + b[..., :1] * a[..., 1:]
                           + np.cross(a[..., 1:], b[..., 1:])], axis=-1)
def map_back(y, s):
    y, R = np.array(y, dtype=float), np.array(s["MAP_R"])
    y[:, 0:3] = (y[:, 0:3] - np.array(s["MAP_D"])) @ R / s["MAP_K"]
    y[:, 3:6] = y[:, 3:6] @ R / s["MAP_K"]
    y[:, 10:13] = y[:, 10:13] @ R
    y[:, 6:10] = quat_mul(quat_mul(np.array(s["MAP_R_INV"]), y[:, 6:10]), np.array(s["MAP_P_INV"]))
    return y
def deviations(y0, y1):
    a = y0[:, 6:10] / np.linalg.norm(y0[:, 6:10], axis=-1, keepdims=True)
    b = y1[:, 6:10] / np.linalg.norm(y1[:, 6:10], axis=-1, keepdims=True)
    d = quat_mul(a * np.array([1.0, -1.0, -1.0, -1.0]), b)
    e = {"position": np.linalg.norm(y1[:, 0:3] - y0[:, 0:3], axis=-1),
         "orientation": 2.0 * np.arctan2(np.linalg.norm(d[:, 1:], axis=-1), np.abs(d[:, 0])),
         "velocity": np.linalg.norm(y1[:, 3:6] - y0[:, 3:6], axis=-1),
         "angular_velocity": np.linalg.norm(y1[:, 10:13] - y0[:, 10:13], axis=-1)}
    ok = np.all(np.isfinite(y0), axis=-1)
    e = {q: np.where(ok, v, 0.0) for q, v in e.items()}
    return {q: float(np.max(v, initial=0.0)) if np.all(np.isfinite(v)) else float("inf")
            for q, v in e.items()}
def main_invariance(world, s):
    versions(s["DIST"])
    t = dict(s, BODIES=s["BODIES_T"], GRAVITY_W=s["GRAVITY_T"], Y0=s["Y0_T"], F_W=s["F_T"], TAU_W=s["TAU_T"])
    devs, allow, base = [], s["ALLOWANCE"][0], s["BASE"]
    for h, n in zip(s["DT_S"], s["STEPS"]):
        with np.errstate(all="ignore"):
            devs.append(deviations(run(world, s, h, n), map_back(run(world, t, h, n), s)))
        dev = devs[0]
        if len(devs) == 1:
            for q in allow:
                print(f"dt = {h:g} s, {n} steps: {q} largest deviation {dev[q]:.3g} {s['UNITS'][q]}, allowed "
                      f"{allow[q]:.3g} (round-off {base[q]:.3g})")
            worst = max(allow, key=lambda q: dev[q] / allow[q] if allow[q] > 0 else float("inf"))
            verdict = ("holds" if all(dev[q] <= base[q] for q in allow) else "precision loss (expected)"
                       if all(dev[q] <= allow[q] for q in allow) else "broken")
            if verdict != "broken" or not np.all(np.isfinite(list(dev.values()))):
                break
    if len(devs) > 1:
        d, dts = [v[worst] for v in devs], s["DT_S"]
        with np.errstate(all="ignore"):
            orders = [float(np.log(a / b) / np.log(h / g)) for a, b, h, g in zip(d, d[1:], dts, dts[1:])]
        gone = [v[worst] <= a[worst] for v, a in zip(devs[1:], s["ALLOWANCE"][1:])]
        print(f"{worst} largest deviation {', '.join(f'{v:.3g}' for v in d)} {s['UNITS'][worst]} at dt = "
              f"{', '.join(f'{h:g}' for h in dts)} s: order {', '.join(f'{o:.2f}' for o in orders)} (the "
              f"step's own truncation error vanishes at order {s['STEP_ORDER'][worst]:g} or more)")
        if np.all(np.isfinite(d)) and all(g or o >= s["STEP_ORDER"][worst] for o, g in zip(orders, gone)):
            verdict = "step-dependent (the step is not covariant under it; no defect of the model)"
    holds = verdict == "broken"
    print(f"{s['VARIANT']} on {s['SCENARIO']} under {s['TRANSFORM']}: {verdict}, expected it to hold: "
          + ("DEFECT" if holds else "no defect"))
    return int(holds)

# the scenario (SI units; states [x_W, v_W, q_WB (w x y z), ω_W]) and the reference values
DIST, VARIANT = ('newton', 'warp-lang'), 'featherstone'
BODIES = [(10.0, [[0.8083333333333333, 0.0, 0.0], [0.0, 0.6833333333333333, 0.0], [0.0, 0.0, 0.14166666666666666]], None)]
GRAVITY_W, Y0 = [0.0, 0.0, -9.8], [0.0, 0.0, 0.0, -2.0, 2.0, 8.0, 1.0, 0.0, 0.0, 0.0, 0.1, 5.0, 0.1]
F_W, TAU_W, SCENARIO, TRANSFORM = [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], 'tumbling_box', 'translation 1e+04 m'
BODIES_T = [(10.0, [[0.8083333333333333, 0.0, 0.0], [0.0, 0.6833333333333333, 0.0], [0.0, 0.0, 0.14166666666666666]], None)]
GRAVITY_T = [0.0, 0.0, -9.8]
Y0_T = [2857.142857142857, -4285.714285714285, 8571.42857142857, -2.0, 2.0, 8.0, 1.0, 0.0, 0.0, 0.0, 0.1, 5.0, 0.1]
F_T, TAU_T = [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]
MAP_D = [2857.142857142857, -4285.714285714285, 8571.42857142857]
MAP_R, MAP_R_INV = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], [1.0, -0.0, -0.0, -0.0]
MAP_P_INV, MAP_K, DT_S, STEPS = [1.0, -0.0, -0.0, -0.0], 1.0, [0.001, 0.0005, 0.00025], [10000, 20000, 40000]
BASE = {'position': 80.10461713951858, 'orientation': 5.677582779436438, 'velocity': 17.346358835353527, 'angular_velocity': 15.781799441920768}
ALLOWANCE = [{'position': 2029.2432265186562, 'orientation': 129.246615170913, 'velocity': 21.525356492017334, 'angular_velocity': 370.5114004659046}, {'position': 4033.000386016213, 'orientation': 183.13332588627281, 'velocity': 40.50210628192467, 'angular_velocity': 524.6871355683905}, {'position': 8029.958030399637, 'orientation': 259.6916528323616, 'velocity': 77.39993840057039, 'angular_velocity': 743.4294391548267}]
STEP_ORDER = {'position': 0.7, 'orientation': 0.7, 'velocity': 0.7, 'angular_velocity': 0.7}
UNITS = {'position': 'm', 'orientation': 'rad', 'velocity': 'm/s', 'angular_velocity': 'rad/s'}
if __name__ == "__main__": sys.exit(main_invariance(world, globals()))
