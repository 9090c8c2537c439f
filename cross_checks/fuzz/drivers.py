"""Running one engine variant on a whole batch of cases: free runs at the three rungs, and one-step runs.

Every engine, the reference included, runs through its own adapter: the free runs of all cases and rungs
in one ``EngineAdapter.simulate_many`` call (MuJoCo's rollout, PyBullet's kept bodies, the default loop
over ``simulate`` elsewhere), the one-step runs through ``one_step``, one call per case and step. Runs are
recorded whole (``(n + 1, B, 13)``, NaN after a divergence or for a failed run); the batch is small enough
(tens of cases, a few hundred steps) that measuring afterwards beats measuring on the fly.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cross_checks.core import tolerances as tol
from cross_checks.engines.base import EngineError, RunRequest
from cross_checks.sweep.lifecycle import each_within_limits

__all__ = ["Runs", "RUNGS", "run_ladder", "one_step", "NOT_EXPRESSIBLE"]

#: The status of a case the variant's engine cannot express (EngineAdapter.expressible; the message says
#: why): nothing is run, nothing is judged, and the campaign counts it per variant.
NOT_EXPRESSIBLE = "not_expressible"

#: Rungs of a case's free-running ladder: steps h, h/2, h/4.
RUNGS = 3


@dataclass
class Runs:
    """A variant's runs of every case of a batch at one step per case (``h_s``, (B,), s).

    y : (n + 1, B, 13) packed states [x_W, v_W, q_WB (w x y z), w_W], NaN from a divergence on, and for
        a failed run. status : per case "ok", "diverged", "failed" or NOT_EXPRESSIBLE. diverged_at_s :
        (B,), NaN when not diverged. message : per case ("" when ok).
    """

    h_s: np.ndarray
    y: np.ndarray
    status: list
    diverged_at_s: np.ndarray
    message: list


def _empty_runs(h_s, n):
    B = len(h_s)
    return Runs(np.asarray(h_s, dtype=float), np.full((n + 1, B, 13), np.nan), ["ok"] * B, np.full(B, np.nan),
                [""] * B)


def _store(runs, i, run, n):
    """Put an adapter's result (a ``reference_sim.simulate.Run``, or the message of its failure) into case
    ``i`` of ``runs``."""
    if isinstance(run, str):
        runs.status[i], runs.message[i] = "failed", run
        return
    k = len(run.y)
    runs.y[:k, i] = run.y
    if run.diverged_at_s is not None:
        runs.status[i] = "diverged"
        runs.diverged_at_s[i] = float(run.diverged_at_s)
        runs.message[i] = run.message or f"diverged at t = {run.diverged_at_s:.6g} s"
    elif k != n + 1:
        runs.y[:, i] = np.nan
        runs.status[i] = "failed"
        runs.message[i] = f"the engine returned {k} states instead of {n + 1}"


def _simulated(adapter, var, requests) -> list:
    """``adapter.simulate_many(var, requests)``, each failure as its message, each run within a run's time
    limit as in a sweep (``lifecycle.each_within_limits``)."""
    runs = each_within_limits(lambda reqs: adapter.simulate_many(var, reqs), requests, tol.RUN_TIME_LIMIT_S,
                              "the run")
    return [f"EngineError: {r}" if isinstance(r, EngineError) else r for r in runs]


def run_ladder(variant, scenarios, h0s, n0: int) -> list:
    """The free runs of ``variant`` (a Resolved) on every case at h0, h0/2, h0/4 (``n0``, 2 n0, 4 n0 steps):
    [Runs] × 3."""
    adapter, var = variant.adapter, variant.variant
    out = [_empty_runs(np.asarray(h0s, dtype=float) / 2 ** r, n0 * 2 ** r) for r in range(RUNGS)]
    cannot = [adapter.expressible(sc, var) for sc in scenarios]
    for i, why in enumerate(cannot):
        for runs in out if why else ():
            runs.status[i], runs.message[i] = NOT_EXPRESSIBLE, why
    cells = [(r, i) for r in range(RUNGS) for i in range(len(scenarios)) if not cannot[i]]
    requests = [RunRequest(scenarios[i], float(out[r].h_s[i]), n0 * 2 ** r) for r, i in cells]
    with np.errstate(all="ignore"):
        for (r, i), run in zip(cells, _simulated(adapter, var, requests)):
            _store(out[r], i, run, n0 * 2 ** r)
    return out


def one_step(variant, scenarios, hs, y_start):
    """One step of ``hs[j]`` from ``y_start[j]`` (M, 13) for members of ``scenarios[j]``: (M, 13), NaN
    where the engine failed; None when the engine has no one-step mode."""
    if not variant.one_step:
        return None
    adapter, var = variant.adapter, variant.variant
    y_start = np.asarray(y_start, dtype=float)
    out = np.full((len(scenarios), 13), np.nan)
    groups: dict = {}   # (id(scenario), h) -> members, in order (the list holds the scenarios)
    for j, sc in enumerate(scenarios):
        if not adapter.expressible(sc, var):   # a case the engine cannot express keeps NaN: it is not judged
            groups.setdefault((id(sc), float(hs[j])), []).append(j)
    for idx in groups.values():
        try:
            with np.errstate(all="ignore"):
                out[idx] = np.asarray(adapter.one_step(scenarios[idx[0]], var,
                                                       float(hs[idx[0]]), y_start[idx]),
                                      dtype=float)
        except KeyboardInterrupt:
            raise
        except Exception:  # noqa: BLE001 - a failed one-step run leaves NaN: the property says so
            pass
    return out
