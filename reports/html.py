"""HTML pages of a results directory: index.html (summary matrix, findings, provenance) and one page
per scenario (tables and figures). Jinja2 templates with autoescape; every string a template shows is
prepared here (templates only loop and place), so user text such as a scenario description is
always escaped.
"""
from __future__ import annotations

import base64
import math
import re

from jinja2 import Environment, PackageLoader, StrictUndefined, TemplateNotFound, select_autoescape
from markupsafe import Markup, escape

from cross_checks.core.quantities import COLUMN_STEM, QUANTITIES, UNITS
from cross_checks.core.tolerances import REPORT_LONG_RUN_CONSERVES
from reports.data import LABELS
from reports.findings import findings, fmt, fmt_dt
from reports.glance import ACCURACY_TIERS, GLYPHS, cell, families, glyph, order_text, verdict_box
from reports.install import incomplete
from reports.integrators import PAGE as INTEGRATORS_PAGE
from reports.ranking import (
    SCENARIO_FAMILIES,
    best_sentences,
    engine_answer,
    engine_sentence,
    family_lines,
    ranking,
    ratio_text,
)
from reports.words import GLOSSARY, explain

__all__ = ["environment", "render_pages", "page_name", "rows_extracts"]

_FAMILIES = ("One column per engine family (more than five wrap into blocks of rows); a row shares its y "
             "axis. Each variant keeps one style in every figure of the report: its family's hue, a shade, "
             "a dash pattern and a marker of its own (the legends under the panels, one per family). A run "
             "that diverged is drawn up to its divergence (×) and the axes follow the runs that did not.")
_FIG_CAPTIONS = {
    "trajectories": "The moving position and orientation components against time at the scenario's "
                    "default Δt; the thick grey line is the reference. " + _FAMILIES,
    "errors": "Error against the reference over time at the default Δt (log–log: a power of t is a straight "
              "line). " + _FAMILIES,
    "conservation": "Relative drift of the quantities the physics conserves, at the default Δt "
                    "(log–log). " + _FAMILIES,
    "convergence": "Final error against Δt (log–log) over the scenario's Δt ladder, one "
                   "column per engine family, each variant in its own style. Filled markers are the points "
                   "of the least-squares order fit; the grey band is the round-off floor; the "
                   "triangles show slopes 1, 2 and 4. The legends list the fitted orders.",
    "local": "One-step (local) error against Δt: every step restarted from the reference state; an "
             "order-p scheme shows slope p + 1.",
    "work": "Work-precision: final error against the engine's own time of each run of the ladder (the "
            "ranking's cost: the time inside its steps, rbcheck's own left out), every variant "
            "on one axis in its own style (hue: engine family). The ranking page reads these curves: "
            "which variant is most accurate at a common cost, and cheapest at a common accuracy.",
    "polhode": "The polhode: the angular momentum L seen from the body (in its principal axes e1 minor, "
               "e2 intermediate, e3 major), on the sphere |L| = |L₀|, at the default Δt (series of ≤ 500 "
               "samples). Grey curves: the polhodes, where that sphere meets the energy ellipsoid 2E = Σ "
               "L_i²/I_i (closed form, not integrated); black: the one of the reference's E and |L|; dashed: "
               "the separatrix through ±e2. The front of the sphere is solid, its back faint and dotted; ○ "
               "the start, □ the end of each path. A correct step stays on the black curve; one that pumps "
               "or drains energy slides across the curves; one without the gyroscopic term sits still (ω "
               "fixed in world axes: the body spins about it). First panel: the reference alone; then one "
               "panel per engine family over the reference's path in thick grey.",
}
_NO_ONE_STEP = ("no one-step mode: an engine file runs whole trajectories only, "
                "so local errors are not measured")
_FIG_TITLES = {"trajectories": "Trajectories", "errors": "Error vs time", "conservation": "Conservation",
               "convergence": "Convergence (free-running)", "local": "Local error (one-step mode)",
               "work": "Work-precision", "polhode": "Polhode (L in body axes)"}


