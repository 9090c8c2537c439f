"""HTML pages of a results directory: index.html (summary matrix, findings, provenance) and one page
per scenario (tables and figures). Jinja2 templates with autoescape; every string a template shows is
prepared here (templates only loop and place), so user text such as a scenario description is
always escaped.
"""
from __future__ import annotations

import base64
import math

from jinja2 import Environment, PackageLoader, StrictUndefined, select_autoescape

from cross_checks.core.quantities import COLUMN_STEM, QUANTITIES, UNITS
from reports.data import LABELS
from reports.findings import findings, fmt, fmt_dt

__all__ = ["environment", "render_pages", "page_name"]

_VERDICT_SHORT = {"converges": "conv.", "does_not_converge": "no conv.", "at_roundoff": "exact",
                  "pre_asymptotic": "pre-asympt.", "diverged": "diverged", "failed": "failed", "insufficient": "n/a"}
_FIG_CAPTIONS = {
    "trajectories": "Position and orientation components against time for every variant at the scenario's "
                    "default Δt; the thick grey line is the reference.",
    "errors": "Error against the reference over time at the default Δt (log scale).",
    "conservation": "Relative drift of the quantities the physics conserves, at the default Δt (log scale).",
    "convergence": "Final error against Δt (log-log) over the scenario's Δt ladder. Filled markers are the "
                   "points of the least-squares order fit; the grey band is the round-off floor; the "
                   "triangles show slopes 1, 2 and 4. The legend lists the fitted orders.",
    "local": "One-step (local) error against Δt: every step restarted from the reference state; an "
             "order-p scheme shows slope p + 1.",
    "work": "Work-precision: final error against the wall time of each run of the ladder.",
}
_NO_ONE_STEP = "no one-step mode: an engine file runs whole trajectories only, so local errors are not measured"
_FIG_TITLES = {"trajectories": "Trajectories", "errors": "Error vs time", "conservation": "Conservation",
               "convergence": "Convergence (free-running)", "local": "Local error (one-step mode)",
               "work": "Work-precision"}


def environment() -> Environment:
    return Environment(loader=PackageLoader("reports", "templates"),
                       autoescape=select_autoescape(["html", "htm", "xml"], default_for_string=True, default=True),
                       undefined=StrictUndefined, trim_blocks=True, lstrip_blocks=True, keep_trailing_newline=True)


def page_name(scenario: str) -> str:
    """The page of a scenario; the name read from the data is made a safe file name first."""
    from cross_checks.sweep.results_dir import safe_file_stem
    return f"scenario-{safe_file_stem(scenario)}.html"


def _img_src(res, fname, self_contained):
    if not self_contained:
        return f"plots/{fname}"
    data = (res.directory / "plots" / fname).read_bytes()
    return "data:image/png;base64," + base64.b64encode(data).decode("ascii")


def _order_text(rec):
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


def _rec_class(rec):
    if rec is None:
        return "missing"
    if rec["matches_expectation"] is False:
        return "bad"
    if rec["expected_verdict"] == "does_not_converge" or rec["verdict"] == "pre_asymptotic":
        return "explained"
    return "good"


def _cell_class(recs, rows):
    if not rows:
        return "missing"
    if any(r["status"] == "failed" for r in rows) or any(rec["matches_expectation"] is False for rec in recs):
        return "bad"
    if any(rec["expected_verdict"] == "does_not_converge" or rec["verdict"] == "pre_asymptotic" for rec in recs):
        return "explained"
    return "good"


def _provenance(res):
    p = res.summary.get("provenance", {})
    run = res.summary.get("run", {})
    keys = [("rbcheck", "rbcheck"), ("numpy", "numpy"), ("scipy", "scipy"), ("mujoco", "MuJoCo"),
            ("pybullet", "PyBullet"), ("python", "Python"), ("platform", "platform"), ("machine", "machine"),
            ("git_commit", "commit"), ("started_at", "started (UTC)"), ("command", "command")]
    out = [(label, str(p.get(k, "")) or "–") for k, label in keys]
    for name, e in (p.get("engines") or {}).items():  # engines from outside rbcheck: where from, which file
        if e.get("source", "").endswith("(rbcheck)"):
            continue
        sha = f", SHA-256 {e['engine_file_sha256'][:16]}…" if e.get("engine_file_sha256") else ""
        out.append((f"engine {name}", f"{e.get('version') or '–'} — {e.get('source', '')}{sha}"))
    if run:
        out.append(("runs", f"{run.get('runs')} ({run.get('cached_runs')} from cache, {run.get('diverged_runs')} "
                            f"diverged, {run.get('failed_runs')} failed) on {run.get('jobs')} worker(s)"))
        out.append(("sweep wall time", f"{run.get('wall_s')} s for the runs and metrics, report excluded (the "
                                       f"runs' own wall times add up to {run.get('cpu_s_in_runs')} s, cached runs "
                                       "excluded)"))
    return out


