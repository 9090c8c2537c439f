"""cross_checks.gates.check.ladder: several files of one scenario at different Δt — each checked, the order
fitted with the sweep's machinery and judged against the scheme the files are."""
import json

import pytest

from .test_check import _run, check, scenario_file, student_file


def test_a_ladder_of_files_fits_the_order(tmp_path, capsys):
    sc = scenario_file(tmp_path, "particle_body", 1.0)
    files = [_run(tmp_path, sc, "reference:midpoint", dt, name=f"m{dt}.csv") for dt in (0.02, 0.01, 0.005)]
    capsys.readouterr()
    rc, out, _ = check(capsys, *files, "--scenario", sc, "--json", tmp_path / "l.json")
    assert rc == 0, out
    assert out.startswith("PASS: every file passes and the errors converge as expected")
    data = json.loads((tmp_path / "l.json").read_text())
    orient = next(r for r in data["ladder"]["convergence"] if r["quantity"] == "orientation")
    assert orient["order"] == pytest.approx(2.0, abs=0.3) and orient["matches_expectation"] is True
    assert len(data["files"]) == 3


def test_a_ladder_of_a_wrong_simulator_fails(tmp_path, capsys):
    sc = scenario_file(tmp_path, "tumbling_box", 1.0)
    files = [student_file(tmp_path, sc, dt, bug="inertia_body", name=f"s{dt}.csv") for dt in (0.01, 0.005)]
    rc, out, _ = check(capsys, *files, "--scenario", sc)
    assert rc == 1 and out.startswith("FAIL: 2 of 2 files fail their own check")


def test_a_ladder_needs_distinct_steps(tmp_path, capsys):
    sc = scenario_file(tmp_path, "projectile")
    a = _run(tmp_path, sc, "reference:course", 0.01, name="a.csv")
    b = _run(tmp_path, sc, "reference:rk4", 0.01, name="b.csv")
    capsys.readouterr()
    rc, _, err = check(capsys, a, b, "--scenario", sc)
    assert rc == 2 and "appears in two files" in err


