"""`rbcheck compare`: direction-aware, names the regressed row, exit 0/1/2."""
import json

import pandas as pd
import pytest

from cross_checks.gates.compare import CompareInputError, compare_dirs, to_markdown
from tests.helpers.repo import BASELINE

ROWS = [
    dict(scenario="tennis_racket", engine="mujoco:euler", dt=1e-3, steps=10000, wall_s=0.1, pos_err_final=0.0,
         vel_err_final=0.0, orient_err_final=0.0125, angvel_err_final=0.02, energy_drift_max=4.6e-3,
         angmom_drift_max=2.4e-3, status="ok"),
    dict(scenario="tennis_racket", engine="reference:course", dt=1e-3, steps=10000, wall_s=1.2,
         pos_err_final=0.0, vel_err_final=0.0, orient_err_final=3.05, angvel_err_final=2.9,
         energy_drift_max=0.0, angmom_drift_max=0.5, status="ok"),
    dict(scenario="projectile", engine="mujoco:rk4", dt=1e-2, steps=100, wall_s=0.01, pos_err_final=1e-15,
         vel_err_final=1e-15, orient_err_final=0.0, angvel_err_final=0.0, energy_drift_max=1e-15,
         angmom_drift_max=0.0, status="ok"),
]
CONV = [dict(scenario="tennis_racket", engine="mujoco:euler", quantity="orientation", order=1.01,
             pairwise_orders=[1.0, 1.01], verdict="converges", expected_order=1)]
PROV = {"versions": {"rbcheck": "0.1.0", "mujoco": "4.0.0", "pybullet": "3.2.7", "numpy": "2.4.6"}}


def write(d, rows=ROWS, conv=CONV, prov=PROV):
    d.mkdir(parents=True, exist_ok=True)
    pd.DataFrame(rows).to_csv(d / "results.csv", index=False)
    (d / "summary.json").write_text(json.dumps({"schema_version": 1, "provenance": prov,
                                                "convergence": conv}))
    return d


def test_identical_results_pass(tmp_path):
    c = compare_dirs(write(tmp_path / "a"), write(tmp_path / "b"))
    assert c.exit_code() == 0 and c.matched_rows == 3 and not c.changes


def test_planted_regression_fails_and_is_named_in_markdown(tmp_path):
    rows = [dict(r) for r in ROWS]
    rows[0]["orient_err_final"] *= 1.5
    c = compare_dirs(write(tmp_path / "a"), write(tmp_path / "b", rows))
    assert c.exit_code() == 1
    [reg] = c.of("regression")
    assert (reg.scenario, reg.engine) == ("tennis_racket", "mujoco:euler") and "orient_err_final" in reg.what
    md = to_markdown(c, "a", "b")
    assert "| tennis_racket | mujoco:euler | dt=0.001 orient_err_final |" in md


def test_lower_error_is_an_improvement_not_a_regression(tmp_path):
    rows = [dict(r) for r in ROWS]
    rows[1]["orient_err_final"] = 1e-3
    c = compare_dirs(write(tmp_path / "a"), write(tmp_path / "b", rows))
    assert c.exit_code() == 0 and len(c.of("improvement")) == 1


def test_roundoff_noise_is_not_a_change(tmp_path):
    rows = [dict(r) for r in ROWS]
    rows[2]["pos_err_final"] = 9e-13  # was 1e-15: both at the round-off floor
    rows[0]["energy_drift_max"] *= 1.01  # 1 % < the 5 % relative tolerance
    assert not compare_dirs(write(tmp_path / "a"), write(tmp_path / "b", rows)).changes


def test_status_change_to_diverged_is_a_regression(tmp_path):
    rows = [dict(r) for r in ROWS]
    rows[2]["status"] = "diverged"
    c = compare_dirs(write(tmp_path / "a"), write(tmp_path / "b", rows))
    assert c.exit_code() == 1 and "status" in c.of("regression")[0].what


def test_order_further_from_expected_is_a_regression(tmp_path):
    conv = [dict(CONV[0], order=0.5)]
    c = compare_dirs(write(tmp_path / "a"), write(tmp_path / "b", conv=conv))
    assert c.exit_code() == 1 and "order of orientation" in c.of("regression")[0].what


