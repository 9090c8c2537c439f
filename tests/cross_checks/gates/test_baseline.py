"""`rbcheck baseline`: the compact baseline holds every result of its results directory cell for cell
(timing columns aside), one line per record; compare reads it like the directory it was made from; a
changed verdict is one changed line of the diff; damaged input is exit 2 and leaves OUT_DIR as it was."""
import csv
import difflib
import json
import shutil

import pytest

from cross_checks.cli import main
from cross_checks.gates.compare import compare_dirs

LISTS = ("scenarios", "variants", "convergence", "local_convergence", "agreement")
#: What a reviewer must see of each convergence record (docs/results.md "The baseline").
REVIEWED = {"scenario", "engine", "quantity", "verdict", "order", "expected_verdict", "expected_order",
            "matches_expectation", "assessment"}


def _rows(path):
    with open(path, newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def _files(d):
    return {p.relative_to(d).as_posix(): p.read_bytes() for p in sorted(d.rglob("*")) if p.is_file()}


@pytest.fixture
def base(tiny_results, tmp_path):
    out = tmp_path / "baseline"
    assert main(["baseline", str(tiny_results), str(out)]) == 0
    return out


def test_the_baseline_holds_every_result_cell_for_cell_without_the_timing_columns(tiny_results, base):
    full = _rows(tiny_results / "results.csv")
    timing = ("wall_s", "engine_s", "cached")
    assert _rows(base / "results.csv") == [{k: v for k, v in r.items() if k not in timing} for r in full]
    header = (base / "results.csv").read_text().splitlines()[0].split(",")
    assert header == [c for c in full[0] if c not in ("wall_s", "engine_s", "cached")]
    assert sorted(_files(base)) == ["results.csv", "summary.json"]  # no marker: a sweep never replaces it


def test_the_summary_has_one_line_per_record_and_keeps_what_compare_and_a_reviewer_read(tiny_results, base):
    full = json.loads((tiny_results / "summary.json").read_text())
    text = (base / "summary.json").read_text()
    comp = json.loads(text)
    assert comp["form"] == "compact baseline" and comp["provenance"] == full["provenance"]
    one_line = [json.loads(line.strip().rstrip(",")) for line in text.splitlines() if line.startswith("  {")]
    n_records = sum(len(comp[k]) for k in LISTS)
    assert n_records == sum(len(full[k]) for k in LISTS) == len(one_line) > 10
    assert len(text.splitlines()) < n_records + 60  # the provenance and the brackets, nothing else
    for key in LISTS:
        for rec, whole in zip(comp[key], full[key]):
            assert rec in one_line and rec == {k: whole[k] for k in rec}
    for key in ("convergence", "local_convergence"):
        assert all(set(rec) >= REVIEWED for rec in comp[key])


def test_compare_reads_the_baseline_like_the_results_it_was_made_from(tiny_results, base):
    n = len(_rows(tiny_results / "results.csv"))
    for old, new in ((base, tiny_results), (tiny_results, base), (base, base)):
        c = compare_dirs(old, new)
        assert c.exit_code() == 0 and c.matched_rows == n and not c.changes and not c.version_diffs


def test_the_baseline_of_a_baseline_is_itself(base, tmp_path):
    again = tmp_path / "again"
    assert main(["baseline", str(base), str(again)]) == 0
    assert _files(again) == _files(base)
    assert main(["baseline", str(base), str(again)]) == 0  # OUT_DIR a baseline already: replaced
    assert _files(again) == _files(base)


def _plant_a_verdict_change(results_dir):
    """What a sweep writes when rk4's orientation stops converging: its finest
    error grows, the record changes."""
    rows = _rows(results_dir / "results.csv")
    finest = min((r for r in rows if r["engine"] == "reference:rk4"), key=lambda r: float(r["dt"]))
    finest["orient_err_final"] = repr(float(finest["orient_err_final"]) * 1e6)
    with open(results_dir / "results.csv", "w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]), lineterminator="\n")
        w.writeheader()
        w.writerows(rows)
    summary = json.loads((results_dir / "summary.json").read_text())
    rec = next(r for r in summary["convergence"]
               if (r["engine"], r["quantity"]) == ("reference:rk4", "orientation"))
    was = rec["verdict"]
    rec.update(verdict="does_not_converge", order=-0.02, matches_expectation=False,
               assessment="does not converge (fitted order -0.02), expected order 4")
    (results_dir / "summary.json").write_text(json.dumps(summary, indent=1))
    return was


def test_a_changed_verdict_is_one_changed_line_of_each_file(tiny_results, base, tmp_path, capsys):
    changed = tmp_path / "changed"
    shutil.copytree(tiny_results, changed)
    was = _plant_a_verdict_change(changed)
    assert was in ("converges", "at_roundoff")
    new_base = tmp_path / "new_baseline"
    assert main(["baseline", str(changed), str(new_base)]) == 0
    for name in ("results.csv", "summary.json"):
        old, new = (base / name).read_text().splitlines(), (new_base / name).read_text().splitlines()
        diff = [d for d in difflib.unified_diff(old, new, n=0, lineterm="")
                if d[:1] in "+-" and d[:3] not in ("---", "+++")]
        assert len(diff) == 2 and diff[0][0] == "-" and diff[1][0] == "+", diff
        assert "reference:rk4" in diff[1] and ("does_not_converge" in diff[1]
                                               if name == "summary.json" else True)
    capsys.readouterr()
    assert main(["compare", str(base), str(new_base)]) == 1
    out = capsys.readouterr().out
    assert f"REGRESSION  tiny reference:rk4 verdict of orientation: {was} -> does_not_converge" in out


def _damage_cell(d):
    rows = _rows(d / "results.csv")
    text = (d / "results.csv").read_text()
    (d / "results.csv").write_text(text.replace(rows[0]["orient_err_final"], "oops", 1))


def _drop_column(d, column="engine_version"):
    rows = _rows(d / "results.csv")
    with open(d / "results.csv", "w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=[c for c in rows[0] if c != column], lineterminator="\n",
                           extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)


@pytest.mark.parametrize("damage, source, out, words", [  # damage is done to {src}, a copy of the results
    (None, "{tmp}/missing", "{base}", "missing: not a directory"),
    (_damage_cell, "{src}", "{base}", "line 2: orient_err_final: not a number: 'oops'"),
    (lambda d: (d / "summary.json").write_text("{"), "{src}", "{base}", "summary.json: cannot parse JSON"),
    (_drop_column, "{src}", "{base}", "columns engine_version missing"),
    (lambda d: (d / "summary.json").write_text(
        (d / "summary.json").read_text().replace('"form": "compact baseline"', '"form": "abridged"')),
     "{src}", "{base}", "summary.form: must be one of compact baseline, got 'abridged'"),
    (None, "{src}", "{src}", "is the results directory"),
    (None, "{src}", "{tiny}",
     "holds more than a baseline (.rbcheck-results.json, index.html, integrators.html"),
    (None, "{src}", "{base}/results.csv", "exists and is not a directory"),
    (None, "{src}", "{tmp}/no/such/dir", "does not exist"),
])
def test_unusable_input_is_exit_2_in_one_line_and_writes_nothing(tiny_results, base, tmp_path, capsys, damage,
                                                                 source, out, words):
    src = tmp_path / "src"
    shutil.copytree(base if "summary.form" in words else tiny_results, src)  # a damaged baseline as input
    if damage is not None:
        damage(src)
    before = {d: _files(d) for d in (base, tiny_results, src)}
    names = {"tmp": tmp_path, "base": base, "src": src, "tiny": tiny_results}
    capsys.readouterr()
    assert main(["baseline", source.format(**names), out.format(**names)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("rbcheck baseline: error: ") and err.count("\n") == 1 and words in err, err
    assert {d: _files(d) for d in before} == before
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no staging directory left


def test_the_report_of_a_baseline_is_refused_in_one_line_and_writes_nothing(base, capsys):
    before = _files(base)
    assert main(["report", str(base)]) == 2
    err = capsys.readouterr().err
    assert ("a compact baseline (written by `rbcheck baseline`) holds no report data" in err
            and err.count("\n") == 1)
    assert _files(base) == before


@pytest.mark.parametrize("edit, words", [
    (lambda s: s["convergence"][0].pop("verdict"), "summary.convergence[0].verdict: missing"),
    (lambda s: s["local_convergence"][0].__setitem__("order", "fast"),
     "summary.local_convergence[0].order: must be a number"),
    # compact records are no full ones
    (lambda s: s.pop("form"), "summary.scenarios[0].description: missing"),
])
def test_a_damaged_baseline_is_unusable_input_for_compare(base, tiny_results, capsys, edit, words):
    s = json.loads((base / "summary.json").read_text())
    edit(s)
    (base / "summary.json").write_text(json.dumps(s))
    capsys.readouterr()
    assert main(["compare", str(base), str(tiny_results)]) == 2
    err = capsys.readouterr().err
    assert words in err and err.count("\n") == 1 and "Traceback" not in err
