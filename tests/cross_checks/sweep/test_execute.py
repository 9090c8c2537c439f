"""The references stage: the slowest solves start first, and each scenario still gets its own reference."""
import tomllib
from pathlib import Path

import cross_checks
from cross_checks.scenario import load_scenario
from cross_checks.sweep.execute import Runner, _reference_cost, run_references

CATALOG = Path(cross_checks.__file__).parent / "scenario" / "catalog"


def test_dop853_references_are_submitted_before_closed_forms():
    names = ["projectile", "spring_pendulum", "tennis_racket", "applied_torque"]
    order = sorted(names, key=lambda n: _reference_cost(load_scenario(n)))
    declared = {n: tomllib.loads((CATALOG / f"{n}.toml").read_text()).get("reference") for n in names}
    assert {declared[n] for n in order[:2]} == {"ground_truth"}  # as the scenario files say
    assert order[0] == "spring_pendulum"  # 5 s at 0.5 ms: the longer DOP853 grid of the two


def test_references_come_back_in_the_order_of_the_scenarios(tmp_path):
    scenarios = [load_scenario(n) for n in ("projectile", "applied_torque", "linear_drag")]
    refs = run_references(Runner(1), scenarios, tmp_path, None, False, None)
    assert [r.label.split(" ")[0] for r in refs] == ["analytic", "ground_truth", "analytic"]
    assert all(Path(r.path).is_file() and not r.error for r in refs)
