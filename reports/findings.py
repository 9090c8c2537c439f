"""Findings: sentences written from the saved results (summary.json records and results.csv rows).

Each finding has a severity — "bad" (a result that contradicts the expectations recorded by the
sweep, a failure, or a disagreement between schemes that should be identical), "explained" (an
expected non-convergence, with the physics the variant misses), "info" — and the text (plain text;
the templates escape it).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from cross_checks.core import tolerances as tol
from cross_checks.core.quantities import QUANTITIES, UNITS
from reports.data import LABELS

__all__ = ["Finding", "findings", "fmt", "fmt_dt", "group_by"]


@dataclass(frozen=True)
class Finding:
    severity: str          # "bad", "explained", "info"
    text: str
    scenario: str | None = None
    engine: str | None = None


def fmt(v, unit: str = "", digits: int = 2) -> str:
    """Compact number: 2 significant digits, scientific below 1e-3 or above 1e4; "–" for NaN/None."""
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "–"
    v = float(v)
    if v == 0:
        s = "0"
    elif 1e-3 <= abs(v) < 1e4:
        s = f"{v:.{digits}g}"
    else:
        s = f"{v:.{max(digits - 1, 0)}e}".replace("e-0", "e-").replace("e+0", "e+")
    return f"{s} {unit}".strip()


def fmt_dt(v) -> str:
    return f"{float(v):g}"


def _and(items) -> str:
    items = list(items)
    if len(items) <= 1:
        return "".join(items)
    return ", ".join(items[:-1]) + " and " + items[-1]


def _error_part(rec):
    """("orientation error ≈ 3.1 rad", flat) or ("… 0.1 … 0.3 m, smallest at Δt = 0.01 s", not flat)."""
    errs = [e for e in rec["errors"] if e is not None and math.isfinite(e)]
    unit = UNITS[rec["quantity"]]
    name = f"{LABELS[rec['quantity']]} error"
    if not errs:
        return f"{name} unavailable", True
    lo, hi = min(errs), max(errs)
    if lo > 0 and hi / lo <= 3.0:
        g = math.exp(sum(math.log(e) for e in errs) / len(errs))
        return f"{name} ≈ {fmt(g, unit)}", True
    finite = [(e, d) for e, d in zip(rec["errors"], rec["dt_s"]) if e is not None and math.isfinite(e)]
    best_dt = min(finite)[1]
    return f"{name} {fmt(lo, unit)} … {fmt(hi, unit)} (smallest at Δt = {fmt_dt(best_dt)} s)", False


def _error_ranges(recs) -> str:
    """The errors of several quantities over the ladder, in one clause."""
    parts = [_error_part(r) for r in recs]
    dts = recs[0]["dt_s"]
    span = f"Δt = {fmt_dt(dts[0])} … {fmt_dt(dts[-1])} s"
    if all(flat for _, flat in parts):
        return _and(p for p, _ in parts) + f" at every {span}"
    return _and(p for p, _ in parts) + f" over {span}"


def group_by(items, key) -> dict:
    """``{key(item): [items]}``, keys and items in the order the items come."""
    out = {}
    for it in items:
        out.setdefault(key(it), []).append(it)
    return out


class _Orders:
    """What every rule needs to sort and filter: the convergence records, the order of scenarios and
    variants in the results, and which quantities move in each scenario."""

    def __init__(self, res):
        self.recs = res.summary.get("convergence", [])
        self.scen_order = {s["name"]: i for i, s in enumerate(res.scenarios)}
        self.var_order = {v: i for i, v in enumerate(res.variants)}
        self.varies = {s["name"]: s.get("varies", {}) for s in res.scenarios}


def findings(res) -> list:
    """All findings of a results directory, most important first: what contradicts the expectations or
    failed, then what is explained (expected non-convergence, pre-asymptotic ladders), then information.
    Each numbered rule is one function below."""
    c = _Orders(res)
    failed, diverged = _failed_and_diverged(res, c)
    bad = _contradictions(res, c) + failed
    explained = _expected_non_convergence(res, c) + _pre_asymptotic(res, c)
    info = diverged + _exact_and_faster(res, c) + _conservation(res, c)
    disagree, agree = _same_schemes(res, c)
    broken, lost, known = _invariance(res, c)
    return bad + broken + disagree + explained + known + info + lost + agree + _not_measured(res, c)


def _invariance(res, c) -> tuple:
    """Invariance checks (summary.json ``invariance``, docs/invariance.md): ``(bad, info, explained)``: a
    broken one is bad; a known finding (declared by the variant with its reason) is explained, with its
    number; a precision loss or a step-dependent one (the scheme's own truncation error) is information,
    with its number, as is a declared finding that no longer breaks."""
    bad, info, explained = [], [], []
    recs = sorted(res.summary.get("invariance") or [],
                  key=lambda r: (c.scen_order.get(r["scenario"], 99), c.var_order.get(r["engine"], 99)))
    for r in recs:
        text = (f"{r['engine']} on {r['scenario']}: under {r['transform']} {r['magnitude']}, "
                f"{r['assessment']}.")
        if r["verdict"] == "broken":
            bad.append(Finding("bad", text, r["scenario"], r["engine"]))
        elif r["verdict"] == "known finding":
            explained.append(Finding("explained", text, r["scenario"], r["engine"]))
        elif r["verdict"] in ("precision loss", "step-dependent"):
            info.append(Finding("info", text, r["scenario"], r["engine"]))
    for d in res.summary.get("invariance_declared") or []:
        if d["verdict"] == "no longer broken":
            text = (f"{d['engine']}: its declared invariance finding under {d['transform']} broke on none "
                    f"of the {d['checks']} check(s) it covers: no longer broken (the declaration can go).")
            info.append(Finding("info", text, None, d["engine"]))
    return bad, info, explained


def _contradictions(res, c) -> list:
    """1. Results that contradict the expectations, per scenario and variant."""
    bad = []
    for (sc, eng), rs in sorted(group_by([r for r in c.recs if r["matches_expectation"] is False],
                                         lambda r: (r["scenario"], r["engine"])).items(),
                                key=lambda kv: (c.scen_order.get(kv[0][0], 99),
                                                c.var_order.get(kv[0][1], 99))):
        parts = [f"{LABELS[r['quantity']]} {r['assessment']}" for r in rs]
        why = {r["reason"] for r in rs if r["expected_verdict"] == "does_not_converge"}
        notes = {r["note"] for r in rs if r.get("note")}
        text = f"{eng} on {sc}: " + "; ".join(parts) + "."
        if why:
            text += " Expected not to converge because " + "; ".join(sorted(why)) + "."
        if notes:
            text += " (" + "; ".join(sorted(notes)) + ")"
        bad.append(Finding("bad", text, sc, eng))
    return bad


def _failed_and_diverged(res, c) -> tuple:
    """2. Failed runs (bad) and diverged runs (information: left out of the order fits)."""
    bad = []
    info = []
    for (sc, eng), rows in group_by([r for r in res.rows if r["status"] == "failed"],
                                    lambda r: (r["scenario"], r["engine"])).items():
        msgs = sorted({r["message"] for r in rows})
        dts = ", ".join(fmt_dt(r["dt"]) for r in rows)
        bad.append(Finding("bad", f"{eng} failed on {sc} at Δt = {dts} s: {'; '.join(msgs)}", sc, eng))
    for (sc, eng), rows in group_by([r for r in res.rows if r["status"] == "diverged"],
                                    lambda r: (r["scenario"], r["engine"])).items():
        where = ", ".join(f"Δt = {fmt_dt(r['dt'])} s (at t = {fmt(r['diverged_at_s'], 's', 3)})"
                          for r in rows)
        info.append(Finding("info",
                            f"{eng} diverged on {sc} at {where}; those runs are left out of the order fits.",
                            sc, eng))
    return bad, info


def _expected_non_convergence(res, c) -> list:
    """3. Expected non-convergence, with the reason (one line when most variants share it)."""
    explained = []
    exp_rs = [r for r in c.recs if r["expected_verdict"] == "does_not_converge" and r["matches_expectation"]]
    per_engine = {}
    for (sc, reason), rs in sorted(group_by(exp_rs, lambda r: (r["scenario"], r["reason"])).items(),
                                   key=lambda kv: c.scen_order.get(kv[0][0], 99)):
        engines = sorted({r["engine"] for r in rs}, key=lambda e: c.var_order.get(e, 99))
        if len(engines) > 2:
            n_run = len({r["engine"] for r in c.recs if r["scenario"] == sc})
            qs = sorted({r["quantity"] for r in rs}, key=QUANTITIES.index)
            sample = [r for r in rs if r["engine"] == engines[0]]
            shown = [r for r in sample if r["quantity"] in ("position", "orientation")] or sample[:1]
            ranges = _error_ranges(shown)
            who = (f"No variant converges on {sc}" if len(engines) == n_run else
                   f"{len(engines)} of the {n_run} variants ({_and(engines)}) do not converge on {sc}")
            text = (f"{who} ({_and(LABELS[q] for q in qs)}, as expected): {reason}. "
                    f"For example {engines[0]}: {ranges}.")
            explained.append(Finding("explained", text, sc, None))
        else:
            for eng in engines:
                per_engine.setdefault((sc, eng), []).extend(r for r in rs if r["engine"] == eng)
    for (sc, eng), er in per_engine.items():
        er.sort(key=lambda r: QUANTITIES.index(r["quantity"]))
        reasons = sorted({r["reason"] for r in er}, key=len)
        # "X" and "X; the spring carries it into the translation": say the longer one only
        reasons = [a for a in reasons if not any(b != a and b.startswith(a) for b in reasons)]
        explained.append(Finding("explained", f"{eng} does not converge on {sc}: {_error_ranges(er)}; "
                                              + "; ".join(reasons) + ".", sc, eng))
    return explained


def _pre_asymptotic(res, c) -> list:
    """3b. No claim on this ladder (pre-asymptotic), with the reason (physics, or the errors themselves)."""
    explained = []
    pre = [r for r in c.recs if r["verdict"] == "pre_asymptotic"]
    for (sc, eng), rs in sorted(group_by(pre, lambda r: (r["scenario"], r["engine"])).items(),
                                key=lambda kv: (c.scen_order.get(kv[0][0], 99),
                                                c.var_order.get(kv[0][1], 99))):
        rs.sort(key=lambda r: QUANTITIES.index(r["quantity"]))
        why = lambda r: (r["reason"] if r["expected_verdict"] == "pre_asymptotic"  # noqa: E731
                         else r["assessment"])
        fitted = ", ".join(f"{LABELS[r['quantity']]} {r['order']:.2f}" for r in rs if r["order"] is not None)
        text = (f"{eng} on {sc}: no order claimed for {_and(LABELS[r['quantity']] for r in rs)} (fitted "
                f"{fitted or 'none'}, not judged). {LABELS[rs[0]['quantity']].capitalize()}: {why(rs[0])}")
        if len(rs) > 1:
            text += f" (likewise, with its own numbers, for {_and(LABELS[r['quantity']] for r in rs[1:])})"
        explained.append(Finding("explained", text + ".", sc, eng))
    return explained


def _exact_and_faster(res, c) -> list:
    """4. Exact to round-off, and orders above the nominal one (information)."""
    info = []
    exact = [r for r in c.recs
             if r["verdict"] == "at_roundoff" and c.varies.get(r["scenario"], {}).get(r["quantity"], True)]
    for (sc, q), rs in sorted(group_by(exact, lambda r: (r["scenario"], r["quantity"])).items(),
                              key=lambda kv: (c.scen_order.get(kv[0][0], 99), QUANTITIES.index(kv[0][1]))):
        engines = sorted({r["engine"] for r in rs}, key=lambda e: c.var_order.get(e, 99))
        info.append(Finding("info", f"On {sc}, {LABELS[q]} is exact to round-off at every Δt with "
                                    f"{_and(engines)}: the scheme integrates this motion exactly.", sc, None))
    above = [r for r in c.recs
             if r["verdict"] == "converges" and r["matches_expectation"] and r["order"] is not None
             and r["expected_order"] is not None and r["order"] > r["expected_order"] + tol.SWEEP_ORDER_TOL]
    for (sc, q), rs in sorted(group_by(above, lambda r: (r["scenario"], r["quantity"])).items(),
                              key=lambda kv: (c.scen_order.get(kv[0][0], 99), QUANTITIES.index(kv[0][1]))):
        rs.sort(key=lambda r: c.var_order.get(r["engine"], 99))
        lo, hi = min(r["order"] for r in rs), max(r["order"] for r in rs)
        orders = f"{lo:.2f}" if hi - lo < 0.05 else f"{lo:.2f} … {hi:.2f}"
        info.append(Finding("info",
                            f"On {sc}, {LABELS[q]} converges faster than the nominal order "
                            f"(order {orders}) with "
                            + _and(f"{r['engine']} (nominal {r['expected_order']:g})" for r in rs) + ".",
                            sc, None))
    return info


def _conservation(res, c) -> list:
    """5. Conservation at the default Δt (information)."""
    info = []
    for s in res.scenarios:
        sc = s["name"]
        rows = [r for r in res.rows if r["scenario"] == sc and r["dt"] == s["dt_s"] and r["status"] == "ok"]
        if s["conserved"]["energy"]["conserved"] and rows:
            sec = [r for r in rows if r["energy_drift_kind"] == "secular"]
            bnd = [r for r in rows if r["energy_drift_kind"] == "bounded"]
            rnd = [r for r in rows if r["energy_drift_kind"] == "roundoff"]
            parts = []
            if sec:
                sec.sort(key=lambda r: -abs(r["energy_drift_final"]))
                parts.append("secular with "
                             + _and(f"{r['engine']} ({fmt(r['energy_drift_final'])})" for r in sec))
            if bnd:
                parts.append(f"bounded with {len(bnd)} variant(s) (at most "
                             f"{fmt(max(r['energy_drift_max'] for r in bnd))})")
            if rnd:
                parts.append(f"conserved to round-off with {_and(r['engine'] for r in rnd)}")
            info.append(Finding("info",
                                f"Energy on {sc} at Δt = {fmt_dt(s['dt_s'])} s over "
                                f"{fmt_dt(s['duration_s'])} s (relative drift): " + "; ".join(parts) + ".",
                                sc, None))
        if s["conserved"]["angular_momentum"]["conserved"] and rows:
            worst = sorted([r for r in rows
                            if np.isfinite(r["angmom_drift_max"]) and r["angmom_drift_max"] > 1e-6],
                           key=lambda r: -r["angmom_drift_max"])
            if worst:
                info.append(Finding("info",
                                    f"World angular momentum on {sc} (conserved by the physics) drifts by "
                                    "up to " + _and(f"{fmt(r['angmom_drift_max'])} with {r['engine']}"
                                                    for r in worst[:4])
                                    + (f" (and {len(worst) - 4} more)" if len(worst) > 4 else "")
                                    + f" at Δt = {fmt_dt(s['dt_s'])} s.", sc, None))
    return info


def _same_schemes(res, c) -> tuple:
    """6. Schemes that must be identical: disagreements (bad) and agreements (information)."""
    bad = []
    info = []
    for (a, b), rs in group_by(res.summary.get("agreement", []), lambda r: (r["a"], r["b"])).items():
        good = [r for r in rs if r["agrees"]]
        badr = [r for r in rs if not r["agrees"]]
        if badr:
            parts = _and(f"{r['scenario']} ({fmt(r['max_rel'])})" if r["max_rel"] is not None
                         else f"{r['scenario']} ({r['note']})" for r in badr)
            bad.append(Finding("bad",
                               f"{a} and {b} should be the same scheme ({rs[0]['reason']}) but their final "
                               f"states differ beyond {fmt(rs[0].get('tolerance', tol.SAME_SCHEME_REL))} "
                               f"(relative) on {parts}.",
                               None, b))
        if good:
            # "both diverged" agreements (at the same step) have no final states, hence no max_rel
            ended = [r["max_rel"] for r in good if r["max_rel"] is not None]
            blew_up = [r["scenario"] for r in good if r["max_rel"] is None]
            how = []
            if ended:
                how.append(f"on {len(ended)} scenario(s) to {fmt(max(ended))} (largest relative final-state "
                           "difference at the default Δt)")
            if blew_up:
                how.append(f"on {_and(blew_up)} by diverging at the same time (within two steps)")
            info.append(Finding("info", f"{b} reproduces {a} {' and '.join(how)}: {rs[0]['reason']}.",
                                None, b))
    return bad, info


def _not_measured(res, c) -> list:
    """7–8. Variants without a one-step mode, and variants not run (information)."""
    info = []
    # 7. variants without a one-step mode (engine-file engines run whole trajectories only)
    whole_runs_only = [v for v in res.variants if not res.has_one_step(v)]
    if whole_runs_only:
        info.append(Finding("info",
                            f"{_and(whole_runs_only)} {'has' if len(whole_runs_only) == 1 else 'have'} no "
                            "one-step mode (an engine file runs whole trajectories only): local (one-step) "
                            "errors are not measured for them; their verdicts come from the free-running "
                            "errors alone.", None, None))

    # 8. variants not run, and scenarios a variant's engine cannot express
    for s in res.summary.get("skipped_variants", []):
        info.append(Finding("info", f"{s['name']} was not run: {s['reason']}.", None, s["name"]))
    for r in res.summary.get("not_expressible") or []:
        info.append(Finding("info", f"{r['engine']} cannot express {r['scenario']}, so it was not run there: "
                            f"{r['reason']}.", r["scenario"], r["engine"]))
    return info
