"""The report's first screen (reports/glance.py): its badges count what the terminal counts (issue 44,
points 8 and 9): verdicts not as expected, failed and diverged runs, the long runs' included."""
from types import SimpleNamespace

from cross_checks.cli.sweep import verdict_count
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
    # each group of the box says its badge's count (not its number of lines: 2 pairs hold the 4 verdicts)
    assert next(g for g in box["groups"] if g["cls"] == "bad")["count"] == "5 verdict(s) not as expected"
    lines = [ln for g in box["groups"] for ln in g["lines"]]
    assert any(ln.startswith("planted:step on long_major (long run): |L| drifts") for ln in lines)


def test_a_failed_run_of_an_engine_file_keeps_the_file_it_names():
    """Issue 44, point 3: "At a glance" cut the command's words before the file name (the run's name and a
    private temporary path came first)."""
    message = ("student:euler at Δt = 0.01 s: the command exited with status 2 — it said: python3: can't "
               "open file '/tmp/rbcheck-student-k2j4x9/work/simm.py': [Errno 2] No such file or directory")
    rows = [{"scenario": "tennis_racket", "engine": "student:euler", "status": "failed", "message": message,
             "dt": 0.01}]
    res = SimpleNamespace(summary={"convergence": []}, scenarios=[{"name": "tennis_racket"}], rows=rows,
                          records=lambda sc, v: [])
    [line] = next(g["lines"] for g in verdict_box(res)["groups"] if g["title"] == "Failures")
    assert line == ("student:euler: 1 run(s) on tennis_racket — the command exited with status 2 — it said: "
                    "python3: can't open file '<its working directory>/simm.py': [Errno 2] No such file or "
                    "directory")
