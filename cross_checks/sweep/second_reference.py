"""The second, independent reference of every scenario: Drake's error-controlled integration
(:mod:`cross_checks.engines.drake_reference`) at ``SECOND_REFERENCE_TARGET_ACCURACY``, compared with the
primary (closed form or DOP853) at up to ``SAMPLES`` times of the default-Δt grid.

Each side's accuracy is measured, not assumed: the primary's measured error (references.reference_error)
plus the round-off the sweep's verdicts allow a run at the default Δt; Drake's distance from a second
Drake solution at a ``SECOND_REFERENCE_CHECK_FACTOR`` times looser target, plus its steps' round-off grown
by the measured amplification (metrics.roundoff_floor). They agree when, in every quantity, their largest
distance is within the sum. The record is ``scenarios[i].second_reference`` of summary.json (None without
Drake); docs/engine_conventions.md, "The second reference".
"""
from __future__ import annotations

import hashlib
import json

import numpy as np

from cross_checks.analysis import metrics as M
from cross_checks.core import tolerances as tol
from cross_checks.core.quantities import QUANTITIES, decimation_indices, quantity_scales, state_errors
from cross_checks.sweep import cache

__all__ = ["SAMPLES", "second_reference", "compare_references", "sample_indices"]

#: Times of the default-Δt grid at which the two references are compared (evenly spread, t = 0 and
#: the final time included): the distance is a maximum over these.
SAMPLES = 500


def sample_indices(scenario, t_union) -> np.ndarray:
    """Indices into the primary reference's time grid ``t_union`` of the comparison times."""
    grid = np.searchsorted(t_union, scenario.dt_s * np.arange(scenario.n_steps() + 1))
    return grid[decimation_indices(len(grid), SAMPLES)]


def compare_references(y_primary, y_second, y_check, *, primary_error: dict, amplification: dict,
                       primary_steps: int, second_steps: int) -> dict:
    """``distance``, ``stated_accuracy`` (and its two parts) and ``agrees`` of two references on the same
    times: ``y_primary``, ``y_second`` and ``y_check`` (the second at a looser accuracy), each (T, 13).

    The primary's accuracy is its measured error ``primary_error`` {quantity: error} plus the round-off
    of ``primary_steps`` steps (the floor the sweep's verdicts put under a run of the scenario's default
    Δt); the second's is its distance from ``y_check`` plus the round-off of its ``second_steps`` steps;
    round-offs grown by the measured error ``amplification`` (metrics.roundoff_floor)."""
    scales = quantity_scales(y_primary)
    dist = state_errors(y_second, y_primary)
    check = state_errors(y_check, y_second)
    distance, second_acc, primary_acc, stated = {}, {}, {}, {}
    for q in QUANTITIES:
        distance[q] = float(np.max(dist[q]))
        amp = float((amplification or {}).get(q, 1.0))
        primary_acc[q] = M.roundoff_floor(scales[q], primary_steps,
                                          reference_error=float((primary_error or {}).get(q) or 0.0),
                                          amplification=amp, quantity=q)
        second_acc[q] = M.roundoff_floor(scales[q], second_steps, reference_error=float(np.max(check[q])),
                                         amplification=amp, quantity=q)
        stated[q] = primary_acc[q] + second_acc[q]
    bad = [q for q in QUANTITIES if not distance[q] <= stated[q]]
    return {"distance": distance, "stated_accuracy": stated, "primary_accuracy": primary_acc,
            "second_accuracy": second_acc, "agrees": not bad, "disagreeing": bad}


def _cache_key(scenario, t_s) -> str:
    """What the Drake solutions depend on: the scenario, Drake's version, the code (code_fingerprint covers
    every module of the engines and sweep layers), the accuracies, the times and the environment."""
    from cross_checks.engines import drake_reference
    from cross_checks.sweep.fingerprint import code_fingerprint, environment
    from cross_checks.sweep.schema import SCHEMA_VERSION
    return hashlib.sha256(json.dumps([SCHEMA_VERSION, "second_reference", scenario.content_hash,
                                      drake_reference.version(), code_fingerprint("drake"),
                                      tol.SECOND_REFERENCE_TARGET_ACCURACY, tol.SECOND_REFERENCE_CHECK_FACTOR,
                                      t_s.tolist(), environment()]).encode()).hexdigest()


