"""``rbcheck bench``: throughput of the batched reference vs MuJoCo and PyBullet, and the cold sweep
against its floor, measured in one run (what each measures, the body and the floor: docs/speed.md,
"What `rbcheck bench` measures"). Every measurement is repeated (``repeats``): median and (min, max);
results are ratios against the engines measured in the same process, never absolute thresholds.

Keys written by ``--json`` (fixed; medians): reference_batched_body_steps_per_s,
mujoco_best_body_steps_per_s, pybullet_body_steps_per_s, reference_single_us_per_step,
mujoco_single_us_per_step, mujoco_bare_step_us, drake_single_us_per_step (None without Drake),
sweep_floor_ratio ((run + report) / floor), sweep_run_floor_ratio (run / floor), ``batched_adapters``
{ENGINE:VARIANT: body-steps/s through the adapter's ``simulate_many``} (mujoco:euler and every installed
engine that batches), plus the individual measurements and ``measurements`` {name: {median, min, max,
repeats}}. Drake is measured on one trajectory only, beside MuJoCo through the same adapter interface
(``mujoco_adapter_single_us_per_step``). ``overhead``: per installed engine (default variant) ``{variant,
engine_us_per_step, engine_step_us_per_step, own_loop_us_per_step, rbcheck_us_per_step,
rbcheck_own_us_per_step}`` (the engine's own cost per step: its own minimal loop of apply + step + read in its
own API where the bench has one (:data:`OWN_LOOP`, the CPU engines), else the time inside its step or compiled
rollout; the time inside its step alone (``Run.engine_s``); the own loop (None without one); the whole cost
through rbcheck; and rbcheck's own time, through rbcheck less the own loop);
``batched``: ``{variant, engine_body_steps_per_s, rbcheck_body_steps_per_s, ratio}`` (the engine's own
batched throughput beside simulate_many's at the same N, the two timed alternately in rounds
(:func:`interleaved`): medians of the rounds, and the median of the rounds' ratios): every installed engine
of :data:`OWN_BATCHED` — MuJoCo (N bodies in one model, or a rollout), PyBullet (N bodies), PhysX and
Rapier (one scene of N bodies), MJX, Brax and jaxsim (N bodies vmapped through one compiled loop of their
own step; compilation timed apart, ``measurements["own_batched[V]"]["compile_s"]``) and MuJoCo Warp (N
worlds); ``own_batched_not_measured`` {variant: why} for a batching engine without one here.
"""
from __future__ import annotations

import json
import math
import os
import platform
import time

import numpy as np

TORQUE_B = np.array([0.0, 0.0, 0.2])
MOMENTS = np.array([1.0, 2.0, 3.0])
G = np.array([0.0, 0.0, -9.81])
H = 1e-3


def _times(fn, repeats) -> list:
    """Wall seconds of ``repeats`` calls of ``fn`` (after one untimed warm-up call)."""
    fn()
    out = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t0)
    return out


def stats(values) -> dict:
    """Median and spread of repeated measurements."""
    v = np.asarray(values, dtype=float)
    return {"median": float(np.median(v)), "min": float(v.min()),
            "max": float(v.max()), "repeats": int(v.size)}


def _rates(work, fn, repeats) -> dict:
    """Stats of ``work / seconds`` over the repeats (e.g. body-steps/s)."""
    return stats([work / t for t in _times(fn, repeats)])


def _per_step_us(n_steps, fn, repeats) -> dict:
    return stats([1e6 * t / n_steps for t in _times(fn, repeats)])


class Runner:
    """One batched measurement made ready to be timed: ``run()`` does ``work`` body-steps (its set-up —
    a scene built, a loop compiled — done before, ``compile_s`` seconds of it a compilation, None where
    nothing compiles), ``close()`` frees what it holds."""

    def __init__(self, run, work: int, compile_s=None, close=None):
        self.run, self.work, self.compile_s = run, int(work), compile_s
        self._close = close

    def close(self) -> None:
        if self._close is not None:
            self._close()


def interleaved(runners: dict, repeats: int) -> dict:
    """Time the ``runners`` ({name: Runner}) alternately: one untimed warm-up call of each, then ``repeats``
    rounds in which every runner runs once, the order reversed every other round (neither side always
    runs right after the other). ``{name: [body-steps/s of each round]}``: a round's figures are taken
    within seconds of each other, so the load a row's ratio sees is the same on both sides (a median of
    the rounds' ratios, :func:`paired_ratio`), where timing each side's repeats apart takes them minutes
    apart on a shared machine."""
    names = list(runners)
    for name in names:
        runners[name].run()
    rates: dict = {name: [] for name in names}
    for k in range(repeats):
        for name in (names if k % 2 == 0 else names[::-1]):
            t0 = time.perf_counter()
            runners[name].run()
            rates[name].append(runners[name].work / (time.perf_counter() - t0))
    return rates


def paired_ratio(num: list, den: list) -> float:
    """The median over rounds of ``num[k] / den[k]`` (two sides' rates of :func:`interleaved`'s round k)."""
    return float(np.median(np.asarray(num, dtype=float) / np.asarray(den, dtype=float)))


def _initial_w(n, seed=0):
    return np.random.default_rng(seed).normal(size=(n, 3))


def _bench_problem(w_W):
    """The benchmark's body as a reference_sim Problem at rest at the origin, angular velocity ``w_W``
    (rad/s, world axes)."""
    from reference_sim.body import RigidBody
    from reference_sim.forces import ForceModel, Torque
    from reference_sim.state import Problem, State
    return Problem(RigidBody(1.0, MOMENTS), ForceModel(gravity_W=G, torques=(Torque(TORQUE_B, "body"),)),
                   State(np.zeros(3), np.zeros(3), np.array([1.0, 0, 0, 0]), w_W))


def reference_batched(n_bodies, n_steps, variant, repeats):
    """The batched reference: N bodies as N members of one compiled run (reference_sim.simulate.run_members),
    every state recorded."""
    from reference_sim.simulate import run_members
    members = _bench_problem(np.zeros(3)).members.take(np.zeros(n_bodies, dtype=int))
    y0 = np.zeros((n_bodies, 13))
    y0[:, 6] = 1.0
    y0[:, 10:13] = _initial_w(n_bodies)
    return _rates(n_bodies * n_steps, lambda: run_members(members, variant, H, n_steps, y0), repeats)


def reference_single_us(n_steps, repeats, variant="expmap_gyro"):
    from reference_sim.simulate import simulate
    problem = _bench_problem(_initial_w(1)[0])
    return _per_step_us(n_steps, lambda: simulate(problem, variant, H, n_steps), repeats)


def _mujoco_model(n_bodies):
    import mujoco
    bodies = "".join(
        f'<body name="b{i}"><freejoint/><inertial pos="0 0 0" mass="1" diaginertia="1 2 3"/></body>'
        for i in range(n_bodies))
    xml = (f'<mujoco><option timestep="{H}" gravity="0 0 -9.81" integrator="Euler">'
           f'<flag autoreset="disable" contact="disable"/></option><worldbody>{bodies}</worldbody></mujoco>')
    return mujoco.MjModel.from_xml_string(xml)


def mujoco_multibody(n_bodies, n_steps, repeats):
    return _rates(n_bodies * n_steps, mujoco_multibody_runner(n_bodies, n_steps).run, repeats)


