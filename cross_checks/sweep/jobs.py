"""One sweep job — a (scenario, engine variant, Δt) run — and its measurement; the job cache.

A worker process calls :func:`run_job`: it runs the variant through the engine registry, compares
every step with the scenario's reference (computed once per scenario by :func:`reference_job` on the
union of the scenario's time grids), measures conservation drifts, takes the one-step (local) errors
from ``LOCAL_SAMPLES`` reference states, and returns small summaries — plus, at the scenario's default
Δt only, series decimated to ``MAX_SERIES_POINTS`` points for the plots. Full trajectories never leave
the worker.

Results are cached per job under the user's cache directory (``$RBCHECK_CACHE_DIR``, else
``$XDG_CACHE_HOME/rbcheck``, else ``~/.cache/rbcheck``; never inside a results directory), keyed by
the scenario's content hash, the variant, Δt, the engine version and a fingerprint of the source
files that determine a job's result (reference_sim, the engine adapter, this module, metrics,
references, scenario parsing, tolerances) — orchestration and report changes keep the cache.
"""
from __future__ import annotations

import hashlib
import json
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from reference_sim.state import Q
from cross_checks.sweep import cache
from cross_checks.analysis import metrics as M
from cross_checks.core.quantities import decimation_indices, error_summary, quantity_scales, state_errors
from cross_checks.core import tolerances as tol
from cross_checks.sweep.lifecycle import TimeLimitExceeded, time_limit
from cross_checks.core.quantities import QUANTITIES
from cross_checks.core.files import json_default
from cross_checks.core.files import save_npz_atomic
from cross_checks.core.quantities import COLUMN_STEM

__all__ = ["SCHEMA_VERSION", "MAX_SERIES_POINTS", "LOCAL_SAMPLES", "RESULT_COLUMNS", "Job", "job_dts",
           "run_job", "reference_job", "measure_reference", "load_reference", "failed_record", "cache_dir",
           "code_fingerprint", "varies"]

#: Version of the results-directory layout and of the cached job records.
SCHEMA_VERSION = 1
#: Points kept per plotted series: enough for a smooth curve at ~1000 px, small on disk.
MAX_SERIES_POINTS = 500
#: Reference states each one-step (local error) measurement starts from, spread over the run.
LOCAL_SAMPLES = 64

RESULT_COLUMNS = (
    "scenario", "engine", "dt", "steps", "wall_s",
    "pos_err_final", "vel_err_final", "orient_err_final", "angvel_err_final",
    "pos_err_max", "vel_err_max", "orient_err_max", "angvel_err_max",
    "energy_drift_max", "energy_drift_final", "energy_drift_kind",
    "angmom_drift_max", "linmom_drift_max",
    "pos_local_err", "vel_local_err", "orient_local_err", "angvel_local_err",
    "status", "diverged_at_s", "message",
    "default_dt", "in_ladder", "reference", "engine_version", "cached",
)


@dataclass(frozen=True)
class Job:
    """One run: scenario index (into the sweep's list), variant, Δt, and its role."""

    scenario_index: int
    scenario: str
    variant: str
    dt_s: float
    in_ladder: bool
    default_dt: bool
    cost: float


def job_dts(scenario):
    """Δt values of a scenario: its ladder, plus its default Δt when the ladder lacks it (descending)."""
    dts = list(scenario.dt_ladder_s)
    if not any(d == scenario.dt_s for d in dts):
        dts.append(scenario.dt_s)
    return sorted(dts, reverse=True)


# --- cache -----------------------------------------------------------------------------------------

def cache_dir() -> Path:
    """The user's rbcheck cache directory (never inside a results directory)."""
    if os.environ.get("RBCHECK_CACHE_DIR"):
        return Path(os.environ["RBCHECK_CACHE_DIR"])
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "rbcheck"


_FINGERPRINTS: dict = {}
_BASE_FINGERPRINT: list = []


def _base_fingerprint() -> bytes:
    """SHA-256 of rbcheck's own files that determine a job's result (computed once per process)."""
    if not _BASE_FINGERPRINT:
        import reference_sim
        here = Path(__file__).resolve().parent
        files = sorted(Path(reference_sim.__file__).resolve().parent.glob("*.py"))
        files += [here / n for n in ("measure.py", "references.py", "metrics.py", "scenario.py", "tolerances.py",
                                     "expectations.py", "physics.py", "trajectory.py", "resolved.py")]
        files += [here / "engines" / "__init__.py", here / "engines" / "base.py"]
        h = hashlib.sha256()
        for f in files:
            h.update(f.name.encode())
            try:
                h.update(f.read_bytes())
            except OSError:
                h.update(b"<missing>")
        _BASE_FINGERPRINT.append(h.digest())
    return _BASE_FINGERPRINT[0]


