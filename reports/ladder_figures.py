"""The report's figures over a scenario's Δt ladder (one column per engine family, one row per quantity,
each variant in its style: reports.canvas), drawn only when the scenario ran a ladder:

``convergence``    final error vs Δt (log-log) with the fitted points and slope triangles
``local``          one-step (local) error vs Δt (log-log), same layout
``work``           work-precision: final error vs the engine's own time (the ranking's cost), every variant
                   on one axis

Each ``fig_*(res, sc, styles, path[, mode])`` draws its figure and returns whether it carried anything;
what it left out is said in ``canvas.NOTES[(sc, kind)]`` (docs/results.md, "The report").
"""
from __future__ import annotations

import math

import numpy as np
from matplotlib.ticker import FixedFormatter, FixedLocator

from cross_checks.core.quantities import COLUMN_STEM, QUANTITIES, UNITS
from reports import canvas
from reports.canvas import (
    NOTES,
    DataStamps,
    add_curves,
    add_line,
    coinciding,
    covered_by,
    family_blocks,
    family_grid,
    figure_legend,
    frame_of,
    legend_entries,
    panel_figure,
    panel_title,
    positive,
    robust_limits,
    row_ylabel,
    same_limits,
    same_note,
)
from reports.data import LABELS
from reports.glance import families, order_text
from reports.ranking import run_cost_s

__all__ = ["fig_ladder", "fig_work"]


def _ladder_at_roundoff(res, sc, q, variants, mode) -> bool:
    """Whether every variant's error in ``q`` is at or below its round-off floor at every Δt of the
    ladder (its convergence record's errors and floors): a row of such errors shows only round-off."""
    for v in variants:
        rec = next(iter(res.records(sc, v, q, mode=mode)), None)
        if rec is None:
            return False
        e, fl = np.asarray(rec["errors"], dtype=float), np.asarray(rec["floors"], dtype=float)
        if not (e.size and np.all(np.isfinite(e)) and np.all(e <= fl)):
            return False
    return bool(variants)




def _slope_triangles(ax, dts, labels, orders=(1, 2, 4)):
    """Reference slope triangles at the lower right of a log-log axis, a third of the Δt range wide,
    with their orders written beside them when ``labels`` (the first panel of a row: the others of the
    row have the same triangles at the same place)."""
    lo, hi = ax.get_ylim()
    span_x = math.log10(max(dts) / min(dts)) or 1.0
    x1 = max(dts) / 10 ** (0.04 * span_x)
    x0 = x1 / 10 ** (0.3 * span_x)
    span = math.log10(hi) - math.log10(lo)
    xs, ys, texts = [], [], []
    for k, p in enumerate(orders):
        y0 = 10 ** (math.log10(lo) + span * (0.04 + 0.09 * k))
        y1 = y0 * (x1 / x0) ** p
        xs += [x0, x1, x1, x0, np.nan]
        ys += [y0, y0, y1, y0, np.nan]
        texts.append((x0 / 10 ** (0.01 * span_x), y0, f"{p}", 7,
                      {"color": "0.3", "va": "bottom", "ha": "right"}))
    add_line(ax, xs, ys, color="0.45", lw=0.8)   # one line for the three triangles (one artist to draw)
    if labels:
        ax.add_artist(DataStamps(texts))


