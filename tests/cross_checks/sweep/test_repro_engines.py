"""cross_checks.sweep.repro for Drake, MuJoCo Warp and jaxsim: a reproducer of each imports only its engine
and NumPy, runs with rbcheck unimportable, and decides as the sweep does — an order claim where the sweep
measures the declared order exits 0, a long run the sweep finds diverged or drifting exits 1 (test_repro.py:
the claims, MuJoCo's and Rapier's scripts)."""
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from cross_checks.core import tolerances as tol
from cross_checks.scenario import load_scenario
from cross_checks.sweep.repro import file_name, reproducer, write_reproducer
from tests.cross_checks.sweep.test_repro import BLOCKED, RBCHECK, _imports

BASELINE = Path(__file__).resolve().parents[3] / "baselines" / "default" / "summary.json"
#: the modules a script of each engine may import
ENGINE_MODULES = {"drake": {"pydrake"}, "mujoco_warp": {"mujoco", "mujoco_warp", "warp"},
                  "jaxsim": {"jax", "jaxsim", "dataclasses"}}
#: the distribution each script's first line names first
FIRST_DIST = {"drake": "drake", "mujoco_warp": "mujoco-warp", "jaxsim": "jaxsim"}


def _run_alone(path, tmp_path, engine):
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONSTARTUP")}
    if engine == "mujoco_warp":   # Warp's kernels compiled once: rbcheck's kernel cache (Warp's own option)
        from cross_checks.core.files import kernel_cache_dir
        env["WARP_CACHE_PATH"] = str(kernel_cache_dir("mujoco_warp"))
    return subprocess.run([sys.executable, "-c", BLOCKED, str(path)], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=1200)


def _sweep_order_defect(variant, scenario, quantity) -> bool:
    """What the sweep decided (the committed baseline, baselines/default/summary.json): a contradicted order,
    or an order the variant's traits expect below its declared one (repro.findings_claims' order claims)."""
    summary = json.loads(BASELINE.read_text())
    rec = next(r for r in summary["convergence"]
               if (r["engine"], r["scenario"], r["quantity"]) == (variant, scenario, quantity))
    declared = next(v["declared_order"] for v in summary["variants"] if v["name"] == variant)
    return rec["matches_expectation"] is False or (rec["expected_verdict"] == "converges"
                                                   and rec["expected_order"] < declared - tol.SWEEP_ORDER_TOL)


def _sweep_long_run(variant, scenario):
    """The sweep's long-run row of ``variant`` on ``scenario`` (its stage, run here, judged as it judges)."""
    from cross_checks.engines import resolve
    from cross_checks.sweep.long_runs import judged_rows, run_long_group
    variant = resolve(variant)   # as the sweep hands its stages a resolved variant
    sc = load_scenario(scenario)
    recs = run_long_group(variant, [sc], None, False, None)
    rows, _ = judged_rows({(scenario, variant): recs[0]}, [sc], [variant])
    return rows[0]


def _check_script(variant, scenario, claim, holds, r, tmp_path):
    engine = variant.split(":")[0]
    assert r.holds is holds, r.output
    assert _imports(r.text) <= {"numpy", "sys", "importlib", "platform", *ENGINE_MODULES[engine]}
    for name in RBCHECK[:3]:
        assert f"import {name}" not in r.text and f"from {name}" not in r.text
    path = write_reproducer(r, tmp_path / file_name(variant, scenario, " ".join(claim)))
    done = _run_alone(path, tmp_path, engine)
    assert done.returncode == int(holds), done.stdout + done.stderr
    lines = done.stdout.strip().splitlines()
    assert lines[-1] == r.summary   # the same numbers without rbcheck as in it
    assert lines[-1].endswith("DEFECT" if holds else "no defect")
    assert lines[0].startswith(FIRST_DIST[engine] + " ") and "numpy" in lines[0] and "Python" in lines[0]
    return lines


@pytest.mark.parametrize("variant,module", [
    ("drake:runge_kutta3", "pydrake"),       # Drake's RK3: order 3 as declared
    ("mujoco_warp:euler", "mujoco_warp"),    # mujoco_warp's Euler (float32): order 1 as declared
    pytest.param("jaxsim:rk4", "jaxsim", marks=pytest.mark.slow),   # order 4 as declared (JAX compiles twice)
])
def test_an_order_claim_the_sweep_finds_as_declared_exits_0_without_rbcheck(variant, module, tmp_path):
    pytest.importorskip(module)
    assert not _sweep_order_defect(variant, "tennis_racket", "orientation")
    r = reproducer(variant, load_scenario("tennis_racket"), ["order", "orientation"])
    lines = _check_script(variant, "tennis_racket", ["order", "orientation"], False, r, tmp_path)
    declared = float(re.search(r"expected (\S+) \(defect", lines[-1]).group(1))
    measured = float(re.search(r"measured ([-0-9.]+)", lines[-1]).group(1))
    # a measured order (not "at round-off") at or above the declared one (jaxsim's RK4: 4.71 on this ladder)
    assert measured >= declared - tol.SWEEP_ORDER_TOL


def test_drakes_semi_explicit_euler_diverges_on_the_major_axis_spin_where_the_sweep_says_so(tmp_path):
    pytest.importorskip("pydrake")
    variant, scenario = "drake:semi_explicit_euler", "long_major_axis_spin"
    row = _sweep_long_run(variant, scenario)
    assert row["status"] == "diverged"   # an explicit gyroscopic step at Δt = 0.05 s (as mujoco:euler)
    r = reproducer(variant, load_scenario(scenario), ["drift"])
    lines = _check_script(variant, scenario, ["drift"], True, r, tmp_path)
    t = float(re.search(r"diverged at t = (\S+) s", lines[-1]).group(1))
    assert t == pytest.approx(row["diverged_at_s"], rel=1e-3)   # the script's "%.4g" of the same step


@pytest.mark.slow   # ~2 min: 62 832 Warp steps, twice
def test_mujoco_warps_implicit_turns_the_long_tennis_racket_as_the_sweep_finds(tmp_path):
    pytest.importorskip("mujoco_warp")
    variant, scenario = "mujoco_warp:implicit", "long_tennis_racket"
    row = _sweep_long_run(variant, scenario)
    assert row["finding"]    # MuJoCo's implicit family: the tumble becomes a major-axis spin (in float32 too)
    r = reproducer(variant, load_scenario(scenario), ["drift"])
    _check_script(variant, scenario, ["drift"], True, r, tmp_path)
