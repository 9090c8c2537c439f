"""One sweep job — a (scenario, engine variant, Δt) run — and its measurement; the job cache.

A worker runs a scenario's jobs of one variant in one call (:func:`run_job_group`), measures each against
the scenario's reference (:func:`reference_job`, once per scenario on the union of its time grids) and
returns small records: full trajectories never leave the worker. Records are cached per job
(:mod:`cross_checks.sweep.cache`), keyed by the scenario's content hash, the variant, Δt, the engine
version and what :mod:`cross_checks.sweep.fingerprint` adds.
"""
from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np

from cross_checks.analysis import metrics as M
from cross_checks.core import tolerances as tol
from cross_checks.core.files import json_default, save_npz_atomic
from cross_checks.core.quantities import (
    COLUMN_STEM,
    QUANTITIES,
    decimation_indices,
    error_summary,
    quantity_scales,
    state_errors,
)
from cross_checks.sweep import cache, fingerprint
from cross_checks.sweep.lifecycle import TimeLimitExceeded, each_within_limits, time_limit
from cross_checks.sweep.schema import SCHEMA_VERSION
from reference_sim.state import Q

__all__ = ["SCHEMA_VERSION", "MAX_SERIES_POINTS", "LOCAL_SAMPLES", "RESULT_COLUMNS", "TIMING_COLUMNS", "Job",
           "job_dts", "run_job_group", "reference_job", "second_reference_job", "failed_second_reference",
           "ReferenceResult", "measure_reference", "load_reference",
           "clear_reference_memo", "failed_record", "varies"]

#: Points kept per plotted series: enough for a smooth curve at ~1000 px, small on disk.
MAX_SERIES_POINTS = 500
#: Reference states each one-step (local error) measurement starts from, spread over the run.
LOCAL_SAMPLES = 64

RESULT_COLUMNS = (
    "scenario", "engine", "dt", "steps", "wall_s", "engine_s",
    "pos_err_final", "vel_err_final", "orient_err_final", "angvel_err_final",
    "pos_err_max", "vel_err_max", "orient_err_max", "angvel_err_max",
    "energy_drift_max", "energy_drift_final", "energy_drift_kind",
    "angmom_drift_max", "linmom_drift_max",
    "pos_local_err", "vel_local_err", "orient_local_err", "angvel_local_err",
    "step_defect_ratio", "step_defect_quantity", "step_defect_t_s",
    "status", "diverged_at_s", "message",
    "default_dt", "in_ladder", "reference", "engine_version", "cached",
)
#: Columns that differ between two runs of the same code (wall time, whether the cache served the
#: row): everything else in a row is a result, reproduced bit for bit by the same code and versions.
TIMING_COLUMNS = ("wall_s", "engine_s", "cached")


@dataclass(frozen=True)
class Job:
    """One run: scenario index (into the sweep's list), variant (the plan's Resolved), Δt, and its role."""

    scenario_index: int
    scenario: str
    variant: str   # a Resolved (cross_checks.engines.resolve): the plan resolved it once
    dt_s: float
    in_ladder: bool
    default_dt: bool
    cost: float


def job_dts(scenario, variants=()):
    """Δt values of a scenario (descending): its ladder, the coarser rungs the ``variants`` are judged on too
    (expectations.judged_ladder_s: a float32 variant's), and its default Δt when the ladder lacks it."""
    from cross_checks.analysis.expectations import judged_ladder_s
    dts = {float(d) for d in scenario.dt_ladder_s}
    for v in variants:
        dts.update(judged_ladder_s(scenario, v))
    dts.add(float(scenario.dt_s))
    return sorted(dts, reverse=True)


# --- cache -----------------------------------------------------------------------------------------

def _job_key(scenario, variant, dt, engine_version):
    engine = variant.split(":", 1)[0]
    blob = json.dumps([SCHEMA_VERSION, scenario.content_hash, variant, repr(float(dt)),
                       repr(scenario.duration_s), engine_version, fingerprint.code_fingerprint(engine),
                       LOCAL_SAMPLES, MAX_SERIES_POINTS, fingerprint.environment()])
    return hashlib.sha256(blob.encode()).hexdigest()


