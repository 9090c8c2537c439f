"""How long ``rbcheck check`` takes on a 10 000-row file, as a ratio against producing the same
trajectory with MuJoCo in the same run (``python -m benchmarks.check_bench [--json FILE]``).

Two files of 10 001 rows: tumbling_box at Δt = 1e-3 s (closed-form reference) and applied_torque at
Δt = 2e-4 s (DOP853 ground truth), both written by MuJoCo Euler through the engine registry. For each:
the MuJoCo run (best of 3), reading the CSV, and the whole check (best of 3; one-step defects, every
reference variant, conserved quantities, the free-running comparison with the scenario's growth).
The target is a few seconds per file; the ratio says what that costs next to simulating it.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import tempfile
import time

CASES = (("tumbling_box", 1e-3), ("applied_torque", 2e-4))


def _best(fn, repeats=3):
    best, out = float("inf"), None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def measure(scenario_name: str, dt: float) -> dict:
    from cross_checks.core.trajectory import Trajectory
    from cross_checks.engines import run_variant
    from cross_checks.gates.check import check_trajectory
    from cross_checks.scenario import load_scenario

    sc = load_scenario(scenario_name)
    mujoco_s, traj = _best(lambda: run_variant(sc, "mujoco:euler", dt))
    with tempfile.TemporaryDirectory() as d:
        path = os.path.join(d, "mujoco.csv")
        traj.write(path)
        read_s, read = _best(lambda: Trajectory.read(path, require=()))
        check_s, res = _best(lambda: check_trajectory(read, sc, path))
    return {"scenario": scenario_name, "dt_s": dt, "rows": len(traj.t_s), "mujoco_run_s": mujoco_s,
            "read_csv_s": read_s, "check_s": check_s, "check_over_mujoco": check_s / mujoco_s,
            "verdict": ("PASS: " if res.passed else "FAIL: ") + res.verdict}


def main(json_path: str | None = None) -> int:
    import cross_checks.gates.check  # noqa: F401 - imports are not part of the measurement
    rows = [measure(name, dt) for name, dt in CASES]
    print(f"{'scenario':<16}{'rows':>7}{'MuJoCo run (s)':>16}{'read CSV (s)':>14}{'check (s)':>11}"
          f"{'check / MuJoCo':>16}")
    for r in rows:
        print(f"{r['scenario']:<16}{r['rows']:>7}{r['mujoco_run_s']:>16.3f}{r['read_csv_s']:>14.3f}"
              f"{r['check_s']:>11.2f}{r['check_over_mujoco']:>16.1f}")
        print(f"  {r['verdict'][:110]}")
    if json_path:
        with open(json_path, "w", encoding="utf-8") as fh:
            json.dump({"python": platform.python_version(), "machine": platform.machine(), "cases": rows},
                      fh, indent=2)
    return 0


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--json", metavar="FILE")
    raise SystemExit(main(p.parse_args().json))
