"""The sweep's long-run stage: every engine variant on every long-run scenario (``kind = "long_run"``,
docs/scenario.md "Long runs"), at the scenario's one Δt over its whole duration, through the same adapter seam
as the ladders (``EngineAdapter.simulate_many``: a variant's long runs in one call), measured by
:func:`cross_checks.analysis.long_run.drift_metrics` and judged by the one judge
(:func:`cross_checks.analysis.judge.judge_long_run`) against the variant's declared invariants.

A worker returns, per (scenario, variant), a record: ``row`` (the metrics of LONG_RUN_COLUMNS that the run
determines) and ``series`` (the invariants at tol.LONG_RUN_SERIES_POINTS times, float32); full trajectories
never leave the worker. Records are cached like the ladders' jobs (cross_checks.sweep.cache), keyed by the
scenario's content hash, the variant, Δt, the duration, the engine version and the code fingerprint. The
verdict is decided when the results are assembled (:func:`judged_rows`), never cached.
"""
from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path

import numpy as np

from cross_checks.core import tolerances as tol
from cross_checks.sweep import cache, fingerprint
from cross_checks.sweep.lifecycle import each_within_limits
from cross_checks.sweep.schema import SCHEMA_VERSION

__all__ = ["LONG_RUN_COLUMNS", "MEASURED_COLUMNS", "run_long_group", "run_long_runs", "judged_rows",
           "long_run_scenario_record"]

#: The columns of long_runs.csv (docs/results.md, "long_runs.csv").
LONG_RUN_COLUMNS = (
    "scenario", "engine", "dt", "steps", "duration_s", "wall_s", "engine_s", "status", "diverged_at_s",
    "message",
    "energy_rate_per_s", "energy_drift_max", "momentum_rate_per_s", "momentum_drift_max",
    "direction_drift_max_rad", "separatrix_start", "separatrix_end", "separatrix_rate_per_s",
    "crossed_separatrix", "toward_intermediate", "away_from_intermediate", "energy_secular",
    "verdict", "matches_expectation", "expected_keeps", "expected_separatrix", "finding",
    "engine_version", "cached",
)
#: The columns a run determines (cached with it); the rest is the judge's, decided at assembly.
MEASURED_COLUMNS = LONG_RUN_COLUMNS[:LONG_RUN_COLUMNS.index("verdict")] + ("engine_version",)
#: drift_metrics' fields, in the row's column names.
_METRICS = ("energy_rate_per_s", "energy_drift_max", "momentum_rate_per_s", "momentum_drift_max",
            "direction_drift_max_rad", "separatrix_start", "separatrix_end", "separatrix_rate_per_s",
            "crossed_separatrix", "toward_intermediate", "away_from_intermediate", "energy_secular")


def _key(scenario, variant: str, version: str) -> str:
    engine = variant.split(":", 1)[0]
    blob = json.dumps(["long_run", SCHEMA_VERSION, scenario.content_hash, variant, repr(float(scenario.dt_s)),
                       repr(scenario.duration_s), version, fingerprint.code_fingerprint(engine),
                       tol.LONG_RUN_SERIES_POINTS, fingerprint.environment()])
    return hashlib.sha256(blob.encode()).hexdigest()


def _empty_row(scenario, variant: str, status: str, message: str, version: str) -> dict:
    row = {c: math.nan for c in MEASURED_COLUMNS}
    row.update(scenario=scenario.name, engine=variant, dt=float(scenario.dt_s), steps=0,
               duration_s=float(scenario.duration_s), status=status, message=message, engine_version=version,
               diverged_at_s=math.nan)
    for c in ("crossed_separatrix", "toward_intermediate", "away_from_intermediate", "energy_secular"):
        row[c] = False
    return row


def _failed(scenarios, variant: str, why: str) -> list:
    """Failed records of ``variant``'s long runs of ``scenarios``, each saying ``why``."""
    return [{"row": {**_empty_row(s, variant, "failed", why, ""), "cached": False}, "series": None}
            for s in scenarios]


