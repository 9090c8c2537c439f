"""Convergence orders over a Δt ladder: pairwise orders, the least-squares fit above the measured
floors, and the comparison of a fitted verdict with an expectation (cross_checks.analysis.expectations).

Orders are global orders of the error at a fixed final time, ``e(Δt) ≈ C Δt^p``; pairwise orders are
``log(e_i / e_{i+1}) / log(Δt_i / Δt_{i+1})`` (``log2(e(h) / e(h/2))`` for a halving ladder).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from cross_checks.core import tolerances as tol


def pairwise_orders(dt_s, errors) -> list:
    """``log(e_i / e_{i+1}) / log(Δt_i / Δt_{i+1})`` for consecutive ladder points (dt descending);
    ``log2(e(h) / e(h/2))`` for a halving ladder. None where an error is zero or not finite."""
    out: list[float | None] = []
    for i in range(len(dt_s) - 1):
        e0, e1 = errors[i], errors[i + 1]
        if e0 is None or e1 is None or not (math.isfinite(e0) and math.isfinite(e1)) or e0 <= 0 or e1 <= 0:
            out.append(None)
        else:
            out.append(float(math.log(e0 / e1) / math.log(dt_s[i] / dt_s[i + 1])))
    return out


@dataclass
class ConvergenceFit:
    """Result of :func:`fit_convergence` (ladder sorted by Δt descending).

    order : least-squares slope over the fitted points, or None.
    pairwise_orders : between consecutive points (None where undefined).
    fitted : which points the slope used.
    verdict : "converges", "does_not_converge", "at_roundoff", "diverged", "failed" or "insufficient".
    note : why points were dropped, in words ("" when none were).
    order_is_lower_bound : the order came from points fewer than RESOLVED_ABOVE_FLOOR times above their
        floors (fewer than two were): round-off can only add to the finer errors, so the true order is
        at least this.
    """

    dt_s: list
    errors: list
    order: float | None
    pairwise_orders: list
    fitted: list
    verdict: str
    note: str = ""
    floors: list = field(default_factory=list)
    order_is_lower_bound: bool = False


def _lsq_slope(x, y):
    """Least-squares slope of y over x ((K,) float arrays); the means are ``add.reduce / K``, what
    ``ndarray.mean`` computes, without its Python wrappers."""
    add = np.add.reduce
    xm = x - add(x) / len(x)
    return float(add(xm * (y - add(y) / len(y))) / add(xm * xm))


def _floats(values) -> list:
    """Python floats (None -> NaN), as ``np.asarray(values, dtype=float).tolist()`` gives."""
    return [math.nan if v is None else float(v) for v in values]


def fit_convergence(dt_s, errors, floors=None, statuses=None,
                    amplified_factor: float = tol.AMPLIFIED_ROUNDOFF_FACTOR) -> ConvergenceFit:
    """Fit the convergence order of final errors over a Δt ladder and give a verdict.

    dt_s : (K,) steps, s (any order; sorted descending here).
    errors : (K,) final errors (NaN for runs that produced none).
    floors : (K,) round-off floor of each point (metrics.roundoff_floor); 0 when omitted.
    statuses : (K,) run status per point ("ok", "diverged", "failed"); "ok" when omitted.
    amplified_factor : how many floors an error growing again at the fine end may reach and still be
        amplified round-off (AMPLIFIED_ROUNDOFF_FACTOR; judge.judge_ladder gives a float32 variant
        AMPLIFIED_ROUNDOFF_FACTOR_FLOAT32).

    Verdicts: fewer than two finished runs -> "diverged" (when any diverged) or "failed"/"insufficient";
    fewer than two points resolved above their floor -> "at_roundoff" (the scheme is exact here); else the
    least-squares order over the asymptotic points: "converges" when it is ≥ CONVERGES_MIN_ORDER and
    the error shrinks at every halving, otherwise "does_not_converge".
    """
    dt0, e0 = _floats(dt_s), _floats(errors)
    K = len(dt0)
    fl0 = [0.0] * K if floors is None else _floats(floors)
    st0 = ["ok"] * K if statuses is None else list(statuses)
    if any(math.isnan(h) for h in dt0):
        order_idx = np.argsort(-np.asarray(dt0), kind="stable").tolist()   # NaN last, as NumPy sorts it
    else:
        order_idx = sorted(range(K), key=lambda i: -dt0[i])   # stable, like argsort(kind="stable")
    dt, e, fl, st = ([v[i] for i in order_idx] for v in (dt0, e0, fl0, st0))
    pw = pairwise_orders(dt, e)
    fitted = [False] * K
    res: dict = dict(dt_s=dt, errors=list(e), pairwise_orders=pw, floors=fl)

    ok = [s == "ok" and math.isfinite(v) for s, v in zip(st, e)]
    notes = []
    bad = [f"Δt = {dt[i]:g} s {st[i]}" for i in range(K) if not ok[i]]
    if bad:
        notes.append("; ".join(bad))
    if sum(ok) < 2:
        verdict = ("diverged" if any(s == "diverged" for s in st)
                   else ("failed" if any(s == "failed" for s in st) else "insufficient"))
        return ConvergenceFit(order=None, fitted=fitted, verdict=verdict, note="; ".join(notes), **res)

    idx_ok = [i for i in range(K) if ok[i]]
    above = _drop_amplified_roundoff(dt, e, fl, _drop_roundoff_tail(dt, e, fl, idx_ok, notes), notes,
                                     amplified_factor)
    lower_bound = False
    if len(above) < 2:
        above = _lower_bound_points(e, fl, idx_ok, above)
        if above is None:
            return ConvergenceFit(order=None, fitted=fitted, verdict="at_roundoff",
                                  note="; ".join(notes), **res)
        lower_bound = True
        notes.append(f"fewer than two errors {tol.RESOLVED_ABOVE_FLOOR:g}× above their floors: fitted on the "
                     f"{len(above)} above it, the order is a lower bound")
    use = _drop_pre_asymptotic_coarsest(dt, e, above, notes)
    dt_use, e_use = [dt[i] for i in use], [e[i] for i in use]
    order = _lsq_slope(np.log(np.array(dt_use)), np.log(np.array(e_use)))
    for i in use:
        fitted[i] = True
    pw_use = pairwise_orders(dt_use, e_use)
    shrinking = all(p is not None and p > 0 for p in pw_use)
    verdict = "converges" if order >= tol.CONVERGES_MIN_ORDER and shrinking else "does_not_converge"
    if (len(pw_use) >= 2 and all(p is not None for p in pw_use) and pw_use[-1] - pw_use[0] >= 0.2
            and all(b > a - 0.05 for a, b in zip(pw_use, pw_use[1:]))):
        notes.append("pairwise orders still rising towards the finest Δt "
                     f"({pw_use[0]:.2f} → {pw_use[-1]:.2f}): pre-asymptotic on this ladder")
    return ConvergenceFit(order=order, fitted=fitted, verdict=verdict, note="; ".join(notes),
                          order_is_lower_bound=lower_bound, **res)


def _drop_roundoff_tail(dt, e, fl, idx_ok, notes) -> list:
    """(a) Round-off at the fine end: the first point not resolved above its floor (≤ RESOLVED_ABOVE_FLOOR
    × floor: round-off may be a tenth of it) and every finer one are dropped, provided none of the finer
    ones is resolved (else the low point is an accident of the ladder). Returns the indices kept (coarse to
    fine)."""
    for k, i in enumerate(idx_ok):
        if all(e[j] <= tol.RESOLVED_ABOVE_FLOOR * fl[j] for j in idx_ok[k:]):
            notes.append(f"{len(idx_ok) - k} point(s) within {tol.RESOLVED_ABOVE_FLOOR:g}× "
                         f"the round-off floor dropped (Δt ≤ {dt[i]:g} s)")
            return idx_ok[:k]
    return list(idx_ok)


def _drop_amplified_roundoff(dt, e, fl, above, notes,
                             factor: float = tol.AMPLIFIED_ROUNDOFF_FACTOR) -> list:
    """(b) Round-off amplified by the dynamics: the error grows again at the fine end while still tiny
    (≤ ``factor`` × floor, AMPLIFIED_ROUNDOFF_FACTOR by default); the fine points within
    ROUNDOFF_NOISE_FACTOR of the smallest error are dropped."""
    if len(above) < 3 or not e[above[-1]] > e[above[-2]]:
        return above
    m = min(e[i] for i in above)
    i_min = min(above, key=lambda i: e[i])
    finer = [i for i in above if i > i_min]
    if not (m <= factor * fl[i_min]
            and all(e[i] <= tol.ROUNDOFF_NOISE_FACTOR * m for i in finer)):
        return above
    keep = list(above)
    while keep and e[keep[-1]] <= tol.ROUNDOFF_NOISE_FACTOR * m:
        keep.pop()
    notes.append(f"errors stop falling at {m:.2g} (Δt = {dt[i_min]:g} s) and grow again: round-off amplified "
                 f"by the dynamics; {len(above) - len(keep)} fine point(s) dropped")
    return keep


def _lower_bound_points(e, fl, idx_ok, above):
    """Fewer than two resolved points: if the coarsest is resolved, the points above the floor itself
    (the order fitted on them is a lower bound: what round-off adds to a finer point can only lower it);
    None when there is no such pair (with no resolved point at all, the errors are round-off whatever
    they do)."""
    cand = list(idx_ok)
    while cand and e[cand[-1]] <= fl[cand[-1]]:
        cand.pop()
    if len(above) == 0 or len(cand) < 2 or len(cand) <= len(above):
        return None
    return cand


def _median(values) -> float:
    """``np.median`` of a few floats, exactly (the middle one, or the two middle ones' sum halved)."""
    s = sorted(values)
    m = len(s) // 2
    return float(s[m] if len(s) % 2 else (s[m - 1] + s[m]) / 2.0)


def _drop_pre_asymptotic_coarsest(dt, e, above, notes) -> list:
    """A pre-asymptotic coarsest point (of four or more): its pairwise order is far from the median of
    the finer pairs (PRE_ASYMPTOTIC_ORDER_DEV); dropped from the fit."""
    use = list(above)
    if len(use) < 4:
        return use
    pw_use = pairwise_orders([dt[i] for i in use], [e[i] for i in use])
    rest = [p for p in pw_use[1:] if p is not None]
    if pw_use[0] is not None and rest and all(p > 0 for p in rest) \
            and abs(pw_use[0] - _median(rest)) > tol.PRE_ASYMPTOTIC_ORDER_DEV:
        notes.append(f"coarsest Δt = {dt[use[0]]:g} s pre-asymptotic "
                     f"(pairwise order {pw_use[0]:.2f}), dropped")
        return use[1:]
    return use


def fmt_order(order: float) -> str:
    """An order to two decimals, a flat fit's tiny negative slope shown as 0.00 (not "-0.00")."""
    text = f"{order:.2f}"
    return "0.00" if text == "-0.00" else text


def measured_pre_asymptotic(fit: ConvergenceFit, expected_order) -> str:
    """Why a converging fit whose order is too LOW is pre-asymptotic on its ladder, from the errors
    themselves ("" when it is not): the errors shrink at every halving, the finest fitted pair already
    shows the expected order (within SWEEP_ORDER_TOL) and the coarser pairs approach it. A scheme of
    the wrong order shows that order on its finest pair too, so it is not excused."""
    if fit.verdict != "converges" or fit.order_is_lower_bound or expected_order is None or fit.order is None:
        return ""
    if fit.order >= expected_order - tol.SWEEP_ORDER_TOL:
        return ""
    idx = [i for i, f in enumerate(fit.fitted) if f]
    pw = pairwise_orders([fit.dt_s[i] for i in idx], [fit.errors[i] for i in idx])
    if len(pw) < 2 or any(p is None for p in pw):
        return ""
    first, last = abs(pw[0] - expected_order), abs(pw[-1] - expected_order)
    if last <= tol.SWEEP_ORDER_TOL and last < first:
        return (f"pre-asymptotic (measured): fitted order {fit.order:.2f} over the ladder, but the "
                f"finest pair already shows {pw[-1]:.2f} (expected {expected_order:g}) and the coarser "
                f"pairs approach it ({', '.join(f'{p:.2f}' for p in pw)}); no claim on this ladder")
    return ""


def order_within_floors(fit: ConvergenceFit):
    """The largest least-squares order the measured errors allow when each may be off by up to its round-off
    floor — over the fitted points, and over those with the finer ones the fit dropped as round-off but that
    are still above their floor (the larger of the two): the errors at Δt above the ladder's mean log Δt
    raised by their floors, those below it lowered (the slope grows with the first and falls with the second).
    Where two or more dropped finer rungs are flat (within a factor 2) above the floor estimate, their level
    is each rung's floor instead: round-off, measured. None when fewer than two points stand above their
    floors (or the fit has no order).

    A claim that the order is too low holds only if this order is too low as well (docs/verdicts.md §4,
    "Within the round-off floors")."""
    if fit.order is None:
        return None
    idx = [i for i, f in enumerate(fit.fitted) if f]
    if not idx:
        return None
    finest = min(fit.dt_s[i] for i in idx)
    tail = [i for i in range(len(fit.dt_s)) if not fit.fitted[i] and fit.dt_s[i] < finest
            and math.isfinite(fit.errors[i]) and fit.errors[i] > 0.0]
    # a flat tail of dropped rungs (two or more within a factor 2: the error no longer shrinks with Δt) is
    # round-off, measured: where it stands above the floor estimate, its level bounds the round-off in every
    # rung instead
    te = [fit.errors[i] for i in tail]
    level = max(te) if len(te) >= 2 and max(te) <= 2.0 * min(te) else 0.0
    floor = [max(f, level) for f in fit.floors]
    # the fitted points alone, and with the dropped ones that still stand above their floor: the claim must
    # fail on both (the tail can only widen the room it leaves, never narrow it below the fit's own points)
    best = None
    for points in (idx, idx + tail):
        use = [i for i in points if math.isfinite(fit.errors[i]) and fit.errors[i] > floor[i]]
        if len(use) < 2:
            continue
        x = [math.log(fit.dt_s[i]) for i in use]
        mean = sum(x) / len(x)
        y = [math.log(fit.errors[i] + (floor[i] if xi > mean else -floor[i] if xi < mean else 0.0))
             for i, xi in zip(use, x)]
        slope = _lsq_slope(np.array(x), np.array(y))
        best = slope if best is None else max(best, slope)
    return best


def compare_with_expectation(verdict: str, order, expected, order_is_lower_bound: bool = False) -> tuple:
    """``(matches, phrase)``: whether an observed verdict/order agrees with an
    :class:`~cross_checks.analysis.expectations.Expectation`; ``matches`` is None when nothing is expected (or
    the expectation makes no claim on this ladder, or the order is only a lower bound below it).

    A scheme that is exact to round-off, or converges faster than its nominal order, agrees with
    "converges"; a lower order (beyond SWEEP_ORDER_TOL), a plateau, a divergence or a failure do not.
    """
    ev, eo = expected.verdict, expected.order
    if ev is None:
        return None, "no expectation"
    if ev == "pre_asymptotic":
        seen = f"{verdict.replace('_', ' ')}" + (f", fitted order {fmt_order(order)}"
                                                 if order is not None else "")
        return None, f"no claim on this ladder (pre-asymptotic; {seen})"
    if verdict == "at_roundoff":
        prec = getattr(expected, "precision", "float64")
        exact = "exact to round-off" if prec == "float64" else f"within {prec} round-off on every rung"
        return (ev == "converges"), (exact if ev == "converges"
                                     else f"{exact} although non-convergence was expected")
    if verdict == "converges":
        if ev != "converges":
            return False, f"converges (order {order:.2f}) although non-convergence was expected"
        if eo is None:
            return True, f"converges (order {order:.2f})"
        if order < eo - tol.SWEEP_ORDER_TOL:
            if order_is_lower_bound:
                return None, (f"order ≥ {order:.2f} only (the finer errors are near the round-off floor), "
                              f"expected {eo:g}: inconclusive")
            return False, f"order {order:.2f}, expected {eo:g}"
        if order > eo + tol.SWEEP_ORDER_TOL:
            return True, f"order {order:.2f}, above the nominal {eo:g}"
        return True, f"order {order:.2f} as expected ({eo:g})"
    if verdict == "does_not_converge":
        if ev == "does_not_converge":
            return True, "does not converge, as expected"
        if order_is_lower_bound:
            return None, "the finer errors are near the round-off floor: inconclusive"
        return False, ("does not converge"
                       + (f" (fitted order {fmt_order(order)})" if order is not None else "")
                       + (f", expected order {eo:g}" if eo is not None else ""))
    return False, verdict.replace("_", " ")