def test_verdict_change_is_a_regression(tmp_path):
    conv = [dict(CONV[0], verdict="does_not_converge")]
    assert compare_dirs(write(tmp_path / "a"), write(tmp_path / "b", conv=conv)).exit_code() == 1


def test_missing_and_new_rows_and_versions_reported(tmp_path):
    rows = ROWS[:2] + [dict(ROWS[2], scenario="linear_drag")]
    c = compare_dirs(write(tmp_path / "a"),
                     write(tmp_path / "b", rows, prov={"versions": {**PROV["versions"], "mujoco": "4.1.0"}}))
    assert len(c.of("missing")) == 1 and len(c.of("new")) == 1
    assert c.exit_code() == 1 and c.exit_code(allow_missing=True) == 0
    assert ("mujoco", "4.0.0", "4.1.0") in c.version_diffs


@pytest.mark.parametrize("setup, words", [
    (lambda d: None, "not a directory"),
    (lambda d: d.mkdir(), "results.csv: missing"),
    (lambda d: (d.mkdir(), (d / "results.csv").write_text("a,b\n1,2\n")), "columns"),
    (lambda d: (write(d), (d / "summary.json").write_text("{")), "cannot parse JSON"),
])
def test_unusable_input_is_an_input_error(tmp_path, setup, words):
    bad = tmp_path / "bad"
    setup(bad)
    with pytest.raises(CompareInputError, match=words):
        compare_dirs(write(tmp_path / "a"), bad)


def test_change_between_two_good_verdicts_is_not_a_regression(tmp_path):
    conv = [dict(CONV[0], verdict="at_roundoff", order=None)]
    c = compare_dirs(write(tmp_path / "a"), write(tmp_path / "b", conv=conv))
    assert c.exit_code() == 0 and len(c.of("changed")) == 1


def test_cli_compare_exit_codes_and_markdown(tmp_path, capsys):
    from cross_checks.cli import main
    a, b = write(tmp_path / "a"), write(tmp_path / "b")
    assert main(["compare", str(a), str(b)]) == 0
    rows = [dict(r) for r in ROWS]
    rows[1]["angvel_err_final"] *= 2
    write(tmp_path / "c", rows)
    md = tmp_path / "diff.md"
    assert main(["compare", str(a), str(tmp_path / "c"), "--markdown", str(md)]) == 1
    assert "| tennis_racket | reference:course | dt=0.001 angvel_err_final |" in md.read_text()
    assert main(["compare", str(a), str(tmp_path / "nope")]) == 2
    assert "nope: not a directory" in capsys.readouterr().err


# --- damaged input is exit 2, never "no regression" (docs/hardening.md) -------------------------------------

def _cli(capsys, a, b):
    from cross_checks.cli import main
    rc = main(["compare", str(a), str(b)])
    return rc, capsys.readouterr()


def test_a_metric_missing_from_the_new_results_is_a_failure(tmp_path):
    with_metric = [dict(r, orient_err_max=r["orient_err_final"]) for r in ROWS]
    c = compare_dirs(write(tmp_path / "a", with_metric), write(tmp_path / "b"))  # b lacks orient_err_max
    [reg] = c.of("regression")
    assert reg.what == "column orient_err_max" and c.exit_code() == 1


@pytest.mark.parametrize("edit, words", [
    (lambda r: r[0].update(orient_err_final="oops"), "line 2: orient_err_final: not a number: 'oops'"),
    (lambda r: r[1].update(pos_err_final=-0.5), "line 3: pos_err_final: must be a finite number >= 0"),
    (lambda r: r[2].update(energy_drift_max=float("inf")),
     "line 4: energy_drift_max: must be a finite number >= 0"),
    (lambda r: r[0].update(status="great"), "line 2: status: must be one of ok, diverged, failed"),
    (lambda r: r[0].update(dt=0.0), "line 2: dt: must be a positive finite number"),
    (lambda r: r.append(dict(r[0])), "duplicate row for tennis_racket, mujoco:euler"),
])
def test_damaged_rows_are_unusable_input_not_a_pass(tmp_path, capsys, edit, words):
    rows = [dict(r) for r in ROWS]
    edit(rows)
    rc, out = _cli(capsys, write(tmp_path / "a"), write(tmp_path / "b", rows))
    assert rc == 2 and words in out.err and out.err.count("\n") == 1 and "Traceback" not in out.err


