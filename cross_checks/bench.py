"""``rbcheck bench``: throughput of the batched reference vs MuJoCo and PyBullet, measured in one run.

Every engine steps the same free bodies: I = diag(1, 2, 3) kg m², m = 1 kg, gravity (0, 0, −9.81),
a constant body-axes torque (0, 0, 0.2) N m, random initial ω, h = 1e-3 s. Results are ratios
against the engines measured in the same process, never absolute thresholds.

Keys written by ``--json`` (fixed): reference_batched_body_steps_per_s, mujoco_best_body_steps_per_s,
pybullet_body_steps_per_s, reference_single_us_per_step, mujoco_single_us_per_step,
drake_single_us_per_step (None without Drake), plus the individual measurements.

Drake (``drake_*``) is measured on one trajectory only, beside MuJoCo on the same trajectory through
the same adapter interface (``mujoco_adapter_single_us_per_step``): the per-step cost a sweep pays.
"""
from __future__ import annotations

import json
import os
import platform
import time

import numpy as np

TORQUE_B = np.array([0.0, 0.0, 0.2])
MOMENTS = np.array([1.0, 2.0, 3.0])
G = np.array([0.0, 0.0, -9.81])
H = 1e-3


def _best_of(fn, repeats):
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def _initial_w(n, seed=0):
    return np.random.default_rng(seed).normal(size=(n, 3))


def reference_batched(n_bodies, n_steps, variant, repeats):
    """The batched reference: N bodies as 13 contiguous (N,) arrays (reference_sim.scalar, NumPy backend)."""
    from reference_sim.body import RigidBody
    from reference_sim.forces import ForceModel, Torque
    from reference_sim.scalar import ScalarStepper
    from reference_sim.state import Problem, State
    problem = Problem(RigidBody(1.0, MOMENTS), ForceModel(gravity_W=G, torques=(Torque(TORQUE_B, "body"),)),
                      State(np.zeros(3), np.zeros(3), np.array([1.0, 0, 0, 0]), np.zeros(3)))
    y0 = np.zeros((13, n_bodies))
    y0[6] = 1.0
    y0[10:13] = _initial_w(n_bodies).T
    step = ScalarStepper(problem, variant, H, backend="numpy").step

    def run():
        y = [np.ascontiguousarray(c) for c in y0]
        for _ in range(n_steps):
            y = step(y)
    return n_bodies * n_steps / _best_of(run, repeats)


def reference_single_us(n_steps, repeats, variant="expmap_gyro"):
    from reference_sim.body import RigidBody
    from reference_sim.forces import ForceModel, Torque
    from reference_sim.simulate import simulate
    from reference_sim.state import Problem, State
    problem = Problem(RigidBody(1.0, MOMENTS), ForceModel(gravity_W=G, torques=(Torque(TORQUE_B, "body"),)),
                      State(np.zeros(3), np.zeros(3), np.array([1.0, 0, 0, 0]), _initial_w(1)[0]))
    return 1e6 * _best_of(lambda: simulate(problem, variant, H, n_steps), repeats) / n_steps


def _mujoco_model(n_bodies):
    import mujoco
    bodies = "".join(
        f'<body name="b{i}"><freejoint/><inertial pos="0 0 0" mass="1" diaginertia="1 2 3"/></body>'
        for i in range(n_bodies))
    xml = (f'<mujoco><option timestep="{H}" gravity="0 0 -9.81" integrator="Euler">'
           f'<flag autoreset="disable" contact="disable"/></option><worldbody>{bodies}</worldbody></mujoco>')
    return mujoco.MjModel.from_xml_string(xml)


def mujoco_multibody(n_bodies, n_steps, repeats):
    import mujoco
    m = _mujoco_model(n_bodies)
    d = mujoco.MjData(m)
    w = _initial_w(n_bodies)

    def run():
        mujoco.mj_resetData(m, d)
        d.qvel.reshape(n_bodies, 6)[:, 3:6] = w
        d.qfrc_applied.reshape(n_bodies, 6)[:, 3:6] = TORQUE_B  # body-axes torque, persists
        mujoco.mj_step(m, d, nstep=n_steps)
    return n_bodies * n_steps / _best_of(run, repeats)