def code_fingerprint(engine: str) -> str:
    """SHA-256 (16 hex digits) of what determines a job's result for ``engine`` besides its inputs:
    reference_sim, this module, references, metrics, scenario parsing, the resolved scenario, tolerances,
    expectations (QUANTITIES), trajectories, the engine registry, and the adapter's own
    ``cache_token()`` (its module; for an engine file, the file and the programs it names, as loaded).
    Memoised per adapter instance, so an engine file re-registered under the same name (a rebuilt
    program) gets its own fingerprint."""
    from cross_checks.engines import get_adapter
    adapter = get_adapter(engine)
    key = (engine, id(adapter))
    if key not in _FINGERPRINTS:
        h = hashlib.sha256(_base_fingerprint())
        h.update(str(adapter.cache_token()).encode())
        _FINGERPRINTS[key] = (adapter, h.hexdigest()[:16])  # the adapter is kept so its id stays unique
    return _FINGERPRINTS[key][1]


def _job_key(scenario, variant, dt, engine_version):
    engine = variant.split(":", 1)[0]
    blob = json.dumps([SCHEMA_VERSION, scenario.content_hash, variant, repr(float(dt)), repr(scenario.duration_s),
                       engine_version, code_fingerprint(engine), LOCAL_SAMPLES, MAX_SERIES_POINTS, cache.environment()])
    return hashlib.sha256(blob.encode()).hexdigest()


def _cache_file(root: Path, kind: str, key: str) -> Path:
    return root / kind / key[:2] / f"{key}.npz"


def _pack_record(rec: dict) -> dict:
    """A job record as npz arrays (JSON for the scalars; no pickles)."""
    arrays = {"__json__": np.array(json.dumps({k: v for k, v in rec.items() if k != "series"},
                                              default=json_default))}
    for k, a in (rec.get("series") or {}).items():
        arrays[f"series::{k}"] = a
    return arrays


def _unpack_record(arrays: dict) -> dict:
    rec = json.loads(str(arrays["__json__"]))
    series = {k[len("series::"):]: v for k, v in arrays.items() if k.startswith("series::")}
    rec["series"] = series or None
    return rec


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
        rec = _unpack_record(arrays)
    except (KeyError, ValueError, TypeError):
        return None
    return rec if _record_is_for(rec, job) else None


def _cache_store(root, path: Path, key: str, rec: dict) -> None:
    cache.store(root, path, key, _pack_record(rec))  # a read-only or full cache never breaks a sweep


# --- references ------------------------------------------------------------------------------------

def _time_grids(scenario):
    return {dt: dt * np.arange(scenario.n_steps(dt) + 1) for dt in job_dts(scenario)}


def reference_job(scenario, out_path: str, cache_root: str | None, use_cache: bool,
                  time_limit_s: float | None = tol.REFERENCE_TIME_LIMIT_S):
    """Compute (or load) the reference on the union of the scenario's time grids; save it to
    ``out_path`` (npz: t_s, y, label). Returns ``(label, error message or "", scales, varies, measured)``
    — ``measured`` (:func:`measure_reference`) holds what the convergence floors and the expectations
    are decided from: the reference's measured error, the error amplification and the physics."""
    label, err, measured = _reference_solution_file(scenario, out_path, cache_root, use_cache, time_limit_s)
    if err:
        ones = {q: 1.0 for q in QUANTITIES}
        return label, err, ones, {}, {"amplification": ones, "reference_error": None, "local_reference_error": {},
                                      "physics": None}
    with np.load(out_path, allow_pickle=False) as d:
        y, t_s = d["y"], d["t_s"]
    from cross_checks.sweep.second_reference import second_reference  # Drake's, beside it (None without Drake)
    with time_limit(time_limit_s, "the second reference (Drake)"):
        measured = {**measured, "second_reference": second_reference(scenario, t_s, y, label, measured, cache_root,
                                                                     use_cache)}
    return label, "", quantity_scales(y), varies(y), measured


def measure_reference(scenario, t_s, y, label) -> dict:
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
            "local_reference_error": _local_reference_errors(scenario, t_s, y),
            "amplification": amp, "physics": phys.as_dict()}


def _local_reference_errors(scenario, t_s, y) -> dict:
    from reference_sim.ground_truth import ground_truth
    out = {}
    for dt in scenario.dt_ladder_s:
        grid = np.searchsorted(t_s, dt * np.arange(scenario.n_steps(dt) + 1))
        starts = decimation_indices(len(grid) - 1, LOCAL_SAMPLES)
        y0, y1 = y[grid[starts]], y[grid[starts + 1]]
        y1_acc = ground_truth(scenario.problem, np.array([0.0, dt]), y0=y0)[-1]
        e = state_errors(y1_acc, y1)
        out[repr(float(dt))] = {q: float(np.max(e[q])) for q in QUANTITIES}
    return out