@pytest.mark.parametrize("summary, words", [
    ("[1, 2]", "summary: must be an object"),
    ('{"schema_version": 1, "provenance": {}}', "summary.convergence: missing"),
    ('{"schema_version": 99, "provenance": {}, "convergence": []}', "schema_version: 99"),
    ('{"schema_version": 1, "provenance": {}, "convergence": [{"scenario": "x"}]}',
     "convergence[0].engine: missing"),
    ('{"schema_version": 1, "provenance": {}, "convergence": [{"scenario": "x", "engine": "e", '
     '"quantity": "position", "order": "fast", "verdict": "converges"}]}',
     "convergence[0].order: must be a number"),
    ("[" * 100000 + "]" * 100000, "cannot parse JSON"),
])
def test_a_malformed_summary_is_unusable_input(tmp_path, capsys, summary, words):
    b = write(tmp_path / "b")
    (b / "summary.json").write_text(summary)
    rc, out = _cli(capsys, write(tmp_path / "a"), b)
    assert rc == 2 and words in out.err and out.err.count("\n") == 1 and "Traceback" not in out.err


def test_a_summary_is_required(tmp_path, capsys):
    b = write(tmp_path / "b")
    (b / "summary.json").unlink()
    rc, out = _cli(capsys, write(tmp_path / "a"), b)
    assert rc == 2 and "summary.json: missing" in out.err


def test_an_order_that_vanished_is_a_regression_not_ignored(tmp_path):
    conv = [dict(CONV[0], order=None)]
    c = compare_dirs(write(tmp_path / "a"), write(tmp_path / "b", conv=conv))
    assert c.exit_code() == 1 and c.of("regression")[0].note == "no order fitted"


def test_a_converging_order_without_expectation_that_moves_is_a_regression(tmp_path):
    old = [dict(CONV[0], expected_order=None, scenario="mystery", engine="user:x")]
    new = [dict(old[0], order=0.6)]
    c = compare_dirs(write(tmp_path / "a", conv=old), write(tmp_path / "b", conv=new))
    assert c.exit_code() == 1


def test_the_committed_baseline_without_a_marker_is_still_valid_input():
    base = BASELINE
    c = compare_dirs(base, base)
    assert c.exit_code() == 0 and c.matched_rows > 100 and not c.changes


# --- a sweep of a subset against the full baseline (README tour) -------------------------------------------

def _scenario(name):
    return {"name": name, "content_hash": "0" * 16, "reference": "analytic", "duration_s": 1.0, "dt_s": 1e-3,
            "dt_ladder_s": [1e-3]}


def _write_scoped(d, rows, conv=CONV, skipped=()):
    """A results directory whose summary lists what its sweep ran, as every rbcheck sweep's does."""
    write(d, rows, conv)
    summary = json.loads((d / "summary.json").read_text())
    summary["form"] = "compact baseline"  # the compact records: what compare reads of a scenario
    summary["scenarios"] = [_scenario(n) for n in sorted({r["scenario"] for r in rows})]
    summary["variants"] = [{"name": n} for n in sorted({r["engine"] for r in rows})]
    summary["skipped_variants"] = [{"name": n, "reason": "not installed"} for n in skipped]
    (d / "summary.json").write_text(json.dumps(summary))
    return d


def test_a_subset_is_compared_on_what_it_ran_and_the_rest_is_counted_not_missing(tmp_path, capsys):
    from cross_checks.cli import main
    subset = _write_scoped(tmp_path / "b", ROWS[:1])  # tennis_racket x mujoco:euler only
    c = compare_dirs(write(tmp_path / "a"), subset)
    assert c.exit_code() == 0 and c.matched_rows == 1 and not c.of("missing")
    assert (c.scope.skipped_rows, c.scope.skipped_scenarios, c.scope.skipped_variants) == (
        2, {"projectile"}, {"reference:course"})
    assert main(["compare", str(tmp_path / "a"), str(subset)]) == 0
    out = capsys.readouterr().out
    assert "not compared: 2 baseline row(s)" in out and "OK: no regression" in out
    assert "MISSING" not in out