def mujoco_rollout(n_bodies, n_steps, repeats):
    import mujoco
    from mujoco import rollout
    m = _mujoco_model(1)
    datas = [mujoco.MjData(m) for _ in range(os.cpu_count() or 1)]
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    d = datas[0]
    states = np.empty((n_bodies, mujoco.mj_stateSize(m, spec)))
    for i, w in enumerate(_initial_w(n_bodies)):
        mujoco.mj_resetData(m, d)
        d.qvel[3:6] = w
        mujoco.mj_getState(m, d, states[i], spec)
    control = np.tile(np.concatenate([np.zeros(3), TORQUE_B]), (n_bodies, 1, 1))
    kw = dict(control_spec=mujoco.mjtState.mjSTATE_QFRC_APPLIED, nstep=n_steps)
    return n_bodies * n_steps / _best_of(lambda: rollout.rollout(m, datas, states, control, **kw), repeats)


def mujoco_single_us(n_steps, repeats):
    import mujoco
    m = _mujoco_model(1)
    d = mujoco.MjData(m)

    def run():
        mujoco.mj_resetData(m, d)
        d.qvel[3:6] = _initial_w(1)[0]
        for _ in range(n_steps):
            d.qfrc_applied[3:6] = TORQUE_B  # re-applied per step, as a harness with forces must
            mujoco.mj_step(m, d)
    return 1e6 * _best_of(run, repeats) / n_steps


def _bench_scenario():
    """The benchmark's body as a scenario (for the engine adapters): one trajectory, ω0 = _initial_w(1)."""
    from cross_checks.scenario import parse_scenario
    w = ", ".join(repr(float(c)) for c in _initial_w(1)[0])
    return parse_scenario(f"""name = "bench"
duration = 1.0
dt = {H!r}
[body]
mass = 1.0
inertia = [{', '.join(repr(float(m)) for m in MOMENTS)}]
[initial]
angular_velocity = [{w}]
[forces]
gravity = [{', '.join(repr(float(g)) for g in G)}]
[[forces.torque]]
torque = [{', '.join(repr(float(t)) for t in TORQUE_B)}]
frame = "body"
""", "<bench>")


def adapter_single_us(engine_module, variant, n_steps, repeats):
    """µs per step of one trajectory through an engine's rbcheck adapter (``simulate``: the model
    built, the forces applied as the adapter applies them, every step recorded): what a sweep pays."""
    sc = _bench_scenario()
    return 1e6 * _best_of(lambda: engine_module.simulate(sc, variant, H, n_steps), repeats) / n_steps


def drake_single_us(n_steps, repeats):
    """Drake's single trajectory, µs per step, through its adapter (semi-explicit Euler; the body
    torque turns with the body, so a LeafSystem evaluates it at every derivative) and, as Drake's
    own floor, with a constant applied force (no Python in the step); ``(None, None)`` without Drake."""
    try:
        from cross_checks.engines import drake_engine
        drake_engine.version()
    except ImportError:
        return None, None
    through_adapter = adapter_single_us(drake_engine, "semi_explicit_euler", n_steps, repeats)
    model = drake_engine.DrakeModel(_bench_scenario(), "semi_explicit_euler")
    model.fixed_step(H)
    model.plant.get_applied_generalized_force_input_port().FixValue(model.context, np.r_[TORQUE_B, 0.0, 0.0, 0.0])
    y0 = _bench_scenario().problem.initial_packed()

    def run():
        model.set_state(y0)
        for k in range(1, n_steps + 1):
            model.simulator.AdvanceTo(k * H)
            model.drake_state()
    return through_adapter, 1e6 * _best_of(run, repeats) / n_steps


