"""``rbcheck check A.csv B.csv C.csv --scenario S``: several runs of one scenario at different Δt.

Each file gets its own check; then the final errors against the reference are fitted over Δt with the
sweep's own machinery and judged by the one judge every entry point uses
(:func:`cross_checks.analysis.judge.judge_ladder`, round-off floors included). The expectation: the reference
variant the files ARE (all the same one), else a consistent scheme (converges, order not claimed).
"""
from __future__ import annotations

import math

from cross_checks.analysis import metrics as M
from cross_checks.analysis.expectations import Expectation, expectation
from cross_checks.analysis.judge import judge_ladder
from cross_checks.core import tolerances as tol
from cross_checks.core.quantities import QUANTITIES, quantity_scales

__all__ = ["LadderError", "check_ladder"]


class LadderError(ValueError):
    """Files that cannot form a ladder (message names the file and the reason) -> exit 2."""


def _final_errors(res):
    out = {}
    for e in res.evidence:
        if e.kind == "free-running" and e.series:
            v = e.series["value"]
            out[e.quantity] = float(v[-1]) if len(v) else math.nan
    return out


def _expected(results, scenario, quantity, scheme=None):
    if scheme is not None:   # "is this exactly SCHEME?": that scheme's own orders
        return scheme, expectation(scenario, scheme, quantity)
    same = set(results[0].identity)
    for r in results[1:]:
        same &= set(r.identity)
    if same:
        v = sorted(same)[0]
        return v, expectation(scenario, v, quantity)
    return None, Expectation("converges", None, "a consistent scheme converges (its order is not claimed)")


def check_ladder(results, scenario, scheme=None) -> dict:
    """The ladder summary of checks ``results`` (CheckResult, one per file) of ``scenario``; ``scheme``: the
    question "is this exactly ENGINE:VARIANT?" (its orders expected) instead of "a correct simulation?"."""
    dts = []
    for r in results:
        if r.input["dt_s"] is None:
            raise LadderError(f"{r.source}: t: variable steps: a ladder needs one Δt per file")
        if any(math.isclose(r.input["dt_s"], d, rel_tol=1e-9) for d in dts):
            raise LadderError(f"{r.source}: t: Δt = {r.input['dt_s']:g} s appears "
                              "in two files; a ladder needs distinct steps")
        dts.append(r.input["dt_s"])
    notes = []
    statuses = []
    for r in results:
        short = r.input["t_end_s"] < scenario.duration_s - 0.5 * r.input["dt_s"]
        statuses.append("failed" if short else "ok")
        if short:
            notes.append(f"{r.source} stops at t = {r.input['t_end_s']:g} s: no final error")
    finals = [_final_errors(r) for r in results]
    prec = "float32" if any(r.input.get("single_precision") for r in results) else "float64"
    records, ok = [], True
    variant = None
    for q in QUANTITIES:
        if not all(q in f for f in finals):
            continue
        errs = [f[q] if s == "ok" else math.nan for f, s in zip(finals, statuses)]
        floors = [M.roundoff_floor(quantity_scales(r.series["y_ref"])[q], int(round(scenario.duration_s / d)),
                                   r.reference_label, eps=tol.MACHINE_EPSILON[prec]) for r, d in zip(results, dts)]
        variant, exp = _expected(results, scenario, q, scheme)
        if exp.precision != prec:    # the files' precision, as read from their digits, sets the floors
            exp = Expectation(exp.verdict, exp.order, exp.reason, prec)
        j = judge_ladder(dts, errs, floors, statuses, exp)
        fit, matches, phrase = j.fit, j.matches, j.assessment
        ok &= matches is not False
        records.append({"quantity": q, "order": fit.order, "pairwise_orders": fit.pairwise_orders,
                        "verdict": j.verdict, "assessment": phrase, "matches_expectation": matches,
                        "expected": exp.as_dict(), "dt_s": fit.dt_s, "errors": fit.errors,
                        "floors": fit.floors, "fitted": fit.fitted, "note": fit.note})
        if fit.note:
            notes.append(f"{q}: {fit.note}")
    files_ok = all(r.passed for r in results)
    bad = [f"{r['quantity']} {r['assessment']}" for r in records if r["matches_expectation"] is False]
    failed_files = [r.source for r in results if not r.passed]
    parts = []
    if failed_files:
        parts.append(f"{len(failed_files)} of {len(results)} files fail "
                     f"their own check ({', '.join(failed_files)})")
    if bad:
        parts.append("convergence: " + "; ".join(bad))
    orders = ", ".join(f"{r['quantity']} {r['order']:.2f}" for r in records if r["order"] is not None)
    verdict = "; ".join(parts) if parts else (f"every file passes and the errors converge as expected "
                                              f"(fitted orders: {orders or 'at round-off'})")
    expected = (f"{variant}'s orders" if variant else "convergence of a consistent scheme "
                "(order ≥ 1 not claimed from the files alone)")
    return {"files": [r.source for r in results], "dt_s": sorted(dts, reverse=True), "convergence": records,
            "passed": bool(files_ok and ok), "verdict": verdict, "expected": expected, "notes": notes}
