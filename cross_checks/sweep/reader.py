"""The one reader of a results directory (docs/results.md), for every command that reads one: ``rbcheck
compare`` (either side may be a compact baseline), ``rbcheck baseline`` and the report.

:func:`read_results_dir` reads ``results.csv`` into typed rows (one schema: :data:`RESULTS_CSV`, the type of
every column a sweep writes; :data:`REQUIRED_COLUMNS`, the columns every reader needs) and ``summary.json``
checked against cross_checks.sweep.schema; :func:`read_series` reads ``series/<scenario>.npz``. Anything
missing or damaged is a :class:`ResultsReadError` whose one line names the file, the field (a line and a
column, a JSON path, an array) and the reason — the commands exit 2 with it. A caller that needs more
columns than every reader does (the baseline copies each non-timing column; the report shows the timings)
names them with ``need=`` and gets the same message for them.
"""
from __future__ import annotations

import csv
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cross_checks.core import tolerances as tol
from cross_checks.core.files import check_npz_size
from cross_checks.sweep.jobs import RESULT_COLUMNS
from cross_checks.sweep.results_dir import inside, safe_file_stem
from cross_checks.sweep.schema import STATUSES, SchemaError, check_summary

__all__ = ["ResultsReadError", "ResultsTable", "ResultsDir", "REQUIRED_COLUMNS", "RESULTS_CSV", "KEY",
           "read_results_dir", "read_results_csv", "read_summary", "read_series", "SERIES_WIDTH"]

#: The columns every reader of results.csv needs — a row's identity and the metrics compare judges — held
#: by every results directory and every compact baseline (no timing columns) since the first schema.
REQUIRED_COLUMNS = ("scenario", "engine", "dt", "steps", "pos_err_final", "vel_err_final", "orient_err_final",
                    "angvel_err_final", "energy_drift_max", "angmom_drift_max", "status")
#: What identifies a row: no two rows of a results.csv share it.
KEY = ("scenario", "engine", "dt")
_NAME, _TEXT, _STATUS, _POSITIVE, _COUNT, _ERROR, _NUMBER, _FLAG = (
    "name", "text", "status", "positive", "count", "error", "number", "flag")
#: The type of each column of results.csv (cross_checks.sweep.jobs.RESULT_COLUMNS, docs/results.md):
#: ``name`` non-empty text; ``text`` any text; ``status`` one of STATUSES; ``positive`` a positive finite
#: number; ``count`` a whole number >= 0 (empty: 0); ``error`` a finite number >= 0 or empty (NaN: not
#: measured); ``number`` any number or empty (NaN); ``flag`` true / false. A column of no known type (a
#: newer rbcheck's) is kept as text.
RESULTS_CSV = {
    "scenario": _NAME, "engine": _NAME, "dt": _POSITIVE, "steps": _COUNT, "wall_s": _NUMBER,
    "engine_s": _NUMBER,
    **{c: _ERROR for c in ("pos_err_final", "vel_err_final", "orient_err_final", "angvel_err_final",
                           "pos_err_max", "vel_err_max", "orient_err_max", "angvel_err_max",
                           "energy_drift_max", "angmom_drift_max", "linmom_drift_max")},
    "energy_drift_final": _NUMBER, "energy_drift_kind": _TEXT,
    **{c: _NUMBER for c in ("pos_local_err", "vel_local_err", "orient_local_err", "angvel_local_err",
                            "step_defect_ratio", "step_defect_t_s", "diverged_at_s")},
    "step_defect_quantity": _TEXT, "status": _STATUS, "message": _TEXT,
    "default_dt": _FLAG, "in_ladder": _FLAG, "reference": _TEXT, "engine_version": _TEXT, "cached": _FLAG,
}
assert set(RESULTS_CSV) == set(RESULT_COLUMNS), "every column a sweep writes has its type here"
_NEED = {_POSITIVE: "a positive finite number", _COUNT: "a whole number >= 0",
         _ERROR: "a finite number >= 0 (or empty)"}


class ResultsReadError(ValueError):
    """A results directory (or compact baseline) that cannot be read: one line naming the file, the field
    and the reason."""


