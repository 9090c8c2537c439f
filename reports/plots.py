"""The report's PNG figures of one scenario, drawn from the saved results only (one idea per figure), on
the report's canvas (reports.canvas: grids, styles, legends, saving).

Figures (``plots/<scenario>__<kind>.png``), by module:

- reports.time_figures: ``trajectories`` (the moving position / orientation components vs time, with the
  reference), ``errors`` (error vs time, log–log) and ``conservation`` (|relative drift| of the conserved
  quantities vs time, log–log), at the default Δt;
- reports.ladder_figures: ``convergence`` (final error vs Δt, log–log, with the fitted points and slope
  triangles), ``local`` (one-step error vs Δt) and ``work`` (work-precision: final error vs the engine's own
  time, every variant on one axis), for a scenario with a Δt ladder.

(The polhode figure, ``plots/<scenario>__polhode.png``, is reports.polhode's, on the same canvas.)

``figure_tasks(res, sc)`` lists the figures a scenario has (so they can be drawn in parallel);
``draw(res, sc, kind, path)`` draws one and returns whether it carried anything, with its caption's note;
``prepare(res)`` builds before the drawing processes are forked what each would build for itself.
What is drawn, marked or left out: docs/results.md, "The report" (Figures).
"""
from __future__ import annotations

import matplotlib

from cross_checks.core.quantities import QUANTITIES
from reports.canvas import (
    NOTES,
    REPORT_DPI,
    TICK_PT,
    family_blocks,
    figure_name,
    legend_entries,
    legend_pixels,
    panel_figure,
    release,
    stamp,
    variant_styles,
)
from reports.glance import families
from reports.ladder_figures import fig_ladder, fig_work
from reports.time_figures import fig_conservation, fig_errors, fig_trajectories

__all__ = ["KINDS", "figure_tasks", "draw", "figure_name", "relative_cost", "prepare", "release"]

KINDS = ("trajectories", "errors", "conservation", "convergence", "local", "work")


def prepare(res) -> None:
    """Build, before the drawing processes are forked, what each would build for itself: the grids of
    panels of each layout of ``res``'s figures (as many rows as a figure can have), the decade labels
    and the legends without orders."""
    fams = families(res.variants)
    blocks, cols = family_blocks(len(fams))
    for layout, rows, log in (("time", 7, False), ("time-log", len(QUANTITIES), True),
                              ("ladder", len(QUANTITIES), True)):
        panel_figure(layout, rows * blocks, cols, (13.0, 4.0), log, block_rows=rows, used=len(fams))
    for n in (1, 2):
        panel_figure("work", 1, n, (13.0, 4.0), log=True, outer=False)
    with matplotlib.rc_context({"text.hinting": "no_hinting"}):
        for text in [f"{10.0 ** e:.0e}" for e in range(-18, 0)] + ["1"]:   # the log panels' decades
            stamp(REPORT_DPI, text, TICK_PT, ha="right", va="center_baseline")
            stamp(REPORT_DPI, text, TICK_PT, ha="center", va="top")
    styles = variant_styles(res.variants)
    for markers in (False, True):
        for fam, items in legend_entries(fams, styles, markers=markers).items():
            legend_pixels(REPORT_DPI, fam, items)

_DRAW = {"trajectories": fig_trajectories, "errors": fig_errors, "conservation": fig_conservation,
         "convergence": lambda r, s, st, p: fig_ladder(r, s, st, p, "free_running"),
         "local": lambda r, s, st, p: fig_ladder(r, s, st, p, "one_step"), "work": fig_work}


def figure_tasks(res, sc) -> list:
    """The figures scenario ``sc`` may have (each decides when drawn whether it carries anything)."""
    return [(sc, k) for k in KINDS]


#: Relative drawing cost of one panel of each kind (CPU time per panel, trajectories = 1).
_PANEL_COST = {"convergence": 1.9, "local": 1.9, "trajectories": 1.0,
               "errors": 1.0, "conservation": 1.0, "work": 1.8}


def relative_cost(res, sc, kind) -> float:
    """A cheap estimate of the time figure ``kind`` of ``sc`` takes to draw (panels × cost per panel),
    to hand out the largest figures first."""
    info = res.scenario(sc)
    varies = {q: info.get("varies", {}).get(q, True) for q in QUANTITIES}
    n_fam = len(families(res.variants))
    rows = {"trajectories": 3 * varies["position"] + 4 * varies["orientation"], "work": 2 / max(n_fam, 1),
            "conservation": sum(bool(c.get("conserved")) for c in info.get("conserved", {}).values())
            }.get(kind, sum(varies.values()))
    return _PANEL_COST[kind] * max(rows, 1) * n_fam * (1 + 0.1 * len(res.variants))


def draw(res, sc, kind, plot_dir) -> tuple:
    """Draw one figure into ``plot_dir``; returns ``(kind, filename or None, note)``."""
    from cross_checks.sweep.results_dir import inside
    name = figure_name(sc, kind)
    ok = _DRAW[kind](res, sc, variant_styles(res.variants), inside(plot_dir, name))
    return kind, (name if ok else None), NOTES.pop((sc, kind), "")