def _ladder_cell(ax, res, sc, q, vs, styles, mode):
    """One family's variants on one quantity; returns the Δt drawn and the finite errors drawn."""
    col = f"{COLUMN_STEM[q]}_err_final" if mode == "free_running" else f"{COLUMN_STEM[q]}_local_err"
    recs = {r["engine"]: r for r in res.records(sc, quantity=q, mode=mode)}
    dts, vals, drawn, parts = [], [], [], []
    for v in vs:
        rows = sorted([r for r in res.rows_for(sc, v) if r["in_ladder"]], key=lambda r: -r["dt"])
        dt = np.array([r["dt"] for r in rows])
        e = np.array([r[col] for r in rows], dtype=float)
        ok = (np.isfinite(e) & np.array([r["status"] == "ok" for r in rows], dtype=bool)
              if rows else np.zeros(0, bool))
        if not ok.any():
            continue
        st = styles[v]
        halo = covered_by(drawn, (v, dt[ok], positive(e[ok])), log=True)
        a = 0.45 if halo else 1.0
        parts += [("line", dt[ok], positive(e[ok]), (*st["color"][:3], a), st["ls"], 3.2 if halo else 1.0),
                  ("marks", dt[ok], positive(e[ok]), st["marker"], 7 if halo else 4, (1.0, 1.0, 1.0, a),
                   (*st["color"][:3], a))]
        drawn.append((v, dt[ok], positive(e[ok])))
        rec = recs.get(v)
        if rec is not None and rec["order"] is not None:
            fitted = np.array(rec["fitted"], dtype=bool)
            c = (*st["color"][:3], 1.0)
            parts.append(("marks", np.array(rec["dt_s"], dtype=float)[fitted],
                          positive(np.array(rec["errors"], dtype=float)[fitted]), st["marker"], 4, c, c))
        dts += dt[ok].tolist()
        vals.append(positive(e[ok]))
    add_curves(ax, parts)
    if recs:
        r0 = next(iter(recs.values()))
        add_line(ax, r0["dt_s"], positive(r0["floors"]), color="0.5", lw=4, alpha=0.22, solid_capstyle="butt")
    return dts, vals, drawn



