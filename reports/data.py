"""A loaded results directory (docs/results.md): results.csv, summary.json and series/*.npz, read by the one
reader of a results directory (cross_checks.sweep.reader, which compare and baseline use too), with the
look-ups the report's pages and figures make.

This is all the report knows about a sweep: it never runs a simulation nor imports an engine.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from cross_checks.sweep import reader
from cross_checks.sweep.reader import ResultsReadError

__all__ = ["Results", "ResultsError", "load_results", "LABELS", "REPORT_COLUMNS"]

#: How the report names each quantity (cross_checks.core.quantities.QUANTITIES) in its sentences.
LABELS = {"position": "position", "velocity": "velocity", "orientation": "orientation",
          "angular_velocity": "angular velocity"}
#: The columns of results.csv the report reads by name, beside those every reader needs
#: (cross_checks.sweep.reader.REQUIRED_COLUMNS); the others (engine_s, the step defect, the divergence time,
#: the maxima) it shows when present, so that a results directory written before them still renders.
REPORT_COLUMNS = ("wall_s", "default_dt", "in_ladder", "cached", "message", "energy_drift_kind",
                  "pos_local_err", "vel_local_err", "orient_local_err", "angvel_local_err")
_WHY_COLUMNS = "the report shows them; run the sweep again with this rbcheck"


class ResultsError(ValueError):
    """A results directory that cannot be read; the message names the file and the reason."""


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
            try:
                self._series[scenario] = reader.read_series(self.directory, scenario)
            except ResultsReadError as exc:
                raise ResultsError(str(exc)) from None
        return self._series[scenario]


def load_results(directory) -> Results:
    """Load a results directory; raises ResultsError naming the file, the field and the reason."""
    try:
        got = reader.read_results_dir(directory, need=REPORT_COLUMNS, why=_WHY_COLUMNS, for_report=True)
    except ResultsReadError as exc:
        raise ResultsError(str(exc)) from None
    return Results(got.directory, got.table.rows, got.summary)
