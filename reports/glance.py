"""What the report's first screen says: the verdict box (what is wrong, and is it expected) and the
summary matrix's cells (colour = verdict, and accuracy where the verdict is "as expected"), built from
the saved results only. Plain text and class names; the templates place them.

Cell colour, most severe first (``CELL_CLASSES``):

``bad``        a verdict contradicts the expectation, a run failed, or the second reference disagrees
``diverged``   the run at the default Δt diverged (expected or not: there is no accuracy to show)
``noconv``     does not converge, as expected (the physics the variant misses is in the verdict box)
``pre``        pre-asymptotic on this ladder: no order claimed
``acc1..3``    converges (or is exact) as expected; largest error at the default Δt relative to the
               scenario's scale of that quantity below ACCURACY_TIERS[0], ACCURACY_TIERS[1], or above
``missing``    not run
"""
from __future__ import annotations

import math

from cross_checks.core import tolerances as tol
from cross_checks.core.quantities import COLUMN_STEM, QUANTITIES
from cross_checks.sweep.assemble import normalise_message, verdict_count
from reports.data import LABELS
from reports.findings import fmt, fmt_dt, group_by

__all__ = ["CELL_CLASSES", "ACCURACY_TIERS", "GLYPHS", "glyph", "cell", "verdict_box", "relative_error",
           "family_of", "families", "order_text"]

CELL_CLASSES = ("bad", "diverged", "noconv", "pre", "acc1", "acc2", "acc3", "missing")
#: Relative-error tiers of the green cells (display only, not a verdict; cross_checks/core/tolerances.py).
ACCURACY_TIERS = tol.REPORT_ACCURACY_TIERS
#: One mark per quantity verdict, shown in every cell (the legend explains them).
GLYPHS = {"good": ("✓", "converges with the expected order"),
          "exact": ("=", "exact to round-off at every Δt"), "noconv": ("~", "does not converge, as expected"),
          "pre": ("?", "pre-asymptotic: no order claimed"), "diverged": ("†", "diverged"),
          "bad": ("✗", "contradicts the expectation"), "missing": ("·", "no verdict (too few points)")}
QUANTITY_MARK = {"position": "x", "velocity": "v", "orientation": "θ", "angular_velocity": "ω"}


def family_of(variant: str) -> str:
    return variant.split(":", 1)[0]


def families(variants) -> dict:
    """``{family: [variants]}`` in the order the variants come (family: the engine, before the colon)."""
    out = {}
    for v in variants:
        out.setdefault(family_of(v), []).append(v)
    return out


_VERDICT_SHORT = {"converges": "conv.", "does_not_converge": "no conv.", "at_roundoff": "exact",
                  "pre_asymptotic": "pre-asympt.", "diverged": "diverged", "failed": "failed",
                  "insufficient": "n/a"}


def order_text(rec) -> str:
    """A fitted order as a table or legend shows it: "2.01", "exact", "no (0.12)", "(0.85)" when
    pre-asymptotic (not judged), the verdict's short name when no order was fitted, "–" without a record."""
    if rec is None:
        return "–"
    if rec["verdict"] == "at_roundoff":
        return "exact"
    if rec["order"] is None:
        return _VERDICT_SHORT.get(rec["verdict"], rec["verdict"])
    o = 0.0 if abs(rec["order"]) < 0.005 else rec["order"]
    if rec["verdict"] == "pre_asymptotic":
        return f"({o:.2f})"
    return f"{o:.2f}" if rec["verdict"] == "converges" else f"no ({o:.2f})"


def glyph(rec) -> str:
    """The class of one quantity's verdict (a key of GLYPHS)."""
    if rec is None or rec["verdict"] == "insufficient":
        return "missing"
    if rec["matches_expectation"] is False or rec["verdict"] == "failed":
        return "bad"
    if rec["verdict"] == "diverged":
        return "diverged"
    if rec["verdict"] == "pre_asymptotic":
        return "pre"
    if rec["verdict"] == "at_roundoff":
        return "exact"
    if rec["verdict"] == "does_not_converge":
        return "noconv"
    return "good"