class _Loader(PackageLoader):
    """The package's templates; one that is missing is an incomplete installation, said with its path."""

    def get_source(self, environment, template):
        try:
            return super().get_source(environment, template)
        except TemplateNotFound:
            raise incomplete(template) from None


def _escape_controls(value):
    """Every value a template shows, with control characters written ``\\xNN``
    (:func:`cross_checks.core.progress.shown`): autoescaping takes care of ``<`` and ``>``, not of ESC. Markup
    (already HTML: an inline figure) stays Markup."""
    from markupsafe import Markup

    from cross_checks.core.progress import shown
    if isinstance(value, Markup):
        return Markup(shown(value))
    return shown(value) if isinstance(value, str) else value


def environment() -> Environment:
    env = Environment(loader=_Loader("reports", "templates"),
                      autoescape=select_autoescape(["html", "htm", "xml"],
                                                   default_for_string=True, default=True),
                      undefined=StrictUndefined, trim_blocks=True, lstrip_blocks=True,
                      keep_trailing_newline=True, finalize=_escape_controls)
    env.filters["breakable"] = breakable
    return env


def breakable(name) -> Markup:
    """A variant's name (escaped) that a narrow table cell may break after its colon and underscores
    only (``<wbr>``), never inside a word: "semi_implicit_euler" wraps as "semi_ implicit_ euler"."""
    parts = re.split(r"(?<=[:_])", str(name))
    return Markup("<wbr>").join(escape(p) for p in parts)


def page_name(scenario: str) -> str:
    """The page of a scenario; the name read from the data is made a safe file name first."""
    from cross_checks.sweep.results_dir import safe_file_stem
    return f"scenario-{safe_file_stem(scenario)}.html"


def _img_src(res, fname, self_contained):
    if not self_contained:
        return f"plots/{fname}"
    data = (res.directory / "plots" / fname).read_bytes()
    return "data:image/png;base64," + base64.b64encode(data).decode("ascii")


#: Background of an order cell by its verdict (reports.glance.glyph): the matrix's colours.
_GLYPH_BG = {"good": "acc1", "exact": "acc1", "noconv": "noconv", "pre": "pre", "diverged": "diverged",
             "bad": "bad", "missing": "missing"}


def _order_cell(rec, local=False):
    g = glyph(rec)
    if rec is None:
        return {"text": "–", "cls": "missing", "title": "", "mark": ""}
    title = rec["assessment"] + (f" — {rec['note']}" if rec.get("note") else "")
    if not local and rec.get("reason"):
        title += f" — expected: {rec['reason']}"
    return {"text": order_text(rec), "cls": _GLYPH_BG[g], "title": title, "mark": GLYPHS[g][0], "glyph": g}


def _provenance(res):
    p = res.summary.get("provenance", {})
    run = res.summary.get("run", {})
    keys = [("rbcheck", "rbcheck"), ("numpy", "numpy"), ("scipy", "scipy"), ("mujoco", "MuJoCo"),
            ("pybullet", "PyBullet"), ("drake", "Drake"), ("python", "Python"), ("platform", "platform"),
            ("machine", "machine"), ("git_commit", "commit"), ("started_at", "started (UTC)"),
            ("command", "command")]
    out = [(label, str(p.get(k, "")) or "–") for k, label in keys]
    # the other engines swept: their version, and where from and which file when not rbcheck's own
    for name, e in (p.get("engines") or {}).items():
        if name in ("reference", "mujoco", "pybullet", "drake"):
            continue
        if e.get("source", "").endswith("(rbcheck)"):
            out.append((f"engine {name}", e.get("version") or "–"))
            continue
        sha = f", SHA-256 {e['engine_file_sha256'][:16]}…" if e.get("engine_file_sha256") else ""
        out.append((f"engine {name}", f"{e.get('version') or '–'} — {e.get('source', '')}{sha}"))
    if run:
        out.append(("runs",
                    f"{run.get('runs')} ({run.get('cached_runs')} from cache, {run.get('diverged_runs')} "
                    f"diverged, {run.get('failed_runs')} failed) on {run.get('jobs')} worker(s)"))
        out.append(("sweep wall time",
                    f"{run.get('wall_s')} s for the runs and metrics, report excluded (the runs' "
                    f"own wall times add up to {run.get('cpu_s_in_runs')} s, cached runs excluded)"))
    return out


