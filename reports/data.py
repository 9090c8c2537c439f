"""Reading a results directory (docs/results.md): results.csv, summary.json and series/*.npz.

This is all the report knows about a sweep: it never runs a simulation nor imports an engine.
"""
from __future__ import annotations

import csv
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from cross_checks.core import tolerances as tol
from cross_checks.core.files import check_npz_size
from cross_checks.sweep.results_dir import inside, safe_file_stem
from cross_checks.sweep.schema import STATUSES

__all__ = ["Results", "ResultsError", "load_results", "read_summary", "LABELS"]

#: How the report names each quantity (cross_checks.core.quantities.QUANTITIES) in its sentences.
LABELS = {"position": "position", "velocity": "velocity", "orientation": "orientation",
          "angular_velocity": "angular velocity"}

_INT = {"steps"}
_BOOL = {"default_dt", "in_ladder", "cached"}
_STR = {"scenario", "engine", "status", "message", "reference", "engine_version", "energy_drift_kind",
        "step_defect_quantity"}
_REQUIRED = ("scenario", "engine", "dt", "steps", "wall_s", "pos_err_final", "vel_err_final",
             "orient_err_final", "angvel_err_final", "energy_drift_max", "angmom_drift_max", "status")


class ResultsError(ValueError):
    """A results directory that cannot be read; the message names the file and the reason."""


def _parse(col, text):
    if col in _STR:
        return text
    if col in _BOOL:
        return text.strip().lower() == "true"
    if col in _INT:
        return int(text) if text.strip() else 0
    return float(text) if text.strip() else math.nan


@dataclass
class Results:
    """A loaded results directory: ``rows`` (results.csv as typed dicts) and ``summary`` (summary.json)."""

    directory: Path
    rows: list
    summary: dict
    _series: dict = field(default_factory=dict, repr=False)
    _index: dict | None = field(default=None, repr=False)
    _records: dict = field(default_factory=dict, repr=False)

    @property
    def scenarios(self) -> list:
        return self.summary.get("scenarios", [])

    @property
    def variants(self) -> list:
        return [v["name"] for v in self.summary.get("variants", [])]

    def has_one_step(self, variant) -> bool:
        """Whether the variant's engine has a one-step mode (summary.json ``variants[].one_step``;
        results written before that key existed: True)."""
        return next((v.get("one_step", True)
                     for v in self.summary.get("variants", []) if v["name"] == variant), True)

    def scenario(self, name) -> dict:
        return next(s for s in self.scenarios if s["name"] == name)

    def rows_for(self, scenario, engine=None) -> list:
        """The rows of ``scenario`` (of one ``engine`` variant), in file order (indexed on first use)."""
        if self._index is None:
            self._index = {}
            for r in self.rows:
                self._index.setdefault((r["scenario"], None), []).append(r)
                self._index.setdefault((r["scenario"], r["engine"]), []).append(r)
        return list(self._index.get((scenario, engine), ()))

    def default_row(self, scenario, engine):
        dt = self.scenario(scenario)["dt_s"]
        return next((r for r in self.rows_for(scenario, engine) if r["dt"] == dt), None)

    def records(self, scenario=None, engine=None, quantity=None, mode="free_running") -> list:
        key = "convergence" if mode == "free_running" else "local_convergence"
        if (key, scenario) not in self._records:   # indexed by scenario once
            self._records[(key, scenario)] = [r for r in self.summary.get(key, [])
                                              if scenario is None or r["scenario"] == scenario]
        return [r for r in self._records[(key, scenario)]
                if (engine is None or r["engine"] == engine)
                and (quantity is None or r["quantity"] == quantity)]

    def series(self, scenario) -> dict:
        """``{variant: {field: array}}`` plus ``"reference"``, from
        series/<scenario>.npz (empty when absent)."""
        if scenario not in self._series:
            path = inside(self.directory, "series", f"{safe_file_stem(scenario)}.npz")
            out = {}
            if path.is_file():
                try:
                    check_npz_size(path, tol.SERIES_FILE_MAX_BYTES)   # from the headers, before any data
                    with np.load(path, allow_pickle=False) as d:
                        for k in d.files:
                            who, fld = k.split("::", 1)
                            out.setdefault(who, {})[fld] = np.asarray(d[k], dtype=float)
                except Exception as exc:  # noqa: BLE001 - zip, npy and dtype errors all mean "damaged"
                    raise ResultsError(f"{path}: cannot read: {type(exc).__name__}: {exc}") from None
                _check_series(path, out)
            self._series[scenario] = out
        return self._series[scenario]


