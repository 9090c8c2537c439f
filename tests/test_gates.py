"""Regression gates: a fresh sweep judged by cross_checks/analysis/expectations.py and
against the committed baseline.

The default run sweeps FAST_SUBSET (every available variant, each scenario's full dt ladder); the
whole catalog runs under ``-m slow``. Every number comes from cross_checks.analysis.expectations /
cross_checks.core.tolerances, each with its derivation there.
"""
import json
from pathlib import Path

import pandas as pd
import pytest

from cross_checks.analysis.expectations import EQUIVALENT_PAIRS, energy_drift_bound
from cross_checks.core.tolerances import SAME_SCHEME_REL
from cross_checks.engines import resolve
from cross_checks.gates.compare import compare_dirs, to_text
from cross_checks.scenario import catalog_names, load_scenario
from cross_checks.sweep import run_sweep
from tests.helpers.sweeps import built_once, gated_variants, private_cache

ROOT = Path(__file__).resolve().parents[1]
BASELINE = ROOT / "baselines" / "default"
#: Scenarios of the default gate: every force type (gravity, drag-free decay, spring, body torque,
#: off-COM force), a full inertia tensor, and the two asymmetric tumbling bodies the course gets wrong.
FAST_SUBSET = ["projectile", "velocity_decay", "spring_oscillator",
               "applied_torque", "particle_body", "tennis_racket"]
ASYMMETRIC_TUMBLING = ["tennis_racket", "particle_body", "tumbling_box"]


def _sweep(tmp_path_factory, names, tag):
    """One sweep of ``names`` with every available variant per test run (the xdist workers share it).

    In this process under pytest-xdist (the README's ``-n 2``: the other worker has the other core, and
    test_fresh_sweep_matches_the_committed_baseline, marked ``first``, starts the build at once, so no worker
    waits for it), else in 2 processes. Each pool worker starts its engines cold, which costs the 2-process
    sweep a third more CPU (measured: 73 s in one process, 104 s in two); the results are the same, row
    for row (tests/cross_checks/sweep/test_run.py::test_parallel_and_cached_sweeps_give_the_same_results)."""
    import os
    jobs = 1 if os.environ.get("PYTEST_XDIST_WORKER") else 2

    def build(folder):
        with private_cache(folder / "cache"):
            run_sweep([load_scenario(n) for n in names], gated_variants(), folder / "results", jobs=jobs,
                      use_cache=False, progress=False)
    out = built_once(tmp_path_factory, f"gates-{tag}", build) / "results"
    return out, pd.read_csv(out / "results.csv"), json.loads((out / "summary.json").read_text())


@pytest.fixture(scope="session")
def fast(tmp_path_factory):
    return _sweep(tmp_path_factory, FAST_SUBSET, "fast")


@pytest.fixture(scope="session")
def full(tmp_path_factory):
    return _sweep(tmp_path_factory, catalog_names(), "full")


def _check_expectations(summary, scenario):
    recs = [r for r in summary["convergence"] if r["scenario"] == scenario]
    assert recs, f"no convergence records for {scenario}"
    wrong = [f"{r['engine']} {r['quantity']}: {r['assessment']} ({r['reason']})" for r in recs
             if r["matches_expectation"] is False]
    assert not wrong, "\n".join(wrong)


def _check_energy_bounds(results, scenario):
    sc = load_scenario(scenario)
    over = []
    for _, r in results[(results["scenario"] == scenario) & (results["status"] == "ok")].iterrows():
        bound = energy_drift_bound(sc, resolve(r["engine"]), float(r["dt"]))
        if bound is not None and not r["energy_drift_max"] <= bound:
            over.append(f"{r['engine']} dt={r['dt']:g}: {r['energy_drift_max']:.3g} > {bound:.3g}")
    assert not over, "\n".join(over)


@pytest.mark.parametrize("scenario", FAST_SUBSET)
def test_every_verdict_matches_its_expectation(fast, scenario):
    _check_expectations(fast[2], scenario)


@pytest.mark.parametrize("scenario", FAST_SUBSET)
def test_energy_drift_within_its_bound(fast, scenario):
    _check_energy_bounds(fast[1], scenario)


@pytest.mark.parametrize("a, b", [(p[0], p[1]) for p in EQUIVALENT_PAIRS])
def test_same_scheme_pairs_agree_on_every_scenario(fast, a, b):
    recs = [r for r in fast[2]["agreement"] if (r["a"], r["b"]) == (a, b)]
    if not recs:
        pytest.skip(f"{a} or {b} not swept here (unavailable, or not an engine of the baseline)")
    assert {r["scenario"] for r in recs} == set(FAST_SUBSET)
    bad = [f"{r['scenario']}: {r['max_rel']:.3g}" for r in recs if not r["max_rel"] <= SAME_SCHEME_REL]
    assert not bad, bad


@pytest.mark.parametrize("scenario", [s for s in ASYMMETRIC_TUMBLING if s in FAST_SUBSET])
def test_course_does_not_converge_on_asymmetric_tumbling_bodies(fast, scenario):
    verdict = {(r["engine"], r["quantity"]): r["verdict"]
               for r in fast[2]["convergence"] if r["scenario"] == scenario}
    assert verdict[("reference:course", "orientation")] == "does_not_converge"
    assert verdict[("reference:course_gyro", "orientation")] == "converges"
    assert verdict[("reference:expmap_gyro", "orientation")] == "converges"