def _matrix(res):
    """Engine variants (rows, grouped by family: one tbody each) × scenarios (columns), each cell at the
    scenario's default Δt (reports.glance.cell)."""
    header = []
    for i, s in enumerate(res.scenarios, start=1):
        sr = s.get("second_reference")
        second = "" if not isinstance(sr, dict) else ("2nd ref. failed" if sr.get("error")
                                                      else "2nd ref. agrees" if sr.get("agrees")
                                                      else "2nd ref. DISAGREES")
        header.append({"name": s["name"], "href": page_name(s["name"]), "col": i, "second": second,
                       "second_cls": "" if not second else ("acc1" if second.endswith("agrees") else "bad"),
                       "title": f"{s['name']}: Δt = {fmt_dt(s['dt_s'])} s over {fmt_dt(s['duration_s'])} s, "
                                f"reference {s['reference']}" + (f"; {second}" if second else "")})
    groups = []
    for fam, vs in families(res.variants).items():
        rows = [{"name": v, "short": v.split(":", 1)[-1], "cells": [cell(res, s, v) for s in res.scenarios]}
                for v in vs]
        groups.append({"family": fam, "rows": rows})
    return {"header": header, "groups": groups, "ncols": len(header) + 1}


def _legend():
    tiers = ACCURACY_TIERS
    return {"cells": [("bad", "contradicts the expectation, or failed"),
                      ("diverged", "diverged at the default Δt"),
                      ("noconv", "does not converge — expected (reason above)"),
                      ("pre", "pre-asymptotic: no order claimed on this ladder"),
                      ("acc1", f"as expected; error ≤ {fmt(tiers[0])} of scale"),
                      ("acc2", f"as expected; error ≤ {fmt(tiers[1])}"),
                      ("acc3", f"as expected; error > {fmt(tiers[1])}"),
                      ("missing", "not run, or the engine cannot express the scenario")],
            "marks": [(mark, g, text) for g, (mark, text) in GLYPHS.items()]}


def _finding_views(fs, res=None):
    """The findings as the templates show them; with ``res``, each one's standalone reproducer where the
    sweep wrote one (``repro``: its path in the results directory; docs/repro.md)."""
    links = _repro_links(res) if res is not None else {}
    return [{"cls": f.severity, "text": f.text, "repro": links.get((f.engine, f.scenario), "")} for f in fs]


def _repro_links(res) -> dict:
    """``(ENGINE:VARIANT, scenario) -> repro/….py`` of summary.json's ``reproducers`` (those written; the
    first of a pair: its order, drift or gyroscopic claim before its broken invariances)."""
    links: dict = {}
    for r in res.summary.get("reproducers") or []:
        if r.get("file"):
            links.setdefault((r["engine"], r["scenario"]), r["file"])
    return links


_SECTIONS = (("bad", "Results that contradict the expectations"),
             ("explained", "Expected non-convergence, and why"),
             ("info", "Observations"))


def _finding_sections(fs, res=None):
    return [{"title": title, "cls": sev, "entries": _finding_views([f for f in fs if f.severity == sev], res)}
            for sev, title in _SECTIONS if any(f.severity == sev for f in fs)]