def pybullet_bodies(n_bodies, n_steps, repeats):
    from cross_checks.engines import pybullet_engine  # noqa: F401  (silences pybullet's banner)
    import pybullet as p
    cid = p.connect(p.DIRECT)
    try:
        p.setGravity(*G, physicsClientId=cid)
        p.setPhysicsEngineParameter(fixedTimeStep=H, numSubSteps=0, physicsClientId=cid)
        ids = []
        for _ in range(n_bodies):
            b = p.createMultiBody(baseMass=1.0, baseCollisionShapeIndex=-1, physicsClientId=cid)
            p.changeDynamics(b, -1, mass=1.0, localInertiaDiagonal=MOMENTS.tolist(), linearDamping=0.0,
                             angularDamping=0.0, maxJointVelocity=1e12, physicsClientId=cid)
            ids.append(b)
        w = _initial_w(n_bodies)

        def run():
            for b, wi in zip(ids, w):
                p.resetBasePositionAndOrientation(b, [0, 0, 0], [0, 0, 0, 1], physicsClientId=cid)
                p.resetBaseVelocity(b, [0, 0, 0], wi.tolist(), physicsClientId=cid)
            for _ in range(n_steps):
                for b in ids:
                    p.applyExternalTorque(b, -1, TORQUE_B.tolist(), p.LINK_FRAME, physicsClientId=cid)
                p.stepSimulation(physicsClientId=cid)
                for b in ids:  # read every state back, as a recorder must
                    p.getBasePositionAndOrientation(b, physicsClientId=cid)
                    p.getBaseVelocity(b, physicsClientId=cid)
        return n_bodies * n_steps / _best_of(run, repeats)
    finally:
        p.disconnect(cid)