def _record_is_for(rec, job) -> bool:
    """A cached record that verified is also checked to be a whole record of this very job."""
    row = rec.get("row") if isinstance(rec, dict) else None
    if not isinstance(row, dict) or any(c not in row for c in RESULT_COLUMNS):
        return False
    y = rec.get("y_final")
    y_ok = y is None or (isinstance(y, list) and len(y) == 13 and all(isinstance(v, (int, float)) for v in y))
    return (row["scenario"] == job.scenario and row["engine"] == job.variant and row["dt"] == job.dt_s
            and row["status"] in ("ok", "diverged") and y_ok)


def _cache_load(root, path: Path, key: str, job):
    arrays = cache.load(root, path, key)
    if arrays is None:
        return None
    try:
        fields, series = cache.unpack(arrays)
        rec = {**fields, "series": series}
    except (KeyError, ValueError, TypeError):
        return None
    return rec if _record_is_for(rec, job) else None


def _cache_store(root, path: Path, key: str, rec: dict) -> None:
    """Store ``rec`` (a read-only or full cache never breaks a sweep)."""
    fields = {k: v for k, v in rec.items() if k != "series"}
    cache.store(root, path, key, cache.pack(fields, rec.get("series")))


# --- references ------------------------------------------------------------------------------------

def _time_grids(scenario, variants=()):
    return {dt: dt * np.arange(scenario.n_steps(dt) + 1) for dt in job_dts(scenario, variants)}


class ReferenceResult(NamedTuple):
    """A scenario's reference as the sweep uses it: ``label`` (``analytic`` or the DOP853 label),
    ``error`` (why it failed; "" when it did not), ``scales`` and ``varies`` per quantity, and
    ``measured`` (:func:`measure_reference`: what the convergence floors and the expectations are
    decided from — the reference's measured error, the error amplification and the physics)."""

    label: str
    error: str
    scales: dict
    varies: dict
    measured: dict


def reference_job(scenario, out_path: str, cache_root: str | None, use_cache: bool,
                  time_limit_s: float | None = tol.REFERENCE_TIME_LIMIT_S, variants=()) -> ReferenceResult:
    """Compute (or load) the reference on the union of the scenario's time grids (those of every Δt the
    ``variants`` run: :func:`job_dts`) and save it to ``out_path`` (npz: t_s, y, label). The second reference
    (Drake's, :func:`second_reference_job`) is a job of its own: no run waits for it."""
    label, err, measured = _reference_solution_file(scenario, out_path, cache_root, use_cache, time_limit_s,
                                                    variants)
    if err:
        ones = {q: 1.0 for q in QUANTITIES}
        return ReferenceResult(label, err, ones, {}, {"amplification": ones, "reference_error": None,
                                                       "local_reference_error": {}, "physics": None})
    with np.load(out_path, allow_pickle=False) as d:
        y = d["y"]
    return ReferenceResult(label, "", quantity_scales(y), varies(y), measured)


def second_reference_job(scenario, ref_path: str, measured: dict, cache_root: str | None, use_cache: bool,
                         time_limit_s: float | None = tol.REFERENCE_TIME_LIMIT_S):
    """The record ``scenarios[i].second_reference`` of summary.json: Drake's reference compared with the
    primary one saved at ``ref_path`` (:func:`cross_checks.sweep.second_reference.second_reference`;
    None without Drake). Over the time limit, or failing, it is a record saying why."""
    from cross_checks.sweep.second_reference import second_reference
    t_s, y, label = load_reference(ref_path)
    try:
        with time_limit(time_limit_s, "the second reference (Drake)"):
            return second_reference(scenario, t_s, y, label, measured, cache_root, use_cache)
    except TimeLimitExceeded as exc:
        return failed_second_reference(f"{exc} (cross_checks/core/tolerances.py)")


def failed_second_reference(why: str) -> dict:
    """The ``second_reference`` record of a second reference that could not be computed: ``why``."""
    return {"label": "drake", "target_accuracy": tol.SECOND_REFERENCE_TARGET_ACCURACY,
            "agrees": None, "error": why}