def _scenario_table(res, sc):
    """The results at the default Δt: one row per variant (family in its own column, for sorting)."""
    table = []
    for v in res.variants:
        d = res.default_row(sc, v)
        if d is None:
            continue
        recs = {r["quantity"]: r for r in res.records(sc, v)}
        lrecs = {r["quantity"]: r for r in res.records(sc, v, mode="one_step")}
        status = d["status"] + (f" at t = {fmt(d['diverged_at_s'], 's', 3)}"
                                if d["status"] == "diverged" else "")
        table.append({
            "variant": v, "status": status,
            "status_cls": {"ok": "", "diverged": "diverged"}.get(d["status"], "bad"),
            "steps": str(d["steps"]), "wall": fmt(d["wall_s"], "s"),
            "errors": [_value(d[f"{COLUMN_STEM[q]}_err_final"]) for q in QUANTITIES],
            "energy": fmt(d["energy_drift_max"]),
            "energy_kind": d["energy_drift_kind"] if not math.isnan(d["energy_drift_max"]) else "",
            "energy_sort": _num(d["energy_drift_max"]),
            "angmom": fmt(d["angmom_drift_max"]), "angmom_sort": _num(d["angmom_drift_max"]),
            "orders": [_order_cell(recs.get(q)) for q in QUANTITIES],
            "local_orders": [_order_cell(lrecs.get(q), local=True) for q in QUANTITIES] if res.has_one_step(v)
            else [{"text": "n/a", "cls": "missing", "title": _NO_ONE_STEP, "mark": ""} for _ in QUANTITIES],
        })
    return table


def _num(v) -> str:
    """A sort key the page's script reads (empty: no value, sorted last)."""
    return "" if v is None or not math.isfinite(v) else repr(float(v))


def _value(v) -> dict:
    """A table cell of a number: its text and its sort key."""
    return {"text": fmt(v), "sort": _num(v)}


def _ladder_rows(res, sc):
    out = []
    for r in sorted(res.rows_for(sc),
                    key=lambda r: (res.variants.index(r["engine"]) if r["engine"] in res.variants
                                                      else 99, -r["dt"])):
        out.append({"variant": r["engine"], "dt": fmt_dt(r["dt"]), "dt_sort": _num(r["dt"]),
                    "status": r["status"],
                    "status_cls": {"ok": "", "diverged": "diverged"}.get(r["status"], "bad"),
                    "flags": ", ".join(x for x, on in (("default Δt", r["default_dt"]),
                                                       ("ladder", r["in_ladder"]),
                                                       ("cached", r["cached"])) if on),
                    "errors": [_value(r[f"{COLUMN_STEM[q]}_err_final"]) for q in QUANTITIES],
                    "local": [_value(r[f"{COLUMN_STEM[q]}_local_err"]) for q in QUANTITIES],
                    "wall": fmt(r["wall_s"], "s"), "wall_sort": _num(r["wall_s"]), "message": r["message"]})
    return out


def _files(res, s):
    """Links to the scenario's own files (each only when it exists) and what is missing."""
    from cross_checks.sweep.results_dir import safe_file_stem
    stem = safe_file_stem(s["name"])
    out = []
    for rel, label, what in ((f"scenarios/{stem}.toml", "scenario file (TOML)", "the file that ran"),
                             (f"rows/{stem}.csv", "results rows (CSV)",
                              "this scenario's rows of results.csv"),
                             (f"series/{stem}.npz", "series data (NPZ)", "the time series behind the plots")):
        exists = (res.directory / rel).is_file() or rel.startswith("rows/")  # rows/ is written with the pages
        out.append({"href": rel if exists else "", "label": label, "what": what if exists else
                    "not in this results directory"
                    + (" (the file could not be read back unchanged when the sweep finished)"
                       if rel.startswith("scenarios/") else "")})
    return out


def _second_reference_text(rec) -> str:
    """One line for summary.json's ``second_reference`` (docs/results.md); "" when there is none."""
    if not rec:
        return ""
    if rec.get("error"):
        return f"{rec['label']}: failed ({rec['error']})"
    dist = "; ".join(f"{LABELS[q]} {fmt(rec['distance'][q], UNITS[q])} (together they claim "
                     f"{fmt(rec['stated_accuracy'][q], UNITS[q])})" for q in QUANTITIES
                     if q in (rec.get("distance") or {}) and q in (rec.get("stated_accuracy") or {}))
    verdict = "agrees with the reference" if rec["agrees"] else "DISAGREES with the reference"
    return (f"{rec['label']}: {verdict} within their measured accuracies — "
            f"largest distance over the run: {dist}")