@dataclass
class ResultsTable:
    """results.csv, read and checked: ``columns`` (the header, in the file's order), ``rows`` (one dict per
    line, in file order, each column typed by :data:`RESULTS_CSV`) and ``cells`` (the same rows as the text
    written, for a caller that copies them unchanged)."""

    path: Path
    columns: list
    rows: list
    cells: list

    def frame(self, columns=None):
        """The rows as a pandas DataFrame of ``columns`` (default: every column), typed."""
        import pandas as pd
        cols = list(self.columns if columns is None else columns)
        return pd.DataFrame({c: [r[c] for r in self.rows] for c in cols}, columns=cols)


@dataclass
class ResultsDir:
    """A results directory read whole: its folder, results.csv (:class:`ResultsTable`) and summary.json."""

    directory: Path
    table: ResultsTable
    summary: dict


def read_results_dir(directory, *, need=(), why: str = "", for_report: bool = False) -> ResultsDir:
    """Read and check ``directory``'s results.csv and summary.json (a compact baseline's too, unless
    ``for_report``: a baseline holds no report data). ``need``: the columns the caller needs beside
    :data:`REQUIRED_COLUMNS`, ``why`` it does (said when one is missing). ResultsReadError otherwise."""
    d = Path(directory)
    if not d.is_dir():
        raise ResultsReadError(f"{d}: not a directory")
    csv_path, sj = d / "results.csv", d / "summary.json"
    if not csv_path.is_file() and not sj.is_file():
        raise ResultsReadError(f"{d}: results.csv: missing, summary.json: missing (not a results directory "
                               "written by `rbcheck sweep`?)")
    if not csv_path.is_file():
        raise ResultsReadError(f"{csv_path}: missing (is {d} a results directory written by "
                               "`rbcheck sweep`?)")
    # the summary first when there is one: it says what the directory is (a compact baseline, which holds
    # no report data, is refused as such, not for the timing columns it does not keep)
    summary = read_summary(sj, for_report=for_report) if sj.is_file() else None
    table = read_results_csv(csv_path, need=need, why=why)
    return ResultsDir(d, table, summary if summary is not None else read_summary(sj, for_report=for_report))


def read_summary(sj, *, for_report: bool = False) -> dict:
    """summary.json, checked against cross_checks.sweep.schema (ResultsReadError naming the field)."""
    sj = Path(sj)
    if not sj.is_file():
        raise ResultsReadError(f"{sj}: missing (every results directory written by `rbcheck sweep` has one)")
    try:
        summary = json.loads(sj.read_text(encoding="utf-8"))
    except OSError as exc:
        raise ResultsReadError(f"{sj}: cannot read: {exc.strerror or exc}") from None
    except (ValueError, RecursionError) as exc:   # UnicodeDecodeError is a ValueError
        raise ResultsReadError(f"{sj}: cannot parse JSON: {str(exc) or type(exc).__name__}") from None
    try:
        check_summary(summary, for_report=for_report)
    except SchemaError as exc:
        raise ResultsReadError(f"{sj}: {exc}") from None
    return summary


def read_results_csv(path, *, need=(), why: str = "") -> ResultsTable:
    """results.csv read and checked: every column of :data:`REQUIRED_COLUMNS` and ``need`` present, every
    cell of its column's type (:data:`RESULTS_CSV`), no two rows with one :data:`KEY`."""
    path = Path(path)
    try:
        with path.open(encoding="utf-8", newline="") as fh:
            reader = csv.DictReader(fh)
            header = list(reader.fieldnames or [])
            _check_header(path, header, need, why)
            rows, cells, seen = [], [], {}  # type: list, list, dict
            for line, raw in enumerate(reader, start=2):
                row = _typed_row(path, line, raw)
                key = tuple(row[c] for c in KEY)
                if key in seen:
                    raise ResultsReadError(f"{path}: line {line}: duplicate row for {key[0]}, {key[1]}, "
                                           f"dt={key[2]} (line {seen[key]} has it)")
                seen[key] = line
                rows.append(row)
                cells.append(raw)
    except OSError as exc:
        raise ResultsReadError(f"{path}: cannot read: {exc.strerror or exc}") from None
    except (csv.Error, UnicodeDecodeError) as exc:
        raise ResultsReadError(f"{path}: cannot parse: {' '.join(str(exc).split()) or type(exc).__name__}") \
            from None
    return ResultsTable(path, header, rows, cells)


