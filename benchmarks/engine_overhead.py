"""Per-run overhead of an engine-file engine: what rbcheck adds around the engine's own runtime.

    python -m benchmarks.engine_overhead [--quick] [--json FILE]

For each step count, the example C engine (examples/c_engine/cbody.c, compiled here; without a C
compiler its stand-alone Python twin) runs the same scenario

* directly: ``subprocess.run`` of its command on a resolved-scenario JSON written beforehand — the
  engine's own runtime (process start, reading the JSON, integrating, writing the CSV);
* through rbcheck: ``ExternalEngine.simulate`` — the same plus the private temporary directory, the
  resolved JSON, the process group and time limit, the folder watch, the shared CSV reader with its
  checks, and the clean-up.

The overhead is the difference of the medians. Its fixed part per run is the overhead of the
shortest run (target: under 30 ms); a least-squares line through all step counts gives the part per
row (reading and checking the engine's CSV: every number goes through the same float() as
`rbcheck check`). For
scale, MuJoCo's Euler runs the same scenario and steps in this process in the same run; the ratios
are overhead / MuJoCo's run and rbcheck's run / the direct run.
"""
from __future__ import annotations

import argparse
import json
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "c_engine"
TARGET_S = 0.030


def _build(folder: Path) -> tuple:
    cc = shutil.which("cc") or shutil.which("gcc") or shutil.which("clang")
    toml = folder / "cbody.toml"
    if cc:
        subprocess.run([cc, "-O2", "-std=c99", "-o", str(folder / "cbody"), str(EXAMPLE / "cbody.c"), "-lm"],
                       check=True)
        shutil.copy(EXAMPLE / "cbody.toml", toml)
        return toml, "C"
    shutil.copy(EXAMPLE / "cbody.py", folder / "cbody.py")
    toml.write_text(f'name = "cbody"\nversion = "1.0"\n[variants.euler]\norder = 1\n'
                    f'command = ["{sys.executable}", "cbody.py", "{{scenario_json}}", "{{out_csv}}"]\n')
    return toml, "Python (no C compiler)"


def _median_time(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def measure(steps_list=(100, 1000, 10000, 40000), repeats: int = 15) -> dict:
    from cross_checks.engines import get_adapter
    from cross_checks.engines.external import load_engine_file
    from cross_checks.scenario import load_scenario
    from cross_checks.scenario.resolved import resolved_json

    sc = load_scenario("tennis_racket")  # torque-free tumble: the engine's own work is the least
    mujoco = get_adapter("mujoco")
    out = {"engine_kind": "", "target_s": TARGET_S, "scenario": sc.name, "rows": []}
    with tempfile.TemporaryDirectory(prefix="rbcheck-bench-") as tmp:
        tmp = Path(tmp)
        (tmp / "engine").mkdir()
        toml, out["engine_kind"] = _build(tmp / "engine")
        engine = load_engine_file(toml)
        for n in steps_list:
            dt = sc.duration_s / n
            (tmp / "s.json").write_text(resolved_json(sc, dt))
            argv = engine.argv("euler", {"scenario_json": str(tmp / "s.json"), "out_csv": str(tmp / "o.csv"),
                                         "dt": repr(dt), "steps": str(n), "duration": repr(sc.duration_s)})
            direct = _median_time(lambda argv=argv: subprocess.run(argv, cwd=engine.folder, check=True),
                                  repeats)
            through = _median_time(lambda dt=dt, n=n: engine.simulate(sc, "euler", dt, n), repeats)
            mj = _median_time(lambda dt=dt, n=n: mujoco.simulate(sc, "euler", dt, n), repeats)
            out["rows"].append({"steps": n, "direct_s": direct, "rbcheck_s": through,
                                "overhead_s": through - direct, "mujoco_euler_s": mj,
                                "overhead_over_mujoco": (through - direct) / mj,
                                "rbcheck_over_direct": through / direct})
    import numpy as np
    n = np.array([r["steps"] + 1 for r in out["rows"]], dtype=float)
    o = np.array([r["overhead_s"] for r in out["rows"]])
    per_row = np.polyfit(n, o, 1)[0]
    out["fixed_overhead_s"] = out["rows"][0]["overhead_s"]  # the shortest run: hardly any rows to read
    out["overhead_per_row_s"] = float(per_row)
    return out


def report(res: dict) -> str:
    lines = [f"engine-file overhead: example engine ({res['engine_kind']}) on {res['scenario']}, medians; "
             f"target < {res['target_s'] * 1e3:.0f} ms per run",
             f"{'steps':>7} {'direct':>10} {'rbcheck':>10} {'overhead':>10} {'MuJoCo Euler':>13} "
             f"{'overhead/MuJoCo':>16} {'rbcheck/direct':>15}"]
    for r in res["rows"]:
        lines.append(f"{r['steps']:>7} {r['direct_s'] * 1e3:>8.2f}ms {r['rbcheck_s'] * 1e3:>8.2f}ms "
                     f"{r['overhead_s'] * 1e3:>8.2f}ms {r['mujoco_euler_s'] * 1e3:>11.2f}ms "
                     f"{r['overhead_over_mujoco']:>16.2f} {r['rbcheck_over_direct']:>15.2f}")
    lines.append(f"fixed overhead per run (the {res['rows'][0]['steps']}-step run): "
                 f"{res['fixed_overhead_s'] * 1e3:.2f} ms (target < {res['target_s'] * 1e3:.0f} ms); "
                 "per CSV row (reading and checking the trajectory, least squares over all runs): "
                 f"{res['overhead_per_row_s'] * 1e6:.2f} µs")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.engine_overhead",
                                 description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="fewer step counts and repeats")
    ap.add_argument("--json", metavar="FILE", help="write the measurements as JSON")
    args = ap.parse_args(argv)
    res = measure((100, 1000, 10000), 5) if args.quick else measure()
    print(report(res))
    if args.json:
        Path(args.json).write_text(json.dumps(res, indent=1) + "\n")
    return 0 if res["fixed_overhead_s"] < TARGET_S else 1


if __name__ == "__main__":
    sys.exit(main())
