"""Assembling a sweep's results from its job records: the rows of results.csv, the convergence records
(fits against measured floors, judged against the expectations), the agreement of variants that
implement the same scheme, the scenario records, the plotted series, and summary.json — every file of
docs/results.md except the report. Pure functions of the records: nothing here runs a simulation."""
from __future__ import annotations

import csv
import io
import json
import math
import re
from pathlib import Path

import numpy as np

from cross_checks.analysis import metrics as M
from cross_checks.analysis.expectations import (
    EQUIVALENT_PAIRS,
    expectation,
    pair_is_same_arithmetic,
)
from cross_checks.analysis.judge import LocalEvidence, judge_ladder
from cross_checks.core import tolerances as tol
from cross_checks.core.files import atomic_write_text, json_default
from cross_checks.core.quantities import (
    COLUMN_STEM,
    QUANTITIES,
    UNITS,
    decimation_indices,
    quantity_scales,
    state_errors,
)
from cross_checks.sweep.jobs import MAX_SERIES_POINTS, RESULT_COLUMNS, SCHEMA_VERSION, load_reference
from reference_sim.state import Q

__all__ = ["result_rows", "results_csv_text", "convergence_records", "ladder_floors", "agreement_records",
           "scenario_record", "series_arrays", "build_summary", "write_json", "write_scenario_files",
           "SCENARIO_FILES", "local_evidence", "verdict_count", "normalise_message", "body_record"]


# --- results.csv ------------------------------------------------------------------------------------

def result_rows(records, scenario_names, variants) -> list:
    """The rows of the job ``records`` in results.csv's order: scenario, variant (as given), Δt descending."""
    order_v = {v: i for i, v in enumerate(variants)}
    return sorted((rec["row"] for rec in records.values()),
                  key=lambda r: (scenario_names.index(r["scenario"]),
                                 order_v.get(r["engine"], 1e9), -r["dt"]))


def _fmt(v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (float, np.floating)):
        v = float(v)
        return "" if math.isnan(v) else repr(v)
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    return "" if v is None else str(v)