def relative_error(res, s, row) -> float:
    """Largest final error of a run relative to the scenario's scale of each quantity (NaN when none)."""
    scales = s.get("scales") or {}
    rel = [row[f"{COLUMN_STEM[q]}_err_final"] / scales[q] for q in QUANTITIES
           if scales.get(q) and math.isfinite(row[f"{COLUMN_STEM[q]}_err_final"])]
    return max(rel) if rel else math.nan


def _second_ref_bad(s) -> bool:
    sr = s.get("second_reference")
    return isinstance(sr, dict) and sr.get("agrees") is False


def cell(res, s, v) -> dict:
    """One matrix cell: ``cls`` (CELL_CLASSES), ``rank`` (sort key: severity), ``head`` (the error at the
    default Δt or what happened), ``marks`` [(mark, glyph class)], ``title`` (every verdict in words)."""
    sc = s["name"]
    recs = {r["quantity"]: r for r in res.records(sc, v)}
    rows = res.rows_for(sc, v)
    d = res.default_row(sc, v)
    marks = [(QUANTITY_MARK[q] + GLYPHS[glyph(recs.get(q))][0], glyph(recs.get(q))) for q in QUANTITIES]
    n_div = sum(r["status"] == "diverged" for r in rows)
    title = [f"{v} on {sc} (Δt = {fmt_dt(s['dt_s'])} s)"]
    title += [f"{LABELS[q]}: {recs[q]['assessment']}" for q in QUANTITIES if q in recs]
    if d is None:
        why = next((r["reason"] for r in res.summary.get("not_expressible") or []
                    if r["scenario"] == sc and r["engine"] == v), "")
        if why:
            return {"cls": "missing", "rank": 98, "head": "cannot express", "marks": [],
                    "title": f"{title[0]}: not run, the engine cannot express this scenario: {why}"}
        return {"cls": "missing", "rank": 99, "head": "not run", "marks": [], "title": title[0] + ": not run"}
    rel = relative_error(res, s, d) if d["status"] == "ok" else math.nan
    if d["status"] == "ok":
        head = f"{fmt(rel, digits=1)}"
        title.insert(1, f"largest final error relative to the scenario's scale: {fmt(rel)}")
    elif d["status"] == "diverged":
        head = f"† t={fmt(d['diverged_at_s'], '', 2)}"
    else:
        head = "failed"
    if n_div and d["status"] == "ok":
        head += f" †{n_div}"
        title.append(f"{n_div} run(s) of the ladder diverged")
    kinds = {g for _, g in marks}
    if d["status"] == "failed" or any(r["status"] == "failed" for r in rows) or "bad" in kinds:
        cls = "bad"
    elif d["status"] == "diverged":
        cls = "diverged"
    elif "noconv" in kinds:
        cls = "noconv"
    elif "pre" in kinds:
        cls = "pre"
    elif not math.isfinite(rel):
        cls = "missing"
    else:
        cls = "acc1" if rel <= ACCURACY_TIERS[0] else "acc2" if rel <= ACCURACY_TIERS[1] else "acc3"
    # sort key: severity first, then (within a class) the relative error on a log scale in [0, 1)
    within = 0.0 if not math.isfinite(rel) else (math.log10(min(max(rel, 1e-20), 1.0)) + 20.0) / 20.5
    return {"cls": cls, "rank": f"{CELL_CLASSES.index(cls) + within:.4f}", "head": head, "marks": marks,
            "title": "\n".join(title)}


# --- the verdict box -------------------------------------------------------------------------------

def _scen_list(names, most=4) -> str:
    names = list(dict.fromkeys(names))
    return ", ".join(names[:most]) + (f" and {len(names) - most} more" if len(names) > most else "")


