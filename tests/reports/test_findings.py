"""reports.findings on records a real sweep writes (issue 45: a report-side error threw a sweep away)."""
import pytest

import reports
from cross_checks.scenario import parse_scenario
from cross_checks.sweep import run_sweep
from reports.data import load_results
from reports.findings import findings
from tests.helpers.scenarios import scenario_toml

#: The issue's blow.toml: a tumble at ω = (0.1, 300, 0.1) rad/s, I = (1, 2, 3) kg m², Δt = 0.01 s. The
#: exponential-map Euler step (MuJoCo Euler, reference:expmap_gyro: the same scheme) diverges at once, at the
#: same step in both, so their agreement record is "both diverged" and has no final-state difference. 0.3 s,
#: not the issue's 1 s: both diverge by 0.2 s (0.14 s at Δt = 0.01 s, 0.2 s at 0.02 s), and the references
#: of a 300 rad/s spin (DOP853's, Drake's) were a third of the test's time.
BLOW = scenario_toml("blow", 0.3, 0.01, (0.02, 0.01), initial="angular_velocity = [0.1, 300.0, 0.1]")


def test_a_same_scheme_pair_that_diverges_together_is_reported_and_the_results_kept(tmp_path, isolated_cache):
    pytest.importorskip("mujoco")
    sc = parse_scenario(BLOW, "blow.toml")
    out = tmp_path / "res"
    summary = run_sweep([sc], ["mujoco:euler", "reference:expmap_gyro"], out, jobs=1, use_cache=False,
                        progress=False, finish=lambda d: reports.render(d, jobs=1))
    [rec] = summary["agreement"]
    assert rec["agrees"] and rec["max_rel"] is None and rec["note"].startswith("both diverged")
    assert (out / "results.csv").is_file() and (out / "index.html").is_file()
    said = [f.text for f in findings(load_results(out)) if "reproduces" in f.text]
    assert said == [f"{rec['b']} reproduces {rec['a']} on blow by diverging at the same time "
                    f"(within two steps): {rec['reason']}."]


def test_a_report_that_raises_keeps_the_sweep_s_results(tmp_path, isolated_cache, monkeypatch, capsys):
    """Any bug on the report's side (here planted: findings raising) leaves the results written, says so and
    how to draw the report again, exit 2 (an internal error), no traceback."""
    from cross_checks.cli import main
    (tmp_path / "tiny.toml").write_text(scenario_toml("tiny", 0.2, 0.01, (0.02, 0.01)))

    def broken(res):
        raise TypeError("'>' not supported between instances of 'NoneType' and 'float'")
    monkeypatch.setattr("reports.html.findings", broken)
    out = tmp_path / "res"
    code = main(["sweep", str(tmp_path / "tiny.toml"), "--jobs", "1", "--out", str(out),
                 "--engines", "reference:course", "reference:rk4"])
    err = capsys.readouterr().err
    assert code == 2, err
    assert "the report could not be drawn (internal error: TypeError" in err
    assert f"rbcheck report {out}" in err
    assert "Traceback" not in err
    from cross_checks.sweep.results_dir import read_marker
    assert {"results.csv", "summary.json"} <= set(read_marker(out)["files"])
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".res")]   # no staging folder left