def mujoco_multibody_runner(n_bodies, n_steps) -> Runner:
    """MuJoCo's own batched run: N free bodies in one model, ``mj_step(nstep=n_steps)`` from rest with the
    body torque in ``qfrc_applied``."""
    import mujoco
    m = _mujoco_model(n_bodies)
    d = mujoco.MjData(m)
    w = _initial_w(n_bodies)

    def run():
        mujoco.mj_resetData(m, d)
        d.qvel.reshape(n_bodies, 6)[:, 3:6] = w
        d.qfrc_applied.reshape(n_bodies, 6)[:, 3:6] = TORQUE_B  # body-axes torque, persists
        mujoco.mj_step(m, d, nstep=n_steps)
    return Runner(run, n_bodies * n_steps)


def mujoco_rollout(n_bodies, n_steps, repeats):
    return _rates(n_bodies * n_steps, mujoco_rollout_runner(n_bodies, n_steps).run, repeats)


def mujoco_rollout_runner(n_bodies, n_steps) -> Runner:
    """MuJoCo's own batched run as a ``mujoco.rollout`` of N single-body states (one thread per core)."""
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
    return Runner(lambda: rollout.rollout(m, datas, states, control, **kw), n_bodies * n_steps)


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
    return _per_step_us(n_steps, run, repeats)


def mujoco_bare_step_us(n_steps, repeats):
    """One bare ``mj_step`` of a free body (gravity, no applied force, no Python between steps): the
    per-step cost the sweep's floor is made of."""
    import mujoco
    m = _mujoco_model(1)
    d = mujoco.MjData(m)

    def run():
        mujoco.mj_resetData(m, d)
        d.qvel[3:6] = _initial_w(1)[0]
        mujoco.mj_step(m, d, nstep=n_steps)
    return _per_step_us(n_steps, run, repeats)


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
    return _per_step_us(n_steps, lambda: engine_module.simulate(sc, variant, H, n_steps), repeats)


def batching_variants(engines=None) -> list:
    """The default (first) ``ENGINE:VARIANT`` of every available engine whose adapter batches (overrides
    ``EngineAdapter.simulate_many``), the engines of their own rows (reference, MuJoCo, PyBullet) excepted;
    ``engines`` narrows them. One row per engine: a JAX engine's batch costs seconds of compilation per
    variant before it is timed."""
    from cross_checks.engines import all_variants, get_adapter
    from cross_checks.engines.base import EngineAdapter
    out: dict = {}
    for v in all_variants():
        if not v.available or v.engine in SWEEP_ENGINES or (engines is not None and v.engine not in engines):
            continue
        if type(get_adapter(v.engine)).simulate_many is not EngineAdapter.simulate_many:
            out.setdefault(v.engine, v.name)
    return list(out.values())


def adapter_batched(variant, n_bodies, n_steps, repeats) -> dict:
    """:func:`adapter_runner`'s body-steps/s over ``repeats``."""
    return _rates(n_bodies * n_steps, adapter_runner(variant, n_bodies, n_steps).run, repeats)


def adapter_runner(variant, n_bodies, n_steps) -> Runner:
    """Body-steps/s of N trajectories of the benchmark's body (one scenario, N requests: the adapters build
    their model — MJX's put_model, a Brax system, a Genesis scene — once per scenario, which a sweep's
    ladder shares too) in ONE ``simulate_many`` call of an engine's adapter, every state recorded. The
    untimed warm-up call takes any compilation (JIT) out of the figure; an engine reports its compile time
    apart (docs/engine_conventions.md)."""
    from cross_checks.engines import get_adapter
    from cross_checks.engines.base import RunRequest
    engine, name = variant.split(":", 1)
    adapter = get_adapter(engine)
    sc = _bench_scenario()
    requests = [RunRequest(sc, H, n_steps) for _ in range(n_bodies)]

    def run():
        for res in adapter.simulate_many(name, requests):
            if isinstance(res, Exception):
                raise res
    return Runner(run, n_bodies * n_steps)


# --- each CPU engine's own minimal loop (issue 43, item 5): one body of the bench (the adapter's model
# builder: its neutralised settings, the same Δt), stepped from Python in the engine's own API as a user
# would write it to record a trajectory: the body torque applied in the engine's own way (turned to world
# axes in plain floats where the engine takes world torques only: the cheapest a user can do it), one step,
# the state read back. Timed over the steps only (the body is built once, before the repeats); the bench's
# overhead rows put it between the engine's step alone and the cost through rbcheck. Each loop also gives
# its final state, which tests/cross_checks/test_bench.py holds equal to rbcheck's run of the same steps:
# a loop that skipped the work a trajectory needs would not reach it.

class OwnLoop(Runner):
    """One engine's own minimal loop of ``n_steps`` from the bench's initial state: a :class:`Runner`
    (``run()`` steps it, ``close()`` frees the world) whose ``final()`` is the packed state (13,) (x_W m,
    v_W m/s, q_WB (w x y z), ω_W rad/s) after the last ``run``."""

    def __init__(self, run, final, n_steps: int, close=None):
        super().__init__(run, n_steps, close=close)
        self.final = final


def _turn(q, v) -> tuple:
    """``R(q) v`` in plain floats: q (w, x, y, z) unit, v (3,): what a user driving an engine that takes
    world torques writes per step (``t = 2 u × v``, ``v + w t + u × t``)."""
    w, x, y, z = q
    a, b, c = v
    tx, ty, tz = 2.0 * (y * c - z * b), 2.0 * (z * a - x * c), 2.0 * (x * b - y * a)
    return (a + w * tx + (y * tz - z * ty), b + w * ty + (z * tx - x * tz), c + w * tz + (x * ty - y * tx))


def _own_world(engine, variant):
    """The adapter's world of the bench's one body at H (its own model builder), at the initial state."""
    from cross_checks.engines import get_adapter
    from cross_checks.engines.base import RunRequest
    sc = _bench_scenario()
    world = get_adapter(engine).build([RunRequest(sc, H, 1)], variant, H)
    return world, sc.problem.initial_packed()


def _world_loop(world, run, n_steps: int) -> OwnLoop:
    """An :class:`OwnLoop` over an adapter world: its final state is the world's own read, converted."""
    return OwnLoop(run, lambda: world.packed(world.rows([world.read()]))[0, 0], n_steps, world.close)


def mujoco_own_loop(variant, n_steps) -> OwnLoop:
    """MuJoCo: the torque in ``qfrc_applied`` (body axes; MuJoCo keeps it), then per step ``mj_step`` and a
    copy of ``qpos`` and ``qvel``."""
    import mujoco
    world, y0 = _own_world("mujoco", variant)
    m, d = world.model, world.data

    def run():
        world.set_state(y0[None])
        d.qfrc_applied[3:6] = TORQUE_B
        for _ in range(n_steps):
            mujoco.mj_step(m, d)
            d.qpos.copy()
            d.qvel.copy()
    return _world_loop(world, run, n_steps)