def _drake_solutions(scenario, t_s, cache_root, use_cache):
    """Drake's solution at the target accuracy and at the check accuracy on ``t_s``, cached."""
    from cross_checks.engines.drake_reference import drake_solution
    key = _cache_key(scenario, t_s)
    path = cache.entry_path(cache_root, "second_reference", key) if cache_root else None
    if path is not None and use_cache:
        arrays = cache.load(cache_root, path, key)
        if arrays is not None and arrays.get("y") is not None and arrays["y"].shape == (t_s.size, 13):
            return arrays["y"], arrays["y_check"], int(arrays["steps"])
    a = tol.SECOND_REFERENCE_TARGET_ACCURACY
    y, steps = drake_solution(scenario, t_s, a)
    y_check, _ = drake_solution(scenario, t_s, a * tol.SECOND_REFERENCE_CHECK_FACTOR)
    if path is not None:
        cache.store(cache_root, path, key, {"y": y, "y_check": y_check, "steps": np.array(steps)})
    return y, y_check, steps


def _ground_truth_error_over_run(scenario, t_s, cache_root, use_cache) -> dict:
    """{quantity: max over ``t_s`` of the distance between DOP853 at its tolerance and at a
    REFERENCE_CHECK_RTOL_FACTOR times looser one} — both solved here, so the claim does not depend on
    the primary's numbers being right (references.reference_error measures it at the final time only)."""
    from reference_sim.ground_truth import GROUND_TRUTH_RTOL, ground_truth
    key = _cache_key(scenario, t_s) + "-dop853-check"
    path = cache.entry_path(cache_root, "second_reference", key) if cache_root else None
    arrays = cache.load(cache_root, path, key) if path is not None and use_cache else None
    if arrays is not None and all(arrays.get(k) is not None and arrays[k].shape == (t_s.size, 13)
                                  for k in ("y", "y_loose")):
        y, y_loose = arrays["y"], arrays["y_loose"]
    else:
        y = ground_truth(scenario.problem, t_s)
        y_loose = ground_truth(scenario.problem, t_s,
                               rtol=tol.REFERENCE_CHECK_RTOL_FACTOR * GROUND_TRUTH_RTOL)
        if path is not None:
            cache.store(cache_root, path, key, {"y": y, "y_loose": y_loose})
    d = state_errors(y_loose, y)
    return {q: float(np.max(d[q])) for q in QUANTITIES}


def second_reference(scenario, t_union, y_primary, label: str, measured: dict, cache_root, use_cache: bool):
    """The record of ``scenarios[i].second_reference`` (None when Drake is not installed)."""
    try:
        from cross_checks.engines.drake_reference import drake_label
        second_label = drake_label(tol.SECOND_REFERENCE_TARGET_ACCURACY)
    except ImportError:
        return None
    rec = {"label": second_label, "target_accuracy": tol.SECOND_REFERENCE_TARGET_ACCURACY,
           "check_factor": tol.SECOND_REFERENCE_CHECK_FACTOR, "primary": label}
    k = sample_indices(scenario, np.asarray(t_union))
    t_s = np.asarray(t_union)[k]
    try:
        y, y_check, steps = _drake_solutions(scenario, t_s, cache_root, use_cache)
    except Exception as exc:  # noqa: BLE001 - Drake's failure is reported, the sweep goes on
        rec.update(agrees=None, error=f"{type(exc).__name__}: {exc}")
        return rec
    if label.startswith("ground_truth"):  # DOP853's error measured over the whole run (its end included)
        primary_error = _ground_truth_error_over_run(scenario, t_s, cache_root, use_cache)
    else:
        primary_error = dict((measured or {}).get("reference_error") or {})
    rec.update(compare_references(np.asarray(y_primary)[k], y, y_check,
                                  primary_error=primary_error,
                                  amplification=(measured or {}).get("amplification"),
                                  primary_steps=scenario.n_steps(), second_steps=steps))
    # no wall time: a cached and a fresh sweep give the same record
    rec.update(samples=int(t_s.size), steps=steps)
    return rec