def _reference_solution_file(scenario, out_path, cache_root, use_cache, time_limit_s):
    from cross_checks.scenario.references import reference_solution
    grids = _time_grids(scenario)
    t_union = np.unique(np.concatenate(list(grids.values())))
    key = hashlib.sha256(json.dumps([SCHEMA_VERSION, scenario.content_hash, code_fingerprint("reference"),
                                     t_union.size, repr(float(t_union[-1])), cache.environment()]).encode()).hexdigest()
    cpath = _cache_file(Path(cache_root), "reference", key) if cache_root else None
    if cpath is not None and use_cache:
        arrays = cache.load(cache_root, cpath, key)
        measured = _measured_of(arrays) if arrays is not None and _reference_is_for(arrays, t_union) else None
        if measured is not None:
            save_npz_atomic(Path(out_path), {k: arrays[k] for k in ("t_s", "y", "label")})
            return str(arrays["label"]), "", measured
    try:
        with time_limit(time_limit_s, "the reference solution"):
            y, label = reference_solution(scenario, t_union)
            measured = measure_reference(scenario, t_union, y, label)
    except TimeLimitExceeded as exc:
        return "", f"reference solution failed: {exc} (cross_checks/tolerances.py)", None
    except Exception as exc:  # noqa: BLE001 - reported per scenario, the sweep goes on
        return "", f"reference solution failed: {type(exc).__name__}: {exc}", None
    save_npz_atomic(Path(out_path), {"t_s": t_union, "y": y, "label": np.array(label)})
    if cpath is not None:
        cache.store(cache_root, cpath, key, {"t_s": t_union, "y": y, "label": np.array(label),
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


def load_reference(path: str):
    if path not in _REF_MEMO:
        _REF_MEMO.clear()  # one scenario's reference in memory at a time per worker
        with np.load(path, allow_pickle=False) as d:
            _REF_MEMO[path] = (d["t_s"], d["y"], str(d["label"]))
    return _REF_MEMO[path]


def clear_reference_memo() -> None:
    _REF_MEMO.clear()


# --- one job ---------------------------------------------------------------------------------------

def _nan_row(job, scenario, status, message, label, version):
    row = {c: math.nan for c in RESULT_COLUMNS}
    row.update(scenario=job.scenario, engine=job.variant, dt=job.dt_s, steps=0, wall_s=math.nan,
               energy_drift_kind="n/a", status=status, diverged_at_s=math.nan, message=message,
               default_dt=job.default_dt, in_ladder=job.in_ladder, reference=label, engine_version=version,
               cached=False)
    return row


class _NoOneStep(Exception):
    """The engine has no one-step mode (EngineAdapter.has_one_step is False)."""


def _canonical_to(q, q_ref):
    """q or −q, whichever is in the hemisphere of q_ref (row-wise), so components can be plotted."""
    s = np.sign(np.sum(q * q_ref, axis=-1, keepdims=True))
    s[s == 0] = 1.0
    return q * s


def run_job(job: Job, scenario, ref_path: str, cache_root: str | None = None, use_cache: bool = True,
            time_limit_s: float | None = tol.RUN_TIME_LIMIT_S) -> dict:
    """Run one job and measure it. Returns a record: ``row`` (results.csv columns), ``y_final``
    (13 numbers or None), ``series`` (dict of float32 arrays for the default Δt, else None),
    ``scales`` (per quantity)."""
    from cross_checks.engines import get_adapter, run_variant, split_variant
    engine, variant = split_variant(job.variant)
    try:
        adapter = get_adapter(engine)
        version = adapter.version()
    except Exception as exc:  # noqa: BLE001
        return {"row": _nan_row(job, scenario, "failed", str(exc), "", ""), "y_final": None, "series": None}

    cpath = None
    if cache_root:
        ckey = _job_key(scenario, job.variant, job.dt_s, version)
        cpath = _cache_file(Path(cache_root), "job", ckey)
        if use_cache:
            rec = _cache_load(cache_root, cpath, ckey, job)
            if rec is not None:
                rec["row"].update(default_dt=job.default_dt, in_ladder=job.in_ladder, cached=True)
                return rec

    t_ref_all, y_ref_all, label = load_reference(ref_path)
    try:
        with time_limit(time_limit_s, "the run"):
            traj = run_variant(scenario, job.variant, job.dt_s)
    except KeyboardInterrupt:
        raise
    except Exception as exc:  # noqa: BLE001 - an engine failure is a row, not a crash
        msg = (f"{exc} (cross_checks/tolerances.py)" if isinstance(exc, TimeLimitExceeded)
               else f"{type(exc).__name__}: {exc}".strip())
        return {"row": _nan_row(job, scenario, "failed", msg, label, version), "y_final": None, "series": None}

    meta = traj.meta
    t, y = traj.t_s, traj.y
    idx = np.searchsorted(t_ref_all, t)
    idx = np.minimum(idx, len(t_ref_all) - 1)
    if np.array_equal(t_ref_all[idx], t):
        y_ref = y_ref_all[idx]
    else:  # an adapter with its own time grid: evaluate the reference there
        from cross_checks.scenario.references import reference_solution
        y_ref, label = reference_solution(scenario, t)

    status = meta.get("status", "ok")
    errs = state_errors(y, y_ref)
    summ = error_summary(errs)
    row = _nan_row(job, scenario, status, meta.get("message", "") or "", label, version)
    row.update(steps=len(t) - 1, wall_s=float(meta.get("wall_s", math.nan)))
    if status == "diverged":
        row["diverged_at_s"] = float(meta.get("diverged_at_s"))
    for q in QUANTITIES:
        stem = COLUMN_STEM[q]
        row[f"{stem}_err_final"] = summ[q]["final"] if status == "ok" else math.nan
        row[f"{stem}_err_max"] = summ[q]["max"]

    # Conservation drifts (only where the physics conserves the quantity).
    problem = scenario.problem
    cons = M.conserved(problem.forces)
    drifts = {}
    with np.errstate(all="ignore"):
        if cons["energy"][0]:
            E, E_terms = M.energy_J(problem, y, with_scale=True)
            drifts["energy"] = M.relative_drift(E)
            d = drifts["energy"]
            amp = float(np.max(E_terms) / abs(E[0])) if E[0] != 0 else 1.0
            row["energy_drift_max"] = float(np.max(np.abs(d)))
            row["energy_drift_final"] = float(d[-1])
            row["energy_drift_kind"] = M.drift_kind(t, d, M.drift_floor(len(t) - 1, amp))
        if cons["angular_momentum"][0]:
            drifts["angular_momentum"] = M.relative_drift(M.angular_momentum_W(problem, y))
            row["angmom_drift_max"] = float(np.max(drifts["angular_momentum"]))
        if cons["linear_momentum"][0]:
            drifts["linear_momentum"] = M.relative_drift(M.linear_momentum_W(problem, y))
            row["linmom_drift_max"] = float(np.max(drifts["linear_momentum"]))

    # One-step (local) errors from reference states on this run's own grid.
    grid_idx = np.searchsorted(t_ref_all, job.dt_s * np.arange(scenario.n_steps(job.dt_s) + 1))
    starts = decimation_indices(len(grid_idx) - 1, LOCAL_SAMPLES)
    y0 = y_ref_all[grid_idx[starts]]
    y1_ref = y_ref_all[grid_idx[starts + 1]]
    try:
        if not adapter.has_one_step:  # e.g. an engine file: whole runs only; the local errors stay empty
            raise _NoOneStep
        with np.errstate(all="ignore"):
            y1 = np.asarray(adapter.one_step(scenario, variant, job.dt_s, y0), dtype=float)
        lerr = state_errors(y1, y1_ref)
        for q in QUANTITIES:
            e = lerr[q]
            row[f"{COLUMN_STEM[q]}_local_err"] = float(np.max(e)) if np.all(np.isfinite(e)) else math.nan
    except KeyboardInterrupt:
        raise
    except _NoOneStep:
        pass
    except Exception as exc:  # noqa: BLE001 - no one-step mode: leave the local errors empty
        row["message"] = (row["message"] + "; " if row["message"] else "") + f"one-step mode failed: {exc}"

    series = None
    if job.default_dt:
        k = decimation_indices(len(t), MAX_SERIES_POINTS)
        series = {"t_s": t[k], "x_W": y[k, 0:3], "q_WB": _canonical_to(y[k][:, Q], y_ref[k][:, Q])}
        for q in QUANTITIES:
            series[f"err_{q}"] = errs[q][k]
        for name, d in drifts.items():
            series[f"drift_{name}"] = d[k]
        series = {key: np.asarray(a, dtype=np.float32) for key, a in series.items()}
    rec = {"row": row, "y_final": y[-1].tolist() if status == "ok" else None, "series": series}
    if cpath is not None and status in ("ok", "diverged"):
        _cache_store(cache_root, cpath, ckey, rec)
    return rec


def varies(y_ref) -> dict:
    """Which quantities change at all along the reference (an exact zero error is only news where they do)."""
    e = state_errors(y_ref, np.broadcast_to(y_ref[0], y_ref.shape))
    return {q: bool(np.max(e[q]) > 1e-12) for q in QUANTITIES}


def failed_record(job, scenario, message):
    return {"row": _nan_row(job, scenario, "failed", message, "", ""), "y_final": None, "series": None}