def pybullet_own_loop(variant, n_steps) -> OwnLoop:
    """PyBullet: per step ``applyExternalTorque(LINK_FRAME)`` (Bullet clears forces after every step),
    ``stepSimulation``, ``getBasePositionAndOrientation`` and ``getBaseVelocity``."""
    import pybullet as p
    world, y0 = _own_world("pybullet", variant)
    b, c, tau = world.bodies[0], world.c, TORQUE_B.tolist()

    def run():
        world.set_state(y0[None])
        for _ in range(n_steps):
            p.applyExternalTorque(b, -1, tau, p.LINK_FRAME, physicsClientId=c)
            p.stepSimulation(physicsClientId=c)
            p.getBasePositionAndOrientation(b, physicsClientId=c)
            p.getBaseVelocity(b, physicsClientId=c)
    return _world_loop(world, run, n_steps)


def dart_own_loop(variant, n_steps) -> OwnLoop:
    """DART: per step ``BodyNode.setExtTorque(τ_B, isLocal=True)`` (DART clears it after every step),
    ``World.step()``, ``getPositions()`` and ``getVelocities()``."""
    world, y0 = _own_world("dart", variant)
    body = world.bodies[0]
    w, node, skel = body.world, body.node, body.skeleton

    def run():
        world.set_state(y0[None])
        for _ in range(n_steps):
            node.setExtTorque(TORQUE_B, True)
            w.step()
            skel.getPositions()
            skel.getVelocities()
    return _world_loop(world, run, n_steps)


def physx_own_loop(variant, n_steps) -> OwnLoop:
    """PhysX: per step the state read in one ``pack()``, the body torque turned to world axes from its
    attitude (PhysX takes world torques only; plain floats, :func:`_turn`) and added with
    ``add_force_torque``, ``PhysxCpuSystem.step()``."""
    world, y0 = _own_world("physx", variant)
    system, c = world.system, world.comps[0]
    zero, tau = np.zeros(3, dtype=np.float32), TORQUE_B.tolist()

    def run():
        world.set_state(y0[None])
        for _ in range(n_steps):
            row = np.frombuffer(system.pack(), dtype=np.float32)   # [q (w x y z), p, v, ω]
            c.add_force_torque(zero, np.array(_turn(row[0:4].tolist(), tau), dtype=np.float32))
            system.step()
        system.pack()
    return _world_loop(world, run, n_steps)


def rapier_own_loop(variant, n_steps) -> OwnLoop:
    """Rapier: per step the attitude read, the torque replaced by the body torque turned to world axes
    (Rapier keeps user torques and takes world ones only; plain floats, :func:`_turn`),
    ``PhysicsWorld.step()``, the state read."""
    world, y0 = _own_world("rapier", variant)
    rb, w, tau = world.bodies[0], world.world, TORQUE_B.tolist()

    def run():
        world.set_state(y0[None])
        for _ in range(n_steps):
            qx, qy, qz, qw = rb.rotation.to_tuple()
            rb.reset_torques(False)
            rb.add_torque(_turn((qw, qx, qy, qz), tau), False)
            w.step()
            rb.translation.to_tuple()
            rb.linvel.to_tuple()
            rb.angvel.to_tuple()
    return _world_loop(world, run, n_steps)


def drake_own_loop(variant, n_steps) -> OwnLoop:
    """Drake: the bench's body in a MultibodyPlant (drake_engine.DrakeModel, the variant's integrator at a
    fixed step), per step the body torque turned to world axes by the plant's quaternion normalised (Drake's
    drifts off unit length; plain floats, :func:`_turn`) and fixed on the generalized-force input
    ([τ_W, f_W]), ``Simulator.AdvanceTo``, the state read."""
    from cross_checks.engines import drake_engine
    model = drake_engine.DrakeModel(_bench_scenario(), variant)
    model.fixed_step(H)
    port = model.plant.get_applied_generalized_force_input_port()
    y0 = _bench_scenario().problem.initial_packed()
    plant, ctx, sim, tau = model.plant, model.context, model.simulator, TORQUE_B.tolist()
    wrench = np.zeros(6)

    def run():
        model.set_state(y0)
        for k in range(1, n_steps + 1):
            # Drake's state: [q_WB (w x y z), x_W, ω_W, v_W]
            w, x, y, z = plant.GetPositionsAndVelocities(ctx)[0:4].tolist()
            n = math.sqrt(w * w + x * x + y * y + z * z)
            wrench[0:3] = _turn((w / n, x / n, y / n, z / n), tau)
            port.FixValue(ctx, wrench)
            sim.AdvanceTo(k * H)
        plant.GetPositionsAndVelocities(ctx)
    return OwnLoop(run, lambda: drake_engine.dkw.from_drake_state(model.drake_state()[None])[0], n_steps)


#: Each CPU engine's own minimal loop (its function takes the engine's variant name and the step count).
OWN_LOOP = {"mujoco": mujoco_own_loop, "pybullet": pybullet_own_loop, "dart": dart_own_loop,
            "physx": physx_own_loop, "rapier": rapier_own_loop, "drake": drake_own_loop}


def overhead_rows(n_steps, repeats, variants=None) -> list:
    """Per installed engine (its default variant), one trajectory of the benchmark's body through rbcheck
    (``simulate``: the host loop, its forces evaluated every step, every step recorded): ``{variant,
    engine_us_per_step, engine_step_us_per_step, own_loop_us_per_step, rbcheck_us_per_step,
    rbcheck_own_us_per_step}``, medians over ``repeats`` — the engine's own cost per step (its own minimal
    loop where there is one, else its step), the time inside the engine's step alone (Run.engine_s; None for
    an adapter that owns its loop and cannot tell it apart), the engine's own minimal loop of the same steps
    in its own API (:data:`OWN_LOOP`: apply, step, read; None for an engine without one here: the compiled
    engines, whose step is one call), the whole cost per step through rbcheck, the engine's included, and
    rbcheck's own time (:func:`rbcheck_own_us`: the median over
    the rounds of through rbcheck less the own loop, the two timed one after the other in each round, so a
    load that moves during the bench moves both)."""
    from cross_checks.engines import all_variants, get_adapter
    sc = _bench_scenario()
    chosen: dict = {}
    for v in all_variants():
        if v.available and v.engine != "reference" and (variants is None or v.name in variants):
            chosen.setdefault(v.engine, v.name)
    med = (lambda xs: float(np.median(xs)))
    out = []
    for name in chosen.values():
        engine, variant = name.split(":", 1)
        adapter = get_adapter(engine)
        adapter.simulate(sc, variant, H, min(n_steps, 50))   # warm-up: compilation, first model build
        loop = OWN_LOOP[engine](variant, n_steps) if engine in OWN_LOOP else None
        whole, own, mine = [], [], []
        try:
            if loop is not None:
                loop.run()   # warm-up
            for _ in range(repeats):
                t0 = time.perf_counter()
                run = adapter.simulate(sc, variant, H, n_steps)
                whole.append((time.perf_counter() - t0) / n_steps * 1e6)
                own.append(None if run.engine_s is None else run.engine_s / n_steps * 1e6)
                if loop is not None:
                    t0 = time.perf_counter()
                    loop.run()
                    mine.append((time.perf_counter() - t0) / n_steps * 1e6)
        finally:
            if loop is not None:
                loop.close()
        step, loop_us = (None if None in own else med(own)), (med(mine) if mine else None)
        out.append({"variant": name, "engine_us_per_step": step if loop_us is None else loop_us,
                    "engine_step_us_per_step": step, "own_loop_us_per_step": loop_us,
                    "rbcheck_us_per_step": med(whole),
                    "rbcheck_own_us_per_step": (med(np.subtract(whole, mine)) if mine else None)})
    return out


