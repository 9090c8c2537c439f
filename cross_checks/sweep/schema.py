"""What a summary.json must hold for ``report`` and ``compare`` to use it: every field they read,
with its type, checked once when the directory is loaded, so a damaged or hand-edited file is one
line naming the file, the field and the reason (exit 2) instead of a traceback while rendering.

A spec is a type (``str``, ``NUM`` = int or float, ``bool``, ``int``), ``[spec]`` (a list of spec),
a dict ``{key: spec}`` (keys ending in ``?`` are optional), or ``Nullable(spec)`` (null allowed).
Extra keys are allowed everywhere (docs/results.md: keys may be added, never renamed).

A compact baseline (``rbcheck baseline``, docs/results.md "The baseline") says ``"form": "compact
baseline"`` and keeps, of each record, the fields of the ``COMPACT_*`` specs (in their order): what
``compare`` reads plus what a reviewer needs to see a verdict change. It has no report data.
"""
from __future__ import annotations

import math
import numbers

__all__ = ["SchemaError", "check", "SUMMARY", "CONVERGENCE_RECORD", "QUANTITIES", "VERDICTS", "STATUSES",
           "KNOWN_SCHEMA_VERSION", "check_summary", "COMPACT_FORM", "COMPACT_SUMMARY", "COMPACT_LISTS"]

QUANTITIES = ("position", "orientation", "velocity", "angular_velocity")
VERDICTS = ("converges", "does_not_converge", "at_roundoff", "diverged", "failed", "insufficient")
STATUSES = ("ok", "diverged", "failed")
#: Version of the results-directory layout and of the cached job records this code writes.
SCHEMA_VERSION = 1
#: The results schema this code reads (the one it writes; kept equal by a test).
KNOWN_SCHEMA_VERSION = SCHEMA_VERSION


class SchemaError(ValueError):
    """``str()`` is ``FIELD: REASON``."""


class Nullable:
    def __init__(self, spec):
        self.spec = spec


class _Num:
    """A finite or non-finite JSON number (not a bool)."""


NUM = _Num
_NAMES = {str: "a string", bool: "true or false", int: "a whole number", NUM: "a number", dict: "an object",
          list: "a list"}


def _type_ok(v, t) -> bool:
    if t is NUM:
        return isinstance(v, numbers.Real) and not isinstance(v, bool)
    if t is int:
        return isinstance(v, int) and not isinstance(v, bool)
    return isinstance(v, t)


def _show(v) -> str:
    s = repr(v)
    return s if len(s) <= 40 else s[:37] + "..."


def check(obj, spec, where: str) -> None:
    """Raise SchemaError naming the first field of ``obj`` that does not follow ``spec``."""
    if isinstance(spec, Nullable):
        if obj is not None:
            check(obj, spec.spec, where)
        return
    if isinstance(spec, dict):
        if not isinstance(obj, dict):
            raise SchemaError(f"{where}: must be an object, got {_show(obj)}")
        for key, sub in spec.items():
            optional = key.endswith("?")
            k = key.rstrip("?")
            if k not in obj:
                if optional:
                    continue
                raise SchemaError(f"{where}.{k}: missing")
            check(obj[k], sub, f"{where}.{k}")
        return
    if isinstance(spec, list):
        if not isinstance(obj, list):
            raise SchemaError(f"{where}: must be a list, got {_show(obj)}")
        for i, e in enumerate(obj):
            check(e, spec[0], f"{where}[{i}]")
        return
    if isinstance(spec, tuple):  # a choice of string values
        if obj not in spec:
            raise SchemaError(f"{where}: must be one of {', '.join(spec)}, got {_show(obj)}")
        return
    if not _type_ok(obj, spec):
        raise SchemaError(f"{where}: must be {_NAMES[spec]}, got {_show(obj)}")