def test_a_regression_inside_the_subset_is_still_caught(tmp_path):
    rows = [dict(ROWS[0], orient_err_final=ROWS[0]["orient_err_final"] * 3)]
    c = compare_dirs(write(tmp_path / "a"), _write_scoped(tmp_path / "b", rows))
    assert c.exit_code() == 1 and [ch.what for ch in c.of("regression")] == ["dt=0.001 orient_err_final"]


def test_a_row_of_a_scenario_and_variant_the_subset_ran_is_still_missing(tmp_path):
    """The subset ran tennis_racket x mujoco:euler; the baseline's row at
    another dt of that pair is absent."""
    base = write(tmp_path / "a", ROWS + [dict(ROWS[0], dt=5e-4, steps=20000)])
    c = compare_dirs(base, _write_scoped(tmp_path / "b", ROWS[:1]))
    assert [ch.what for ch in c.of("missing")] == ["dt=0.0005"] and c.exit_code() == 1


def test_a_variant_unavailable_in_the_new_sweep_is_missing_not_skipped(tmp_path, capsys):
    """A default sweep where PyBullet/MuJoCo could not be imported must not pass the gate by skipping."""
    from cross_checks.cli import main
    new = _write_scoped(tmp_path / "b", ROWS[1:2], conv=[], skipped=["mujoco:euler", "mujoco:rk4"])
    summary = json.loads((new / "summary.json").read_text())
    summary["scenarios"] = [_scenario("tennis_racket"), _scenario("projectile")]
    (new / "summary.json").write_text(json.dumps(summary))
    c = compare_dirs(write(tmp_path / "a"), new)
    assert len(c.of("missing")) == 3 and all("unavailable" in ch.note for ch in c.of("missing")[:2])
    assert main(["compare", str(tmp_path / "a"), str(new)]) == 1
    out = capsys.readouterr().out
    assert "MISSING: 3" in out and "0 regressions" in out and "REGRESSION" not in out


def test_the_markdown_heading_agrees_with_the_counts(tmp_path):
    c = compare_dirs(write(tmp_path / "a"), write(tmp_path / "b", ROWS[:2]))  # no scope: one row missing
    md = to_markdown(c, "a", "b")
    assert "❌ rows missing" in md and "**0 regressions**" in md
    ok = compare_dirs(write(tmp_path / "a"), _write_scoped(tmp_path / "c", ROWS[:2]))
    md = to_markdown(ok, "a", "c")
    assert "✅ no regression" in md and "Not compared: 1 baseline row(s)" in md


# --- an optional engine not installed where the new results were made (the README's main command) --------

def _baseline_without(tmp_path, engine, installed=False, required=False):
    """The committed baseline as a sweep on a machine without ``engine`` would write it: its rows and records
    gone, its variants listed as skipped with the registry's flags."""
    import shutil
    new = tmp_path / f"without-{engine}"
    shutil.copytree(BASELINE, new)
    df = pd.read_csv(new / "results.csv", dtype=str, keep_default_na=False)
    df[~df["engine"].str.startswith(f"{engine}:")].to_csv(new / "results.csv", index=False)
    s = json.loads((new / "summary.json").read_text())
    gone = [v["name"] for v in s["variants"] if v["name"].startswith(f"{engine}:")]
    assert gone, f"the baseline has no {engine} variant"
    s["variants"] = [v for v in s["variants"] if v["name"] not in gone]
    for key in ("convergence", "local_convergence"):
        s[key] = [r for r in s[key] if r["engine"] not in gone]
    s["agreement"] = [a for a in s["agreement"] if a["a"] not in gone and a["b"] not in gone]
    why = (f"{engine} is not installed" if not installed
           else f"{engine} 1.0 is installed but cannot be imported: X")
    s["skipped_variants"] = [{"name": n, "reason": why, "installed": installed, "required": required}
                             for n in gone]
    (new / "summary.json").write_text(json.dumps(s))
    n_rows = int(pd.read_csv(BASELINE / "results.csv")["engine"].str.startswith(f"{engine}:").sum())
    return new, n_rows