def measure_reference(scenario, t_s, y, label, ladder_dts=None) -> dict:
    """Measurements of a scenario's reference ``y`` (on the union grid ``t_s``), JSON-ready:

    ``reference_error`` {quantity: its measured error at the final time} (references.reference_error);
    ``local_reference_error`` {repr(Δt): {quantity: error}}: how far each reference step of Δt, at the
    LOCAL_SAMPLES starts of the one-step mode, is from a DOP853 step from the same state (rtol
    GROUND_TRUTH_RTOL) — the floor of the one-step errors; ``amplification`` {quantity: A};
    ``physics`` (physics.ScenarioPhysics.as_dict: rates on the default-Δt grid, separatrix proximity).
    """
    from cross_checks.analysis.physics import RATE_SAMPLES, scenario_physics
    from cross_checks.scenario.references import error_amplification, reference_error
    scales = quantity_scales(y)
    amp = error_amplification(scenario, scales)
    grid = np.searchsorted(t_s, scenario.dt_s * np.arange(scenario.n_steps() + 1))
    rows = grid[decimation_indices(len(grid), RATE_SAMPLES)]
    phys = scenario_physics(scenario, amplification=amp, y_ref=y[rows])
    return {"reference_error": reference_error(scenario, y[-1], label, scales),
            "local_reference_error": _local_reference_errors(scenario, t_s, y, ladder_dts),
            "amplification": amp, "physics": phys.as_dict()}


def _local_reference_errors(scenario, t_s, y, ladder_dts=None) -> dict:
    from reference_sim.ground_truth import ground_truth
    out = {}
    for dt in scenario.dt_ladder_s if ladder_dts is None else ladder_dts:
        grid = np.searchsorted(t_s, dt * np.arange(scenario.n_steps(dt) + 1))
        starts = decimation_indices(len(grid) - 1, LOCAL_SAMPLES)
        y0, y1 = y[grid[starts]], y[grid[starts + 1]]
        y1_acc = ground_truth(scenario.problem, np.array([0.0, dt]), y0=y0)[-1]
        e = state_errors(y1_acc, y1)
        out[repr(float(dt))] = {q: float(np.max(e[q])) for q in QUANTITIES}
    return out


def _reference_key(scenario, t_union) -> str:
    return hashlib.sha256(json.dumps([SCHEMA_VERSION, scenario.content_hash,
                                      fingerprint.code_fingerprint("reference"), t_union.size,
                                      repr(float(t_union[-1])),
                                      fingerprint.environment()]).encode()).hexdigest()


def _cached_reference(cache_root, cpath, key, t_union):
    """The verified cache entry of this reference (arrays and measurements), or None."""
    arrays = cache.load(cache_root, cpath, key)
    measured = _measured_of(arrays) if arrays is not None and _reference_is_for(arrays, t_union) else None
    return None if measured is None else (arrays, measured)


def _reference_solution_file(scenario, out_path, cache_root, use_cache, time_limit_s, variants=()):
    """``(label, error message or "", measured)``; the reference saved to ``out_path`` when it exists."""
    from cross_checks.scenario.references import reference_solution
    grids = _time_grids(scenario, variants)
    t_union = np.unique(np.concatenate(list(grids.values())))
    key = _reference_key(scenario, t_union)
    cpath = cache.entry_path(cache_root, "reference", key) if cache_root else None
    hit = _cached_reference(cache_root, cpath, key, t_union) if cpath is not None and use_cache else None
    if hit is not None:
        arrays, measured = hit
        save_npz_atomic(Path(out_path), {k: arrays[k] for k in ("t_s", "y", "label")}, compress=False)
        return str(arrays["label"]), "", measured
    try:
        with time_limit(time_limit_s, "the reference solution"):
            y, label = reference_solution(scenario, t_union)
            ladder = [d for d in grids if d != scenario.dt_s or d in scenario.dt_ladder_s]
            measured = measure_reference(scenario, t_union, y, label, ladder_dts=ladder)
    except TimeLimitExceeded as exc:
        return "", f"reference solution failed: {exc} (cross_checks/core/tolerances.py)", None
    except Exception as exc:  # noqa: BLE001 - reported per scenario, the sweep goes on
        return "", f"reference solution failed: {type(exc).__name__}: {exc}", None
    save_npz_atomic(Path(out_path), {"t_s": t_union, "y": y, "label": np.array(label)}, compress=False)
    if cpath is not None:
        cache.store(cache_root, cpath, key,
                    {"t_s": t_union, "y": y, "label": np.array(label),
                     "measured": np.array(json.dumps(measured, default=json_default))})
    return label, "", measured