def results_csv_text(rows, columns=RESULT_COLUMNS) -> str:
    """results.csv of ``rows`` (dicts): ``columns`` in order, floats as their
    shortest exact repr, NaN empty."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(columns)
    for r in rows:
        w.writerow([_fmt(r.get(c)) for c in columns])
    return buf.getvalue()


# --- convergence ------------------------------------------------------------------------------------

def ladder_floors(ladder, q, scales, mode, label, measured, variant):
    """Round-off floor of each ladder point for quantity ``q``: the one rule of the sweep and the fuzz,
    :func:`cross_checks.analysis.metrics.run_floor` of ``variant`` — the reference's MEASURED error (at the
    final time, or of one step in the one-step mode) plus the run's own round-off in the variant's
    rounding unit, amplified by the scenario's measured error amplification; the differencing floor of a
    variant that recomputes its velocity from positions.

    The lever-arm term (metrics.lever_floor) is given when the reference's measurements hold lever arms
    (``measured["lever_arms"]``: metrics.lever_arms); the sweep does not measure them yet. Its model, which
    the fuzz's random cases need (docs/fuzz.md §5), is far above what the catalog's engines pay on the
    catalog's motions: on applied_torque (a body falling 15.7 m) it is 9e-12 … 3.1e-11 rad in the orientation
    over the ladder, while mujoco:rk4's errors fall on a clean order-4 line to 2.3e-13 rad — 130× below it —
    and would lose their resolved rungs (docs/verdicts.md §1)."""
    free = mode == "free_running"
    lever = measured.get("lever_arms")
    if free:
        amp = measured.get("amplification", {}).get(q, 1.0)
        ref = (measured.get("reference_error") or {}).get(q)
        return [M.run_floor(variant, q, max(int(r["steps"]), 1), float(r["dt"]), scales, ref,
                            amplification=amp, lever=lever, reference_label=label) for r in ladder]
    local = measured.get("local_reference_error") or {}
    return [M.run_floor(variant, q, 1, float(r["dt"]), scales,
                        (local.get(repr(float(r["dt"]))) or {}).get(q), lever=lever, reference_label=label)
            for r in ladder]


def _ladder_errors(ladder, q, mode):
    """``(errors, statuses)`` of quantity ``q`` over the ladder: the final errors of the free runs, or
    the one-step errors (a point counts when its one-step error was measured)."""
    stem = COLUMN_STEM[q]
    if mode == "free_running":
        return [r[f"{stem}_err_final"] for r in ladder], [r["status"] for r in ladder]
    errs = [r[f"{stem}_local_err"] for r in ladder]
    statuses = ["ok" if r["status"] in ("ok", "diverged") and np.isfinite(e) else "failed"
                for r, e in zip(ladder, errs)]
    return errs, statuses


def local_evidence(rows, variant) -> LocalEvidence | None:
    """The worst one-step defect of the runs ``rows`` of one (scenario, ``variant``), measured on their own
    recorded states (results.csv's ``step_defect_*``), or None when no run has it."""
    have = [r for r in rows
            if isinstance(r.get("step_defect_ratio"), float) and math.isfinite(r["step_defect_ratio"])]
    if not have:
        return None
    worst = max(have, key=lambda r: r["step_defect_ratio"])
    return LocalEvidence(worst["step_defect_ratio"], worst["step_defect_quantity"],
                         worst["dt"], variant.order)


def convergence_records(scenario, variant, rows, scales, mode, measured=None) -> list:
    """Convergence records of one (scenario, variant), one per quantity: the fit over the ladder against
    floors from measurement (:func:`ladder_floors`) and the expectation decided from the scenario's measured
    physics (:func:`cross_checks.analysis.judge.judge_ladder`, the one judge; the fit's own verdict is kept in
    ``fit_verdict``). ``mode`` is
    ``free_running`` (final errors) or ``one_step`` (local errors)."""
    from cross_checks.analysis.physics import physics_from_dict
    measured = measured or {}
    phys = physics_from_dict(measured["physics"]) if measured.get("physics") else None
    ladder = sorted([r for r in rows if r["in_ladder"]], key=lambda r: -r["dt"])
    if len(ladder) < 2:
        return []
    dts = [r["dt"] for r in ladder]
    label = next((r["reference"] for r in ladder if r["reference"]), "analytic")
    local = local_evidence(rows, variant)
    out = []
    for q in QUANTITIES:
        errs, statuses = _ladder_errors(ladder, q, mode)
        exp = expectation(scenario, variant, q, mode, physics=phys, measure_physics=False)
        floors = ladder_floors(ladder, q, scales, mode, label, measured, variant)
        j = judge_ladder(dts, errs, floors, statuses, exp, local, q)
        fit, verdict, matches, phrase = j.fit, j.verdict, j.matches, j.assessment
        out.append({
            "scenario": scenario.name, "engine": str(variant), "quantity": q, "mode": mode,
            "order": fit.order, "pairwise_orders": fit.pairwise_orders, "verdict": verdict,
            "fit_verdict": fit.verdict,
            "dt_s": fit.dt_s, "errors": [None if not np.isfinite(e) else e for e in fit.errors],
            "floors": fit.floors, "fitted": fit.fitted, "order_is_lower_bound": fit.order_is_lower_bound,
            "note": fit.note, "unit": UNITS[q],
            **exp.as_dict(), "matches_expectation": matches, "assessment": phrase,
        })
    return out


# --- agreement of same-scheme variants --------------------------------------------------------------

def _agreement(a, b, reason, sc, ra, rb, ref=None) -> dict:
    """The agreement record of variants ``a`` and ``b`` (records ``ra``, ``rb``) on scenario ``sc``: their
    final states within :func:`cross_checks.analysis.metrics.same_scheme_allowance` (the fuzz's rule too) of
    the default Δt's steps, relative to the reference ``ref``'s scales and grown by its measured
    amplification (without ``ref``: the scales of b's final state, no amplification)."""
    rec = {"a": a, "b": b, "scenario": sc.name, "dt_s": sc.dt_s, "differences": None, "max_rel": None}
    ta, tb = ra["row"].get("diverged_at_s"), rb["row"].get("diverged_at_s")
    if ra["row"]["status"] == "diverged" == rb["row"]["status"] and ta is not None and tb is not None:
        return {**rec, "agrees": M.diverged_together(ta, tb, sc.dt_s), "reason": reason,
                "note": f"both diverged, at t = {float(ta):.6g} s and {float(tb):.6g} s"}
    if ra["y_final"] is None or rb["y_final"] is None:
        return {**rec, "agrees": False, "reason": reason, "note": "one of the runs did not finish"}
    ya, yb = np.array([ra["y_final"]]), np.array([rb["y_final"]])
    d = {q: float(v[0]) for q, v in state_errors(ya, yb).items()}
    if ref is not None and not ref.error:
        scales, amp = ref.scales, max((ref.measured or {}).get("amplification", {}).values(), default=1.0)
    else:
        scales, amp = quantity_scales(yb), 1.0
    mx, _ = M.same_scheme_difference(d, scales)
    allowed = M.same_scheme_allowance(sc.n_steps(), max(a.rounding_unit, b.rounding_unit), amp)
    return {**rec, "differences": d, "max_rel": mx, "agrees": bool(mx <= allowed),
            "reason": reason, "tolerance": allowed, "note": ""}


def agreement_records(scenarios, variants, records_by_key, refs=None) -> list:
    """Final-state differences of the pairs that implement the same scheme, both among the sweep's
    ``variants`` (Resolved), at each default Δt — only between runs that both ran to the end (two failed
    runs, or one, make no claim either way: their failures are rows of their own). ``refs``: each
    scenario's reference (execute.ScenarioReference, in the order of ``scenarios``), whose scales and
    amplification the allowance is measured in."""
    out = []
    refs = dict(zip((sc.name for sc in scenarios), refs)) if refs is not None else {}
    have = {v: v for v in variants}   # the sweep's own Resolved variants, looked up by name
    for a, b, reason in EQUIVALENT_PAIRS:
        if a not in have or b not in have:
            continue
        a, b = have[a], have[b]
        for sc in scenarios:
            ra = records_by_key.get((sc.name, a, sc.dt_s))
            rb = records_by_key.get((sc.name, b, sc.dt_s))
            if ra is None or rb is None or "failed" in (ra["row"]["status"], rb["row"]["status"]):
                continue
            if pair_is_same_arithmetic(sc, a, b):
                out.append(_agreement(a, b, reason, sc, ra, rb, refs.get(sc.name)))
    return out


# --- scenarios and series ---------------------------------------------------------------------------

def scenario_record(sc, ref) -> dict:
    """summary.json's record of a scenario and its reference (a :class:`execute.ScenarioReference`)."""
    cons = M.conserved(sc.problem.forces)
    meas = ref.measured or {}
    return {"name": sc.name, "description": sc.description, "source": sc.source,
            "content_hash": sc.content_hash, "duration_s": sc.duration_s, "dt_s": sc.dt_s,
            "dt_ladder_s": list(sc.dt_ladder_s), "reference": ref.label, "scales": ref.scales,
            "conserved": {k: {"conserved": v[0], "why_not": v[1]} for k, v in cons.items()},
            "error_amplification": meas.get("amplification", {}),
            "reference_error": meas.get("reference_error"), "physics": meas.get("physics"),
            "varies": ref.varies, "second_reference": meas.get("second_reference"),
            **body_record(sc.problem.body)}


def body_record(body) -> dict:
    """The body's mass (kg) and inertia tensor about the COM in body axes (kg m²): what the report's
    polhode and animation draw the body from (docs/results.md)."""
    return {"mass_kg": float(body.mass_kg),
            "inertia_B_kg_m2": np.asarray(body.inertia_B, dtype=float).tolist()}


def series_arrays(sc, ref, records_by_key, variants) -> dict:
    """series/<scenario>.npz: the reference (unless it failed) and every variant's series at the
    scenario's default Δt, as ``<owner>::<field>`` float32 arrays."""
    arrays = {}
    if not ref.error:
        t_ref, y_ref, _ = load_reference(ref.path)
        grid = np.searchsorted(t_ref, sc.dt_s * np.arange(sc.n_steps() + 1))
        k = grid[decimation_indices(len(grid), MAX_SERIES_POINTS)]
        arrays["reference::t_s"] = t_ref[k].astype(np.float32)
        arrays["reference::x_W"] = y_ref[k, 0:3].astype(np.float32)
        arrays["reference::q_WB"] = y_ref[k][:, Q].astype(np.float32)
        arrays["reference::w_W"] = y_ref[k, 10:13].astype(np.float32)   # rad/s, world axes
    for v in variants:
        rec = records_by_key.get((sc.name, v, sc.dt_s))
        for key, a in ((rec or {}).get("series") or {}).items():
            arrays[f"{v}::{key}"] = np.asarray(a, dtype=np.float32)
    return arrays


#: Where the results directory keeps each scenario's TOML (docs/results.md): ``scenarios/<name>.toml``.
SCENARIO_FILES = "scenarios"


def _source_text(sc):
    """The text of the file ``sc`` was parsed from, or None when it is gone or no longer parses to the
    same scenario (edited since: the copy must be the file that ran)."""
    from cross_checks.scenario import ScenarioError, catalog_path, parse_scenario
    src = sc.source
    try:
        text = (catalog_path(src[len("catalog:"):]) if src.startswith("catalog:") else Path(src)).read_text(
            encoding="utf-8")
        same = parse_scenario(text, source=src).content_hash == sc.content_hash
    except (OSError, UnicodeDecodeError, ValueError, ScenarioError):
        return None
    return text if same else None


def write_scenario_files(directory, scenarios) -> None:
    """Copy each scenario's TOML into ``directory/scenarios/<name>.toml`` (the report links it); a
    scenario whose file cannot be read back unchanged gets no copy (its page says so)."""
    out = Path(directory) / SCENARIO_FILES
    out.mkdir(exist_ok=True)
    for sc in scenarios:
        text = _source_text(sc)
        if text is not None:
            atomic_write_text(out / f"{sc.name}.toml", text)


# --- summary.json -----------------------------------------------------------------------------------

def _run_statistics(jobs, rows, wall_s) -> dict:
    return {"jobs": jobs, "runs": len(rows), "cached_runs": sum(1 for r in rows if r.get("cached")),
            "diverged_runs": sum(1 for r in rows if r["status"] == "diverged"),
            "failed_runs": sum(1 for r in rows if r["status"] == "failed"),
            "wall_s": round(wall_s, 3),
            "cpu_s_in_runs": round(float(np.nansum([r["wall_s"] for r in rows if not r.get("cached")]
                                                   or [0.0])), 3),
            # the part of it inside the engines' own steps (runs whose engine time is measured)
            "engine_s_in_runs": round(float(np.nansum([r.get("engine_s", np.nan) for r in rows
                                                      if not r.get("cached")] or [0.0])), 3),
            "tolerances": {"same_scheme_rel": tol.SAME_SCHEME_REL, "order_tol": tol.SWEEP_ORDER_TOL,
                           "converges_min_order": tol.CONVERGES_MIN_ORDER}}


def _skipped_records(skipped: dict) -> list:
    """The variants the sweep left out: why, and whether each one's engine is an optional one that is simply
    not installed (``installed`` false, ``required`` false: compare counts its baseline rows as not
    compared) or one that is installed and broken (its rows are missing)."""
    if not skipped:
        return []
    from cross_checks.engines import all_variants
    infos = {v.name: v for v in all_variants()}
    return [{"name": name, "reason": reason,
             "installed": infos[name].installed if name in infos else True,
             "required": infos[name].required if name in infos else False}
            for name, reason in skipped.items()]


def build_summary(*, provenance, scenarios, variants, skipped, convergence, local, agreement, rows, jobs,
                  wall_s, cannot=None) -> dict:
    """summary.json (docs/results.md): ``scenarios`` are scenario records, ``variants`` variant records."""
    return {
        "schema_version": SCHEMA_VERSION,
        "provenance": provenance,
        "scenarios": scenarios,
        "variants": variants,
        "skipped_variants": _skipped_records(skipped),
        "not_expressible": [{"scenario": s, "engine": v, "reason": why}
                            for (s, v), why in (cannot or {}).items()],
        "convergence": convergence,
        "local_convergence": local,
        "agreement": agreement,
        "run": _run_statistics(jobs, rows, wall_s),
        "files": {"results": "results.csv",
                  "series": "series/<scenario>.npz: keys '<ENGINE:VARIANT>::<field>' "
                  "(t_s, x_W, q_WB, w_W, err_<quantity>, drift_<quantity>) and 'reference::<field>', "
                  "float32, "
                  "at the scenario's default dt, decimated to <= %d points" % MAX_SERIES_POINTS},
    }


def _nan_to_none(o):
    if isinstance(o, float) and not math.isfinite(o):
        return None
    if isinstance(o, dict):
        return {k: _nan_to_none(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_nan_to_none(v) for v in o]
    return o


def write_json(path, obj) -> None:
    """``obj`` as JSON (indent 1; NaN and infinities as null), written atomically."""
    atomic_write_text(path, json.dumps(_nan_to_none(obj), indent=1, sort_keys=False, default=json_default,
                                       allow_nan=False) + "\n")


def verdict_count(summary) -> tuple:
    """``(verdicts, not as expected)`` of a summary: every convergence verdict, same-scheme agreement,
    agreement of a scenario's two references and long-run verdict the sweep judged, and how many of them
    contradict what is expected — the one count the terminal, the report and the CI formats give."""
    conv = [r for r in summary.get("convergence", []) if r.get("matches_expectation") is not None]
    agree = summary.get("agreement", [])
    refs = [sc["second_reference"]
            for sc in summary.get("scenarios", []) if (sc.get("second_reference") or {})
            .get("agrees") is not None]
    long = [r for r in summary.get("long_runs", []) if r.get("matches_expectation") is not None]
    total = len(conv) + len(agree) + len(refs) + len(long)
    wrong = (sum(r["matches_expectation"] is False for r in conv) + sum(not a.get("agrees") for a in agree)
             + sum(r["agrees"] is False for r in refs) + sum(r["matches_expectation"] is False for r in long))
    return total, wrong


#: A run's private temporary directory as an engine-file command's words may name it (``rbcheck-NAME-XXXX``,
#: created by cross_checks/engines/external.py for each run): replaced by what it stands for, so the same
#: reason on every run reads as one.
_PRIVATE = re.compile(r"(?:/[^\s'\"]*)?/rbcheck-[A-Za-z0-9_.-]+-[A-Za-z0-9_]+/(work|out|scenario\.json)")
_PRIVATE_WORDS = {"work": "<its working directory>", "out": "<the directory of {out_csv}>",
                  "scenario.json": "{scenario_json}"}


def normalise_message(message) -> str:
    """A failed run's message on one line, without what differs from run to run: its own name and Δt (said
    once in the list of runs) and the private temporary paths of an engine-file command."""
    text = " ".join(str(message or "no message").split())
    text = re.sub(r"^(?:\w+Error: )?\S+ at Δt = [0-9.eE+-]+ s: ", "", text)
    return _PRIVATE.sub(lambda m: _PRIVATE_WORDS[m.group(1)], text)
