"""cross_checks.sweep.reader: one reader of a results directory for compare, baseline and the report — the
same typed rows, and for the same damage the same one line (file, field, reason) and exit 2 from each."""
import csv
import math
import shutil

import pytest

from cross_checks.cli import main
from cross_checks.sweep.jobs import RESULT_COLUMNS
from cross_checks.sweep.reader import (
    REQUIRED_COLUMNS,
    RESULTS_CSV,
    ResultsReadError,
    read_results_dir,
)


def _rows(path):
    with open(path, newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def _write(path, rows, columns=None):
    columns = columns or list(rows[0])
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=columns, lineterminator="\n", extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)


def _edit(**cells):
    def damage(d):
        rows = _rows(d / "results.csv")
        rows[0].update(cells)
        _write(d / "results.csv", rows)
    return damage


def _drop(column):
    def damage(d):
        rows = _rows(d / "results.csv")
        _write(d / "results.csv", rows, [c for c in rows[0] if c != column])
    return damage


def _duplicate(d):
    rows = _rows(d / "results.csv")
    _write(d / "results.csv", rows + [rows[0]])


def _short_row(d):
    text = (d / "results.csv").read_text(encoding="utf-8").splitlines()
    text[2] = ",".join(text[2].split(",")[:5])
    (d / "results.csv").write_text("\n".join(text) + "\n", encoding="utf-8")


@pytest.mark.parametrize("damage, words", [
    (_drop("orient_err_final"), "results.csv: columns orient_err_final missing"),
    (_edit(orient_err_final="oops"), "results.csv: line 2: orient_err_final: not a number: 'oops'"),
    (_edit(pos_err_final="-0.5"), "results.csv: line 2: pos_err_final: must be a finite number >= 0"),
    (_edit(steps="2.5"), "results.csv: line 2: steps: must be a whole number >= 0, got 2.5"),
    (_edit(engine=" "), "results.csv: line 2: engine: empty"),
    (_edit(status="great"), "results.csv: line 2: status: must be one of ok, diverged, failed, got 'great'"),
    (_duplicate, "duplicate row for "),
    (_short_row, "results.csv: line 3: fewer cells than columns"),
    (lambda d: (d / "results.csv").unlink(), "results.csv: missing"),
    (lambda d: (d / "summary.json").write_text("{"), "summary.json: cannot parse JSON"),
])
def test_compare_baseline_and_report_say_the_same_line_for_the_same_damage(tiny_results, tmp_path, capsys,
                                                                            damage, words):
    """Before, each read results.csv its own way: the report took a duplicate row, a negative error, an empty
    engine or a short row as data, and said a missing column in other words than compare."""
    said = {}
    for command in ("compare", "baseline", "report"):
        d = tmp_path / command
        shutil.copytree(tiny_results, d)
        damage(d)
        argv = {"compare": ["compare", str(tiny_results), str(d)],
                "baseline": ["baseline", str(d), str(tmp_path / f"{command}-base")],
                "report": ["report", str(d), "--jobs", "1"]}[command]
        capsys.readouterr()
        assert main(argv) == 2, command
        err = capsys.readouterr().err
        prefix = f"rbcheck {command}: error: "
        assert err.startswith(prefix) and err.count("\n") == 1 and "Traceback" not in err, err
        assert words in err, (command, err)
        said[command] = err[len(prefix):].replace(str(d), "DIR")
    assert said["compare"] == said["baseline"] == said["report"]


def test_the_rows_are_typed_by_one_schema(tiny_results):
    got = read_results_dir(tiny_results, need=RESULT_COLUMNS, for_report=True)
    assert got.table.columns == list(RESULT_COLUMNS) and got.table.rows
    want = {"name": str, "text": str, "status": str, "positive": float, "count": int, "error": float,
            "number": float, "flag": bool}
    for row in got.table.rows:
        assert list(row) == list(RESULT_COLUMNS)
        for col, value in row.items():
            assert type(value) is want[RESULTS_CSV[col]], (col, value)
        assert row["dt"] > 0 and row["steps"] >= 0
        assert all(math.isnan(row[c]) or row[c] >= 0 for c in REQUIRED_COLUMNS if RESULTS_CSV[c] == "error")
    # the cells as written, for the baseline to copy unchanged
    assert got.table.cells == _rows(tiny_results / "results.csv")
    frame = got.table.frame(["scenario", "dt", "in_ladder"])
    assert list(frame.columns) == ["scenario", "dt", "in_ladder"] and len(frame) == len(got.table.rows)
    assert str(frame["dt"].dtype) == "float64" and str(frame["in_ladder"].dtype) == "bool"


def test_a_column_one_command_needs_is_said_with_why(tiny_results, tmp_path, capsys):
    """compare reads a results.csv without the report's columns (a compact baseline has no timings); the
    report says which it needs (before: a KeyError, a traceback) and still renders a directory written before
    the columns it only shows when present (engine_s)."""
    d = tmp_path / "d"
    shutil.copytree(tiny_results, d)
    _drop("in_ladder")(d)
    assert read_results_dir(d).table.rows
    capsys.readouterr()
    assert main(["report", str(d), "--jobs", "1"]) == 2
    err = capsys.readouterr().err
    assert "results.csv: columns in_ladder missing (the report shows them" in err and "Traceback" not in err
    old = tmp_path / "old"
    shutil.copytree(tiny_results, old)
    _drop("engine_s")(old)
    assert main(["report", str(old), "--jobs", "1"]) == 0


def test_an_empty_directory_names_both_files(tmp_path):
    with pytest.raises(ResultsReadError, match=r"results\.csv: missing, summary\.json: missing"):
        read_results_dir(tmp_path)