def _second_reference(s):
    """The scenario page's second-reference section (None when the record is absent)."""
    sr = s.get("second_reference")
    if not isinstance(sr, dict):
        return None
    dist, stated = sr.get("distance") or {}, sr.get("stated_accuracy") or {}
    rows = []
    for q in list(dict.fromkeys([*dist, *stated])):
        dv, sv = dist.get(q), stated.get(q)
        within = None if dv is None or sv is None else dv <= sv
        rows.append({"q": LABELS.get(q, q), "distance": fmt(dv, UNITS.get(q, "")),
                     "stated": fmt(sv, UNITS.get(q, "")),
                     "cls": "missing" if within is None else ("acc1" if within else "bad"),
                     "within": "–" if within is None else ("yes" if within else "NO")})
    return {"label": str(sr.get("label", "?")), "target": fmt(sr.get("target_accuracy")),
            "agrees": None if sr.get("error") else sr.get("agrees"), "error": str(sr.get("error") or ""),
            "rows": rows, "line": _second_reference_text(sr)}


def _scenario_view(res, s, figs, all_findings, self_contained):
    sc = s["name"]
    cons = []
    for k, label in (("energy", "energy"), ("angular_momentum", "angular momentum"),
                     ("linear_momentum", "linear momentum")):
        c = s["conserved"][k]
        cons.append(f"{label}: " + ("conserved" if c["conserved"] else c["why_not"]))
    no_local = [v for v in res.variants if not res.has_one_step(v)]
    captions = dict(_FIG_CAPTIONS)
    if no_local:
        captions["local"] += f" Not shown ({_NO_ONE_STEP}): {', '.join(no_local)}."
    mine = [f for f in all_findings if f.scenario == sc]
    found = _finding_views([f for f in mine if f.severity != "info"], res)
    observed = _finding_views([f for f in mine if f.severity == "info"], res)
    _explain_in_place([found, observed])
    return {
        "name": sc, "description": s["description"], "source": s["source"], "hash": s["content_hash"],
        "duration": fmt_dt(s["duration_s"]), "dt": fmt_dt(s["dt_s"]),
        "ladder": ", ".join(fmt_dt(d) for d in s["dt_ladder_s"]), "reference": s["reference"],
        "conserved": cons, "files": _files(res, s), "second": _second_reference(s),
        "findings": found, "any_bad": any(f.severity == "bad" for f in mine), "observations": observed,
        "quantities": [f"{LABELS[q]} ({UNITS[q]})" for q in QUANTITIES],
        "quantity_names": [LABELS[q] for q in QUANTITIES],
        "table": _scenario_table(res, sc), "ladder_rows": _ladder_rows(res, sc),
        "figures": [{"src": _img_src(res, fname, self_contained), "title": _FIG_TITLES[kind],
                     "caption": captions[kind] + (f" {note}" if note else ""),
                     "alt": f"{sc}: {_FIG_TITLES[kind]}"}
                    for kind, fname, note in figs if fname],
        "not_drawn": [f"{_FIG_TITLES[kind]}: {note}" for kind, fname, note in figs if not fname and note],
        "animation": _animation_view(res, sc),
    }


def _animation_view(res, sc):
    """The scenario page's animation (reports.animation.report_animation): its data as JSON for the page's
    script (``</`` escaped: it sits in a <script> element), the variants to pick by family, the caption."""
    import json

    from reports.animation import report_animation
    from reports.canvas import variant_styles
    data = report_animation(res, sc, variant_styles(res.variants))
    if data is None:
        return None
    runs = {r["name"]: r for r in data["runs"][1:]}
    fams = [{"name": fam, "runs": [{"name": v, "short": v.split(":", 1)[-1], "color": runs[v]["color"],
                                    "checked": v == data["default"], "div": runs[v]["div"] is not None}
                                   for v in vs if v in runs]}
            for fam, vs in families(res.variants).items()]
    text = ("The body as the box of its principal moments, with its principal axes (e1 minor red, e2 "
            "intermediate green, e3 major blue), turning about its centre of mass: the reference, then each "
            "variant picked above over the reference's box drawn faint and dashed, with its orientation "
            "error to the reference. A run that diverged stops at its divergence and says so. "
            + data["caption"] + (f" Shown first: {data['default']}, the largest orientation error among the "
                                 "runs that did not diverge." if data["default"] else ""))
    blob = json.dumps(data, separators=(",", ":")).replace("</", "<\\/")
    return {"json": Markup(blob), "frames": len(data["t"]), "families": [f for f in fams if f["runs"]],
            "text": text}