def batched_rows(variants, n_bodies, n_steps, repeats) -> tuple:
    """``(rows, measurements, why)``: per ``ENGINE:VARIANT`` of ``variants`` with an own batched run here
    (:data:`OWN_BATCHED`), the engine's own run and N trajectories of the benchmark's body in one
    ``simulate_many`` call (:func:`adapter_runner`), at the same N and steps (PyBullet's: :data:`OWN_STEPS`),
    timed alternately (:func:`interleaved`, ``repeats`` rounds). A row ``{variant, engine_body_steps_per_s,
    rbcheck_body_steps_per_s, ratio}``: the medians of the rounds (the engine's own: the better of its runs
    in each round, where it has two) and the median of the rounds' ratios (rbcheck ÷ engine);
    ``measurements`` ``{"own_batched[V]": stats + compile_s, "adapter_batched[V]": stats}``; ``why``
    ``{variant: why not measured}`` for an engine without an own run here (Drake, DART) or one that cannot
    run (not installed, its model refused)."""
    from cross_checks.engines import EngineError
    rows, measured, why = [], {}, {}
    for v in variants:
        engine, name = v.split(":", 1)
        fn = OWN_BATCHED.get(engine)
        if fn is None:
            why[v] = (f"this bench has no batched run of {engine} by itself (the issue's goal names "
                      "MuJoCo, PyBullet, PhysX, Rapier, MJX, Brax, jaxsim and MuJoCo Warp)")
            continue
        steps = OWN_STEPS.get(engine, lambda k: k)(n_steps)
        try:
            own = fn(n_bodies, steps, name)
        except (ImportError, EngineError) as exc:
            why[v] = f"{type(exc).__name__}: {exc}"
            continue
        own = own if isinstance(own, tuple) else (own,)
        try:
            runners = {("own", k): r for k, r in enumerate(own)}
            runners["rbcheck"] = adapter_runner(v, n_bodies, steps)
            rates = interleaved(runners, repeats)
        finally:
            for r in own:
                r.close()
        best = np.max([rates["own", k] for k in range(len(own))], axis=0).tolist()
        compile_s = [r.compile_s for r in own if r.compile_s is not None]
        measured[f"own_batched[{v}]"] = _with_compile(stats(best), sum(compile_s) if compile_s else None)
        measured[f"adapter_batched[{v}]"] = stats(rates["rbcheck"])
        rows.append({"variant": v, "engine_body_steps_per_s": float(np.median(best)),
                     "rbcheck_body_steps_per_s": float(np.median(rates["rbcheck"])),
                     "ratio": paired_ratio(rates["rbcheck"], best)})
    return rows, measured, why


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
    model.plant.get_applied_generalized_force_input_port().FixValue(
        model.context, np.r_[TORQUE_B, 0.0, 0.0, 0.0])
    y0 = _bench_scenario().problem.initial_packed()

    def run():
        model.set_state(y0)
        for k in range(1, n_steps + 1):
            model.simulator.AdvanceTo(k * H)
            model.drake_state()
    return through_adapter, _per_step_us(n_steps, run, repeats)


def pybullet_bodies(n_bodies, n_steps, repeats):
    runner = pybullet_bodies_runner(n_bodies, n_steps)
    try:
        return _rates(runner.work, runner.run, repeats)
    finally:
        runner.close()


def pybullet_bodies_runner(n_bodies, n_steps) -> Runner:
    """PyBullet's own batched run: N bodies in one client, per step the body torque applied to each
    (``LINK_FRAME``), ``stepSimulation``, every state read back."""
    import pybullet as p

    from cross_checks.engines import pybullet_engine  # noqa: F401  (silences pybullet's banner)
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
    except BaseException:
        p.disconnect(cid)
        raise
    return Runner(run, n_bodies * n_steps, close=lambda: p.disconnect(cid))


# --- the engines' own batched throughput (issue 43, item 4): the bench's body built by each adapter's own
# model builder (its neutralised defaults, the same Δt), stepped by the engine's own API, not rbcheck's loop

def _own_problem(n_bodies):
    """The bench's scenario and the packed initial states (N, 13) of its N bodies (ω0 = _initial_w(N), world
    axes = body axes at the identity attitude)."""
    sc = _bench_scenario()
    y0 = np.tile(sc.problem.initial_packed(), (n_bodies, 1))
    y0[:, 10:13] = _initial_w(n_bodies)
    return sc, y0


def _with_compile(st: dict, compile_s) -> dict:
    return {**st, "compile_s": compile_s}


def physx_scene(n_bodies, n_steps, variant="tgs") -> Runner:
    """PhysX: ONE scene of N rigid dynamics (physx_engine.PhysxWorld's: the same mass properties and
    neutralised settings, the variant's solver, Δt), stepped by ``PhysxCpuSystem.step()``; before each step
    every body's attitude is read in one ``pack()`` and the body torque, turned to world axes, is added per
    body (PhysX clears forces each step and takes world torques only)."""
    from cross_checks.engines import physx_engine
    from cross_checks.engines.base import RunRequest
    from reference_sim.quaternion import rotate
    sc, y0 = _own_problem(n_bodies)
    world = physx_engine.PhysxWorld([RunRequest(sc, H, n_steps)] * n_bodies, variant, H)
    system, comps, zero = world.system, world.comps, np.zeros(3, dtype=np.float32)
    tau_B = np.tile(TORQUE_B, (n_bodies, 1))

    def run():
        world.set_state(y0)
        for _ in range(n_steps):
            q = np.frombuffer(system.pack(), dtype=np.float32).reshape(n_bodies, 13)[:, 0:4]   # w x y z
            for c, t in zip(comps, rotate(q.astype(float), tau_B).astype(np.float32)):
                c.add_force_torque(zero, t)
            system.step()
    return Runner(run, n_bodies * n_steps, close=world.close)


def rapier_world(n_bodies, n_steps, variant="symplectic_euler") -> Runner:
    """Rapier: ONE ``PhysicsWorld`` of N dynamic bodies (rapier_engine.RapierWorld's: the same mass
    properties, world and body settings, gyroscopic flag, Δt, one thread), stepped by ``world.step()``;
    before each step every body's attitude is read and its torque replaced by the body torque turned to world
    axes (Rapier keeps user forces and takes world torques only)."""
    from cross_checks.engines import rapier_engine
    from cross_checks.engines.base import RunRequest
    from reference_sim.quaternion import rotate
    sc, y0 = _own_problem(n_bodies)
    world = rapier_engine.RapierWorld([RunRequest(sc, H, n_steps)] * n_bodies, variant, H)
    bodies, w = world.bodies, world.world
    tau_B = np.tile(TORQUE_B, (n_bodies, 1))

    def run():
        world.set_state(y0)
        for _ in range(n_steps):
            xyzw = np.array([rb.rotation.to_tuple() for rb in bodies])
            for rb, t in zip(bodies, rotate(xyzw[:, [3, 0, 1, 2]], tau_B).tolist()):
                rb.reset_torques(False)
                rb.add_torque(tuple(t), False)
            w.step()
    return Runner(run, n_bodies * n_steps, close=world.close)


def _jax_timed(compile_fn, args, work) -> Runner:
    """``compile_fn`` compiled ahead of time for ``args`` (timed apart: ``compile_s``), its calls run to
    completion."""
    import jax
    t0 = time.perf_counter()
    exe = jax.jit(compile_fn).lower(*args).compile()
    compile_s = time.perf_counter() - t0
    return Runner(lambda: jax.block_until_ready(exe(*args)), work, compile_s)