def _measure(scenario, variant: str, version: str, run) -> dict:
    """The record of one long run (a Trajectory, or the failure's message)."""
    from cross_checks.analysis.expectations import long_run_expectation
    from cross_checks.analysis.long_run import drift_metrics, drift_series
    if isinstance(run, str):
        return {"row": _empty_row(scenario, variant, "failed", run, version), "series": None}
    meta, t, y = run.meta, np.asarray(run.t_s, dtype=float), np.asarray(run.y, dtype=float)
    status = meta.get("status", "ok")
    row = _empty_row(scenario, variant, status, meta.get("message", "") or "", version)
    row.update(steps=len(t) - 1, wall_s=float(meta.get("wall_s", math.nan)),
               engine_s=float(meta.get("engine_s", math.nan)))
    if status == "diverged":
        row["diverged_at_s"] = float(meta.get("diverged_at_s"))
    if len(t) < 3:
        return {"row": row, "series": None}
    exp = long_run_expectation(variant)
    floor = tol.long_run_roundoff(len(t) - 1, tol.UNIT_ROUNDOFF[exp.precision], exp.rounding_factor)
    with np.errstate(all="ignore"):
        m = drift_metrics(scenario.problem, t, y, energy_floor=floor)
        series = drift_series(scenario.problem, t, y, tol.LONG_RUN_SERIES_POINTS)
    for c in _METRICS:
        v = getattr(m, c)
        row[c] = bool(v) if isinstance(v, (bool, np.bool_)) else float(v)
    return {"row": row, "series": series}


def _unpack(arrays: dict, scenario, variant: str):
    """The cached record of ``variant``'s long run of ``scenario``, or None when it is not a whole one."""
    try:
        row, series = cache.unpack(arrays)
    except (KeyError, ValueError, TypeError):
        return None
    if (not isinstance(row, dict) or any(c not in row for c in MEASURED_COLUMNS)
            or row["scenario"] != scenario.name or row["engine"] != variant
            or row["status"] not in ("ok", "diverged")):
        return None
    return {"row": row, "series": series}


def run_long_group(variant: str, scenarios, cache_root: str | None = None, use_cache: bool = True,
                   time_limit_s: float | None = tol.RUN_TIME_LIMIT_S) -> list:
    """The records of ``variant``'s long runs of ``scenarios`` (in order): cached ones verified and reused,
    the others run in one ``simulate_many`` call (engines.run_requests) within their time limits. A run that
    finished (ok or diverged) is cached; a failed one is not. ``row["cached"]`` says which were reused."""
    from cross_checks.engines import EngineError, run_requests
    from cross_checks.engines.base import RunRequest
    try:
        version = variant.adapter.version()
    except Exception as exc:  # noqa: BLE001 - an engine that cannot run here: failed rows
        return _failed(scenarios, variant, str(exc))
    out: list = [None] * len(scenarios)
    keys = {}
    for i, sc in enumerate(scenarios):
        if cache_root:
            k = _key(sc, variant, version)
            keys[i] = (k, cache.entry_path(cache_root, "long_run", k))
            arrays = cache.load(Path(cache_root), keys[i][1], k) if use_cache else None
            rec = _unpack(arrays, sc, variant) if arrays is not None else None
            if rec is not None:
                rec["row"]["cached"] = True
                out[i] = rec
    todo = [i for i in range(len(scenarios)) if out[i] is None]
    if todo:
        reqs = [RunRequest(scenarios[i], float(scenarios[i].dt_s), scenarios[i].n_steps()) for i in todo]
        runs = each_within_limits(lambda rs: run_requests(variant, rs), reqs, time_limit_s, "the long run")
        for i, run in zip(todo, runs):
            if isinstance(run, EngineError):
                run = f"{type(run).__name__}: {run}".strip()
            rec = _measure(scenarios[i], variant, version, run)
            rec["row"]["cached"] = False
            out[i] = rec
            if i in keys and rec["row"]["status"] in ("ok", "diverged"):
                cache.store(Path(cache_root), keys[i][1], keys[i][0], cache.pack(rec["row"], rec["series"]))
    return out


def _run_long_item(item):
    """``item`` = (variant, scenarios, cache_root, use_cache, user engines, time limit): one variant's long
    runs (a small pickle per variant, like the ladders' groups); any error of the harness becomes failed
    rows."""
    variant, scenarios, cache_root, use_cache, user_engines, time_limit_s = item
    try:
        from cross_checks.engines import adopt_user_engines
        adopt_user_engines(user_engines)
        return run_long_group(variant, scenarios, cache_root, use_cache, time_limit_s)
    except Exception as exc:  # noqa: BLE001
        return _failed(scenarios, variant,
                       f"internal error while measuring the long run: {type(exc).__name__}: {exc}")


def _cost(variant: str, scenarios) -> float:
    from cross_checks.sweep.plan import job_cost_s
    return sum(job_cost_s(s, variant, s.dt_s) for s in scenarios)