def _matrix(res):
    """Engine variants (rows) × scenarios (columns), each cell at the scenario's default Δt."""
    header = [{"name": s["name"], "href": page_name(s["name"]), "dt": fmt_dt(s["dt_s"]),
               "reference": "DOP853" if s["reference"].startswith("ground_truth") else s["reference"]}
              for s in res.scenarios]
    rows = []
    for v in res.variants:
        cells = []
        for s in res.scenarios:
            sc = s["name"]
            recs = res.records(sc, v)
            rws = res.rows_for(sc, v)
            d = res.default_row(sc, v)
            by_q = {r["quantity"]: r for r in recs}
            lines = []
            if d is None:
                lines = ["not run"]
            elif d["status"] != "ok":
                lines = [d["status"] + (f" at t = {fmt(d['diverged_at_s'], 's', 3)}"
                                        if d["status"] == "diverged" else "")]
            else:
                lines.append(f"x {fmt(d['pos_err_final'], 'm')}")
                lines.append(f"θ {fmt(d['orient_err_final'], 'rad')}")
            if by_q:
                lines.append("p " + " / ".join(_order_text(by_q.get(q)) for q in ("position", "orientation")))
            if d is not None and not math.isnan(d["energy_drift_max"]):
                lines.append(f"E {fmt(d['energy_drift_max'])} {d['energy_drift_kind']}")
            title = f"{v} on {sc}\n" + "\n".join(
                f"{LABELS[q]}: {by_q[q]['verdict'].replace('_', ' ')} — {by_q[q]['assessment']}"
                for q in QUANTITIES if q in by_q)
            cells.append({"cls": _cell_class(recs, rws), "lines": lines, "title": title})
        rows.append({"name": v, "cells": cells})
    return {"header": header, "rows": rows}


def _finding_views(fs):
    return [{"cls": f.severity, "text": f.text} for f in fs]


_SECTIONS = (("bad", "Results that contradict the expectations"),
             ("explained", "Expected non-convergence, and why"),
             ("info", "Observations"))


def _finding_sections(fs):
    return [{"title": title, "cls": sev, "entries": _finding_views([f for f in fs if f.severity == sev])}
            for sev, title in _SECTIONS if any(f.severity == sev for f in fs)]


def _second_reference_text(rec) -> str:
    """One line for summary.json's ``second_reference`` (docs/results.md); "" when there is none."""
    if not rec:
        return ""
    if rec.get("error"):
        return f"{rec['label']}: failed ({rec['error']})"
    dist = "; ".join(f"{LABELS[q]} {fmt(rec['distance'][q], UNITS[q])} (together they claim "
                     f"{fmt(rec['stated_accuracy'][q], UNITS[q])})" for q in QUANTITIES)
    verdict = "agrees with the reference" if rec["agrees"] else "DISAGREES with the reference"
    return f"{rec['label']}: {verdict} within their measured accuracies — largest distance over the run: {dist}"


