"""CI formats (cross_checks/gates/ci.py; issue 44): JUnit XML that parses, one test case per verdict, a
failure per contradiction, failed run and regression whose message is the verdict sentence naming the variant;
the job summary appended to $GITHUB_STEP_SUMMARY; GitHub annotations."""
import xml.etree.ElementTree as ET

from cross_checks.cli import main
from cross_checks.gates.ci import annotation, sweep_junit
from tests.cross_checks.gates.test_compare import BROKEN, CONV, ROWS, write


def _failures(path):
    root = ET.parse(path).getroot()
    assert root.tag == "testsuites"
    return root, [(tc, tc.find("failure")) for tc in root.iter("testcase") if tc.find("failure") is not None]


def test_a_planted_regression_is_a_junit_failure_naming_the_variant(tmp_path, capsys, monkeypatch):
    summary_md = tmp_path / "step_summary.md"
    summary_md.write_text("earlier step\n")
    monkeypatch.setenv("GITHUB_STEP_SUMMARY", str(summary_md))
    rows = [dict(r) for r in ROWS]
    rows[0]["orient_err_final"] *= 1.5            # mujoco:euler on tennis_racket, worse
    a, b = write(tmp_path / "a"), write(tmp_path / "b", rows)
    junit = tmp_path / "compare.xml"
    assert main(["compare", str(a), str(b), "--junit", str(junit), "--github-annotations"]) == 1
    out = capsys.readouterr().out
    root, failed = _failures(junit)
    assert int(root.get("tests")) >= 1 and int(root.get("failures")) == len(failed) == 1
    tc, f = failed[0]
    assert tc.get("classname") == "rbcheck.mujoco:euler" and tc.get("name") == "tennis_racket: orientation"
    assert "mujoco:euler" in f.get("message") and "orient_err_final" in f.get("message")
    assert "REGRESSION mujoco:euler on tennis_racket" in f.get("message")
    # the same sentence annotates the run, and the markdown is appended to the job summary
    assert f"::error title=rbcheck compare::{f.get('message')}" in out.splitlines()
    text = summary_md.read_text()
    assert text.startswith("earlier step\n") and "## rbcheck compare: ❌ regression" in text


def test_identical_results_give_passing_test_cases_and_no_annotation(tmp_path, capsys):
    a, b = write(tmp_path / "a"), write(tmp_path / "b")
    junit = tmp_path / "c.xml"
    assert main(["compare", str(a), str(b), "--junit", str(junit), "--github-annotations"]) == 0
    root, failed = _failures(junit)
    assert not failed and root.get("tests") == str(len(CONV)) and "::error" not in capsys.readouterr().out


def test_a_new_variant_that_contradicts_its_declaration_is_a_failure(tmp_path):
    rows = ROWS + [dict(ROWS[0], engine=BROKEN["engine"])]
    a, b = write(tmp_path / "a"), write(tmp_path / "b", rows, conv=CONV + [BROKEN])
    assert main(["compare", str(a), str(b), "--junit", str(tmp_path / "c.xml")]) == 1
    _, failed = _failures(tmp_path / "c.xml")
    [(tc, f)] = failed
    assert tc.get("classname") == "rbcheck.student:broken" and f.get("type") == "contradiction"
    assert f.get("message") == ("CONTRADICTION student:broken on tennis_racket: orientation does not "
                                "converge (fitted order -0.02), expected order 1 (new in these results)")


def test_sweep_junit_has_one_case_per_verdict_and_failures_with_the_sentences():
    conv = [dict(scenario="tennis_racket", engine="cbody_broken:euler", quantity=q,
                 verdict="does_not_converge", order=-0.02, matches_expectation=False, dt_s=[0.01, 0.005],
                 errors=[1.0, 1.1],
                 assessment="does not converge (fitted order -0.02), expected order 1")
            for q in ("orientation", "angular_velocity")]
    conv.append(dict(conv[0], engine="cbody:euler", matches_expectation=True, verdict="converges",
                     assessment="order 1.00 as expected (1)"))
    conv.append(dict(conv[0], engine="cbody:euler", quantity="position", matches_expectation=None,
                     verdict="pre_asymptotic", assessment="pre-asymptotic on this ladder"))
    long_runs = [dict(scenario="long_major", engine="cbody:euler", status="ok", matches_expectation=False,
                      assessment="|L| drifts by 0.2 though declared kept")]
    failed = [dict(scenario="projectile", engine="cbody:euler", dt="0.01", status="failed",
                   message="cbody:euler at Δt = 0.01 s: the command exited with status 3 — it said: boom")]
    summary = {"convergence": conv, "long_runs": long_runs, "agreement": [
        dict(a="reference:expmap_gyro", b="mujoco:euler", scenario="tennis_racket", agrees=False)]}
    root = ET.fromstring(ET.tostring(sweep_junit(summary, failed)))   # what is written parses back
    cases = {(tc.get("classname"), tc.get("name")): tc for tc in root.iter("testcase")}
    assert len([k for k in cases if not k[1].endswith(": runs")]) == len(conv) + len(long_runs) + 1
    bad = cases[("rbcheck.cbody_broken:euler", "tennis_racket: angular velocity")].find("failure")
    assert bad.get("message").startswith("cbody_broken:euler on tennis_racket: angular velocity does not "
                                         "converge (fitted order -0.02), expected order 1")
    assert cases[("rbcheck.cbody:euler", "tennis_racket: orientation")].find("failure") is None
    assert cases[("rbcheck.cbody:euler", "tennis_racket: position")].find("skipped") is not None
    assert "long run" in cases[("rbcheck.cbody:euler", "long_major: long run")].find("failure").get("message")
    runs = cases[("rbcheck.cbody:euler", "projectile: runs")].find("failure")
    assert runs.get("message") == ("cbody:euler failed on 1 run (projectile at Δt = 0.01 s): the command "
                                   "exited with status 3 — it said: boom")
    assert runs.get("type") == "failed run"
    # two contradictions, the long run, the agreement, the failed run
    assert int(root.get("failures")) == 2 + 1 + 1 + 1


def test_annotations_are_escaped_as_github_reads_them():
    assert annotation("error", "rbcheck: sweep", "50% worse\nsecond line") == \
        "::error title=rbcheck%3A sweep::50%25 worse%0Asecond line"


def test_the_junit_failures_agree_with_the_exit_code(tmp_path):
    """A JUnit reader and the exit code never disagree: failures exactly when compare exits 1."""
    from cross_checks.gates.ci import compare_junit
    from cross_checks.gates.compare import compare_dirs, read_results_dir
    better = [dict(r) for r in ROWS]
    better[1]["orient_err_final"] = 1e-3        # an improvement (exit 0; 1 with --fail-on-change)
    worse = [dict(r) for r in ROWS]
    worse[2]["status"] = "diverged"             # a regression
    cases = {"same": ROWS, "better": better, "worse": worse, "missing": ROWS[:2]}
    a = write(tmp_path / "a")
    for name, rows in cases.items():
        b = write(tmp_path / name, rows)
        c = compare_dirs(a, b)
        for allow, strict in ((False, False), (True, False), (False, True)):
            root = compare_junit(c, read_results_dir(b)[1], allow, strict)
            assert (int(root.get("failures")) > 0) == (c.exit_code(allow, strict) == 1), (name, allow, strict)