_CONSERVED = {"conserved": bool, "why_not": str}
SCENARIO = {
    "name": str, "description": str, "source": str, "content_hash": str, "duration_s": NUM, "dt_s": NUM,
    "dt_ladder_s": [NUM], "reference": str,
    "conserved": {"energy": _CONSERVED, "angular_momentum": _CONSERVED, "linear_momentum": _CONSERVED},
    "varies?": {q + "?": bool for q in QUANTITIES},
    "mass_kg?": NUM, "inertia_B_kg_m2?": [[NUM]],   # the body (the report's polhode and animation)
    # Drake's error-controlled solution beside the primary reference (None without Drake; docs/results.md)
    "second_reference?": Nullable({"label": str, "target_accuracy": NUM, "agrees": Nullable(bool),
                                   "distance?": {q: NUM for q in QUANTITIES},
                                   "stated_accuracy?": {q: NUM for q in QUANTITIES}, "error?": str}),
}
CONVERGENCE_RECORD = {
    "scenario": str, "engine": str, "quantity": QUANTITIES, "order": Nullable(NUM), "verdict": str,
    "pairwise_orders?": [Nullable(NUM)], "dt_s?": [NUM], "errors?": [Nullable(NUM)],
    "floors?": [Nullable(NUM)], "fitted?": [bool], "note?": str, "expected_order?": Nullable(NUM),
    "expected_verdict?": Nullable(str), "matches_expectation?": Nullable(bool), "assessment?": str,
    "reason?": str,
}
#: What the report needs beyond what compare needs.
REPORT_RECORD = {"expected_verdict": Nullable(str), "matches_expectation": Nullable(bool), "assessment": str,
                 "note": str, "reason": str, "dt_s": [NUM], "errors": [Nullable(NUM)],
                 "floors": [Nullable(NUM)], "fitted": [bool], "pairwise_orders": [Nullable(NUM)]}
#: A long run's record (docs/results.md, "Long runs"): what the report's integrators page reads.
LONG_RUN_RECORD = {
    "scenario": str, "engine": str, "dt": NUM, "steps": int, "status": STATUSES, "verdict": str,
    "matches_expectation": Nullable(bool), "finding": str, "assessment": str, "reason?": str,
    "expected_keeps?": [str], "expected_separatrix?": str,
    **{k + "?": Nullable(NUM) for k in (
        "duration_s", "diverged_at_s", "energy_rate_per_s", "energy_drift_max", "momentum_rate_per_s",
        "momentum_drift_max", "direction_drift_max_rad", "separatrix_start", "separatrix_end",
        "separatrix_rate_per_s")},
}
LONG_RUN_SCENARIO = {"name": str, "description": str, "duration_s": NUM, "dt_s": NUM, "steps": int,
                     "content_hash?": str, "source?": str, "inertia_B_kg_m2?": [[NUM]]}
AGREEMENT = {"a": str, "b": str, "scenario": str, "dt_s": NUM, "agrees": bool, "max_rel": Nullable(NUM),
             "reason": str, "note?": str}
#: An invariance check that does not hold (docs/invariance.md): summary.json's ``invariance`` list.
INVARIANCE_RECORD = {"engine": str, "scenario": str, "transform": str, "magnitude": str, "verdict": str,
                     "worst_quantity": str, "worst_ratio": Nullable(NUM), "assessment": str,
                     "declared?": str}
#: A declared invariance finding's outcome over the checks it covers: summary.json's ``invariance_declared``.
INVARIANCE_DECLARED = {"engine": str, "transform": str, "checks": int, "known_findings": int, "beyond": int,
                       "verdict": str}
SUMMARY = {
    "schema_version": int,
    "provenance": {k + "?": Nullable(str)
                   for k in ("rbcheck", "numpy", "scipy", "mujoco", "pybullet", "drake", "python",
                             "platform", "machine", "numerics", "git_commit", "started_at", "command")},
    "convergence": [CONVERGENCE_RECORD],
    "scenarios?": [SCENARIO],
    "variants?": [{"name": str, "description?": Nullable(str), "version?": Nullable(str)}],
    "skipped_variants?": [{"name": str, "reason": str, "installed?": bool, "required?": bool}],
    "not_expressible?": [{"scenario": str, "engine": str, "reason": str}],
    "local_convergence?": [CONVERGENCE_RECORD],
    "agreement?": [AGREEMENT],
    "long_run_scenarios?": [LONG_RUN_SCENARIO],
    "long_runs?": [LONG_RUN_RECORD],
    "invariance?": [INVARIANCE_RECORD],
    "invariance_declared?": [INVARIANCE_DECLARED],
    "reproducers?": [{"engine": str, "scenario": str, "claim": str, "file": str, "note?": str}],
    "run?": {k + "?": Nullable(NUM) for k in ("jobs", "runs", "cached_runs", "diverged_runs", "failed_runs",
                                               "wall_s", "cpu_s_in_runs", "engine_s_in_runs",
                                               "compile_s")},
}


