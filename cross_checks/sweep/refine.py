"""A sweep's too-low free-running orders, judged again on the scenario's ladder continued to finer steps
(docs/verdicts.md, "On the ladder continued to finer steps").

Where a free-running record does not match its claimed order while its errors shrink
(``analysis.refinement.worth_refining``), the variant is run again at the file's finest Δt halved
``tol.REFINE_HALVINGS`` times, its final errors measured against the same reference with floors as for
the file's rungs (``assemble.ladder_floors``); only a positive result
(``analysis.refinement.refined_ladder_shows_the_order``) turns the record into ``pre_asymptotic``. The
extra runs are not rows of results.csv. They run on the sweep's runner, never in the sweep's own process
(a JAX engine started there would be unusable in the workers it forks next): :func:`requests` says which,
:func:`run_refinements` runs them, :func:`rejudge` judges each record again.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from cross_checks.analysis.expectations import expectation
from cross_checks.analysis.physics import physics_from_dict
from cross_checks.analysis.refinement import refined_ladder_shows_the_order, worth_refining
from cross_checks.core import tolerances as tol
from cross_checks.core.quantities import COLUMN_STEM, QUANTITIES, state_errors
from cross_checks.sweep.assemble import ladder_floors
from cross_checks.sweep.jobs import load_reference
from cross_checks.sweep.lifecycle import each_within_limits

__all__ = ["rejudge", "qualifies", "requests", "run_refinements", "Refinement"]


def qualifies(rec) -> bool:
    """A free-running record whose claimed order was not met while its errors shrink."""
    if (rec["mode"] != "free_running" or rec["matches_expectation"] is not False
            or rec["expected_verdict"] != "converges"):
        return False
    return worth_refining(rec["fit_verdict"], rec["errors"])


def _refined_runs(scenario, variant, dt_min, n_min, y_end_ref, time_limit_s):
    """[(dt, steps, status, {quantity: final error})] at dt_min/2 … dt_min/2^REFINE_HALVINGS (in one
    ``engines.run_variants`` call), up to the first run that cannot finish: a finer run that cannot shows
    nothing, the verdict stands."""
    from cross_checks.engines import EngineError, run_variants
    dts = [dt_min / 2 ** k for k in range(1, tol.REFINE_HALVINGS + 1)]
    trajs = each_within_limits(lambda d: run_variants(scenario, variant, d), dts, time_limit_s, "the run")
    out = []
    for k, (dt, traj) in enumerate(zip(dts, trajs), start=1):
        if isinstance(traj, (str, EngineError)):
            break
        ok = traj.meta.get("status", "ok") == "ok" and len(traj.t_s) - 1 == n_min * 2 ** k
        err = state_errors(traj.y[-1:], y_end_ref[None, :]) if ok else None
        out.append((dt, n_min * 2 ** k, "ok" if ok else "failed",
                    {q: float(err[q][0]) if ok else math.nan for q in QUANTITIES}))
    return out


@dataclass(frozen=True)
class Refinement:
    """The continued ladder of one (scenario, variant): below the file's finest ok rung ``dt_s`` (``n_steps``
    steps), against the reference's final state ``y_end_ref`` (13,)."""

    scenario: object
    variant: str
    dt_s: float
    n_steps: int
    y_end_ref: np.ndarray


def requests(scenario, variant, rows, ref, records) -> Refinement | None:
    """The :class:`Refinement` to run when one of ``records`` (convergence records of the scenario and
    variant, from ``rows``) qualifies and the reference ends at the scenario's duration; else None."""
    if not any(qualifies(r) for r in records) or not ref.path:
        return None
    ladder = sorted([r for r in rows if r["in_ladder"] and r["status"] == "ok"], key=lambda r: -r["dt"])
    t_ref, y_ref, _ = load_reference(ref.path)
    if not ladder or not np.isclose(t_ref[-1], scenario.duration_s):
        return None
    return Refinement(scenario, variant, float(ladder[-1]["dt"]), int(ladder[-1]["steps"]), y_ref[-1])


class _RefineTask:
    """One :class:`Refinement`'s runs, in a worker (picklable: the time limit only)."""

    def __init__(self, time_limit_s):
        self.time_limit_s = time_limit_s

    def __call__(self, req: Refinement) -> list:
        return _refined_runs(req.scenario, req.variant, req.dt_s, req.n_steps, req.y_end_ref,
                             self.time_limit_s)


def run_refinements(runner, reqs, time_limit_s=tol.RUN_TIME_LIMIT_S) -> dict:
    """``{(scenario name, variant): runs}`` of every request, run on ``runner`` (``execute.Runner``); a
    request whose worker dies has no runs (its verdict stands)."""
    done = runner.map_unordered(_RefineTask(time_limit_s), list(reqs), on_crash=lambda _req: [],
                                in_flight=lambda _req: True)
    return {(req.scenario.name, req.variant): fine for req, fine in done}


def rejudge(scenario, variant, rows, ref, records, fine) -> list:
    """``records`` (convergence records of one scenario and variant, from ``rows``) with each qualifying
    free-running record judged again on the continued ladder ``fine`` (the runs of its :class:`Refinement`,
    [] or None when it had none; module docstring)."""
    todo = [i for i, r in enumerate(records) if qualifies(r)]
    if not todo or not fine:
        return records
    finest = sorted([r for r in rows if r["in_ladder"] and r["status"] == "ok"], key=lambda r: -r["dt"])[-1]
    phys = physics_from_dict(ref.measured["physics"]) if (ref.measured or {}).get("physics") else None
    pseudo = [{"dt": dt, "steps": n} for dt, n, _, _ in fine]
    out = list(records)
    for i in todo:
        rec = records[i]
        q = rec["quantity"]
        dts = [float(finest["dt"])] + [p["dt"] for p in pseudo]
        errs = [float(finest[f"{COLUMN_STEM[q]}_err_final"])] + [e[q] for _, _, _, e in fine]
        statuses = ["ok"] + [s for _, _, s, _ in fine]
        floors = ladder_floors([finest] + pseudo, q, ref.scales, "free_running",
                               finest["reference"] or "analytic",
                               ref.measured or {}, variant)
        exp = expectation(scenario, variant, q, "free_running", physics=phys, measure_physics=False)
        shows, fit = refined_ladder_shows_the_order(dts, errs, floors, statuses, exp)
        if shows:
            out[i] = {**rec, "verdict": "pre_asymptotic", "matches_expectation": None,
                      "assessment": _assessment(rec, fit, exp)}
    return out


def _assessment(rec, fit, exp) -> str:
    pw = ", ".join("–" if p is None else f"{p:.2f}" for p in fit.pairwise_orders)
    seen = (f"order {rec['order']:.2f}" if rec.get("order") is not None
            else rec["fit_verdict"].replace("_", " "))
    return (f"pre-asymptotic on this ladder (measured): {seen} on the file's Δt, "
            f"but the ladder continued to Δt = {fit.dt_s[-1]:.3g} s shows order "
            f"{fit.order:.2f} (pairwise {pw}; expected {exp.order:g}); no claim")