def _first_sentence(text: str, limit: int = 120) -> str:
    """The first clause of a reason, at most about ``limit`` characters (cut at a comma or bracket, "…")."""
    s = text.split("; ")[0].split(". ")[0].rstrip(".")
    if len(s) <= limit:
        return s
    cut = max(s.rfind(", ", 0, limit), s.rfind(" (", 0, limit))
    return (s[:cut] if cut > 40 else s[:limit]).rstrip(" ,") + " …"


def verdict_box(res) -> dict:
    """``{"headline": [(count, label, cls)], "groups": [{"title", "cls", "lines": [text], "count"}]}``: what
    contradicts the expectations, what failed, what diverged, then what is expected not to converge and
    what is pre-asymptotic, each with a one-line reason."""
    recs = res.summary.get("convergence", [])
    order = {s["name"]: i for i, s in enumerate(res.scenarios)}
    long_recs = res.summary.get("long_runs") or []
    noconv = [r for r in recs if r["expected_verdict"] == "does_not_converge" and r["matches_expectation"]]
    pre = [r for r in recs if r["verdict"] == "pre_asymptotic"]
    groups = [
        {"title": "Contradicts the expectations", "cls": "bad",
         "lines": _contradiction_lines(res, recs, order, long_recs)},
        {"title": "Failures", "cls": "bad", "lines": _failure_lines(res, long_recs)},
        {"title": "Diverged runs (left out of the order fits; long runs judged as diverged)",
         "cls": "diverged", "lines": _divergence_lines(res, long_recs)},
        {"title": "Does not converge, as expected (why)", "cls": "noconv", "lines": _noconv_lines(noconv)},
        {"title": "Pre-asymptotic on this ladder: no order claimed (why)", "cls": "pre",
         "lines": _pre_lines(pre, order)}]

    # counted as the terminal counts them: verdicts not as expected (cross_checks.sweep.assemble), runs failed
    # and runs diverged, the long runs' included
    _, wrong = verdict_count(res.summary)
    n_failed = (sum(r["status"] == "failed" for r in res.rows)
                + sum(r.get("status") == "failed" for r in long_recs))
    n_div = (sum(r["status"] == "diverged" for r in res.rows)
             + sum(r.get("status") == "diverged" for r in long_recs))
    headline = [(wrong, "verdict(s) not as expected", "bad"),
                (n_failed, "failed run(s)", "bad"), (n_div, "diverged run(s)", "diverged"),
                (len({(r['engine'], r['scenario']) for r in noconv}),
                 "expected non-convergence(s)", "noconv"),
                (len({(r['engine'], r['scenario']) for r in pre}), "pre-asymptotic", "pre")]
    for g, (n, label, _) in zip(groups, headline):   # each group says the count of its badge
        g["count"] = f"{n} {label}"
    return {"headline": headline, "groups": [g for g in groups if g["lines"]],
            "all_clear": not groups[0]["lines"] and not groups[1]["lines"]}


def _contradiction_lines(res, recs, order, long_recs) -> list:
    """The verdicts not as expected (per variant and scenario), the same-scheme agreements that do not hold,
    the second references that disagree, and the long runs not as expected."""
    contra = [r for r in recs if r["matches_expectation"] is False]
    lines = []
    for (v, sc), rs in sorted(group_by(contra, lambda r: (r["engine"], r["scenario"])).items(),
                              key=lambda kv: (kv[0][0], order.get(kv[0][1], 99))):
        lines.append(f"{v} on {sc}: " + "; ".join(f"{LABELS[r['quantity']]} {r['assessment']}" for r in rs))
    for a in res.summary.get("agreement", []):
        if not a["agrees"]:
            lines.append(f"{a['b']} should reproduce {a['a']} on "
                         f"{a['scenario']} ({a['reason']}) but differs by "
                         + (fmt(a["max_rel"]) if a.get("max_rel") is not None else a.get("note", "?")))
    for s in res.scenarios:
        if _second_ref_bad(s):
            sr = s["second_reference"]
            lines.append(f"{s['name']}: the second reference ({sr.get('label', '?')}) "
                         "disagrees with the reference beyond their stated accuracy")
    lines += [f"{r['engine']} on {r['scenario']} (long run): {r.get('assessment', 'not as expected')}"
              for r in long_recs if r.get("matches_expectation") is False]
    return lines