#: summary.json's ``form`` in a compact baseline (a full results directory has no ``form``).
COMPACT_FORM = "compact baseline"
COMPACT_CONVERGENCE = {
    "scenario": str, "engine": str, "quantity": QUANTITIES, "verdict": str, "order": Nullable(NUM),
    "fit_verdict?": str, "expected_verdict?": Nullable(str), "expected_order?": Nullable(NUM),
    "matches_expectation?": Nullable(bool), "assessment?": str,
}
#: The lists a compact baseline keeps, each record reduced to its spec's fields.
COMPACT_LISTS = {
    "scenarios": {"name": str, "content_hash": str, "reference": str, "duration_s": NUM, "dt_s": NUM,
                  "dt_ladder_s": [NUM], "second_reference?": SCENARIO["second_reference?"]},
    "variants": {"name": str, "version?": Nullable(str), "declared_order?": Nullable(NUM)},
    "skipped_variants": {"name": str, "reason": str, "installed?": bool, "required?": bool},
    "not_expressible": {"scenario": str, "engine": str, "reason": str},
    "convergence": COMPACT_CONVERGENCE,
    "local_convergence": COMPACT_CONVERGENCE,
    "agreement": {"a": str, "b": str, "scenario": str, "dt_s": NUM, "agrees": bool, "max_rel": Nullable(NUM),
                  "note?": str},
    "invariance": INVARIANCE_RECORD,
    "invariance_declared": INVARIANCE_DECLARED,
}
COMPACT_SUMMARY = {"schema_version": int, "form": (COMPACT_FORM,), "provenance": SUMMARY["provenance"],
                   "convergence": [COMPACT_CONVERGENCE],
                   **{f"{k}?": [spec] for k, spec in COMPACT_LISTS.items() if k != "convergence"}}


def _unique(items, key, where, what):
    seen = set()
    for i, it in enumerate(items):
        k = key(it)
        if k in seen:
            raise SchemaError(f"{where}[{i}]: {what} {', '.join(map(str, k)) if isinstance(k, tuple) else k} "
                              "appears twice")
        seen.add(k)


def check_summary(summary, for_report: bool = False) -> None:
    """SchemaError (FIELD: REASON) unless ``summary`` is a summary.json this code can use: a full one,
    or (not ``for_report``) a compact baseline's."""
    compact = isinstance(summary, dict) and "form" in summary
    if compact and for_report and summary["form"] == COMPACT_FORM:
        raise SchemaError("summary.form: a compact baseline (written by `rbcheck baseline`) "
                          "holds no report data; render the results directory it was made from")
    check(summary, COMPACT_SUMMARY if compact else SUMMARY, "summary")
    v = summary["schema_version"]
    if not 1 <= v <= KNOWN_SCHEMA_VERSION:
        newer = "; written by a newer rbcheck?" if v > KNOWN_SCHEMA_VERSION else ""
        raise SchemaError(f"summary.schema_version: {v} is not a results schema this rbcheck reads "
                          f"(1..{KNOWN_SCHEMA_VERSION}){newer}")
    for key in ("convergence", "local_convergence"):
        recs = summary.get(key, [])
        _unique(recs, lambda r: (r["scenario"], r["engine"], r["quantity"]), f"summary.{key}", "record")
        for i, r in enumerate(recs):
            if r["order"] is not None and not math.isfinite(r["order"]):
                raise SchemaError(f"summary.{key}[{i}].order: must be a "
                                  f"finite number or null, got {r['order']}")
            if for_report:
                check(r, REPORT_RECORD, f"summary.{key}[{i}]")
    if for_report:
        for key in ("scenarios", "variants"):
            if key not in summary:
                raise SchemaError(f"summary.{key}: missing")
        _unique(summary["scenarios"], lambda s: s["name"], "summary.scenarios", "scenario")
        _unique(summary["variants"], lambda s: s["name"], "summary.variants", "variant")
        for i, s in enumerate(summary["scenarios"]):
            if not s["name"]:
                raise SchemaError(f"summary.scenarios[{i}].name: must not be empty")
            if not (s["dt_s"] > 0 and math.isfinite(s["dt_s"])):
                raise SchemaError(f"summary.scenarios[{i}].dt_s: must be a "
                                  f"positive finite number, got {s['dt_s']}")