@pytest.mark.first   # the sweep every test here reads: started first (tests/conftest.py)
def test_fresh_sweep_matches_the_committed_baseline(fast):
    assert (BASELINE / "results.csv").is_file(), (
        f"{BASELINE} missing: see baselines/README.md to regenerate it")
    c = compare_dirs(BASELINE, fast[0])
    assert c.matched_rows == len(fast[1]), "every row of the fresh subset must exist in the baseline"
    assert c.exit_code(allow_missing=True) == 0, to_text(c, allow_missing=True)


#: What decides a result's last bits: the versions of everything that computes it and the numerical stack
#: (CPU architecture, BLAS kernels, the CPU numba compiles for). Not the kernel build or the host name.
EXACT_KEYS = ("rbcheck", "numpy", "scipy", "mujoco", "pybullet", "drake", "python", "numerics")


def exactness_mismatch(made: dict, here: dict) -> str:
    """"" when results made with provenance ``made`` must be reproduced bit for bit with ``here``, else
    one line saying what differs."""
    if not made.get("numerics"):
        return "the baseline records no numerical stack (made before rbcheck recorded it): regenerate it"
    diff = [f"{k} {made.get(k) or '-'} (here {here.get(k) or '-'})"
            for k in EXACT_KEYS if made.get(k) != here.get(k)]
    return "numerical stack differs from the baseline's: " + "; ".join(diff) if diff else ""


def test_exactness_is_claimed_on_the_numerical_stack_not_the_machine_name():
    made = {k: f"v-{k}" for k in EXACT_KEYS} | {"platform": "Linux-6.18.44-fc-v595",
                                                "machine": "x86_64, EPYC"}
    assert exactness_mismatch(made, made | {"platform": "Linux-6.18.44-fc-v669", "machine": "other"}) == ""
    assert "numpy v-numpy (here 2.5)" in exactness_mismatch(made, made | {"numpy": "2.5"})
    assert exactness_mismatch({k: v for k, v in made.items() if k != "numerics"},
                              made).startswith("the baseline")


def test_fresh_sweep_is_bit_identical_to_the_baseline_where_it_was_made(fast, tmp_path):
    """Results are reproduced exactly, not only within compare's tolerance, wherever the numerical stack
    matches the baseline's: every cell of every row (timing aside) and every verdict record."""
    import csv

    from cross_checks.gates.baseline import write_baseline
    made = json.loads((BASELINE / "summary.json").read_text())
    fresh = write_baseline(fast[0], tmp_path / "fresh").summary
    why = exactness_mismatch(made["provenance"], fresh["provenance"])
    if why:
        pytest.skip(f"exactness not claimed here ({why}); the tolerant comparison ran")

    def rows(path):
        with open(path, newline="", encoding="utf-8") as fh:
            return {(r["scenario"], r["engine"], r["dt"]): r for r in csv.DictReader(fh)}
    old, new = rows(BASELINE / "results.csv"), rows(tmp_path / "fresh" / "results.csv")
    assert len(new) == len(fast[1]) and [k for k in new if old.get(k) != new[k]] == []
    swept = set(gated_variants())   # the baseline's JAX engines are CI's to sweep (tests/helpers/sweeps.py)
    for key in ("convergence", "local_convergence", "agreement"):
        in_subset = [r for r in made[key] if r["scenario"] in FAST_SUBSET
                     and ({r["engine"]} if "engine" in r else {r["a"], r["b"]}) <= swept]
        assert sorted(map(json.dumps, fresh[key])) == sorted(map(json.dumps, in_subset)), key


@pytest.mark.slow
@pytest.mark.parametrize("scenario", catalog_names())
def test_full_catalog_matches_expectations_and_bounds(full, scenario):
    _check_expectations(full[2], scenario)
    _check_energy_bounds(full[1], scenario)


@pytest.mark.slow
def test_full_sweep_matches_the_baseline_row_for_row(full):
    c = compare_dirs(BASELINE, full[0])
    assert c.exit_code() == 0, to_text(c)


def test_planted_regression_in_the_baseline_is_caught_and_named(tmp_path):
    import shutil

    from cross_checks.cli import main
    new = tmp_path / "new"
    shutil.copytree(BASELINE, new)
    assert main(["compare", str(BASELINE), str(new)]) == 0  # identical results
    df = pd.read_csv(new / "results.csv")
    i = df.index[(df["scenario"] == "tennis_racket") & (df["engine"] == "mujoco:euler")
                 & (df["dt"] == 0.00125)][0]
    df.loc[i, "orient_err_final"] *= 1.5
    df.to_csv(new / "results.csv", index=False)
    md = tmp_path / "summary.md"
    assert main(["compare", str(BASELINE), str(new), "--markdown", str(md)]) == 1
    text = md.read_text()
    assert "| tennis_racket | mujoco:euler | dt=0.00125 orient_err_final |" in text
    assert text.count("\n| tennis_racket") == 1  # that row and nothing else
