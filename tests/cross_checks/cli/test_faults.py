"""Faults a user meets: a real Ctrl-C mid-sweep, an engine that rejects a model, file permissions."""
import json
import os
import signal
import subprocess
import sys
import time

import pytest

from cross_checks.cli import main
from cross_checks.scenario import load_scenario
from reference_sim.compiled import VARIANT_CODES

TINY = """
name = "{name}"
description = "torque-free asymmetric spin"
duration = 4.0
dt = 0.001
dt_ladder = [0.004, 0.002, 0.001, 0.0005, 0.00025]
[body]
mass = 1.0
inertia = [1.0, 2.0, 3.0]
[initial]
angular_velocity = [0.3, 1.0, 0.2]
"""

#: Mass and inertia below MuJoCo's mjMINVAL (1e-15): valid physics for rbcheck's loader, rejected
#: by MuJoCo's compiler (docs/engine_conventions.md).
FEATHER = """
name = "feather"
description = "a body lighter than MuJoCo accepts"
duration = 0.05
dt = 0.01
dt_ladder = [0.01, 0.005]
[body]
mass = 1e-20
inertia = [1e-20, 1e-20, 1e-20]
[initial]
velocity = [1.0, 0.0, 0.0]
"""


@pytest.mark.first   # one of the longest tests (tests/conftest.py)
def test_real_sigint_keeps_previous_results_and_the_rerun_reuses_finished_runs(tmp_path):
    files = []
    # enough runs of the fast compiled schemes to be still running at the interrupt: 4 scenarios x 16
    # variants x 5 rungs, 320 runs, of which 8 are done when the interrupt comes, then the analysis and the
    # report; the rerun does the rest (1 s of the spin, not 4: a quarter of the steps)
    for i in range(4):
        f = tmp_path / f"spin_{i}.toml"
        f.write_text(TINY.format(name=f"spin_{i}").replace("duration = 4.0", "duration = 1.0"))
        files.append(str(f))
    out, cache = tmp_path / "res", tmp_path / "cache"
    env = {**os.environ, "RBCHECK_CACHE_DIR": str(cache), "MPLBACKEND": "Agg"}
    base = [sys.executable, "-m", "cross_checks.cli", "sweep", "--jobs", "2", "--out", str(out)]
    # the reference's compiled schemes (the interrupt, not the variants, is under test); --engines takes
    # several values: keep it last
    engines = ["--engines", *(f"reference:{v}" for v in VARIANT_CODES)]
    cmd = base + files + engines
    first = subprocess.run(base + [files[0], "--engines", "reference:course"], env=env, capture_output=True,
                           text=True, timeout=300)
    assert first.returncode == 0, first.stderr
    before = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}

    proc = subprocess.Popen(base + ["--no-cache"] + files + engines, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    old = set(cache.rglob("*.npz"))   # the first sweep's: only runs of THIS sweep count below
    deadline = time.time() + 120
    while time.time() < deadline and len(set(cache.rglob("*.npz")) - old) < 8:  # some runs finished, cached
        time.sleep(0.1)
    os.killpg(proc.pid, signal.SIGINT)  # what Ctrl-C in a terminal does: the whole process group
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert len(err.strip().splitlines()) == 1 and "interrupted" in err and "Traceback" not in err
    after = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    assert after == before  # previous results and report intact
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".res")]  # no staging directory left

    rerun = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=600)
    assert rerun.returncode in (0, 1), rerun.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["run"]["cached_runs"] >= 1  # whatever finished before the interrupt is reused