def test_an_optional_engine_not_installed_is_one_line_not_a_failure(tmp_path, capsys):
    from cross_checks.cli import main
    new, n_rows = _baseline_without(tmp_path, "drake")
    assert main(["compare", str(BASELINE), str(new), "--markdown", str(tmp_path / "c.md")]) == 0
    out = capsys.readouterr().out
    lines = [ln for ln in out.splitlines() if "drake" in ln]
    assert len(lines) == 1 and lines[0].startswith(f"drake not installed: {n_rows} baseline rows and ")
    assert "--require drake makes its absence a failure" in lines[0] and "OK: no regression" in out
    assert "MISSING" not in out
    md = (tmp_path / "c.md").read_text()
    # every engine not installed in ONE paragraph of the markdown (issue 44, point 9)
    assert [p for p in md.split("\n\n") if "not installed" in p] == [
        p for p in md.split("\n\n") if "Not compared: 1 optional engine(s) not installed" in p]
    assert f"drake ({n_rows} baseline rows, " in md


def test_require_makes_an_absent_optional_engine_a_failure(tmp_path, capsys):
    from cross_checks.cli import main
    new, n_rows = _baseline_without(tmp_path, "drake")
    assert main(["compare", str(BASELINE), str(new), "--require", "drake"]) == 1
    c = compare_dirs(BASELINE, new, require=["drake"])
    assert len([m for m in c.of("missing")
                if m.engine.startswith("drake:") and m.what.startswith("dt=")]) == n_rows
    assert "drake is not installed" in c.of("missing")[0].note


def test_require_of_an_engine_the_new_results_never_mentioned_fails(tmp_path):
    c = compare_dirs(BASELINE, BASELINE, require=["newton"])   # optional, not in the baseline
    assert (c.exit_code() == 1
            and c.of("missing")[0].note == "--require newton: the new results ran none of its variants")


def test_a_required_or_broken_engine_is_still_missing(tmp_path):
    broken, _ = _baseline_without(tmp_path, "drake", installed=True)
    assert compare_dirs(BASELINE, broken).exit_code() == 1
    required, _ = _baseline_without(tmp_path / "r", "pybullet", required=True)
    assert compare_dirs(BASELINE, required).exit_code() == 1


# --- changes grouped by variant and judged as a whole (an engine change explained) -----------------------

def _with_rows(tmp_path, name, edit, conv=CONV, summary_extra=None):
    rows = [dict(r) for r in ROWS]
    edit(rows)
    d = write(tmp_path / name, rows, conv)
    if summary_extra:
        s = json.loads((d / "summary.json").read_text())
        s.update(summary_extra)
        (d / "summary.json").write_text(json.dumps(s))
    return d


def test_errors_moved_both_ways_at_the_same_order_are_a_changed_scheme_not_a_regression(tmp_path):
    from cross_checks.gates.compare import variant_changes, verdict_line
    more = ROWS + [dict(ROWS[0], scenario="tumbling_box")]
    a = write(tmp_path / "a", more)
    rows = [dict(r) for r in more]
    rows[0]["orient_err_final"] *= 1.9      # worse on one scenario ...
    rows[3]["orient_err_final"] *= 0.69     # ... better on another: another scheme of the same order
    c = compare_dirs(a, write(tmp_path / "b", rows))
    [v] = variant_changes(c)
    assert (v.variant, v.category) == ("mujoco:euler", "scheme changed") and c.exit_code() == 0
    assert v.ratio_range == pytest.approx((0.69, 1.9))
    assert "baseline is stale" in verdict_line(c) and c.exit_code(fail_on_change=True) == 1
    rows[0]["orient_err_final"] *= 10.0     # one error 19x worse: a regression, whatever improved elsewhere
    c = compare_dirs(a, write(tmp_path / "c", rows))
    assert variant_changes(c)[0].category == "regression" and c.exit_code() == 1


def test_a_one_step_order_and_an_agreement_are_causes_and_judged(tmp_path):
    from cross_checks.gates.compare import variant_changes
    local = [dict(scenario="tennis_racket", engine="mujoco:euler", quantity="orientation", order=2.0,
                  verdict="converges", expected_order=2)]
    agree = [dict(a="mujoco:euler", b="pybullet:multibody", scenario="tennis_racket", dt_s=1e-3, agrees=True,
                  max_rel=1e-14, reason="the same scheme")]
    a = _with_rows(tmp_path, "a", lambda r: None,
                   summary_extra={"local_convergence": local, "agreement": agree})
    b = _with_rows(tmp_path, "b", lambda r: None, summary_extra={
        "local_convergence": [dict(local[0], order=1.0)],
        "agreement": [dict(agree[0], agrees=False, max_rel=0.2)]})
    c = compare_dirs(a, b)
    by = {v.variant: v for v in variant_changes(c)}
    assert by["mujoco:euler"].category == "regression" and c.exit_code() == 1
    causes = " ".join(by["mujoco:euler"].causes)
    assert "orientation one-step order 2.00 -> 1.00 on tennis_racket" in causes
    assert "agreement with pybullet:multibody agrees -> differs" in causes
    assert by["pybullet:multibody"].category == "regression"