def run_long_runs(runner, scenarios, variants, cache_root, use_cache, time_limit_s, show_progress: bool,
                  leave_out=()) -> dict:
    """``{(scenario name, variant): record}`` of every long run (by variant, longest first, on ``runner``:
    cross_checks.sweep.execute.Runner), except the (scenario name, variant) pairs in ``leave_out`` (the
    engine cannot express the scenario). A worker that dies leaves its variant's rows failed, saying so."""
    from cross_checks.core.progress import Progress
    from cross_checks.engines import user_engines
    extra = user_engines()
    items = []
    for v in variants:
        scs = tuple(s for s in scenarios if (s.name, v) not in leave_out)
        if scs:
            items.append((v, scs, cache_root, use_cache, extra, time_limit_s))
    items.sort(key=lambda it: -_cost(it[0], it[1]))
    out: dict = {}
    n_runs = sum(len(it[1]) for it in items)
    costs = {it[0]: _cost(it[0], it[1]) for it in items}   # the time left follows the estimated cost
    with Progress("rbcheck sweep", "long runs", n_runs, enabled=show_progress,
                  total_work=sum(costs.values())) as bar:
        def done(item, recs):
            for k, (sc, rec) in enumerate(zip(item[1], recs)):
                out[(sc.name, item[0])] = rec
                bar.update(1, f"{sc.name} {item[0]}", work=costs[item[0]] if k == 0 else 0.0)

        def crashed(item):
            return _failed(item[1], item[0], "the worker process died running this variant's long runs "
                                             "(a crash inside the engine?)")

        runner.map_unordered(_run_long_item, items, done, on_crash=crashed, in_flight=lambda it: True)
    return out


def judged_rows(records: dict, scenarios, variants) -> tuple:
    """``(rows, summary records)`` of the long runs, in scenario then variant order: each row of
    LONG_RUN_COLUMNS with the judge's verdict (analysis.judge.judge_long_run against
    analysis.expectations.long_run_expectation), each summary record that row plus the assessment and the
    expectation's reason."""
    from cross_checks.analysis.expectations import long_run_expectation
    from cross_checks.analysis.judge import judge_long_run
    from cross_checks.analysis.long_run import DriftMetrics
    rows, recs = [], []
    for sc in scenarios:
        for v in variants:
            rec = records.get((sc.name, v))
            if rec is None:
                continue
            row = dict(rec["row"])
            exp = long_run_expectation(v)
            m = None
            if row["status"] != "failed" and math.isfinite(row.get("separatrix_start", math.nan)):
                m = DriftMetrics(*(row[c] for c in _METRICS[:8]), bool(row["toward_intermediate"]),
                                 bool(row["away_from_intermediate"]), float(row["steps"]) * float(row["dt"]),
                                 bool(row["crossed_separatrix"]), bool(row["energy_secular"]),
                                 int(row["steps"]))
            status = "failed" if m is None and row["status"] != "diverged" else row["status"]
            j = judge_long_run(v, sc.name, m, exp, status,
                               row.get("diverged_at_s") if row["status"] == "diverged" else None)
            row.update(verdict=j.verdict, matches_expectation=j.matches, expected_keeps=" ".join(exp.keeps),
                       expected_separatrix=exp.separatrix or "", finding=j.finding)
            rows.append({c: row.get(c, "") for c in LONG_RUN_COLUMNS})
            recs.append({**{c: row.get(c) for c in LONG_RUN_COLUMNS if c not in ("wall_s", "cached")},
                         "assessment": j.assessment, "reason": exp.reason,
                         "expected_keeps": list(exp.keeps)})
    return rows, recs


def long_run_scenario_record(sc) -> dict:
    """The summary's record of a long-run scenario: name, description, source, content hash, duration, Δt,
    steps, and the body's principal moments (kg m²) and initial spin (rad/s) the page states."""
    moments = np.linalg.eigvalsh(sc.problem.body.inertia_B)
    return {"name": sc.name, "description": sc.description, "source": sc.source,
            "content_hash": sc.content_hash, "duration_s": float(sc.duration_s), "dt_s": float(sc.dt_s),
            "steps": int(sc.n_steps()), "principal_moments_kg_m2": [float(m) for m in moments],
            "spin_rad_s": float(np.linalg.norm(sc.problem.initial.w_W)),
            "inertia_B_kg_m2": np.asarray(sc.problem.body.inertia_B, dtype=float).tolist()}