def _check_header(path, header, need, why) -> None:
    missing = [c for c in REQUIRED_COLUMNS if c not in header]
    if missing:
        raise ResultsReadError(f"{path}: columns {', '.join(missing)} missing (every results.csv written by "
                               "`rbcheck sweep` has them)")
    missing = [c for c in need if c not in header]
    if missing:
        raise ResultsReadError(f"{path}: columns {', '.join(missing)} missing ({why or 'needed here'})")
    dup = next((c for c in header if header.count(c) > 1), None)
    if dup is not None:
        raise ResultsReadError(f"{path}: header: column {dup} appears twice")


def _typed_row(path, line, raw) -> dict:
    if None in raw:
        raise ResultsReadError(f"{path}: line {line}: more cells than columns")
    row = {}
    for col, text in raw.items():
        if text is None:
            raise ResultsReadError(f"{path}: line {line}: fewer cells than columns ({col}: missing)")
        row[col] = _cell(path, line, col, text)
    return row


def _cell(path, line, col, text):
    """One cell of results.csv as its column's type (ResultsReadError naming line, column and reason)."""
    kind = RESULTS_CSV.get(col, _TEXT)
    where = f"{path}: line {line}: {col}"
    if kind == _TEXT:
        return text
    if kind == _NAME:
        if not text.strip():
            raise ResultsReadError(f"{where}: empty")
        return text
    if kind == _STATUS:
        if text not in STATUSES:
            raise ResultsReadError(f"{where}: must be one of {', '.join(STATUSES)}, got {text[:40]!r}")
        return text
    if kind == _FLAG:
        return text.strip().lower() == "true"
    t = text.strip()
    if t == "":
        if kind == _POSITIVE:
            raise ResultsReadError(f"{where}: missing")
        return 0 if kind == _COUNT else math.nan
    try:
        v = float(t)
    except ValueError:
        raise ResultsReadError(f"{where}: not a number: {t[:40]!r}") from None
    if kind == _NUMBER or (kind == _ERROR and math.isnan(v)):
        return v
    ok = (math.isfinite(v) and (v > 0 if kind == _POSITIVE else v >= 0)
          and (kind != _COUNT or v == int(v)))
    if not ok:
        raise ResultsReadError(f"{where}: must be {_NEED[kind]}, got {t[:40]}")
    return int(v) if kind == _COUNT else v


#: The width of each vector field of a series (0: a scalar per sample, as t_s).
SERIES_WIDTH = {"t_s": 0, "x_W": 3, "q_WB": 4, "w_W": 3, "L_B": 3}


def read_series(directory, scenario) -> dict:
    """``{owner: {field: array}}`` of ``series/<scenario>.npz`` (owners: the variants and ``"reference"``;
    empty when the file is absent), every field of an owner as long as its ``t_s``, vectors of their width
    (ResultsReadError otherwise; the file is refused from its headers when too large to read)."""
    path = inside(Path(directory), "series", f"{safe_file_stem(scenario)}.npz")
    out: dict = {}
    if not path.is_file():
        return out
    try:
        check_npz_size(path, tol.SERIES_FILE_MAX_BYTES)   # from the headers, before any data
        with np.load(path, allow_pickle=False) as d:
            for k in d.files:
                who, fld = k.split("::", 1)
                out.setdefault(who, {})[fld] = np.asarray(d[k], dtype=float)
    except Exception as exc:  # noqa: BLE001 - zip, npy and dtype errors all mean "damaged"
        raise ResultsReadError(f"{path}: cannot read: {type(exc).__name__}: {exc}") from None
    for who, fields in out.items():
        if "t_s" not in fields:
            raise ResultsReadError(f"{path}: {who}::t_s: missing")
        n = fields["t_s"].shape
        for fld, a in fields.items():
            width = SERIES_WIDTH.get(fld, 0)
            want = n if width == 0 else (n[0], width) if len(n) == 1 else None
            if len(n) != 1 or a.shape != want:
                raise ResultsReadError(f"{path}: {who}::{fld}: shape {a.shape} does not match {who}::t_s {n}")
    return out