def test_an_energy_drift_kind_change_is_information(tmp_path):
    from cross_checks.gates.compare import variant_changes
    a = _with_rows(tmp_path, "a", lambda rows: [r.update(energy_drift_kind="bounded") for r in rows])
    b = _with_rows(tmp_path, "b", lambda rows: [r.update(energy_drift_kind="bounded") for r in rows]
                   + [rows[0].update(energy_drift_kind="secular")])
    c = compare_dirs(a, b)
    [v] = variant_changes(c)
    assert (v.category == "changed" and "energy-drift kind bounded -> secular" in v.causes[0]
            and c.exit_code() == 0)


def test_a_rerun_that_changed_nothing_is_one_line(tmp_path, capsys):
    from cross_checks.cli import main
    assert main(["compare", str(write(tmp_path / "a")), str(write(tmp_path / "b"))]) == 0
    out = capsys.readouterr().out
    assert out == "OK: no regression: 3 matching rows compared, nothing changed\n"


# --- a NEW variant is judged on its own verdicts (issue 44, point 1) ---------------------------------------

BROKEN = dict(scenario="tennis_racket", engine="student:broken", quantity="orientation", order=-0.02,
              pairwise_orders=[0.1, -0.02], verdict="does_not_converge", expected_order=1,
              matches_expectation=False,
              assessment="does not converge (fitted order -0.02), expected order 1")
GOOD_NEW = dict(BROKEN, engine="student:euler", order=1.0, verdict="converges", matches_expectation=True,
                assessment="order 1.00 as expected (1)")


def _with_new_variants(tmp_path, records):
    rows = ROWS + [dict(ROWS[0], engine=r["engine"]) for r in records]
    return write(tmp_path / "b", rows, conv=CONV + records)


def test_a_new_variant_whose_verdict_contradicts_its_declaration_fails_the_gate(tmp_path, capsys):
    from cross_checks.cli import main
    a, b = write(tmp_path / "a"), _with_new_variants(tmp_path, [GOOD_NEW, BROKEN])
    c = compare_dirs(a, b)
    assert c.exit_code() == 1 and c.exit_code(allow_missing=True) == 1
    [ch] = c.of("contradiction")
    assert (ch.engine, ch.scenario) == ("student:broken", "tennis_racket")
    assert main(["compare", str(a), str(b), "--markdown", str(tmp_path / "c.md")]) == 1
    out = capsys.readouterr().out.splitlines()
    first_screen = "\n".join(out[:10])
    assert "student:broken: CONTRADICTION" in first_screen
    assert "does not converge (fitted order -0.02), expected order 1" in first_screen
    assert out[-1].startswith("CONTRADICTION: 1 new variant(s) contradict what they declare (student:broken)")
    assert "OK" not in out[-1] and "student:euler: CONTRADICTION" not in first_screen
    md = (tmp_path / "c.md").read_text()
    assert md.startswith("## rbcheck compare: ❌ a new variant contradicts what it declares")


def test_a_new_variant_as_declared_is_new_and_passes(tmp_path):
    c = compare_dirs(write(tmp_path / "a"), _with_new_variants(tmp_path, [GOOD_NEW]))
    assert c.exit_code() == 0 and not c.of("contradiction") and c.of("new")


def test_counts_are_written_in_the_singular_and_plural(tmp_path):
    from cross_checks.gates.compare import to_text
    rows = [dict(r) for r in ROWS]
    rows[0]["orient_err_final"] *= 1.5
    c = compare_dirs(write(tmp_path / "a"), write(tmp_path / "b", rows))
    assert "1 regression," in to_text(c) and "1 regressions" not in to_text(c)
    assert "**1 regression**" in to_markdown(c, "a", "b")
