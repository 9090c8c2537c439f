"""The sweep judges a too-low free-running order again on its ladder continued to finer steps: a correct
scheme that is merely pre-asymptotic on the file's ladder passes (with its verdict saying so), a scheme of
the wrong order still fails, and errors that sink into round-off excuse nothing."""
import tomllib

import pytest

from cross_checks.analysis.expectations import Expectation
from cross_checks.analysis.refinement import errors_shrink, refined_ladder_shows_the_order
from cross_checks.cli.sweep import _gate_failures
from cross_checks.fuzz.generate import to_toml
from cross_checks.scenario import parse_scenario
from cross_checks.sweep import refine, run_sweep
from tests.helpers.scenarios import PRE_ASYMPTOTIC_ON_ITS_LADDER
from tests.mutants import MUTANTS

pytestmark = pytest.mark.usefixtures("isolated_cache")

PRE_ASYMPTOTIC = PRE_ASYMPTOTIC_ON_ITS_LADDER   # velocity order 0.52 on its file's ladder, 0.80 → 0.95 below


def _sweep(tmp_path, text, variant):
    summary = run_sweep([parse_scenario(text, "s.toml")], [variant], tmp_path / "out", jobs=1,
                        use_cache=False, progress=False)
    return summary, _gate_failures(summary)


def test_a_correct_scheme_pre_asymptotic_on_the_file_s_ladder_passes_and_says_why(tmp_path):
    summary, fails = _sweep(tmp_path, PRE_ASYMPTOTIC, "reference:course_gyro")
    assert fails == []
    (rec,) = [r for r in summary["convergence"] if r["quantity"] == "velocity"]
    assert rec["verdict"] == "pre_asymptotic" and rec["matches_expectation"] is None
    assert "the ladder continued to Δt = 0.000625 s shows order" in rec["assessment"]
    assert 0.4 < rec["order"] < 0.7   # the file's own fit is kept as measured


def test_without_the_continued_ladder_the_same_file_fails(tmp_path, monkeypatch):
    monkeypatch.setattr(refine, "qualifies", lambda rec: False)
    _, fails = _sweep(tmp_path, PRE_ASYMPTOTIC, "reference:course_gyro")
    assert any("velocity" in f for f in fails), fails


def test_a_scheme_of_the_wrong_order_still_fails_on_the_continued_ladder(tmp_path, monkeypatch):
    calls = []
    real = refine.refined_ladder_shows_the_order
    monkeypatch.setattr(refine, "refined_ladder_shows_the_order", lambda *a: calls.append(a) or real(*a))
    mutant = next(m for m in MUTANTS if m.name == "rk4_wrong_stage_weight")   # order 2 where 4
    mutant.apply(monkeypatch)
    spec = tomllib.loads(PRE_ASYMPTOTIC)
    spec.update(duration=0.2, dt=0.01, dt_ladder=[0.01, 0.005, 0.0025])
    spec["initial"] = {"angular_velocity": [0.3, 1.0, 0.2]}
    spec["forces"] = {"gravity": [0.0, 0.0, -9.81], "torque": [{"torque": [0.0, 0.2, 0.05], "frame": "body"}]}
    summary, fails = _sweep(tmp_path, to_toml(spec), mutant.swept)
    assert calls and fails
    assert any(r["matches_expectation"] is False and r["order"] < 3.0 for r in summary["convergence"])


def test_errors_that_sink_into_round_off_excuse_nothing():
    exp = Expectation(verdict="converges", order=2.0, reason="an order-2 scheme")
    floors = [1e-12] * 4
    at_roundoff = [5e-11, 3e-12, 2e-12, 2e-12]     # the finest original rung resolved, the finer ones not
    shows, fit = refined_ladder_shows_the_order([1e-3, 5e-4, 2.5e-4, 1.25e-4],
                                                at_roundoff, floors, ["ok"] * 4, exp)
    assert not shows, (fit.verdict, fit.order, fit.order_is_lower_bound)
    clean = [4e-6, 1e-6, 2.5e-7, 6.25e-8]
    assert refined_ladder_shows_the_order([1e-3, 5e-4, 2.5e-4, 1.25e-4], clean, floors, ["ok"] * 4, exp)[0]
    first_order = [4e-6, 2e-6, 1e-6, 5e-7]
    assert not refined_ladder_shows_the_order([1e-3, 5e-4, 2.5e-4, 1.25e-4],
                                              first_order, floors, ["ok"] * 4, exp)[0]


def test_only_shrinking_errors_are_judged_again():
    assert errors_shrink([1.0, 0.9, 0.85]) and errors_shrink([1.0, 0.3, 0.4])
    assert errors_shrink([6.38e-7, 6.88e-7, 5.24e-7])   # the fuzz's case 9698: up, then down below the start
    assert not errors_shrink([1.0, 1.0, 1.0]) and not errors_shrink([1.0, 2.0, 1.1])
    assert not errors_shrink([1.0, float("nan"), 0.1])


def test_the_continued_ladder_runs_in_the_sweep_s_workers_not_in_its_own_process(tmp_path, monkeypatch):
    """An engine started in the sweep's process (JAX) would be unusable in the workers it forks next."""
    import os
    pids = tmp_path / "pids"
    real = refine._refined_runs

    def recorded(*args):
        with open(pids, "a") as f:
            f.write(f"{os.getpid()}\n")
        return real(*args)

    monkeypatch.setattr(refine, "_refined_runs", recorded)
    summary = run_sweep([parse_scenario(PRE_ASYMPTOTIC, "s.toml")], ["reference:course_gyro"],
                        tmp_path / "out", jobs=2, use_cache=False, progress=False)
    ran_in = {int(p) for p in pids.read_text().split()}
    assert ran_in and os.getpid() not in ran_in
    (rec,) = [r for r in summary["convergence"] if r["quantity"] == "velocity"]
    assert rec["verdict"] == "pre_asymptotic"    # and its result came back to the judge