def _scenario_view(res, s, figs, all_findings, self_contained):
    sc = s["name"]
    cons = []
    for k, label in (("energy", "energy"), ("angular_momentum", "angular momentum"),
                     ("linear_momentum", "linear momentum")):
        c = s["conserved"][k]
        cons.append(f"{label}: " + ("conserved" if c["conserved"] else c["why_not"]))
    table = []
    for v in res.variants:
        d = res.default_row(sc, v)
        if d is None:
            continue
        recs = {r["quantity"]: r for r in res.records(sc, v)}
        lrecs = {r["quantity"]: r for r in res.records(sc, v, mode="one_step")}
        table.append({
            "variant": v, "status": d["status"], "steps": str(d["steps"]), "wall": fmt(d["wall_s"], "s"),
            "errors": [fmt(d[f"{COLUMN_STEM[q]}_err_final"]) for q in QUANTITIES],
            "energy": (f"{fmt(d['energy_drift_max'])} ({d['energy_drift_kind']})"
                       if not math.isnan(d["energy_drift_max"]) else "–"),
            "angmom": fmt(d["angmom_drift_max"]),
            "orders": [{"text": _order_text(recs.get(q)), "cls": _rec_class(recs.get(q)),
                        "title": (recs[q]["assessment"] + (f" — {recs[q]['note']}" if recs[q]["note"] else "")
                                  + (f" — expected: {recs[q]['reason']}" if recs[q]["reason"] else ""))
                        if q in recs else ""} for q in QUANTITIES],
            "local_orders": [{"text": _order_text(lrecs.get(q)),
                              "cls": "good" if lrecs.get(q) and lrecs[q]["matches_expectation"] else
                              ("bad" if lrecs.get(q) and lrecs[q]["matches_expectation"] is False else "missing"),
                              "title": lrecs[q]["assessment"] if q in lrecs else ""} for q in QUANTITIES]
            if res.has_one_step(v) else [{"text": "n/a", "cls": "missing", "title": _NO_ONE_STEP} for _ in QUANTITIES],
        })
    ladder = []
    for r in res.rows_for(sc):
        ladder.append({"variant": r["engine"], "dt": fmt_dt(r["dt"]), "status": r["status"],
                       "flags": ", ".join(x for x, on in (("default Δt", r["default_dt"]), ("ladder", r["in_ladder"]),
                                                          ("cached", r["cached"])) if on),
                       "errors": [fmt(r[f"{COLUMN_STEM[q]}_err_final"]) for q in QUANTITIES],
                       "local": [fmt(r[f"{COLUMN_STEM[q]}_local_err"]) for q in QUANTITIES],
                       "wall": fmt(r["wall_s"], "s"), "message": r["message"]})
    no_local = [v for v in res.variants if not res.has_one_step(v)]
    captions = dict(_FIG_CAPTIONS)
    if no_local:
        captions["local"] += f" Not shown ({_NO_ONE_STEP}): {', '.join(no_local)}."
    return {
        "name": sc, "description": s["description"], "source": s["source"], "hash": s["content_hash"],
        "duration": fmt_dt(s["duration_s"]), "dt": fmt_dt(s["dt_s"]),
        "ladder": ", ".join(fmt_dt(d) for d in s["dt_ladder_s"]), "reference": s["reference"],
        "second_reference": _second_reference_text(s.get("second_reference")),
        "conserved": cons,
        "findings": _finding_views([f for f in all_findings if f.scenario == sc]),
        "quantities": [f"{LABELS[q]} ({UNITS[q]})" for q in QUANTITIES],
        "quantity_names": [LABELS[q] for q in QUANTITIES],
        "table": table, "ladder_rows": ladder,
        "figures": [{"src": _img_src(res, fname, self_contained), "title": _FIG_TITLES[kind],
                     "caption": captions[kind], "alt": f"{sc}: {_FIG_TITLES[kind]}"} for kind, fname in figs],
    }


def render_pages(res, figures: dict, self_contained: bool = False) -> dict:
    """``{filename: html}`` of every page. ``figures``: ``{scenario: [(kind, png filename)]}``."""
    env = environment()
    all_f = findings(res)
    nav = [{"name": s["name"], "href": page_name(s["name"])} for s in res.scenarios]
    common = {"nav": nav, "provenance": _provenance(res)}
    pages = {}
    pages["index.html"] = env.get_template("index.html").render(
        title="rbcheck results", matrix=_matrix(res), sections=_finding_sections(all_f),
        skipped=res.summary.get("skipped_variants", []),
        counts={"bad": sum(f.severity == "bad" for f in all_f),
                "explained": sum(f.severity == "explained" for f in all_f)},
        **common)
    for s in res.scenarios:
        view = _scenario_view(res, s, figures.get(s["name"], []), all_f, self_contained)
        pages[page_name(s["name"])] = env.get_template("scenario.html").render(
            title=f"rbcheck: {s['name']}", s=view, **common)
    return pages