def rows_extracts(res) -> dict:
    """``{"rows/<scenario>.csv": text}``: each scenario's rows of results.csv, cells as written there."""
    import csv
    import io

    from cross_checks.sweep.results_dir import safe_file_stem
    with (res.directory / "results.csv").open(encoding="utf-8", newline="") as fh:
        table = list(csv.reader(fh))
    col = table[0].index("scenario")
    out = {}
    for s in res.scenarios:
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(table[0])
        w.writerows(r for r in table[1:] if r and r[col] == s["name"])
        out[f"rows/{safe_file_stem(s['name'])}.csv"] = buf.getvalue()
    return out


def render_pages(res, figures: dict, self_contained: bool = False) -> dict:
    """``{filename: html}`` of every page. ``figures``:
    ``{scenario: [(kind, png filename or None, note)]}``."""
    env = environment()
    all_f = findings(res)
    nav = [{"name": "ranking", "href": RANKING_PAGE}, {"name": "integrators", "href": INTEGRATORS_PAGE}]
    nav += [{"name": s["name"], "href": page_name(s["name"])} for s in res.scenarios]
    common = {"nav": nav, "provenance": _provenance(res)}
    pages = {}
    sections = _finding_sections([f for f in all_f if f.severity != "info"], res)
    box = verdict_box(res)
    observations = _finding_views([f for f in all_f if f.severity == "info"], res)
    _explain_in_place([*(g["lines"] for g in box["groups"]), *(sec["entries"] for sec in sections),
                       observations])
    rk = ranking(res)
    answer = engine_answer(res)
    pages[RANKING_PAGE] = env.get_template("ranking.html").render(
        title="rbcheck: which engine?", r=_ranking_view(res, rk), e=answer, **common)
    pages[INTEGRATORS_PAGE] = env.get_template("integrators.html").render(
        title="rbcheck: the integrators, on work precision and over long runs",
        v=_integrators_view(res, rk, figures.get(None, []), self_contained), **common)
    pages["index.html"] = env.get_template("index.html").render(
        title="rbcheck results", matrix=_matrix(res), legend=_legend(), box=box,
        which=_which_view(rk, answer),
        sections=sections, observations=observations,
        skipped=res.summary.get("skipped_variants", []), second=_second_summary(res),
        invariance=(res.summary.get("run") or {}).get("invariance"), **common)
    for s in res.scenarios:
        view = _scenario_view(res, s, figures.get(s["name"], []), all_f, self_contained)
        pages[page_name(s["name"])] = env.get_template("scenario.html").render(
            title=f"rbcheck: {s['name']}", s=view, legend=_legend(), **common)
    return pages


RANKING_PAGE = "ranking.html"


def _g(x, digits: int = 2) -> str:
    """A number to read (``digits`` significant digits), "–" for none or a non-finite one."""
    if not isinstance(x, (int, float)) or isinstance(x, bool) or not math.isfinite(x):
        return "–"
    return f"{x:.{digits}g}"