def run_bench(quick: bool = False) -> dict:
    """All measurements of one run (see the module docstring); ``quick`` uses fewer bodies and steps."""
    import mujoco
    from cross_checks.engines import pybullet_engine  # imports pybullet with its stderr banner silenced
    # MuJoCo's multi-body model is measured at N = 1000, its best: 10,000 free bodies in one model take
    # 35 s to compile and step slower per body (2.2-2.8e6 body-steps/s measured), so comparing there
    # would flatter the reference. Its rollout runs N = 10,000 single-body trajectories.
    n_ref, n_mj, n_roll, n_pb = (2000, 1000, 1000, 100) if quick else (10_000, 1000, 10_000, 1000)
    steps, rep = (20, 2) if quick else (100, 3)
    r = {
        "quick": quick,
        "n_bodies": {"reference": n_ref, "mujoco": n_mj, "mujoco_rollout": n_roll, "pybullet": n_pb},
        "versions": {"mujoco": mujoco.__version__, "pybullet": pybullet_engine.version(),
                     "numpy": np.__version__, "python": platform.python_version()},
        "cpu_count": os.cpu_count(),
        "reference_course_body_steps_per_s": reference_batched(n_ref, steps, "course", rep),
        "reference_expmap_gyro_body_steps_per_s": reference_batched(n_ref, steps, "expmap_gyro", rep),
        "mujoco_multibody_body_steps_per_s": mujoco_multibody(n_mj, steps, rep),
        "mujoco_rollout_body_steps_per_s": mujoco_rollout(n_roll, steps, rep),
        "pybullet_body_steps_per_s": pybullet_bodies(n_pb, max(steps // 4, 5), rep),
        "reference_single_us_per_step": reference_single_us(2000 if not quick else 500, rep),
        "mujoco_single_us_per_step": mujoco_single_us(20000 if not quick else 5000, rep),
    }
    from cross_checks.engines import mujoco_engine
    # 5000 steps in both modes: a run's set-up (model compile, simulator) is part of its cost per step
    r["mujoco_adapter_single_us_per_step"] = adapter_single_us(mujoco_engine, "euler", 5000, rep)
    r["drake_single_us_per_step"], r["drake_constant_force_us_per_step"] = drake_single_us(5000, rep)
    r["versions"]["drake"] = _drake_version()
    r["reference_batched_body_steps_per_s"] = max(r["reference_course_body_steps_per_s"],
                                                  r["reference_expmap_gyro_body_steps_per_s"])
    r["mujoco_best_body_steps_per_s"] = max(r["mujoco_multibody_body_steps_per_s"], r["mujoco_rollout_body_steps_per_s"])
    r["ratio_reference_batched_vs_mujoco_best"] = r["reference_batched_body_steps_per_s"] / r["mujoco_best_body_steps_per_s"]
    r["ratio_reference_single_vs_mj_step"] = r["reference_single_us_per_step"] / r["mujoco_single_us_per_step"]
    r["targets"] = {
        "reference_batched >= 3x mujoco_best": r["ratio_reference_batched_vs_mujoco_best"] >= 3.0,
        "reference_single <= 5x mj_step": r["ratio_reference_single_vs_mj_step"] <= 5.0,
    }
    return r


def _drake_version():
    try:
        from cross_checks.engines.drake_engine import version
        return version()
    except ImportError:
        return None


def format_table(r: dict) -> str:
    rows = [
        ("reference batched, course", r["reference_course_body_steps_per_s"], r["n_bodies"]["reference"]),
        ("reference batched, expmap_gyro", r["reference_expmap_gyro_body_steps_per_s"], r["n_bodies"]["reference"]),
        ("MuJoCo, N bodies in one model (mj_step)", r["mujoco_multibody_body_steps_per_s"], r["n_bodies"]["mujoco"]),
        ("MuJoCo, rollout of N single bodies", r["mujoco_rollout_body_steps_per_s"], r["n_bodies"]["mujoco_rollout"]),
        ("PyBullet, N bodies incl. state read-back", r["pybullet_body_steps_per_s"], r["n_bodies"]["pybullet"]),
    ]
    best = r["mujoco_best_body_steps_per_s"]
    out = [f"{'measurement':<44} {'N':>6} {'body-steps/s':>14} {'vs MuJoCo best':>15}"]
    out += [f"{name:<44} {n:>6} {v:>14.3e} {v / best:>14.2f}x" for name, v, n in rows]
    out.append("")
    out.append(f"single trajectory: reference:expmap_gyro {r['reference_single_us_per_step']:.2f} us/step, "
               f"mj_step {r['mujoco_single_us_per_step']:.2f} us/step "
               f"(ratio {r['ratio_reference_single_vs_mj_step']:.1f}x)")
    d = r.get("drake_single_us_per_step")
    out.append(f"single trajectory through the adapters (every step recorded, body torque applied as each adapter "
               f"does): mujoco:euler {r['mujoco_adapter_single_us_per_step']:.2f} us/step, "
               + (f"drake:semi_explicit_euler {d:.2f} us/step ({d / r['mujoco_adapter_single_us_per_step']:.1f}x); "
                  f"Drake with a constant applied force {r['drake_constant_force_us_per_step']:.2f} us/step"
                  if d is not None else "Drake not installed (pip install 'rbcheck[drake]')"))
    for name, ok in r["targets"].items():
        out.append(f"target {name}: {'met' if ok else 'NOT met'}")
    return "\n".join(out)


def main(quick: bool = False, json_path: str | None = None, extra=None) -> int:
    """``rbcheck bench``: measure, print the table, write ``json_path`` (checked writable by the CLI first).
    ``extra``: {key: (measure(quick) -> dict, format(dict) -> str)} of measurements from layers bench may
    not import (the fuzz's cases/s, passed in by the cli), run in this same process and written under key."""
    r = run_bench(quick)
    print(format_table(r))
    for key, (measure, fmt) in (extra or {}).items():
        r[key] = measure(quick)
        print()
        print(fmt(r[key]))
    if json_path:
        from cross_checks.core.files import atomic_write_text
        atomic_write_text(json_path, json.dumps(r, indent=2, sort_keys=True) + "\n")
    return 0