def fig_ladder(res, sc, styles, path, mode):
    """Final (or one-step) error against Δt, families in columns; False without a ladder."""
    info = res.scenario(sc)
    ladder = sorted({r["dt"] for r in res.rows_for(sc) if r["in_ladder"]})
    kind = "convergence" if mode == "free_running" else "local"
    vs_all = [v for v in res.variants if res.records(sc, v, mode=mode)]
    if len(ladder) < 2 or not vs_all:
        NOTES[(sc, kind)] = "no Δt ladder (one Δt only), so no order to show" if len(ladder) < 2 else ""
        return False
    fams = families(vs_all)
    moving = [q for q in QUANTITIES if info.get("varies", {}).get(q, True)]
    exact = [q for q in moving if _ladder_at_roundoff(res, sc, q, vs_all, mode)]
    qs = [q for q in moving if q not in exact]
    exact_note = (" Not drawn, every variant's error at or below its round-off floor at every Δt (exact to "
                  "within what can be measured; order \"exact\"): " + ", ".join(LABELS[q] for q in exact)
                  + ".") if exact else ""
    if not qs:
        NOTES[(sc, kind)] = exact_note.strip()
        return False
    what = "final error" if mode == "free_running" else "one-step (local) error"
    orders = {v: "p " + " / ".join(order_text(next((r for r in res.records(sc, v, q, mode=mode)), None))
                                   for q in qs)
              for v in vs_all}
    fig, axes = family_grid(len(qs), len(fams),
                      f"{sc}: {what} vs Δt (filled: points of the fitted order; grey band: "
                      "round-off floor; triangles: slopes 1, 2, 4)", log=True,
                      layout="ladder", legend=legend_entries(fams, styles, orders))
    same = []
    for i, q in enumerate(qs):
        vals = []
        for j, vs in enumerate(fams.values()):
            _, got, drawn = _ladder_cell(axes[i, j], res, sc, q, vs, styles, mode)
            vals += got
            same += [(a, b, LABELS[q]) for a, b in coinciding(drawn, log=True)]
            if axes[i, j].has_data():
                axes[i, j].autoscale_view()
        lim = robust_limits(vals, log=True)
        same_limits(axes[i], "y", None if lim is None else (lim[0] / 10, lim[1]))
        for j, ax in enumerate(axes[i]):
            if lim is not None:
                _slope_triangles(ax, ladder, labels=j % family_blocks(len(fams))[1] == 0)
        row_ylabel(axes, i, f"{LABELS[q]} ({UNITS[q]})")
    same_limits(axes.flat, "x")
    # every row: the same Δt grid lines; labels on the bottom row only, on at most 4 of them (they would
    # overlap at a panel's width)
    step = -(-len(ladder) // 4)
    asc = sorted(ladder)
    shown = {d for k, d in enumerate(asc) if k % step == 0}
    for ax in axes.flat:
        ax.xaxis.set_major_locator(FixedLocator(asc))
        ax.xaxis.set_major_formatter(FixedFormatter([f"{d:g}" if d in shown else "" for d in asc]))
    for ax in axes[-1]:
        frame_of(ax).x_size = 7
        ax.set_xlabel("time step Δt (s)", fontsize=8)
    for ax, fam in zip(axes[0], fams):
        panel_title(ax, fam)
    left = [LABELS[q] for q in QUANTITIES if q not in moving]
    NOTES[(sc, kind)] = (("Not drawn: " + ", ".join(left) + " (does not move). ") if left else "") + \
        "Orders in the legends: " + " / ".join(LABELS[q] for q in qs) + "." + exact_note + same_note(same)
    canvas.save_png(fig, path)
    return True


def fig_work(res, sc, styles, path):
    """Work-precision across every engine on one axis (the comparison an engine choice needs)."""
    ladder = {r["dt"] for r in res.rows_for(sc) if r["in_ladder"]}
    if len(ladder) < 2:
        NOTES[(sc, "work")] = "no Δt ladder (one Δt only)"
        return False
    qs = [q for q in ("position", "orientation") if res.scenario(sc).get("varies", {}).get(q, True)]
    if not qs:
        NOTES[(sc, "work")] = "nothing moves: neither position nor orientation has an error to weigh"
        return False
    width = 13.0 if len(qs) > 1 else 8.0
    fig, axes = panel_figure("work", 1, len(qs), (width, 4.0), log=True, outer=False)
    drawn_vs = [v for v in res.variants
                if any(r["in_ladder"] and r["status"] == "ok" for r in res.rows_for(sc, v))]
    leg_h = figure_legend(fig, width, legend_entries(families(drawn_vs), styles)) if drawn_vs else 0.0
    axes_h = 3.6
    h = 0.75 + axes_h + 0.6 + leg_h + 0.15
    fig.set_size_inches(width, h)
    fig.suptitle(f"{sc}: work-precision — final error vs the engine's time of each run", fontsize=11,
                 x=0.01, ha="left")
    same = []
    for ax, q in zip(axes[0], qs):
        col = f"{COLUMN_STEM[q]}_err_final"
        drawn, parts = [], []
        for v in drawn_vs:
            rows = sorted([r for r in res.rows_for(sc, v) if r["in_ladder"] and r["status"] == "ok"],
                          key=lambda r: -r["dt"])
            w = np.array([run_cost_s(r) for r in rows], dtype=float)   # the ranking's cost, not wall_s
            e = np.array([r[col] for r in rows], dtype=float)
            ok = np.isfinite(w) & np.isfinite(e) & (w > 0)
            if not ok.any():
                continue
            st = styles[v]
            halo = covered_by(drawn, (v, w[ok], positive(e[ok])), log=True)
            if halo:
                same.append((halo, v, LABELS[q]))
            c = (*st["color"][:3], 0.45 if halo else 0.9)
            parts += [("line", w[ok], positive(e[ok]), c, st["ls"], 3.2 if halo else 1.0),
                      ("marks", w[ok], positive(e[ok]), st["marker"], 7 if halo else 4, c, c)]
            drawn.append((v, w[ok], positive(e[ok])))
        add_curves(ax, parts)
        if ax.has_data():
            ax.autoscale_view()
        panel_title(ax, LABELS[q])
        ax.set_xlabel("time inside the engine, whole run (s)", fontsize=8)
        ax.set_ylabel(f"final {LABELS[q]} error ({UNITS[q]})", fontsize=8)
    fig.subplots_adjust(left=0.75 / width, right=1.0 - 0.2 / width, top=1.0 - 0.75 / h,
                        bottom=(0.6 + leg_h + 0.15) / h, wspace=0.22)
    canvas.save_png(fig, path)
    NOTES[(sc, "work")] = same_note(same).strip()
    return True