def test_a_body_outside_the_physical_ranges_is_refused_before_any_run(tmp_path, capsys):
    f = tmp_path / "feather.toml"
    f.write_text(FEATHER)
    assert main(["sweep", str(f), "--engines", "mujoco:euler", "--out", str(tmp_path / "res")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "feather.toml: body.mass: the mass 1e-20 kg is outside the range" in err
    assert not (tmp_path / "res").exists()


def test_a_model_mujoco_rejects_is_a_failed_row_with_mujocos_words(tmp_path, capsys):
    """Handed a body below MuJoCo's mjMINVAL (through the Python API: the parser refuses such a file), the
    MuJoCo runs are failed rows with MuJoCo's own words, the sweep goes on and the report says it."""
    pytest.importorskip("mujoco")
    import reports
    from cross_checks.cli.sweep import _gate_failures
    from cross_checks.sweep import run_sweep
    from tests.helpers.scenarios import with_body
    f = tmp_path / "feather.toml"
    f.write_text(FEATHER.replace("1e-20", "1.0"))
    sc = with_body(load_scenario(f), 1e-20, 1e-20)
    out = tmp_path / "res"
    summary = run_sweep([sc], ["mujoco:euler", "reference:course"], out, jobs=1, use_cache=False,
                        progress=False, finish=reports.render)
    # a failed run is reported as a failure of the sweep, after writing everything
    assert _gate_failures(summary)
    import pandas as pd
    df = pd.read_csv(out / "results.csv")
    mj = df[df["engine"] == "mujoco:euler"]
    assert set(mj["status"]) == {"failed"} and mj["message"].str.contains("mjMINVAL").all()
    assert set(df[df["engine"] == "reference:course"]["status"]) == {"ok"}  # the sweep went on
    assert "mjMINVAL" in (out / "index.html").read_text()


def test_written_files_have_the_users_usual_permissions(tmp_path):
    out = tmp_path / "t.csv"
    assert main(["run", "projectile", "--engine", "reference:course", "--out", str(out)]) == 0
    mask = os.umask(0)
    os.umask(mask)
    assert (out.stat().st_mode & 0o777) == (0o666 & ~mask)
    assert (out.with_suffix(".json").stat().st_mode & 0o777) == (0o666 & ~mask)


@pytest.mark.first   # one of the longest tests (tests/conftest.py)
def test_reruns_are_bit_identical_across_engines(tmp_path, isolated_cache):
    pytest.importorskip("mujoco")
    pytest.importorskip("pybullet")
    import csv

    from cross_checks.engines import available_variants
    from cross_checks.scenario import parse_scenario
    from cross_checks.sweep import run_sweep
    from tests.helpers.sweeps import gated_variants
    # 0.5 s on the ladder's three coarsest rungs: every variant's whole pipeline (its steps, reference and
    # metrics); the finer rungs would only repeat the same steps longer
    text = TINY.format(name="spin").replace("duration = 4.0", "duration = 0.5")
    sc = parse_scenario(text.replace("[0.004, 0.002, 0.001, 0.0005, 0.00025]", "[0.004, 0.002, 0.001]"),
                        "spin.toml")
    assert sc.dt_ladder_s == (0.004, 0.002, 0.001)
    texts = []
    # first in a pool of 2 fresh workers (runs land on either, finish in any order), then in this process
    # after the first sweep's runs (an engine's state left over from an earlier run would show here)
    for k, jobs in enumerate((2, 1)):
        out = tmp_path / f"r{k}"
        run_sweep([sc], gated_variants(), out, jobs=jobs, use_cache=False, progress=False)
        with open(out / "results.csv", newline="") as fh:
            rows = [{c: v for c, v in r.items() if c not in ("wall_s", "engine_s", "cached")}
                    for r in csv.DictReader(fh)]
        texts.append(rows)
    assert texts[0] == texts[1]  # every digit of every metric, of every installed variant
    # the optional ones installed here
    optional = ("drake", "dart", "rapier", "physx", "mujoco_warp")
    have = {v.split(":")[0] for v in available_variants()}
    engines = {"reference", "mujoco", "pybullet"} | {e for e in optional if e in have}
    assert {r["engine"].split(":")[0] for r in texts[0]} == engines


def test_same_scheme_pairs_that_both_diverge_agree_on_the_time(tmp_path, isolated_cache):
    pytest.importorskip("mujoco")
    from cross_checks.scenario import parse_scenario
    from cross_checks.sweep import run_sweep
    # docs/engine_conventions.md: MuJoCo Euler diverges on this fast spin at t = 8.65 s;
    # expmap_gyro is the same scheme.
    sc = parse_scenario("""
name = "fast_spin"
duration = 10.0
dt = 0.01
dt_ladder = [0.01, 0.005]
[body]
mass = 1.0
inertia = [1.0, 2.0, 3.0]
[initial]
angular_velocity = [0.1, 20.0, 0.1]
""", "fast.toml")
    summary = run_sweep([sc], ["reference:expmap_gyro", "mujoco:euler"], tmp_path / "r", jobs=1,
                        use_cache=False, progress=False)
    [rec] = summary["agreement"]
    assert rec["agrees"] and rec["note"].startswith("both diverged, at t = 8.6")