def _reference_is_for(arrays: dict, t_union) -> bool:
    """A verified reference entry is also checked to be a whole, finite reference on this grid."""
    try:
        t, y, label = arrays["t_s"], arrays["y"], str(arrays["label"])
    except KeyError:
        return False
    return (np.array_equal(t, t_union) and y.shape == (t_union.size, 13) and y.dtype == np.float64
            and bool(np.all(np.isfinite(y))) and bool(label))


def _measured_of(arrays: dict):
    """The reference's measurements stored with a verified cache entry (None when absent or unreadable:
    the entry is then recomputed like any other that does not verify)."""
    try:
        measured = json.loads(str(arrays["measured"]))
    except (KeyError, ValueError):
        return None
    return measured if isinstance(measured, dict) and "amplification" in measured else None


_REF_MEMO: dict = {}
#: References a worker keeps in memory (the jobs run longest first, which interleaves the scenarios).
REFERENCE_MEMO_SIZE = 32


def load_reference(path: str):
    """``(t_s, y, label)`` of a reference file written by :func:`reference_job` (up to
    REFERENCE_MEMO_SIZE are kept, the least recently used dropped first)."""
    if path in _REF_MEMO:
        _REF_MEMO[path] = _REF_MEMO.pop(path)  # most recently used last
        return _REF_MEMO[path]
    while len(_REF_MEMO) >= REFERENCE_MEMO_SIZE:
        _REF_MEMO.pop(next(iter(_REF_MEMO)))
    with np.load(path, allow_pickle=False) as d:
        _REF_MEMO[path] = (d["t_s"], d["y"], str(d["label"]))
    return _REF_MEMO[path]


def clear_reference_memo() -> None:
    """Forget the reference :func:`load_reference` keeps in memory."""
    _REF_MEMO.clear()


# --- one job ---------------------------------------------------------------------------------------

def _nan_row(job, scenario, status, message, label, version):
    row = {c: math.nan for c in RESULT_COLUMNS}
    row.update(scenario=job.scenario, engine=job.variant, dt=job.dt_s, steps=0, wall_s=math.nan,
               engine_s=math.nan, energy_drift_kind="n/a", step_defect_quantity="", status=status,
               diverged_at_s=math.nan, message=message, default_dt=job.default_dt, in_ladder=job.in_ladder,
               reference=label, engine_version=version, cached=False)
    return row


def _record(row, y_final=None, series=None) -> dict:
    return {"row": row, "y_final": y_final, "series": series}


def _canonical_to(q, q_ref):
    """q or −q, whichever is in the hemisphere of q_ref (row-wise), so components can be plotted."""
    s = np.sign(np.sum(q * q_ref, axis=-1, keepdims=True))
    s[s == 0] = 1.0
    return q * s


def run_job_group(jobs, scenario, ref_path: str, cache_root: str | None = None, use_cache: bool = True,
                  time_limit_s: float | None = tol.RUN_TIME_LIMIT_S) -> list:
    """Run jobs of one scenario and one variant (e.g. its Δt ladder) and measure each, or take its verified
    cache entry: a record per job, in order — ``row`` (results.csv columns), ``y_final`` (13 numbers or
    None), ``series`` (dict of float32 arrays for the default Δt, else None). The runs not cached are asked
    of the engine in one call (:func:`_runs`). A run that finished (ok or diverged) is cached; a failed one
    is not."""
    resolved = jobs[0].variant   # the plan's Resolved
    try:
        adapter = resolved.adapter
        version = adapter.version()
    except Exception as exc:  # noqa: BLE001 - an engine that cannot run here is a failed row
        return [_record(_nan_row(job, scenario, "failed", str(exc), "", "")) for job in jobs]
    out: list = [None] * len(jobs)
    keys = {}
    for k, job in enumerate(jobs):
        if cache_root:
            ckey = _job_key(scenario, job.variant, job.dt_s, version)
            keys[k] = (ckey, cache.entry_path(cache_root, "job", ckey))
            rec = _cache_load(cache_root, keys[k][1], ckey, job) if use_cache else None
            if rec is not None:
                rec["row"].update(default_dt=job.default_dt, in_ladder=job.in_ladder, cached=True)
                out[k] = rec
    todo = [k for k in range(len(jobs)) if out[k] is None]
    t_ref_all, y_ref_all, label = load_reference(ref_path) if todo else (None, None, "")
    for k, run in zip(todo, _runs([jobs[k] for k in todo], scenario, time_limit_s)):
        out[k] = rec = _measure(jobs[k], scenario, resolved, version, run, t_ref_all, y_ref_all, label)
        if k in keys and rec["row"]["status"] in ("ok", "diverged"):
            _cache_store(cache_root, keys[k][1], keys[k][0], rec)
    return out