def mjx_vmapped(n_bodies, n_steps, variant="euler") -> Runner:
    """MJX: the model mjx_engine builds (mujoco_engine's, ``mjx.put_model``), N bodies vmapped through ONE
    compiled ``jax.lax.fori_loop`` of ``mjx.step``; the body torque in ``qfrc_applied`` (the free joint's
    rotational DOFs are body axes; it persists between steps). Compilation timed apart (``compile_s``)."""
    from cross_checks.engines import mjx_engine
    _, xm = mjx_engine.device_model(_bench_scenario(), variant, H)   # starts JAX (float64)
    import jax
    import jax.numpy as jnp
    import mujoco
    from mujoco import mjx

    from cross_checks.engines import mujoco_engine
    m = mujoco_engine.build_model(_bench_scenario(), variant, H)
    d0 = mjx.put_data(m, mujoco.MjData(m))
    d0 = d0.replace(qfrc_applied=d0.qfrc_applied.at[3:6].set(jnp.asarray(TORQUE_B)))
    qvel0 = np.zeros((n_bodies, 6))
    qvel0[:, 3:6] = _initial_w(n_bodies)

    def member(model, qvel):
        d = jax.lax.fori_loop(0, n_steps, lambda i, d: mjx.step(model, d), d0.replace(qvel=qvel))
        return d.qpos, d.qvel
    return _jax_timed(jax.vmap(member, in_axes=(None, 0)), (xm, jnp.asarray(qvel0)), n_bodies * n_steps)


def brax_vmapped(n_bodies, n_steps, variant="generalized") -> Runner:
    """Brax (generalized pipeline): brax_engine's neutralised System of the bench's body at Δt (its six
    DOF actuators: ``act`` is the generalized force [f_W, τ_B]; brax applies gravity), N bodies vmapped
    through ONE compiled ``jax.lax.fori_loop`` of ``pipeline.step`` with ``act = [0, τ_B]``. Compilation timed
    apart (``compile_s``)."""
    from cross_checks.engines import brax_engine
    sc, y0 = _own_problem(n_bodies)
    sys = brax_engine.build_system(sc, variant, H)   # starts JAX (float64)
    import importlib

    import jax
    import jax.numpy as jnp
    pipeline = importlib.import_module(f"brax.{variant}.pipeline")
    q, qd = brax_engine.to_q_qd(y0)
    act = jnp.asarray(np.r_[np.zeros(3), TORQUE_B])

    def member(s, q, qd):
        st = jax.lax.fori_loop(0, n_steps, lambda i, st: pipeline.step(s, st, act), pipeline.init(s, q, qd))
        return st.q, st.qd
    return _jax_timed(jax.vmap(member, in_axes=(None, 0, 0)), (sys, jnp.asarray(q), jnp.asarray(qd)),
                      n_bodies * n_steps)


def jaxsim_vmapped(n_bodies, n_steps, variant="semi_implicit_euler") -> Runner:
    """jaxsim: jaxsim_engine's model of the bench's body (its SDF, gravity, integrator) at Δt, N bodies
    vmapped through ONE compiled ``jax.lax.fori_loop`` of ``js.model.step`` on the body's own
    ``JaxSimModelData`` (Mixed representation); the link force [0, R_WB τ_B] each step (jaxsim takes world
    torques). The model is stacked per body (vmapped on its first axis, as the adapter does): jaxsim's
    vmapped step runs 7-10x faster that way than with one model shared by the N bodies (``in_axes=None``;
    measured interleaved in one process at N = 1024: 0.15 against 1.0 CPU s for 100 steps). Compilation
    timed apart (``compile_s``)."""
    import dataclasses

    from cross_checks.engines import jaxsim_engine
    sc, y0 = _own_problem(n_bodies)
    model = dataclasses.replace(jaxsim_engine.build_model(sc, variant), time_step=H)   # starts JAX
    import jax
    import jax.numpy as jnp
    import jaxsim.api as js
    from jaxsim import VelRepr
    tau_B = jnp.asarray(TORQUE_B)

    def member(model, y):
        data = js.data.JaxSimModelData.build(model=model, base_position=y[0:3], base_quaternion=y[6:10],
                                             base_linear_velocity=y[3:6], base_angular_velocity=y[10:13],
                                             velocity_representation=VelRepr.Mixed)

        def body(i, data):
            w, x, y_, z = data.base_quaternion
            R = jnp.array([[1 - 2 * (y_ * y_ + z * z), 2 * (x * y_ - w * z), 2 * (x * z + w * y_)],
                           [2 * (x * y_ + w * z), 1 - 2 * (x * x + z * z), 2 * (y_ * z - w * x)],
                           [2 * (x * z - w * y_), 2 * (y_ * z + w * x), 1 - 2 * (x * x + y_ * y_)]])
            f6 = jnp.concatenate([jnp.zeros(3), R @ tau_B])[None, :]
            return js.model.step(model, data, link_forces=f6)
        data = jax.lax.fori_loop(0, n_steps, body, data)
        return data.base_position, data.base_quaternion
    stacked = jax.tree.map(lambda x: np.stack([np.asarray(x)] * n_bodies), model)
    return _jax_timed(jax.vmap(member, in_axes=(0, 0)), (stacked, jnp.asarray(y0)), n_bodies * n_steps)


def mujoco_warp_worlds(n_bodies, n_steps, variant="euler") -> Runner:
    """MuJoCo Warp: the model mujoco_warp_engine builds (mujoco_engine's, autoreset cleared) as N worlds of
    one ``mjw.put_data(..., nworld=N)`` on Warp's CPU device, one ``mjw.step`` captured as a Warp graph and
    replayed per step (as the adapter does); the body torque in ``qfrc_applied`` (body axes, persists).
    The first step, which loads or compiles the kernels, is timed apart (``compile_s``)."""
    from cross_checks.engines import mujoco_warp_engine as mwe
    m = mwe.host_model(_bench_scenario(), variant, H)   # starts Warp (its kernel cache)
    import mujoco
    import mujoco_warp as mjw
    import warp as wp
    with wp.ScopedDevice("cpu"):
        wm = mwe.device_model(m, [H] * n_bodies)
        wd = mjw.put_data(m, mujoco.MjData(m), nworld=n_bodies)
    qpos0 = np.tile(np.r_[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0], (n_bodies, 1)).astype(np.float32)
    qvel0 = np.zeros((n_bodies, 6), dtype=np.float32)
    qvel0[:, 3:6] = _initial_w(n_bodies)
    wd.qfrc_applied.assign(np.tile(np.r_[0.0, 0.0, 0.0, TORQUE_B], (n_bodies, 1)).astype(np.float32))
    t0 = time.perf_counter()
    with wp.ScopedDevice("cpu"):
        mjw.step(wm, wd)            # loads (or compiles) every kernel of the step
        wp.synchronize()
        with wp.ScopedCapture() as cap:
            mjw.step(wm, wd)
    compile_s = time.perf_counter() - t0

    def run():
        wd.qpos.assign(qpos0)
        wd.qvel.assign(qvel0)
        with wp.ScopedDevice("cpu"):
            for _ in range(n_steps):
                wp.capture_launch(cap.graph)
            wp.synchronize()
    return Runner(run, n_bodies * n_steps, compile_s)


