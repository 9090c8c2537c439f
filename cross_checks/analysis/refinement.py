"""A free-running order that came out too low, judged again on the ladder continued to finer steps.

An order claim is about the asymptotic regime. On a short ladder a correct scheme can still be
pre-asymptotic: its error series e(h) = h^p A(t) + h^(p+1) B(t) + … with A small where the error is
measured, so the next term bends the fitted order at the coarse rungs (docs/fuzz.md §5). A scheme of the
wrong order has that order on the finer rungs too. So a too-low order whose errors do shrink is judged
again on the ladder's finest rung and ``tol.REFINE_HALVINGS`` halvings below it, by
the same fit (:func:`convergence.fit_convergence`), and it is excused only by a POSITIVE result there: a
converging fit on points resolved above their floors (not a lower bound, not round-off) whose order matches
the claim. Errors that sink into round-off on the finer rungs show nothing, and the verdict stands.

Used by the sweep (``cross_checks.sweep.refine``) and the fuzz (``cross_checks.fuzz.pipeline``).
"""
from __future__ import annotations

import math

from cross_checks.analysis.convergence import fit_convergence
from cross_checks.analysis.judge import judge_fit

__all__ = ["errors_shrink", "worth_refining", "refined_ladder_shows_the_order"]


def errors_shrink(errors) -> bool:
    """Whether a ladder's errors (coarse to fine, all finite) shrink over the ladder: the finest below the
    coarsest, however slowly and whether or not at every halving (a velocity error crossing zero at one
    rung; the largest error over a short run moving in time). A flat plateau, a growth or a failed point
    does not qualify. Only the ladder continued decides: a plateau that happens to dip at the finest rung
    stays a plateau there (refined_ladder_shows_the_order)."""
    errs = list(errors)
    if len(errs) < 2 or any(e is None or not math.isfinite(e) for e in errs):
        return False
    return errs[-1] < errs[0]


def worth_refining(fit_verdict: str, errors) -> bool:
    """Whether a ladder that contradicted its claimed order is judged again on finer steps: the one rule of
    the sweep and the fuzz. Its fit converged (too slowly: the order was below the claim) or did not converge
    while its errors still shrink (finest below coarsest: not at every halving); every error finite. A
    plateau, a growth, a failed or a diverged ladder shows no order to continue."""
    errs = [math.nan if e is None else e for e in errors]
    if fit_verdict not in ("converges", "does_not_converge") or len(errs) < 2:
        return False
    if any(not math.isfinite(e) for e in errs):
        return False
    return fit_verdict == "converges" or errors_shrink(errs)


def refined_ladder_shows_the_order(dts, errors, floors, statuses, exp) -> tuple:
    """``(shows, fit)``: whether the continued ladder (finest original rung first, then the finer ones)
    shows the order the expectation ``exp`` claims — a converging fit on resolved points matching it,
    or one whose finest pair already shows it while the coarser approach it (``measured_pre_asymptotic``)."""
    fit = fit_convergence(dts, errors, floors, statuses)
    if exp.verdict != "converges" or exp.order is None:
        return False, fit
    if fit.verdict != "converges" or fit.order is None or fit.order_is_lower_bound:
        return False, fit
    j = judge_fit(fit, exp)   # the one judge: a match, or the order measured on the finest pair (a claim)
    return bool(j.matches is True or (j.verdict == "pre_asymptotic" and j.claimed)), fit
