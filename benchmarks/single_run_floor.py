"""The single-run floor of PyBullet, DART and PhysX: what one recorded trajectory must cost in each engine's
own Python API, beside what it costs through rbcheck (issue 43, point 4; docs/speed.md, "The single-run
floor").

    python benchmarks/single_run_floor.py [--steps N] [--repeats R] [--json FILE]

For the benchmark's body (cross_checks.bench: I = diag(1, 2, 3) kg m², gravity, a torque fixed in body
axes, h = 1 ms), built by each adapter's own model builder, CPU microseconds per step of:

* **step alone**: the engine's step call, bound once, in a bare loop (nothing applied, nothing read);
* **floor**: the engine's own calls that any driver recording every step must make, bound once, with nothing
  else in the loop:
  - PyBullet: ``applyExternalTorque(LINK_FRAME)`` (Bullet clears forces after every step),
    ``stepSimulation``, ``getBasePositionAndOrientation``, ``getBaseVelocity`` (no call returns both);
  - DART: ``World.step(False)`` with the body torque set once before the loop (kept: World::step's
    resetCommand), ``getPositions``, ``getVelocities`` (no call returns both);
  - PhysX: ``pack()`` (the state, and the attitude the torque needs), ``add_force_torque`` (PhysX takes
    world torques only; turning the body torque by the attitude is the driver's arithmetic, left out: a
    floor below any real driver), ``PhysxCpuSystem.step``;
* **through rbcheck**: the adapter's ``simulate`` of the same run (the host loop, the forces, every state
  recorded and checked), whole; beside it the run's own ``engine_s`` per step (wall time inside the step,
  what ``rbcheck bench`` calls the engine's cost).

CPU time of this process (``time.process_time``), not wall time: other jobs on a shared machine then
inflate the figures far less. Each repeat measures the three in turn; the table shows medians, and the
ratios the single-run goal reads (``through rbcheck ≤ 2 × step alone``) and what no driver can go below
(``floor ÷ step``).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from cross_checks import bench  # noqa: E402
from cross_checks.engines import get_adapter  # noqa: E402
from cross_checks.engines.base import RunRequest  # noqa: E402

VARIANTS = ("pybullet:multibody", "dart:semi_implicit_euler", "physx:tgs")


def _cpu_us(fn, n_steps: int) -> float:
    t0 = time.process_time()
    fn()
    return (time.process_time() - t0) / n_steps * 1e6


def _world(name: str):
    engine, variant = name.split(":", 1)
    sc = bench._bench_scenario()
    world = get_adapter(engine).build([RunRequest(sc, bench.H, 1)], variant, bench.H)
    world.set_state(sc.problem.initial_packed()[None])
    return world, sc.problem.initial_packed()[None]


def _pybullet(world, n):
    import pybullet as p
    b, c, tau = world.bodies[0], world.c, bench.TORQUE_B.tolist()
    step, apply, frame = p.stepSimulation, p.applyExternalTorque, p.LINK_FRAME
    pose, vel = p.getBasePositionAndOrientation, p.getBaseVelocity

    def alone():
        for _ in range(n):
            step(c)

    def floor():
        for _ in range(n):
            apply(b, -1, tau, frame, c)
            step(c)
            pose(b, c)
            vel(b, c)
    return alone, floor


def _dart(world, n):
    body = world.bodies[0]
    step, node = body.world.step, body.node
    pos, vel = body.skeleton.getPositions, body.skeleton.getVelocities

    def alone():
        for _ in range(n):
            step(False)

    def floor():
        node.setExtTorque(bench.TORQUE_B, True)
        for _ in range(n):
            step(False)
            pos()
            vel()
    return alone, floor


def _physx(world, n):
    step, pack, add = world.system.step, world.system.pack, world.comps[0].add_force_torque
    zero, tau = [0.0, 0.0, 0.0], bench.TORQUE_B.tolist()

    def alone():
        for _ in range(n):
            step()

    def floor():
        for _ in range(n):
            pack()
            add(zero, tau)
            step()
    return alone, floor


CALLS = {"pybullet": _pybullet, "dart": _dart, "physx": _physx}


def measure(name: str, n_steps: int, repeats: int) -> dict:
    engine, variant = name.split(":", 1)
    adapter = get_adapter(engine)
    sc = bench._bench_scenario()
    adapter.simulate(sc, variant, bench.H, 50)   # first model build, imports
    world, y0 = _world(name)
    alone, floor = CALLS[engine](world, n_steps)
    rows = {"step": [], "floor": [], "rbcheck": [], "engine_s": []}
    try:
        for _ in range(repeats):
            world.set_state(y0)
            rows["step"].append(_cpu_us(alone, n_steps))
            world.set_state(y0)
            rows["floor"].append(_cpu_us(floor, n_steps))
            t0 = time.process_time()
            run = adapter.simulate(sc, variant, bench.H, n_steps)
            rows["rbcheck"].append((time.process_time() - t0) / n_steps * 1e6)
            rows["engine_s"].append(run.engine_s / n_steps * 1e6)
    finally:
        world.close()
    med = {k: statistics.median(v) for k, v in rows.items()}
    return {"variant": name, "step_us": med["step"], "floor_us": med["floor"], "rbcheck_us": med["rbcheck"],
            "engine_s_us": med["engine_s"], "floor_over_step": med["floor"] / med["step"],
            "rbcheck_over_step": med["rbcheck"] / med["step"],
            "rbcheck_over_floor": med["rbcheck"] / med["floor"]}


def _versions() -> str:
    from importlib.metadata import PackageNotFoundError, version
    out = []
    for dist in ("pybullet", "dartpy", "sapien", "numpy"):
        try:
            out.append(f"{dist} {version(dist)}")
        except PackageNotFoundError:
            pass
    return ", ".join(out) + f", Python {platform.python_version()}"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    ap.add_argument("--steps", type=int, default=20000, help="steps per measurement (default 20000)")
    ap.add_argument("--repeats", type=int, default=5, help="repeats; the table shows medians (default 5)")
    ap.add_argument("--json", help="also write the rows to this file")
    a = ap.parse_args(argv)
    load = os.getloadavg()[0]
    rows = []
    for name in VARIANTS:
        engine = name.split(":", 1)[0]
        try:
            get_adapter(engine).version()
        except Exception as exc:  # noqa: BLE001 - an engine not installed: no row, said why
            print(f"{name}: not measured ({type(exc).__name__}: {exc})")
            continue
        rows.append(measure(name, a.steps, a.repeats))
    print(f"one trajectory of the bench's body, {a.steps} steps, CPU us/step, median of {a.repeats}; "
          f"load average {load:.1f} at the start on {os.cpu_count()} cores; {_versions()}")
    print(f"{'variant':28s} {'step alone':>10s} {'floor':>8s} {'rbcheck':>8s} {'(engine_s)':>10s} "
          f"{'floor/step':>10s} {'rbcheck/step':>12s} {'rbcheck/floor':>13s}")
    for r in rows:
        print(f"{r['variant']:28s} {r['step_us']:10.2f} {r['floor_us']:8.2f} {r['rbcheck_us']:8.2f} "
              f"{r['engine_s_us']:10.2f} {r['floor_over_step']:10.2f} {r['rbcheck_over_step']:12.2f} "
              f"{r['rbcheck_over_floor']:13.2f}")
    if a.json:
        Path(a.json).write_text(json.dumps({"load_average": load, "steps": a.steps, "repeats": a.repeats,
                                            "versions": _versions(), "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