def _integrators_view(res, rk, drawn, self_contained) -> dict:
    """The integrators page (reports.integrators): the work-precision and the long-run standings, every
    finding in a sentence, the figures drawn."""
    from reports.integrators import (
        FIGURES,
        VERDICT_WORDS,
        conservation_score,
        integrators_view,
        long_cell_class,
    )
    iv = integrators_view(res, rk)
    figs = {FIGURES[f]: _img_src(res, f, self_contained) for f in drawn if f in FIGURES}
    orders = {x["name"]: x.get("declared_order") for x in res.summary.get("variants", [])}
    work = [{**_standing_row(s, len(rk.groups["overall"]["scenarios"])),
             "order": "" if orders.get(s.variant) is None else f"{orders[s.variant]:g}"} for s in iv.work]
    unranked = [v for v in iv.variants if v not in {s.variant for s in iv.work}]
    long_rows = []
    for s in iv.long:
        cells = []
        for n in iv.long_runs:
            r = s.records.get(n)
            if r is None:
                cells.append({"text": "–", "sub": "", "cls": ""})
                continue
            ok = r.get("status") == "ok"
            sub = (f"E {_g(r.get('energy_drift_max'))}, |L| {_g(r.get('momentum_drift_max'))}, L turns "
                   f"{_g(r.get('direction_drift_max_rad'))} rad; δ {_g(r.get('separatrix_start'), 3)} → "
                   f"{_g(r.get('separatrix_end'), 3)}" if ok or r.get("status") == "diverged"
                   else r.get("message", ""))
            if r.get("status") == "diverged":
                sub = f"at t = {_g(r.get('diverged_at_s'), 4)} s; " + sub
            mark = ("✗ " if r.get("matches_expectation") is False else
                    "✓ " if r.get("matches_expectation") is True else "")
            words = VERDICT_WORDS.get(r.get("verdict"), str(r.get("verdict")))
            cls = long_cell_class(r)   # green: keeps what it declares AND conserves; amber: drifts
            if cls == "noconv" and mark:
                words = f"as declared, but drifts (largest {_g(conservation_score(r))}): {words}"
            cells.append({"text": mark + words, "sub": sub, "cls": cls})
        long_rows.append({"rank": s.rank, "variant": s.variant, "score": _g(s.score), "cells": cells,
                          "score_sort": (_num(s.score) if s.score is not None and math.isfinite(s.score)
                                         else "1e300"),
                          "cls": "bad" if s.contradicts else ""})
    links = _repro_links(res)
    findings = [{"text": r.get("finding") or f"{r['engine']} on {r['scenario']}: {r.get('assessment', '')}",
                 "judged": r.get("assessment", ""), "repro": links.get((r["engine"], r["scenario"]), ""),
                 "cls": "bad" if r.get("matches_expectation") is False else "info"} for r in iv.findings]
    scen = res.summary.get("long_run_scenarios") or []
    return {"work": work, "unranked": unranked, "long_runs": iv.long_runs, "long": long_rows,
            "sentences": [iv.sentences[v] for v in iv.variants], "findings": findings, "figs": figs,
            "n_variants": len(iv.variants), "long_scenarios": scen, "delta_meaning": GLOSSARY["δ"],
            "conserves": f"{REPORT_LONG_RUN_CONSERVES:g}"}


def _which_view(rk, answer) -> dict:
    """The first screen's answer to "which engine?": the engines' best overall (and over the long runs), then
    every variant's, the reference's schemes included, with the link to the ranking."""
    engines_first = [(f"{label} (engines)", text) for label, text in answer["overall"] + answer["long"]]
    return {"lines": engines_first + [(f"{label} (every variant)", text)
                                      for label, text, _ in best_sentences(rk, "overall")],
            "families": family_lines(rk),
            "note": next((n for _, _, n in best_sentences(rk, "overall")), ""), "href": RANKING_PAGE}


def _micro(us) -> str:
    """A cost per step in µs: "0.61", "17", "360", "12000" (no exponent: these are read side by side)."""
    if us is None or not math.isfinite(us):
        return "–"
    return f"{us:.2g}" if us < 100 else f"{float(f'{us:.2g}'):.0f}"