def _measure(job, scenario, resolved, version, run, t_ref_all, y_ref_all, label) -> dict:
    """Measure the job's run ``run`` (``(trajectory, "")`` or ``(None, why it failed)``) against the
    reference ``y_ref_all`` on ``t_ref_all``: errors, conservation drifts, one-step errors and (at the
    default Δt) the plotted series."""
    traj, failure = run
    if traj is None:
        return _record(_nan_row(job, scenario, "failed", failure, label, version))
    meta, t, y = traj.meta, traj.t_s, traj.y
    y_ref, label = _reference_on(t, t_ref_all, y_ref_all, scenario, label)
    status = meta.get("status", "ok")
    errs = state_errors(y, y_ref)
    row = _nan_row(job, scenario, status, meta.get("message", "") or "", label, version)
    row.update(steps=len(t) - 1, wall_s=float(meta.get("wall_s", math.nan)),
               engine_s=float(meta.get("engine_s", math.nan)))
    if status == "diverged":
        row["diverged_at_s"] = float(meta.get("diverged_at_s"))
    summ = error_summary(errs)
    for q in QUANTITIES:
        stem = COLUMN_STEM[q]
        row[f"{stem}_err_final"] = summ[q]["final"] if status == "ok" else math.nan
        row[f"{stem}_err_max"] = summ[q]["max"]
    drifts = _conservation_columns(row, scenario.problem, t, y, resolved.rounding_unit)
    _local_error_columns(row, resolved, scenario, job.dt_s, t_ref_all, y_ref_all)
    _step_defect_columns(row, scenario, y, job.dt_s, resolved)
    series = _series(t, y, y_ref, errs, drifts) if job.default_dt else None
    return _record(row, y[-1].tolist() if status == "ok" else None, series)


def _step_defect_columns(row, scenario, y, dt_s, resolved) -> None:
    """The run judged on its own recorded states, as ``rbcheck check`` judges a file: from each of
    tol.STEP_DEFECT_ROWS recorded states spread over the run, the exact flow over Δt against the next
    row, over what a consistent scheme of order ≥ 1 leaves there (``analysis.flow.run_local_defect``).
    A ratio above 1 says the run's equations are not the scenario's (the judge then grants no
    pre-asymptotic excuse); every engine, engine files included, has it."""
    from cross_checks.analysis.flow import run_local_defect
    # the precision's unit roundoff × the step's declared rounding factor
    tr = resolved.traits
    u = tol.UNIT_ROUNDOFF[resolved.precision] * float(tr.rounding_factor)
    ratio, quantity, t_s = run_local_defect(scenario, y, dt_s, max_rows=tol.STEP_DEFECT_ROWS, unit_roundoff=u,
                                            velocity_from_positions=tr.velocity_from_positions)
    row.update(step_defect_ratio=ratio, step_defect_quantity=quantity, step_defect_t_s=t_s)


def _runs(jobs, scenario, time_limit_s) -> list:
    """Per job ``(trajectory, "")``, or ``(None, the failure's message)``: the jobs' runs in one call
    (``engines.run_variants``), each within its time limit (``lifecycle.each_within_limits``). An engine
    failure (or a run over its time limit) is a row, not a crash."""
    from cross_checks.engines import EngineError, run_variants
    if not jobs:
        return []
    runs = each_within_limits(lambda js: run_variants(scenario, js[0].variant, [j.dt_s for j in js]), jobs,
                              time_limit_s, "the run")
    return [(None, r) if isinstance(r, str) else (None, f"{type(r).__name__}: {r}".strip())
            if isinstance(r, EngineError) else (r, "") for r in runs]