_SERIES_WIDTH = {"t_s": 0, "x_W": 3, "q_WB": 4, "w_W": 3, "L_B": 3}


def _check_series(path, out) -> None:
    """Every series of one owner shares t_s's length; vectors have their width (ResultsError otherwise)."""
    for who, fields in out.items():
        if "t_s" not in fields:
            raise ResultsError(f"{path}: {who}::t_s: missing")
        n = fields["t_s"].shape
        for fld, a in fields.items():
            width = _SERIES_WIDTH.get(fld, 0)
            want = n if width == 0 else (n[0], width) if len(n) == 1 else None
            if len(n) != 1 or a.shape != want:
                raise ResultsError(f"{path}: {who}::{fld}: shape {a.shape} does not match {who}::t_s {n}")


def load_results(directory) -> Results:
    """Load a results directory; raises ResultsError naming the file and the reason."""
    d = Path(directory)
    if not d.is_dir():
        raise ResultsError(f"{d}: no such directory")
    sj = d / "summary.json"
    rc = d / "results.csv"
    for p in (sj, rc):
        if not p.is_file():
            raise ResultsError(f"{p}: missing (not an rbcheck results directory?)")
    summary = read_summary(sj, for_report=True)
    try:
        with rc.open(encoding="utf-8", newline="") as fh:
            reader = csv.DictReader(fh)
            missing = [c for c in _REQUIRED if c not in (reader.fieldnames or [])]
            if missing:
                raise ResultsError(f"{rc}: header: missing column(s) {', '.join(missing)}")
            rows = []
            for i, raw in enumerate(reader, start=2):
                rows.append(_parse_row(rc, i, raw))
    except OSError as exc:
        raise ResultsError(f"{rc}: cannot read: {exc}") from None
    except (csv.Error, UnicodeDecodeError) as exc:
        raise ResultsError(f"{rc}: cannot parse: {exc}") from None
    return Results(d, rows, summary)


def read_summary(sj: Path, for_report: bool = False) -> dict:
    """summary.json, checked against cross_checks.sweep.schema (ResultsError
    naming the file and the field)."""
    from cross_checks.sweep.schema import SchemaError, check_summary
    try:
        summary = json.loads(sj.read_text(encoding="utf-8"))
    except (OSError, ValueError, RecursionError) as exc:
        raise ResultsError(f"{sj}: cannot parse: {str(exc) or type(exc).__name__}") from None
    try:
        check_summary(summary, for_report=for_report)
    except SchemaError as exc:
        raise ResultsError(f"{sj}: {exc}") from None
    return summary


def _parse_row(rc, line, raw) -> dict:
    if None in raw:
        raise ResultsError(f"{rc}: line {line}: more cells than columns")
    row = {}
    for k, v in raw.items():
        try:
            row[k] = _parse(k, v if v is not None else "")
        except ValueError:
            raise ResultsError(f"{rc}: line {line}: {k}: not a number: {v[:40]!r}") from None
    if row["status"] not in STATUSES:
        raise ResultsError(f"{rc}: line {line}: status: must be one of "
                           f"{', '.join(STATUSES)}, got {row['status'][:40]!r}")
    if not (row["dt"] > 0 and math.isfinite(row["dt"])):
        raise ResultsError(f"{rc}: line {line}: dt: must be a positive finite number, got {row['dt']}")
    return row