def _failure_lines(res, long_recs) -> list:
    """The failed runs per variant (the command's words, without the run's name and private paths: the
    file it names is kept), the failed second references and the failed long runs."""
    failed = [r for r in res.rows if r["status"] == "failed"]
    lines = [f"{v}: {len(rs)} run(s) on {_scen_list(r['scenario'] for r in rs)} "
             f"— {_first_sentence(normalise_message(rs[0]['message']), 240)}"
             for v, rs in group_by(failed, lambda r: r["engine"]).items()]
    lines += [f"{s['name']}: the second reference ({s['second_reference'].get('label', '?')}) failed: "
              f"{_first_sentence(str(s['second_reference']['error']))}" for s in res.scenarios
              if isinstance(s.get("second_reference"), dict) and s["second_reference"].get("error")]
    long_failed = [r for r in long_recs if r.get("status") == "failed"]
    lines += [f"{v}: {len(rs)} long run(s) on {_scen_list(r['scenario'] for r in rs)} "
              f"— {_first_sentence(str(rs[0].get('message') or 'failed'))}"
              for v, rs in group_by(long_failed, lambda r: r["engine"]).items()]
    return lines


def _divergence_lines(res, long_recs) -> list:
    """The diverged runs per variant (each scenario's smallest Δt that diverged; whether its verdicts are
    still as expected) and the diverged long runs (when)."""
    div = [r for r in res.rows if r["status"] == "diverged"]
    lines = []
    for v, rs in group_by(div, lambda r: r["engine"]).items():
        scs = list(dict.fromkeys(r["scenario"] for r in rs))
        unexpected = [sc for sc in scs if any(x["matches_expectation"] is False for x in res.records(sc, v))]
        per = [f"{sc} (Δt ≥ {fmt_dt(min(r['dt'] for r in rs if r['scenario'] == sc))} s)" for sc in scs]
        lines.append(f"{v}: {len(rs)} run(s) — " + _scen_list(per, 5)
                     + ("" if unexpected else "; every verdict of these scenarios is still as expected"))
    long_div = [r for r in long_recs if r.get("status") == "diverged"]
    for v, rs in group_by(long_div, lambda r: r["engine"]).items():
        lines.append(f"{v}: {len(rs)} long run(s) — " + _scen_list(
            [f"{r['scenario']} (at t = {fmt(r.get('diverged_at_s'), '', 3)} s)" for r in rs], 5))
    return lines


def _noconv_lines(noconv) -> list:
    """The expected non-convergences, grouped by their reason (the commonest first)."""
    lines = []
    for reason, rs in sorted(group_by(noconv, lambda r: _first_sentence(r["reason"] or "")).items(),
                             key=lambda kv: -len(kv[1])):
        by_v = group_by(rs, lambda r: r["engine"])
        lines.append(f"{reason or 'no reason recorded'} — " + "; ".join(
            f"{v} on {_scen_list(r['scenario'] for r in vr)}" for v, vr in by_v.items()))
    return lines


def _pre_lines(pre, order) -> list:
    """The pre-asymptotic records per variant and reason, with their scenarios and quantities."""
    def why(r):
        text = r["reason"] if r["expected_verdict"] == "pre_asymptotic" else r["assessment"]
        return _first_sentence(text.removeprefix("pre-asymptotic on this ladder: "), 140)
    lines = []
    for (v, reason), rs in group_by(pre, lambda r: (r["engine"], why(r))).items():
        per = group_by(rs, lambda r: r["scenario"])
        lines.append(f"{v} on "
                     + _scen_list([f"{sc} ({', '.join(LABELS[r['quantity']] for r in x)})"
                                   for sc, x in sorted(per.items(), key=lambda kv: order.get(kv[0], 99))], 5)
                     + f" — {reason}")
    return lines