def _reference_on(t, t_ref_all, y_ref_all, scenario, label):
    """The reference at the run's times ``t``: rows of the union grid, or (an adapter with its own time
    grid) the reference evaluated there. Returns ``(y_ref, label)``."""
    idx = np.minimum(np.searchsorted(t_ref_all, t), len(t_ref_all) - 1)
    if np.array_equal(t_ref_all[idx], t):
        return y_ref_all[idx], label
    from cross_checks.scenario.references import reference_solution
    return reference_solution(scenario, t)


def _conservation_columns(row, problem, t, y, eps: float) -> dict:
    """Fill the drift columns of ``row`` where the physics conserves the quantity (``eps``: the variant's
    rounding unit, Resolved.rounding_unit); returns the drift series {quantity: relative drift per step}."""
    cons = M.conserved(problem.forces)
    drifts = {}
    with np.errstate(all="ignore"):
        if cons["energy"][0]:
            E, E_terms = M.energy_J(problem, y, with_scale=True)
            drifts["energy"] = d = M.relative_drift(E)
            amp = float(np.max(E_terms) / abs(E[0])) if E[0] != 0 else 1.0
            row["energy_drift_max"] = float(np.max(np.abs(d)))
            row["energy_drift_final"] = float(d[-1])
            row["energy_drift_kind"] = M.drift_kind(t, d, M.drift_floor(len(t) - 1, amp, eps))
        if cons["angular_momentum"][0]:
            drifts["angular_momentum"] = M.relative_drift(M.angular_momentum_W(problem, y))
            row["angmom_drift_max"] = float(np.max(drifts["angular_momentum"]))
        if cons["linear_momentum"][0]:
            drifts["linear_momentum"] = M.relative_drift(M.linear_momentum_W(problem, y))
            row["linmom_drift_max"] = float(np.max(drifts["linear_momentum"]))
    return drifts


def _local_error_columns(row, resolved, scenario, dt_s, t_ref_all, y_ref_all) -> None:
    """One-step (local) errors from LOCAL_SAMPLES reference states on the run's own grid. They stay
    empty for an engine without a one-step mode (an engine file: whole runs only); a one-step mode that
    fails leaves them empty and says so in the row's message."""
    if not resolved.one_step:
        return
    grid_idx = np.searchsorted(t_ref_all, dt_s * np.arange(scenario.n_steps(dt_s) + 1))
    starts = decimation_indices(len(grid_idx) - 1, LOCAL_SAMPLES)
    y0, y1_ref = y_ref_all[grid_idx[starts]], y_ref_all[grid_idx[starts + 1]]
    try:
        with np.errstate(all="ignore"):
            y1 = np.asarray(resolved.adapter.one_step(scenario, resolved.variant, dt_s, y0), dtype=float)
        lerr = state_errors(y1, y1_ref)
    except Exception as exc:  # noqa: BLE001
        row["message"] = (row["message"] + "; " if row["message"] else "") + f"one-step mode failed: {exc}"
        return
    for q in QUANTITIES:
        e = lerr[q]
        row[f"{COLUMN_STEM[q]}_local_err"] = float(np.max(e)) if np.all(np.isfinite(e)) else math.nan


def _series(t, y, y_ref, errs, drifts) -> dict:
    """The plotted series of a run at its scenario's default Δt: decimated to MAX_SERIES_POINTS, float32."""
    k = decimation_indices(len(t), MAX_SERIES_POINTS)
    series = {"t_s": t[k], "x_W": y[k, 0:3], "q_WB": _canonical_to(y[k][:, Q], y_ref[k][:, Q]),
              "w_W": y[k, 10:13]}   # angular velocity, world axes, rad/s: the report's polhode
    for q in QUANTITIES:
        series[f"err_{q}"] = errs[q][k]
    for name, d in drifts.items():
        series[f"drift_{name}"] = d[k]
    return {key: np.asarray(a, dtype=np.float32) for key, a in series.items()}


def varies(y_ref) -> dict:
    """Which quantities change at all along the reference (an exact zero error is only news where they do)."""
    e = state_errors(y_ref, np.broadcast_to(y_ref[0], y_ref.shape))
    return {q: bool(np.max(e[q]) > 1e-12) for q in QUANTITIES}


def failed_record(job, scenario, message):
    """The record of a job that could not run (its reference failed, its worker died): a failed row."""
    return _record(_nan_row(job, scenario, "failed", message, "", ""))