def _standing_row(s, n_sc) -> dict:
    c = s.verdicts
    verdict = ("✗ contradicts on " + ", ".join(s.contradicts_on) if s.contradicts_on
               else f"✗ {s.failed} failed run(s)" if s.failed else "✓ as expected")
    detail = ", ".join(x for x in (f"{c['noconv']} no conv. (expected)" if c["noconv"] else "",
                                   f"{c['pre']} pre-asymptotic" if c["pre"] else "",
                                   f"{s.diverged} diverged run(s)" if s.diverged else "") if x)
    return {"variant": s.variant, "family": s.variant.split(":", 1)[0],
            "acc_rank": str(s.acc_rank or ""), "acc": ratio_text(s.acc_score),
            "acc_sort": _num(s.acc_score) if s.acc_rank else "", "acc_n": f"{s.acc_n}/{n_sc}",
            "cost_rank": str(s.cost_rank or ""),
            "cost": ratio_text(s.cost_score),
            "cost_sort": _num(s.cost_score) if s.cost_rank else "", "cost_n": f"{s.cost_n}/{n_sc}",
            "per_step": _micro(s.per_step_us), "per_step_sort": _num(s.per_step_us),
            "overhead": _micro(s.overhead_us), "overhead_sort": _num(s.overhead_us),
            "verdict": verdict, "verdict_cls": "bad" if (s.contradicts_on or s.failed) else "acc1",
            "verdict_detail": detail, "energy": s.energy or "–", "energy_sort": _num(s.energy_sort)}


def _ranking_view(res, rk) -> dict:
    groups = []
    for g, grp in rk.groups.items():
        n_sc = len(grp["scenarios"])
        rows = sorted(grp["standings"],
                      key=lambda s: (s.acc_rank or 10 ** 6, s.cost_rank or 10 ** 6, s.variant))
        groups.append({"name": g, "id": "g-" + g.replace(" ", "-"), "scenarios": ", ".join(grp["scenarios"]),
                       "best": [(label, text) for label, text, _ in best_sentences(rk, g)],
                       "rows": [_standing_row(s, n_sc) for s in rows]})
    scen = []
    for sc, r in rk.scenarios.items():
        acc = sorted(((v, x) for v, x in r.accuracy.items() if x.value is not None), key=lambda t: t[1].value)
        cost = sorted(((v, x) for v, x in r.cost.items() if x.value is not None), key=lambda t: t[1].value)
        variants = [{"variant": v, "acc": r.accuracy[v].text(), "acc_sort": _num(r.accuracy[v].value),
                     "acc_why": r.accuracy[v].why,
                     "cost": r.cost[v].text("s") if v in r.cost else "–",
                     "cost_sort": _num(r.cost[v].value) if v in r.cost else "",
                     "cost_why": r.cost[v].why if v in r.cost else "",
                     "per_step": _micro(r.per_step[v] * 1e6), "per_step_sort": _num(r.per_step[v] * 1e6)}
                    for v in res.variants if v in r.accuracy]
        scen.append({"name": sc, "href": page_name(sc), "family": r.family,
                     "cost": fmt(r.common_cost, "s"), "n_cost": r.n_cost,
                     "error": fmt(r.common_error), "n_error": r.n_error, "n": len(r.per_step),
                     "best_acc": acc[0][0] if acc else "–", "best_cost": cost[0][0] if cost else "–",
                     "variants": variants})
    cached = sum(bool(r["cached"]) for r in res.rows)
    sentences = [engine_sentence(rk, v) for v in res.variants
                 if any(s.variant == v for s in rk.groups["overall"]["standings"])]
    return {"groups": groups, "scenarios": scen, "sentences": sentences, "families": SCENARIO_FAMILIES,
            "cached": cached, "n_rows": len(res.rows)}


def _explain_in_place(lists) -> None:
    """Each symbol explained at its first use on the page (reports.words), in the order of ``lists`` —
    lists of lines (str) or of finding views (their "text") — as the page shows them."""
    flat = [(lst, i) for lst in lists for i in range(len(lst))]
    texts = [lst[i]["text"] if isinstance(lst[i], dict) else lst[i] for lst, i in flat]
    for (lst, i), text in zip(flat, explain(texts)):
        if isinstance(lst[i], dict):
            lst[i] = {**lst[i], "text": text}
        else:
            lst[i] = text


def _second_summary(res) -> str:
    srs = [s.get("second_reference") for s in res.scenarios if isinstance(s.get("second_reference"), dict)]
    if not srs:
        return ""
    ok = sum(bool(sr.get("agrees")) for sr in srs)
    labels = sorted({str(sr.get("label", "?")) for sr in srs})
    return (f"Second reference ({', '.join(labels)}): agrees with the reference "
            f"within their stated accuracy on {ok} of {len(srs)} scenario(s).")
