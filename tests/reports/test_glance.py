"""The report's first screen (reports/glance.py): its badges count what the terminal counts (issue 44,
points 8 and 9): verdicts not as expected, failed and diverged runs, the long runs' included."""
from types import SimpleNamespace

from cross_checks.cli import verdict_count
from reports.glance import verdict_box


def _conv(engine, scenario, quantity, matches):
    return {"engine": engine, "scenario": scenario, "quantity": quantity, "matches_expectation": matches,
            "assessment": "does not converge (fitted order 0.01), expected order 1" if not matches else "ok",
            "verdict": "does_not_converge" if not matches else "converges", "expected_verdict": "converges",
            "reason": ""}


def test_the_badges_count_verdicts_and_long_runs_as_the_terminal_does():
    conv = [_conv("student:broken", "tennis_racket", q, False) for q in ("orientation", "angular_velocity")]
    conv += [_conv("student:broken", "applied_torque", q, False) for q in ("orientation", "angular_velocity")]
    conv += [_conv("reference:rk4", "tennis_racket", "orientation", True)]
    long_runs = [{"engine": f"reference:explicit_euler{i}", "scenario": "long_tennis_racket",
                  "status": "diverged", "diverged_at_s": 12.5, "matches_expectation": True,
                  "assessment": "diverged, as expected"} for i in range(12)]
    long_runs.append({"engine": "planted:step", "scenario": "long_major", "status": "ok",
                      "matches_expectation": False, "assessment": "|L| drifts by 0.1, declared kept"})
    summary = {"convergence": conv, "agreement": [], "scenarios": [], "long_runs": long_runs}
    res = SimpleNamespace(summary=summary, scenarios=[{"name": "tennis_racket"}, {"name": "applied_torque"}],
                          rows=[],
                          records=lambda sc, v: [r for r in conv if (r["scenario"], r["engine"]) == (sc, v)])
    box = verdict_box(res)
    counts = {label: n for n, label, _ in box["headline"]}
    total, wrong = verdict_count(summary)
    assert wrong == 5 and counts["verdict(s) not as expected"] == wrong   # 4 verdicts (2 pairs) + 1 long run
    assert counts["diverged run(s)"] == 12                                  # the long runs that diverged
    lines = [ln for g in box["groups"] for ln in g["lines"]]
    assert any(ln.startswith("planted:step on long_major (long run): |L| drifts") for ln in lines)
