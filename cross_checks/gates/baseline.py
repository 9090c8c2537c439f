"""``rbcheck baseline RESULTS_DIR OUT_DIR``: the committed baseline, in a form a reviewer can read in a diff.

``results.csv`` without the timing columns (cells copied as text) and a compact ``summary.json``
(``"form": "compact baseline"``, records reduced to :data:`cross_checks.sweep.schema.COMPACT_LISTS`).
OUT_DIR is replaced as a whole (a staging sibling and two renames), and only when absent, empty, or
holding nothing but those two files; RESULTS_DIR is validated in full first, and what is written is read
back through compare's validation before it replaces anything. Contents and rules: docs/results.md,
"The baseline".
"""
from __future__ import annotations

import csv
import io
import json
import shutil
from pathlib import Path
from typing import NamedTuple

from cross_checks.core.files import atomic_write_text
from cross_checks.gates.compare import CompareInputError, read_results_dir
from cross_checks.sweep import reader
from cross_checks.sweep.jobs import RESULT_COLUMNS, TIMING_COLUMNS
from cross_checks.sweep.reader import ResultsReadError, ResultsTable
from cross_checks.sweep.results_dir import (
    ResultsDirError,
    check_writable_dir,
    fix_permissions,
    remove_stale_siblings,
    replace_dir,
    staging_dir,
    work_place,
)
from cross_checks.sweep.schema import COMPACT_FORM, COMPACT_LISTS

__all__ = ["BASELINE_COLUMNS", "BASELINE_FILES", "Baseline", "BaselineError", "compact_summary",
           "compact_summary_text", "compact_results_text", "write_baseline"]

#: results.csv's columns in a baseline: all but the timing columns, in results.csv's order.
BASELINE_COLUMNS = tuple(c for c in RESULT_COLUMNS if c not in TIMING_COLUMNS)
#: What a baseline directory holds (and all that ``rbcheck baseline`` ever replaces).
BASELINE_FILES = ("results.csv", "summary.json")
_WHY_COLUMNS = "a baseline keeps every result column; not written by this rbcheck's sweep?"


class BaselineError(ValueError):
    """RESULTS_DIR or OUT_DIR cannot be used (the message names the directory or file and the reason)."""


class Baseline(NamedTuple):
    """What :func:`write_baseline` wrote: the number of rows of results.csv and the compact summary."""

    rows: int
    summary: dict


def compact_summary(summary: dict) -> dict:
    """The compact form of a (validated) summary.json: schema version, form, provenance, and each list
    of :data:`COMPACT_LISTS` with every record reduced to its fields (those it has, in the spec's order)."""
    out = {"schema_version": summary["schema_version"],
           "form": COMPACT_FORM, "provenance": summary["provenance"]}
    for key, spec in COMPACT_LISTS.items():
        if key in summary:
            fields = [k.rstrip("?") for k in spec]
            out[key] = [{f: rec[f] for f in fields if f in rec} for rec in summary[key]]
    return out


def _member(key: str, value, last: bool) -> list:
    """Lines of one top-level member: a list one record per line, anything else as indented JSON."""
    comma = "" if last else ","
    head = f" {json.dumps(key)}: "
    if isinstance(value, list) and value:
        lines = [head + "["]
        lines += [f"  {json.dumps(rec, ensure_ascii=False, allow_nan=False)}"
                  f"{',' if i < len(value) - 1 else ''}"
                  for i, rec in enumerate(value)]
        return lines + [f" ]{comma}"]
    text = json.dumps(value, indent=1, ensure_ascii=False, allow_nan=False).replace("\n", "\n ")
    return [head + text + comma]


def compact_summary_text(compact: dict) -> str:
    """JSON with one record per line inside each list (a changed record is one changed line)."""
    items = list(compact.items())
    lines = ["{"]
    for i, (key, value) in enumerate(items):
        lines += _member(key, value, i == len(items) - 1)
    return "\n".join(lines + ["}"]) + "\n"


def compact_results_text(table: ResultsTable) -> str:
    """results.csv without the timing columns, every kept cell copied as it is written in ``table`` (read
    by cross_checks.sweep.reader with every column of :data:`BASELINE_COLUMNS`)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(BASELINE_COLUMNS)
    for r in table.cells:
        w.writerow([r[c] for c in BASELINE_COLUMNS])
    return buf.getvalue()


def _check_out_dir(results_dir: Path, out_dir: Path) -> Path:
    """The absolute OUT_DIR, when a baseline may be written there (BaselineError otherwise)."""
    out = out_dir.expanduser().resolve()
    if out == results_dir.resolve():
        raise BaselineError(f"OUT_DIR {out_dir}: is RESULTS_DIR; name "
                            "another directory (e.g. baselines/default)")
    if out.exists() and not out.is_dir():
        raise BaselineError(f"OUT_DIR {out_dir}: exists and is not a directory")
    if not out.parent.is_dir():
        raise BaselineError(f"OUT_DIR {out_dir}: parent directory {out.parent} does not exist")
    try:
        check_writable_dir(work_place(out), "OUT_DIR", str(out_dir))
    except ResultsDirError as exc:
        raise BaselineError(str(exc)) from None
    remove_stale_siblings(out)   # what a killed run left (inside OUT_DIR when it is a mount point)
    other = sorted(p.name for p in out.iterdir() if p.name not in BASELINE_FILES) if out.is_dir() else []
    if other:
        shown = ", ".join(other[:3]) + (f" and {len(other) - 3} more" if len(other) > 3 else "")
        raise BaselineError(f"OUT_DIR {out_dir}: holds more than a baseline ({shown}); refusing "
                            "to replace it: name a new or empty directory, or a baseline's")
    return out


def write_baseline(results_dir, out_dir) -> Baseline:
    """Write the compact baseline of ``results_dir`` (a results directory or a baseline) into ``out_dir``,
    replacing it as a whole. Raises BaselineError (unusable OUT_DIR) or
    CompareInputError (a damaged RESULTS_DIR, or — never expected — a baseline compare could not read)."""
    results_dir, out_dir = Path(results_dir), Path(out_dir)
    out = _check_out_dir(results_dir, out_dir)
    try:   # the one reader of a results directory, with every column a baseline keeps
        got = reader.read_results_dir(results_dir, need=BASELINE_COLUMNS, why=_WHY_COLUMNS)
    except ResultsReadError as exc:
        raise CompareInputError(str(exc)) from None
    compact = compact_summary(got.summary)
    csv_text, n_rows = compact_results_text(got.table), len(got.table.rows)
    staging = staging_dir(out)
    try:
        atomic_write_text(staging / "results.csv", csv_text)
        atomic_write_text(staging / "summary.json", compact_summary_text(compact))
        read_results_dir(staging)  # what compare will read must pass compare's validation
        fix_permissions(staging)
        replace_dir(staging, out, owned=set(BASELINE_FILES))
        staging = None
    finally:
        if staging is not None:
            shutil.rmtree(staging, ignore_errors=True)
    return Baseline(n_rows, compact)