def mujoco_own_runners(n_bodies, n_steps, variant="euler") -> tuple:
    """MuJoCo's two own batched runs (N bodies in one model; a rollout of N single bodies): the row takes
    the better in each round. The bench's body model is Euler's, as ``mujoco:euler``."""
    return mujoco_multibody_runner(n_bodies, n_steps), mujoco_rollout_runner(n_bodies, n_steps)


def pybullet_own_runner(n_bodies, n_steps, variant="multibody") -> Runner:
    """PyBullet's own batched run (:func:`pybullet_bodies_runner`; its maximal-coordinates body is the
    same free body)."""
    return pybullet_bodies_runner(n_bodies, n_steps)


#: The engine's own batched run, per engine (``fn(n_bodies, n_steps, variant)``: a Runner, or a tuple of
#: them of which each round takes the better): N bodies in one model or a rollout (MuJoCo), N bodies of one
#: client (PyBullet), one scene or world of N bodies (PhysX, Rapier), N bodies vmapped in one compiled
#: loop (MJX, Brax, jaxsim), N worlds (MuJoCo Warp).
OWN_BATCHED = {"mujoco": mujoco_own_runners, "pybullet": pybullet_own_runner, "physx": physx_scene,
               "rapier": rapier_world, "mjx": mjx_vmapped, "brax": brax_vmapped, "jaxsim": jaxsim_vmapped,
               "mujoco_warp": mujoco_warp_worlds}
