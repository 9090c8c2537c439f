"""A scenario an engine cannot express (EngineAdapter.expressible) is said, the same way, by every entry
point: the sweep runs nothing for the pair and lists it with the engine's sentence (summary.json
``not_expressible``, one line each on the terminal, a "cannot express" cell and a finding in the report)
and its verdicts stay true; `compare` names the reason when a baseline had rows there; `assert_engine`
refuses to pass a pair it could not check; the fuzz runs nothing and counts it; a direct run is a
NotExpressible error.

The engine: the course's scheme with the gyroscopic term (correct everywhere it runs) that declares it
takes no torque — as brax's spring and positional pipelines take no force but gravity."""
from __future__ import annotations

import json
import re

import numpy as np
import pytest

from cross_checks import engines
from cross_checks.engines import resolve
from cross_checks.engines.base import EngineAdapter, NotExpressible, Variant
from cross_checks.scenario import load_scenario

REASON = "this engine takes no applied torque"


class NoTorqueEngine(EngineAdapter):
    name = "notorque"
    variants = {"euler": Variant(1, "semi-implicit Euler with the gyroscopic term; no applied torque")}

    def version(self) -> str:
        return "1.0"

    def expressible(self, scenario, variant):
        from cross_checks.engines.forces import harness_force_torque
        _, tau = harness_force_torque(scenario, scenario.problem.initial_packed(), scenario.dt_s)
        return REASON if np.any(tau != 0.0) else ""

    def simulate(self, scenario, variant, dt_s, n_steps):
        return engines.get_adapter("reference").simulate(scenario, "course_gyro", dt_s, n_steps)


@pytest.fixture
def notorque():
    engines.reset_registry()
    engines.register_adapter(NoTorqueEngine(), "tests/cross_checks/sweep/test_not_expressible.py")
    yield "notorque:euler"
    engines.reset_registry()


def test_the_pair_is_not_run_and_is_said_everywhere(notorque, tmp_path):
    from cross_checks.cli.sweep import _gate_failures, verdict_count
    from cross_checks.sweep import run_sweep
    scs = [load_scenario("applied_torque"), load_scenario("projectile")]
    assert NoTorqueEngine().expressible(scs[0], "euler") == REASON   # applied_torque has a torque
    assert NoTorqueEngine().expressible(scs[1], "euler") == ""
    summary = run_sweep(scs, [notorque], tmp_path / "r", jobs=1, use_cache=False, progress=False)
    listed = {"scenario": "applied_torque", "engine": notorque, "reason": REASON}
    assert summary["not_expressible"] == [listed]
    rows = (tmp_path / "r" / "results.csv").read_text().splitlines()
    assert not any(",applied_torque," in f",{r}," or r.startswith("applied_torque,") for r in rows[1:])
    assert any(r.startswith("projectile,") for r in rows[1:])
    assert {r["scenario"] for r in summary["convergence"]} == {"projectile"}
    assert not _gate_failures(summary)   # a limit of the engine, said; not a failure
    total, wrong = verdict_count(summary)   # projectile's 4 quantities (and its references' agreement)
    assert total >= 4 and wrong == 0
    saved = json.loads((tmp_path / "r" / "summary.json").read_text())
    assert saved["not_expressible"] == summary["not_expressible"]


def test_a_direct_run_is_refused_with_the_engines_sentence(notorque):
    with pytest.raises(NotExpressible, match=REASON):
        engines.run_variant(load_scenario("applied_torque"), notorque)
    assert engines.not_expressible(load_scenario("applied_torque"), notorque) == REASON
    assert engines.not_expressible(load_scenario("projectile"), notorque) == ""


def test_the_sweep_command_lists_the_pair_and_exits_0(notorque, tmp_path, capsys):
    from cross_checks.cli import main
    rc = main(["sweep", "applied_torque", "projectile", "--engines", notorque, "--out", str(tmp_path / "r"),
               "--no-cache", "--jobs", "1"])
    out = capsys.readouterr().out
    assert rc == 0, out
    assert "1 (scenario, variant) pair(s) not run because the engine cannot express the scenario" in out
    assert f"{notorque} on applied_torque: {REASON}" in out
    assert re.search(r"all \d+ verdicts as expected", out)
    index = (tmp_path / "r" / "index.html").read_text()
    assert "cannot express" in index and f"{notorque} cannot express applied_torque" in index


def test_assert_engine_refuses_to_pass_what_it_could_not_check(notorque):
    from cross_checks.testing import assert_engine
    assert_engine(notorque, ["projectile"])
    with pytest.raises(AssertionError, match=f"{notorque} cannot express applied_torque, so nothing was "
                                             f"checked there: {REASON}"):
        assert_engine(notorque, ["applied_torque", "projectile"])


def test_compare_names_the_reason_when_a_baseline_had_rows_there(notorque, tmp_path):
    from cross_checks.gates.compare import compare_dirs
    from cross_checks.sweep import run_sweep
    sc = load_scenario("applied_torque")
    # the baseline: the same engine before it declared the limit (it ran, and converged)
    engines.reset_registry()

    class Before(NoTorqueEngine):
        def expressible(self, scenario, variant):
            return ""
    engines.register_adapter(Before(), "before")
    run_sweep([sc], [notorque], tmp_path / "old", jobs=1, use_cache=False, progress=False)
    engines.reset_registry()
    engines.register_adapter(NoTorqueEngine(), "after")
    run_sweep([sc], [notorque], tmp_path / "new", jobs=1, use_cache=False, progress=False)
    c = compare_dirs(tmp_path / "old", tmp_path / "new")
    missing = c.of("missing")
    assert missing and all(ch.note == f"not expressible by its engine in the new results: {REASON}"
                           for ch in missing)


def test_the_fuzz_runs_nothing_it_cannot_express_and_counts_it(notorque):
    from cross_checks.fuzz import drivers
    scs = [load_scenario("applied_torque"), load_scenario("projectile")]
    ladder = drivers.run_ladder(resolve(notorque), scs, [sc.dt_s for sc in scs], 4)
    for runs in ladder:
        assert runs.status[0] == drivers.NOT_EXPRESSIBLE and runs.message[0] == REASON
        assert np.all(np.isnan(runs.y[:, 0]))
        assert runs.status[1] == "ok" and np.all(np.isfinite(runs.y[:, 1]))