#: The steps of an engine's batched row when not the table's (both sides of the row): PyBullet's N bodies
#: step at a few thousand body-steps/s, so its row has a quarter of the steps, as its throughput row.
OWN_STEPS = {"pybullet": lambda n_steps: max(n_steps // 4, 5)}
#: What each engine's own batched run is, as the table prints it.
OWN_HOW = {"mujoco": "N bodies in one model (best of it and a rollout)", "pybullet": "N bodies, states read",
           "physx": "one scene of N bodies", "rapier": "one world of N bodies",
           "mjx": "N vmapped, one compiled fori_loop", "brax": "N vmapped, one compiled fori_loop",
           "jaxsim": "N vmapped, one compiled fori_loop", "mujoco_warp": "N worlds, one captured step"}


#: The quick bench's sweep: a light scenario and two of the heaviest (long, fine ladders; a DOP853 reference).
QUICK_SCENARIOS = ("projectile", "tennis_racket", "spring_pendulum")
#: The engines of "the default sweep" the floor ratio is defined on (what the README's main command runs,
#: which installs no Drake): every variant of these.
SWEEP_ENGINES = ("reference", "mujoco", "pybullet")


def _sweep_once(scenarios, variants, jobs, render) -> dict:
    """One cold sweep in a temporary directory (its own cache, ``use_cache=False``); the run stage and
    ``render(staging_dir)`` (the report) timed apart. Returns seconds and the total engine steps."""
    import tempfile

    import pandas as pd

    from cross_checks.sweep import run_sweep
    from cross_checks.sweep.cache import using_cache_dir
    t = {}
    with (tempfile.TemporaryDirectory(prefix="rbcheck-bench-") as tmp,
          using_cache_dir(os.path.join(tmp, "cache"))):   # a cold cache; the user's stays untouched

        def finish(staging):
            t["run"] = time.perf_counter() - t0
            t["steps"] = int(pd.read_csv(os.path.join(staging, "results.csv"),
                                         usecols=["steps"])["steps"].sum())
            if render is not None:
                r0 = time.perf_counter()
                render(staging)
                t["report"] = time.perf_counter() - r0
        t0 = time.perf_counter()
        # Drake's second reference is a cross-check of the references, not engine steps of this sweep
        summary = run_sweep(scenarios, variants, os.path.join(tmp, "out"), jobs=jobs, use_cache=False,
                            progress=False, finish=finish, second_reference=False)
    return {"run_s": t["run"], "report_s": t.get("report", 0.0), "steps": t["steps"],
            "runs": summary["run"]["runs"], "s_in_simulate": summary["run"]["cpu_s_in_runs"]}


def sweep_floor(quick: bool, repeats: int, render=None, bare_step_us: float | None = None) -> dict:
    """The cold sweep (catalog, or QUICK_SCENARIOS) against its floor; see the module docstring.
    ``render(results_dir)`` draws the report (the CLI passes ``reports.render``; None: no report)."""
    from cross_checks.core.files import usable_cores
    from cross_checks.engines import all_variants
    from cross_checks.scenario import catalog_names, load_scenario
    names = [n for n in catalog_names() if not quick or n in QUICK_SCENARIOS]
    scenarios = [load_scenario(n) for n in names]
    variants = [v.name for v in all_variants() if v.available and v.engine in SWEEP_ENGINES]
    cores = usable_cores()
    runs = [_sweep_once(scenarios, variants, cores, render) for _ in range(repeats)]
    bare = bare_step_us if bare_step_us is not None else mujoco_bare_step_us(100_000, 5)["median"]
    floor_s = runs[0]["steps"] * bare * 1e-6 / cores
    return {
        "scenarios": names, "variants": variants, "cores": cores, "engine_steps": runs[0]["steps"],
        "runs": runs[0]["runs"], "bare_mj_step_us": bare, "floor_s": floor_s,
        "run_s": stats([r["run_s"] for r in runs]), "report_s": stats([r["report_s"] for r in runs]),
        "total_s": stats([r["run_s"] + r["report_s"] for r in runs]),
        "s_in_simulate": stats([r["s_in_simulate"] for r in runs]),
        "report_included": render is not None,
    }


def run_bench(quick: bool = False, repeats: int = 3, render=None, sweep: bool = True) -> dict:
    """All measurements of one run (see the module docstring); ``quick`` uses fewer bodies and steps and
    a smaller sweep. ``render`` draws the sweep's report (timed as its own stage); ``sweep=False`` skips
    the sweep."""
    import mujoco

    from cross_checks.engines import pybullet_engine  # imports pybullet with its stderr banner silenced
    # one N for every row: a row compares engines on the same work
    n = 200 if quick else 1000
    steps = 20 if quick else 100
    m = {
        "reference_course_body_steps_per_s": reference_batched(n, steps, "course", repeats),
        "reference_expmap_gyro_body_steps_per_s": reference_batched(n, steps, "expmap_gyro", repeats),
        "mujoco_multibody_body_steps_per_s": mujoco_multibody(n, steps, repeats),
        "mujoco_rollout_body_steps_per_s": mujoco_rollout(n, steps, repeats),
        "pybullet_body_steps_per_s": pybullet_bodies(n, OWN_STEPS["pybullet"](steps), repeats),
        "reference_single_us_per_step": reference_single_us(500 if quick else 2000, repeats),
        "mujoco_single_us_per_step": mujoco_single_us(5000 if quick else 20000, repeats),
        "mujoco_bare_step_us": mujoco_bare_step_us(20_000 if quick else 100_000, max(repeats, 5)),
    }
    r = {
        "quick": quick, "repeats": repeats, "n_bodies": n, "n_steps": steps,
        "versions": {"mujoco": mujoco.__version__, "pybullet": pybullet_engine.version(),
                     "numpy": np.__version__, "python": platform.python_version()},
        "cpu_count": os.cpu_count(),
        "load_average": list(os.getloadavg()) if hasattr(os, "getloadavg") else None,
        "measurements": m,
        **{k: v["median"] for k, v in m.items()},
    }
    # the sweep before any adapter row: it forks its workers, which must not inherit a running JAX or Warp
    sw = sweep_floor(quick, repeats, render, r["mujoco_bare_step_us"]) if sweep else None
    from cross_checks.engines import mujoco_engine
    # 5000 steps in both modes: a run's set-up (model compile, simulator) is part of its cost per step
    m["mujoco_adapter_single_us_per_step"] = adapter_single_us(mujoco_engine, "euler", 5000, repeats)
    drake, drake_const = drake_single_us(5000, repeats)
    for k, st in (("drake_single_us_per_step", drake), ("drake_constant_force_us_per_step", drake_const)):
        if st is not None:
            m[k] = st
        r[k] = None if st is None else st["median"]
    r["mujoco_adapter_single_us_per_step"] = m["mujoco_adapter_single_us_per_step"]["median"]
    # every engine's own batched run and its simulate_many at the same N, timed alternately (after the sweep:
    # the JAX and Warp ones start their runtime in this process); an engine without an own run here is
    # measured through its adapter alone and says why
    # the CPU engines' rows first: a JAX or Warp runtime started in this process (its worker threads, its
    # memory) must not weigh on them
    batching = sorted(batching_variants(), key=lambda v: v.split(":", 1)[0] not in CPU_ENGINES)
    r["batched"], own_m, r["own_batched_not_measured"] = batched_rows(
        ["mujoco:euler", "pybullet:multibody", *batching], n, steps, repeats)
    m.update(own_m)
    # the throughput table's simulate_many rows: the batched rows' own figures, or measured alone
    r["batched_adapters"] = {}
    for v in ["mujoco:euler", *batching]:
        if f"adapter_batched[{v}]" not in m:
            m[f"adapter_batched[{v}]"] = adapter_batched(v, n, steps, repeats)
        r["batched_adapters"][v] = m[f"adapter_batched[{v}]"]["median"]
    # the engines' own cost against the cost through rbcheck (its loop, forces and recording)
    r["overhead"] = overhead_rows(1000 if quick else 5000, repeats)
    r["versions"]["drake"] = _drake_version()
    r["reference_batched_body_steps_per_s"] = max(r["reference_course_body_steps_per_s"],
                                                  r["reference_expmap_gyro_body_steps_per_s"])
    r["mujoco_best_body_steps_per_s"] = max(r["mujoco_multibody_body_steps_per_s"],
                                            r["mujoco_rollout_body_steps_per_s"])
    r["ratio_reference_batched_vs_mujoco_best"] = (r["reference_batched_body_steps_per_s"]
                                                   / r["mujoco_best_body_steps_per_s"])
    r["ratio_reference_single_vs_mj_step"] = (r["reference_single_us_per_step"]
                                              / r["mujoco_single_us_per_step"])
    r["targets"] = {
        "reference_batched >= 3x mujoco_best": r["ratio_reference_batched_vs_mujoco_best"] >= 3.0,
        "reference_single <= 5x mj_step": r["ratio_reference_single_vs_mj_step"] <= 5.0,
    }
    r["targets"].update(overhead_targets(r["overhead"], r["batched"], r["mujoco_single_us_per_step"]))
    if sw is not None:
        r["sweep"] = sw
        r["sweep_floor_ratio"] = sw["total_s"]["median"] / sw["floor_s"]
        r["sweep_run_floor_ratio"] = sw["run_s"]["median"] / sw["floor_s"]
        r["targets"]["sweep (run + report) <= 8x its floor"] = r["sweep_floor_ratio"] <= 8.0
    return r


#: The CPU engines whose single-run overhead the bench holds to its target (the compiled engines' rollouts
#: are one call, their host time the compilation's and the callbacks').
CPU_ENGINES = ("mujoco", "pybullet", "drake", "dart", "rapier", "physx")


def rbcheck_own_us(row: dict):
    """rbcheck's own time per step in an ``overhead`` row: the cost through rbcheck less the engine's own
    minimal loop of the same steps (which reaches the same final state bit for bit: test_bench.py), i.e.
    everything a run through rbcheck does beyond what a user recording the trajectory in the engine's own
    API must; None for an engine without an own loop here."""
    if row.get("rbcheck_own_us_per_step") is not None:   # the median of the rounds' differences
        return row["rbcheck_own_us_per_step"]
    o = row.get("own_loop_us_per_step")
    return None if o is None else row["rbcheck_us_per_step"] - o


def overhead_targets(overhead: list, batched: list, mj_step_loop_us: float) -> dict:
    """The speed targets of rbcheck's own time (docs/speed.md), met or not, from this run's rows: per CPU
    engine, the whole cost per step through rbcheck at most twice the engine's own cost per step (issue 43,
    item 5's formula, ``rbcheck_us_per_step <= 2 x engine_us_per_step``, the engine's own cost being its own
    minimal loop: the same statement as item 4's "rbcheck's own time at most the engine's own"), and
    rbcheck's own time per step (:func:`rbcheck_own_us`) at most the engine's step alone (item 4 read as
    strictly as it can be: the engine's apply and read calls left out of its time); per batched row,
    ``simulate_many`` at least half the engine's own batched throughput; and MuJoCo's time inside its step
    through rbcheck at most 3x a bare Python loop of ``mj_step`` with the same body torque re-applied
    (``mj_step_loop_us``). A row without ``engine_step_us_per_step`` (hand-made, older files) reads its
    ``engine_us_per_step`` as the step."""
    out = {}
    for row in overhead:
        e, w = row["engine_us_per_step"], row["rbcheck_us_per_step"]
        step = row.get("engine_step_us_per_step", e)
        if row["variant"].split(":", 1)[0] in CPU_ENGINES and e:
            out[f"{row['variant']}: through rbcheck <= 2x the engine's own cost per step"] = w <= 2.0 * e
            own = rbcheck_own_us(row)
            if own is not None and step:
                out[f"{row['variant']}: rbcheck's own time per step <= the engine's step alone"] = own <= step
        if row["variant"] == "mujoco:euler" and step:
            out["mujoco:euler: engine_s per step <= 3x a Python loop of mj_step"] = (
                step <= 3.0 * mj_step_loop_us)
    for row in batched:
        if row["engine_body_steps_per_s"]:
            out[f"{row['variant']}: simulate_many >= 0.5x the engine's own batched throughput"] = (
                batched_ratio(row) >= 0.5)
    return out


def batched_ratio(row: dict) -> float:
    """A ``batched`` row's ratio, rbcheck ÷ engine: the median of its interleaved rounds' ratios (``ratio``),
    or, for a row without one, the ratio of its two medians."""
    if row.get("ratio") is not None:
        return row["ratio"]
    return row["rbcheck_body_steps_per_s"] / row["engine_body_steps_per_s"]


def _spread(st: dict, fmt: str = ".3g") -> str:
    return f"[{st['min']:{fmt}}, {st['max']:{fmt}}]"


def _drake_version():
    try:
        from cross_checks.engines.drake_engine import version
        return version()
    except ImportError:
        return None


def format_table(r: dict) -> str:
    m, n = r["measurements"], r["n_bodies"]
    rows = [
        ("reference batched, course", "reference_course_body_steps_per_s"),
        ("reference batched, expmap_gyro", "reference_expmap_gyro_body_steps_per_s"),
        ("MuJoCo, N bodies in one model (mj_step)", "mujoco_multibody_body_steps_per_s"),
        ("MuJoCo, rollout of N single bodies", "mujoco_rollout_body_steps_per_s"),
        ("PyBullet, N bodies incl. state read-back", "pybullet_body_steps_per_s"),
    ]
    rows += [(f"through the adapter, simulate_many: {v}", f"adapter_batched[{v}]")
             for v in r.get("batched_adapters", {})]
    best = r["mujoco_best_body_steps_per_s"]
    out = [f"every row: N = {n} bodies; median of {r['repeats']} repeats, [min, max] beside it"
           + (f"; load average {r['load_average'][0]:.1f} on {r['cpu_count']} cores"
              if r.get("load_average") else ""),
           f"{'measurement':<42} {'body-steps/s':>12} {'[min, max]':>22} {'vs MuJoCo best':>15}"]
    out += [f"{name:<42} {m[k]['median']:>12.3e} {_spread(m[k]):>22} {m[k]['median'] / best:>14.2f}x"
            for name, k in rows]
    out.append("")
    out.append(f"single trajectory: reference:expmap_gyro {r['reference_single_us_per_step']:.2f} us/step "
               f"{_spread(m['reference_single_us_per_step'])}, mj_step with a force "
               f"{r['mujoco_single_us_per_step']:.2f} us/step {_spread(m['mujoco_single_us_per_step'])} "
               f"(ratio {r['ratio_reference_single_vs_mj_step']:.1f}x); bare mj_step "
               f"{r['mujoco_bare_step_us']:.3f} us {_spread(m['mujoco_bare_step_us'])}")
    d = r.get("drake_single_us_per_step")
    out.append("single trajectory through the adapters (every step recorded, body torque applied as "
               f"each adapter does): mujoco:euler {r['mujoco_adapter_single_us_per_step']:.2f} us/step, "
               + (f"drake:semi_explicit_euler {d:.2f} us/step "
                  f"({d / r['mujoco_adapter_single_us_per_step']:.1f}x); Drake with a constant applied "
                  f"force {r['drake_constant_force_us_per_step']:.2f} us/step"
                  if d is not None else "Drake not installed (pip install 'rbcheck[drake]')"))
    if r.get("overhead"):
        head = (f"{'one trajectory, us per step':<36} {'step':>7} {'own loop':>9} {'through rbcheck':>16} "
                f"{'/ own':>7} {'/ step':>7} {'rbcheck own':>12}")
        out += ["", head]
        ratio = (lambda a, b: "" if not b else f"{a / b:.2f}x")
        for row in r["overhead"]:
            w, o = row["rbcheck_us_per_step"], row.get("own_loop_us_per_step")
            e = row.get("engine_step_us_per_step", row["engine_us_per_step"])
            own = rbcheck_own_us(row)
            out.append(f"{row['variant']:<36} {'n/a' if e is None else f'{e:.2f}':>7} "
                       f"{'n/a' if o is None else f'{o:.2f}':>9} {w:>16.2f} {ratio(w, o):>7} "
                       f"{ratio(w, e):>7} {'' if own is None else f'{own:+.2f}':>12}")
        out.append("(step: inside the engine's step only, as rbcheck's run times it; own loop: the engine's "
                   "own minimal loop in its own API, apply + step + read, the same final state: the engine's "
                   "own cost per step; / own: through rbcheck / own loop, the goal <= 2; / step: through "
                   "rbcheck / step; rbcheck own: through rbcheck - own loop, the goal <= step)")
    if r.get("batched"):
        title = f"batched, N = {n}, body-steps/s"
        out += ["", f"{title:<42} {'engine':>10} {'through rbcheck':>16} {'ratio':>7}  engine's own run"]
    for row in r.get("batched", []):
        e, w, v = row["engine_body_steps_per_s"], row["rbcheck_body_steps_per_s"], row["variant"]
        st = m.get(f"own_batched[{v}]", {})
        how = OWN_HOW.get(v.split(":", 1)[0], "")
        if st.get("compile_s") is not None:
            how += f" (compiled in {st['compile_s']:.1f} s, not counted)"
        out.append(f"{v:<42} {'n/a' if e is None else f'{e:.3e}':>10} {w:>16.3e} "
                   f"{'' if not e else f'{batched_ratio(row):.2f}':>7}  {how}")
    if r.get("batched"):
        out.append(f"(a row's two runs timed alternately, {r['repeats']} rounds after a warm-up each; ratio: "
                   "the median of the rounds' through rbcheck / engine, the goal >= 0.5; PyBullet's "
                   f"row {OWN_STEPS['pybullet'](r.get('n_steps', 100))} steps)")
    for v, why in r.get("own_batched_not_measured", {}).items():
        out.append(f"{v}: the engine's own batched run not measured: {why}")
    if "sweep" in r:
        out += ["", *_sweep_lines(r)]
    for name, ok in r["targets"].items():
        out.append(f"target {name}: {'met' if ok else 'NOT met'}")
    return "\n".join(out)


def _sweep_lines(r: dict) -> list:
    sw = r["sweep"]
    what = "the catalog" if len(sw["scenarios"]) > len(QUICK_SCENARIOS) else ", ".join(sw["scenarios"])
    rep = "report" if sw["report_included"] else "no report drawn"
    return [
        f"cold sweep of {what} x {len(sw['variants'])} variants ({sw['runs']} runs, {sw['engine_steps']:,} "
        f"engine steps) on {sw['cores']} cores, median of {sw['run_s']['repeats']}:",
        f"  floor = steps x bare mj_step / cores = {sw['engine_steps']:,} x {sw['bare_mj_step_us']:.3f} us / "
        f"{sw['cores']} = {sw['floor_s']:.2f} s",
        "  run stage (references without Drake's second one, runs, metrics, results "
        f"files) {sw['run_s']['median']:.1f} s {_spread(sw['run_s'], '.1f')}; inside the "
        f"engines' simulate {sw['s_in_simulate']['median']:.1f} s summed over workers",
        f"  {rep} {sw['report_s']['median']:.1f} s {_spread(sw['report_s'], '.1f')}",
        f"  sweep / floor = {r['sweep_floor_ratio']:.1f}x "
        f"(run stage alone {r['sweep_run_floor_ratio']:.1f}x)",
    ]


def main(quick: bool = False, json_path: str | None = None, extra=None, *, repeats: int = 3, render=None,
         sweep: bool = True) -> int:
    """``rbcheck bench``: measure, print the table, write ``json_path`` (checked writable by the CLI first).
    ``extra``: {key: (measure(quick) -> dict, format(dict) -> str)} of measurements from layers bench may
    not import (the fuzz's cases/s, passed in by the cli), run in this same process and written under key.
    ``render(results_dir)``: the report of the sweep against its floor (also passed in by the cli)."""
    r = run_bench(quick, repeats, render, sweep)
    print(format_table(r))
    for key, (measure, fmt) in (extra or {}).items():
        r[key] = measure(quick)
        print()
        print(fmt(r[key]))
    if json_path:
        from cross_checks.core.files import atomic_write_text
        atomic_write_text(json_path, json.dumps(r, indent=2, sort_keys=True) + "\n")
    return 0
