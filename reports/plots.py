"""PNG figures of one scenario, drawn from the saved results only (one idea per figure).

Small multiples: one column per engine family (more than MAX_COLUMNS wrap into blocks of rows), one row
per quantity sharing its y axis, each variant in its one style (``variant_styles``), one legend per
family under the panels; what is drawn, marked or left out: docs/results.md, "The report" (Figures).

Figures (``plots/<scenario>__<kind>.png``):

``trajectories``   the moving position / orientation components vs time, with the reference
``errors``         error vs time (log–log), every moving quantity, at the default Δt
``conservation``   |relative drift| of energy / angular momentum / linear momentum vs time (log–log)
``convergence``    final error vs Δt (log-log) with the fitted points and slope triangles (ladders only)
``local``          one-step (local) error vs Δt (log-log), same layout (ladders only)
``work``           work-precision: final error vs wall time, every variant on one axis (ladders only)

(The polhode figure, ``plots/<scenario>__polhode.png``, is reports.polhode's: it draws with these styles.)

``figure_tasks(res, sc)`` lists the figures a scenario has (so they can be drawn in parallel);
``draw(res, sc, kind, path)`` draws one and returns whether it carried anything.

Drawn with matplotlib's public API on the Agg canvas, margins in inches; a drawing process keeps one
figure per layout and empties it for the next (same pixels as a fresh one: tests/reports/test_plots.py).
How the drawing is kept fast (``_Frame``, ``_stamp``, ``_Curves``): docs/speed.md, "The report".
"""
from __future__ import annotations

import math
import textwrap

import matplotlib
import numpy as np
from matplotlib.artist import Artist
from matplotlib.backends.backend_agg import FigureCanvasAgg, RendererAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.markers import MarkerStyle
from matplotlib.path import Path as MplPath
from matplotlib.text import Text
from matplotlib.ticker import FixedFormatter, FixedLocator, LogFormatter, LogLocator, MaxNLocator, NullLocator
from matplotlib.transforms import Bbox, IdentityTransform

from cross_checks.core.quantities import COLUMN_STEM, QUANTITIES, UNITS
from reference_sim.quaternion import sign_continuous
from reports.data import LABELS
from reports.glance import families, order_text

__all__ = ["KINDS", "figure_tasks", "draw", "families", "variant_styles", "NOTES", "save_png",
           "prepare", "release", "DataStamps", "figure_legend", "diverged_at", "legend_entries",
           "figure_name", "relative_cost", "MAX_COLUMNS", "REPORT_DPI"]

KINDS = ("trajectories", "errors", "conservation", "convergence", "local", "work")
DPI = 100            # rbcheck check --plot (reports.check_plot)
REPORT_DPI = 90      # the report's figures: up to 13 in wide, 1170 px, fits a 1400 px page without scaling
#: Errors of exactly zero cannot be drawn on a log axis; they are drawn at this value (and said so).
LOG_FLOOR = 1e-17
_MARKERS = "osD^vP*Xh<>p"
#: What a figure left out, by (scenario, kind): filled while drawing, read by the page's caption.
NOTES: dict = {}


#: One hue per engine family (in the order the families come), distinct from the reference's grey; a
#: family's variants are shades of its hue (dark to light), each with its own marker and dash pattern.
FAMILY_HUES = ("#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#17becf",
               "#bcbd22", "#393b79", "#637939", "#252525")
_DASHES = ("-", "--", "-.", ":")


def _shade(hex_color, f):
    """``hex_color`` darkened (f < 0, towards black) or lightened (f > 0, towards white) by |f|."""
    rgb = np.array(matplotlib.colors.to_rgb(hex_color))
    rgb = rgb * (1 + f) if f < 0 else rgb + (1 - rgb) * f
    return tuple(float(c) for c in np.clip(rgb, 0.0, 1.0))


def variant_styles(variants) -> dict:
    """A colour, dash pattern and marker per variant, the same in every figure of a report (they depend on
    the list of variants only): the family's hue, a shade per variant from dark to light, and a marker
    and dash pattern by its place in its family."""
    out = {}
    for k, vs in enumerate(families(variants).values()):
        hue = FAMILY_HUES[k % len(FAMILY_HUES)]
        n = len(vs)
        for i, v in enumerate(vs):
            f = 0.0 if n == 1 else -0.35 + 0.8 * i / (n - 1)
            out[v] = {"color": _shade(hue, f), "ls": _DASHES[i % len(_DASHES)],
                      "marker": _MARKERS[i % len(_MARKERS)]}
    return out


def _short(v):
    return v.split(":", 1)[1] if ":" in v else v


# --- text drawn once per process ------------------------------------------------------------------------
#: Text bitmaps by (dpi, text, size, alignment, rotation, weight, colour), each drawn once by matplotlib.
_STAMPS: dict = {}
_SCRATCH: dict = {}   # dpi -> (figure the Text artists belong to, a renderer to measure them with)


def _stamp(dpi, text, size, ha="left", va="baseline", rotation=0, weight="normal", color="black"):
    """(pixels, x0, y0, width, height) of ``text`` drawn by matplotlib, unhinted: RGBA rows bottom row
    first, the image's lower left corner (x0, y0) px from the text's anchor (its ``ha``/``va`` point,
    rotated about it as matplotlib's y labels are), and the text's own extent (w, h px)."""
    key = (dpi, text, size, ha, va, rotation, weight, color)
    got = _STAMPS.get(key)
    if got is None:
        if dpi not in _SCRATCH:
            fig = Figure(figsize=(1.0, 1.0), dpi=dpi)
            FigureCanvasAgg(fig)
            _SCRATCH[dpi] = (fig, RendererAgg(8, 8, dpi))
        fig, probe = _SCRATCH[dpi]
        t = Text(0.0, 0.0, text, fontsize=size, ha=ha, va=va, rotation=rotation, rotation_mode="anchor",
                 fontweight=weight, color=color, transform=IdentityTransform())
        t.set_figure(fig)
        if matplotlib.rcParams["text.hinting"] == "no_hinting":   # drawing a figure (save_png): as it is
            got = _STAMPS[key] = _stamp_pixels(t, probe, dpi)
        else:                                                     # (an rc_context copies every setting)
            with matplotlib.rc_context({"text.hinting": "no_hinting"}):
                got = _STAMPS[key] = _stamp_pixels(t, probe, dpi)
    return got


def _stamp_pixels(t, probe, dpi) -> tuple:
    box = t.get_window_extent(probe)
    x0, y0 = math.floor(box.x0) - 2, math.floor(box.y0) - 2      # 2 px for antialiased edges
    r = RendererAgg(math.ceil(box.x1) + 2 - x0, math.ceil(box.y1) + 2 - y0, dpi)
    t.set_position((-x0, -y0))
    t.draw(r)
    return np.asarray(r.buffer_rgba())[::-1].copy(), x0, y0, box.width, box.height


def _place(renderer, gc, dpi, x, y, text, size, **style) -> Bbox:
    """Draw ``text`` (:func:`_stamp`) with its anchor at display pixel (x, y); returns its extent."""
    img, x0, y0, w, h = _stamp(dpi, text, size, **style)
    left, bottom = round(x) + x0, round(y) + y0
    renderer.draw_image(gc, left, bottom, img)
    return Bbox.from_bounds(left + 2, bottom + 2, w, h)


class _Stamps(Artist):
    """Texts (:func:`_stamp`) at display pixels: ``items`` [(x, y, text, size, style)]."""

    def __init__(self, items):
        super().__init__()
        self.items = items

    def draw(self, renderer):
        if not self.get_visible():
            return
        gc = renderer.new_gc()
        for x, y, text, size, style in self.items:
            _place(renderer, gc, self.get_figure(root=True).dpi, x, y, text, size, **style)
        gc.restore()


class _DataStamps(Artist):
    """Texts (:func:`_stamp`) at data coordinates of their axes, over the curves as an ``ax.text`` is:
    ``items`` [(x, y, text, size, style)]."""

    zorder = 3

    def __init__(self, items):
        super().__init__()
        self.items = items

    def draw(self, renderer):
        if not self.get_visible() or self.axes is None:
            return
        dpi = self.get_figure(root=True).dpi
        gc = renderer.new_gc()
        for x, y, text, size, style in self.items:
            px, py = self.axes.transData.transform((x, y))
            _place(renderer, gc, dpi, px, py, text, size, **style)
        gc.restore()


def _ticks(axis, labels=True):
    """(display positions, labels) of ``axis``'s major ticks inside its view, as matplotlib draws them
    (the locator's ticks, the formatter's labels)."""
    locs = np.asarray(axis.get_major_locator()(), dtype=float)
    lo, hi = sorted(axis.get_view_interval())
    tol = 1e-10 * (hi - lo)
    if axis.get_scale() == "log":
        tol = 0.0
    locs = locs[(locs >= lo - tol) & (locs <= hi + tol)]
    texts = axis.get_major_formatter().format_ticks(locs) if labels and locs.size else [""] * len(locs)
    ax = axis.axes
    if axis is ax.xaxis:
        pix = ax.transData.transform(np.column_stack([locs, np.ones_like(locs)]))[:, 0] if locs.size else locs
    else:
        pix = ax.transData.transform(np.column_stack([np.ones_like(locs), locs]))[:, 1] if locs.size else locs
    return pix, texts


class _Frame(Artist):
    """A panel's grid lines (one path at the major ticks), tick labels, axis labels and title, drawn by
    one artist as :func:`_stamp` images at matplotlib's places (the axes' axis artists are hidden). Tick
    labels where the tick parameters say (``labelbottom``, ``labelleft``); the labels' texts and sizes
    are the axes' own (``set_xlabel``, ``set_ylabel``)."""

    zorder = 0.5

    def __init__(self):
        super().__init__()
        self.title = ""
        self.x_size = _TICK_PT

    def draw(self, renderer):
        ax = self.axes
        if not self.get_visible():
            return
        dpi = self.get_figure(root=True).dpi
        pt = dpi / 72.0
        box = ax.bbox
        bottom = ax.xaxis.get_tick_params().get("labelbottom", True)
        left = ax.yaxis.get_tick_params().get("labelleft", True)
        xs, xlabels = _ticks(ax.xaxis, bottom)
        ys, ylabels = _ticks(ax.yaxis, left)
        gc = renderer.new_gc()
        segs = [((x, box.y0), (x, box.y1)) for x in xs] + [((box.x0, y), (box.x1, y)) for y in ys]
        if segs:
            codes = [MplPath.MOVETO, MplPath.LINETO] * len(segs)
            gc.set_foreground((0.690, 0.690, 0.690, 0.3), isRGBA=True)      # #b0b0b0 at alpha 0.3
            gc.set_linewidth(0.8)
            renderer.draw_path(gc, MplPath(np.array(segs, dtype=float).reshape(-1, 2), codes),
                               IdentityTransform())
        gc.restore()
        gc = renderer.new_gc()
        for x, text in zip(xs, xlabels):
            if text:
                _place(renderer, gc, dpi, x, box.y0 - _TICK_PAD_PT * pt, text, self.x_size, ha="center",
                       va="top")
        for y, text in zip(ys, ylabels):
            if text:
                _place(renderer, gc, dpi, box.x0 - _TICK_PAD_PT * pt, y, text, _TICK_PT, ha="right",
                       va="center_baseline")
        x_offset = (box.x1, box.y0 - (_TICK_PAD_PT + 1.2 * self.x_size) * pt, "right", "top")
        for axis, offset in ((ax.xaxis, x_offset), (ax.yaxis, (box.x0, box.y1 + _TITLE_PAD_PT * pt, "left",
                                                               "baseline"))):
            shown = bottom if axis is ax.xaxis else left
            extra = axis.get_major_formatter().get_offset() if shown else ""
            if extra:
                _place(renderer, gc, dpi, offset[0], offset[1], extra, _TICK_PT, ha=offset[2], va=offset[3])
        xl, yl = ax.xaxis.label, ax.yaxis.label
        if xl.get_text():
            _place(renderer, gc, dpi, (box.x0 + box.x1) / 2, box.y0 - _XLABEL_PT * pt, xl.get_text(),
                   xl.get_fontsize(), ha="center", va="top")
        if yl.get_text():
            _place(renderer, gc, dpi, box.x0 - _YLABEL_PT * pt, (box.y0 + box.y1) / 2, yl.get_text(),
                   yl.get_fontsize(), ha="center", va="bottom", rotation=90)
        if self.title:
            _place(renderer, gc, dpi, box.x0, box.y1 + _TITLE_PAD_PT * pt, self.title, 10.0)
        gc.restore()


def _frame(ax) -> _Frame:
    return next(a for a in ax.artists if isinstance(a, _Frame))


_FIGURES: dict = {}   # (layout, columns, log, outer) -> (figure, rows of axes): kept per drawing process
#: Tick labels' size (pt) and the axis labels' fixed distances from their axes (pt), so that no tick
#: label need be measured to place them: y label left of the widest tick label drawn ("1e-15",
#: "−0.25": 5 characters of ~0.6 em) plus tick (3.5 pt), pad (3.5 pt) and 4 pt; x label under the tick,
#: pad, one line of tick labels (1.2 em) and 3 pt. Tick labels sit tick + pad (7 pt) off their axes, a
#: title 4 pt above its panel (matplotlib's places).
_TICK_PT = 10.0
_TICK_PAD_PT = 3.5 + 3.5
_TITLE_PAD_PT = 4.0
_YLABEL_PT = 5 * 0.6 * _TICK_PT + 3.5 + 3.5 + 4.0
_XLABEL_PT = 3.5 + 3.5 + 1.2 * _TICK_PT + 3.0


def _panels(layout, nrows, ncols, size_in, log, outer=True, block_rows=None, used=None, spacer=0.0):
    """A figure of ``nrows`` × ``ncols`` panels (log x and y scales when ``log``), emptied of any previous
    drawing and resized to ``size_in`` (w, h inches); kept per layout, surplus rows hidden. With
    ``outer`` only the bottom row has x tick labels and the first column y tick labels (callers then
    share limits: :func:`_same_limits`). ``block_rows``: the rows are blocks of that many (the bottom row
    of each has x tick labels); ``used``: the panels of a row of blocks that are shown; ``spacer``: the
    height of an empty row between two blocks, relative to a panel's."""
    block_rows = block_rows or nrows
    n_blocks = nrows // block_rows
    at = lambda i: i + i // block_rows       # noqa: E731 - a panel row's grid row (spacers between blocks)
    key = (layout, ncols, log, outer)
    fig, rows = _FIGURES.setdefault(key, (Figure(dpi=REPORT_DPI), []))
    if not isinstance(fig.canvas, FigureCanvasAgg):
        FigureCanvasAgg(fig)
    if n_blocks > 1:
        ratios = [x for b in range(n_blocks)
                  for x in [1.0] * block_rows + ([spacer] if b < n_blocks - 1 else [])]
        grid = fig.add_gridspec(len(ratios), ncols, height_ratios=ratios)
    else:
        grid = fig.add_gridspec(nrows, ncols)
    while len(rows) < nrows:
        rows.append([fig.add_subplot(grid[at(len(rows)), j]) for j in range(ncols)])
        for j, ax in enumerate(rows[-1]):
            _style(ax, log, left=j == 0 or not outer)
    for i, row in enumerate(rows):
        for j, ax in enumerate(row):
            shown = i < nrows and (used is None or (i // block_rows) * ncols + j < used)
            ax.set_visible(shown)
            if i < nrows:
                ax.set_subplotspec(grid[at(i), j])
            bottom = i % block_rows == block_rows - 1 or not outer
            if ax.xaxis.get_tick_params().get("labelbottom") != bottom:   # tick_params restyles every tick
                ax.tick_params(axis="x", labelbottom=bottom)
            for art in (*ax.lines, *ax.collections, *ax.texts,
                        *[a for a in ax.artists if isinstance(a, _DataStamps)]):
                art.remove()
            ax.set(xlabel="", ylabel="")
            frame = _frame(ax)
            frame.title, frame.x_size = "", _TICK_PT
            ax.relim()
            ax.set_autoscale_on(True)
    for art in (*fig.images, *fig.texts, *fig.legends):   # titles, legends
        art.remove()
    fig.set_size_inches(*size_in)
    return fig, np.array(rows[:nrows], dtype=object)


def _style(ax, log, left) -> None:
    """Plain decade labels ("1e-06", not mathtext) and no minor ticks on log axes, at most 5 ticks on
    linear ones; no tick marks; grid, labels and title drawn by a :class:`_Frame`."""
    ax.patch.set_visible(False)   # white on the figure's white
    ax.tick_params(labelsize=_TICK_PT, labelleft=left, bottom=False, left=False)
    ax.xaxis.set_visible(False)
    ax.yaxis.set_visible(False)
    ax.add_artist(_Frame())
    if log:
        ax.set_xscale("log")
        ax.set_yscale("log")
    for axis in (ax.xaxis, ax.yaxis):
        if log:
            axis.set_major_locator(LogLocator(base=10.0, numticks=6))
            axis.set_major_formatter(LogFormatter(labelOnlyBase=True))
            axis.set_minor_locator(NullLocator())
        else:
            axis.set_major_locator(MaxNLocator(nbins=4))


def _same_limits(axes, which, lim=None) -> None:
    """One range over ``axes``, as shared axes would have: ``lim``, or the union of the panels' own."""
    axes = list(axes)
    lims = [lim] if lim is not None else [ax.get_xlim() if which == "x" else ax.get_ylim() for ax in axes
                                          if ax.has_data()]
    if not lims:
        return
    lo, hi = min(lo for lo, _ in lims), max(hi for _, hi in lims)
    for ax in axes:
        ax.set_xlim(lo, hi) if which == "x" else ax.set_ylim(lo, hi)


def _title(ax, text) -> None:
    """A panel's title at the left, at a fixed height (:class:`_Frame`)."""
    _frame(ax).title = text


def prepare(res) -> None:
    """Build, before the drawing processes are forked, what each would build for itself: the grids of
    panels of each layout of ``res``'s figures (as many rows as a figure can have), the decade labels
    and the legends without orders."""
    fams = families(res.variants)
    blocks, cols = _blocks(len(fams))
    for layout, rows, log in (("time", 7, False), ("time-log", len(QUANTITIES), True),
                              ("ladder", len(QUANTITIES), True)):
        _panels(layout, rows * blocks, cols, (13.0, 4.0), log, block_rows=rows, used=len(fams))
    for n in (1, 2):
        _panels("work", 1, n, (13.0, 4.0), log=True, outer=False)
    with matplotlib.rc_context({"text.hinting": "no_hinting"}):
        for text in [f"{10.0 ** e:.0e}" for e in range(-18, 0)] + ["1"]:   # the log panels' decades
            _stamp(REPORT_DPI, text, _TICK_PT, ha="right", va="center_baseline")
            _stamp(REPORT_DPI, text, _TICK_PT, ha="center", va="top")
    styles = variant_styles(res.variants)
    for markers in (False, True):
        for fam, items in legend_entries(fams, styles, markers=markers).items():
            _legend_pixels(REPORT_DPI, fam, items)


def release() -> None:
    """Drop the figures and legends this process keeps (a caller that drew in its own process does not
    keep them)."""
    _FIGURES.clear()
    _LEGENDS.clear()
    _STAMPS.clear()


_TITLE_CHARS_PER_IN = 12


#: At most this many family columns side by side; more families wrap into blocks of rows.
MAX_COLUMNS = 5
#: Vertical gap between two blocks of rows (inches): x tick labels, x label, the next block's titles.
_BLOCK_GAP_IN = 0.85


def _blocks(nfam) -> tuple:
    """(blocks, columns) of a grid of ``nfam`` family columns: as few blocks as MAX_COLUMNS allows, the
    families spread evenly over them."""
    blocks = max(1, math.ceil(nfam / MAX_COLUMNS))
    return blocks, max(1, math.ceil(nfam / blocks))


def _grid(nrows, nfam, title, panel_h=2.1, log=False, layout="time", legend=None):
    """A grid of ``nrows`` quantity rows × ``nfam`` family columns under a title (families wrap into blocks
    of at most MAX_COLUMNS columns), with the figure's legend (:func:`_figure_legend` entries) under it;
    margins in inches. Returns (figure, axes[row, family])."""
    blocks, cols = _blocks(nfam)
    w = min(13.0, 2.2 + 3.6 * cols)
    axes_h = (panel_h * nrows - 0.15) / (nrows + 0.35 * (nrows - 1))
    gap = 0.35 * axes_h
    spacer = max(_BLOCK_GAP_IN - 2 * gap, 0.05) if blocks > 1 else 0.0    # between blocks: x labels, titles
    fig, phys = _panels(layout, nrows * blocks, cols, (w, 4.0), log, block_rows=nrows, used=nfam,
                        spacer=spacer / axes_h)
    leg_h = _figure_legend(fig, w, legend) if legend else 0.0
    strip = leg_h + 0.15 if legend else 0.0
    n_grid = nrows * blocks + blocks - 1
    area = axes_h * nrows * blocks + spacer * (blocks - 1) + gap * (n_grid - 1)
    # wrapped to the figure's width (≈ 12 characters per inch at 11 pt): a one-column figure is 5.8 in wide
    title = textwrap.fill(title, width=int(w * _TITLE_CHARS_PER_IN))
    extra = 0.2 * title.count("\n")
    h = 0.75 + extra + area + 0.5 + strip
    fig.set_size_inches(w, h)
    fig.suptitle(title, fontsize=11, x=0.01, ha="left")
    mean_cell = (area - gap * (n_grid - 1)) / n_grid
    fig.subplots_adjust(left=0.09 if w > 8 else 0.14, right=0.98, top=1.0 - (0.75 + extra) / h,
                        bottom=(0.5 + strip) / h, hspace=gap / mean_cell, wspace=0.08)
    axes = np.empty((nrows, nfam), dtype=object)
    for j in range(nfam):
        b, c = divmod(j, cols)
        axes[:, j] = phys[b * nrows:(b + 1) * nrows, c]
    return fig, axes


def _ylabel(axes, i, text) -> None:
    """Row ``i``'s y label on the first panel of each block of family columns."""
    for j in range(0, axes.shape[1], _blocks(axes.shape[1])[1]):
        axes[i, j].set_ylabel(text, fontsize=8)


#: The legend's font size (pt) and the figure's left margin for it (inches).
_LEGEND_PT = 8.5
_LEGEND_X_IN = 0.1


def legend_entries(fams, styles, extra=None, markers=True) -> dict:
    """The entries of a figure's legends: ``{family: [(label, style)]}``, each variant's short name (and
    ``extra[v]``) with its colour, dash pattern and (when ``markers``) marker."""
    out = {}
    for fam, vs in fams.items():
        out[fam] = [(_short(v) + (f"  {extra[v]}" if extra and extra.get(v) else ""),
                     {**styles[v], "marker": styles[v]["marker"] if markers else None}) for v in vs]
    return out


_LEGENDS: dict = {}   # a family's legend -> its pixels (RGBA, transparent background), per process
#: A family's legend has at most this many rows (more variants: more columns).
_LEGEND_ROWS = 4
_LEGEND_GAP_IN = 0.3
#: Transparent margin around a legend's pixels (px): antialiased edges of its text are not cut.
_LEGEND_PAD_PX = 2


class LegendBoxes:
    """Where :func:`legend_figure` put a legend's texts: ``texts`` [(text, extent)], display pixels of
    its figure, the title first; ``get_window_extent()`` the extent of the whole legend."""

    def __init__(self, texts, extent):
        self.texts, self.extent = texts, extent

    def get_window_extent(self, renderer=None) -> Bbox:
        return self.extent


def legend_figure(dpi, fam, items):
    """A family's legend (its name in bold, its variants' lines, markers and names in columns of at most
    _LEGEND_ROWS, spaced as matplotlib's ``Legend``: handles 2.6 em long, 0.5 em to the text, 1.2 em
    between columns, 0.25 em between rows), laid out from the texts' measured extents (:func:`_stamp`)
    on a transparent figure sized to them plus _LEGEND_PAD_PX, so nothing is cut. Returns (figure,
    :class:`LegendBoxes`)."""
    pt = dpi / 72.0
    em = _LEGEND_PT * pt
    pad = _LEGEND_PAD_PX
    title = _stamp(dpi, fam, 9, va="top", weight="bold")
    # a label "name  extra" is drawn as two texts, the extra (a ladder's orders) where it would be in the
    # whole label: texts' widths add up (advances), the two spaces measured once
    parts = [label.partition("  ")[::2] for label, _ in items]
    text = lambda t: _stamp(dpi, t, _LEGEND_PT, va="center_baseline")   # noqa: E731
    stamps = [(text(name), text(extra) if extra else None) for name, extra in parts]
    sep = text("a  p")[3] - text("a")[3] - text("p")[3] if any(extra for _, extra in parts) else 0.0
    labels = [(a[3] + (sep + b[3] if b else 0.0), max(a[4], b[4] if b else 0.0)) for a, b in stamps]
    row_h = max([h for _, h in labels] + [1.0])
    ncols = max(1, math.ceil(len(items) / _LEGEND_ROWS))
    nrows = min(len(items), _LEGEND_ROWS)
    handle, gap, col_gap, row_gap = 2.6 * em, 0.5 * em, 1.2 * em, 0.25 * em
    columns = [range(c * _LEGEND_ROWS, min(len(items), (c + 1) * _LEGEND_ROWS)) for c in range(ncols)]
    widths = [handle + gap + max([labels[k][0] for k in col] + [0.0]) for col in columns]
    w = math.ceil(2 * pad + max(title[3], sum(widths) + col_gap * (ncols - 1)))
    top_rows = title[4] + 0.5 * em
    h = math.ceil(2 * pad + top_rows + nrows * row_h + max(nrows - 1, 0) * row_gap)
    fig = Figure(figsize=(w / dpi, h / dpi), dpi=dpi, facecolor="none")
    FigureCanvasAgg(fig)
    texts = [(pad, h - pad, fam, 9, {"va": "top", "weight": "bold"})]
    x = float(pad)
    for c, col in enumerate(columns):
        for r, k in enumerate(col):
            y = h - pad - top_rows - r * (row_h + row_gap) - row_h / 2
            st = items[k][1]
            fig.add_artist(Line2D([x, x + handle / 2, x + handle], [y, y, y], color=st["color"], ls=st["ls"],
                                  lw=1.4, marker=st.get("marker") or None, ms=4, markevery=[1],
                                  transform=IdentityTransform()))
            name, extra = parts[k]
            texts.append((x + handle + gap, y, name, _LEGEND_PT, {"va": "center_baseline"}))
            if extra:
                texts.append((x + handle + gap + stamps[k][0][3] + sep, y, extra, _LEGEND_PT,
                              {"va": "center_baseline"}))
        x += widths[c] + col_gap
    fig.add_artist(_Stamps(texts))
    boxes = []
    for tx, ty, text, size, style in texts:
        _, x0, y0, bw, bh = _stamp(dpi, text, size, **style)
        boxes.append((text, Bbox.from_bounds(round(tx) + x0 + 2, round(ty) + y0 + 2, bw, bh)))
    extent = Bbox.union([b for _, b in boxes])
    return fig, LegendBoxes(boxes, extent)


def _legend_pixels(dpi, fam, items) -> np.ndarray:
    """The pixels of :func:`legend_figure`, drawn once per process."""
    key = (dpi, fam, tuple((label, st["color"], st["ls"], st.get("marker")) for label, st in items))
    if key not in _LEGENDS:
        with matplotlib.rc_context({"text.hinting": "no_hinting"}):
            fig, _ = legend_figure(dpi, fam, items)
            fig.canvas.draw()
        _LEGENDS[key] = np.asarray(fig.canvas.buffer_rgba()).copy()
    return _LEGENDS[key]


def _figure_legend(fig, width_in, entries) -> float:
    """The figure's legends under its panels, one per family (:func:`legend_figure`), left to right and
    wrapped to ``width_in``, none cut or overlapping; placed as images (FigureImage, labelled with the
    family's name) in pixels from the figure's bottom, so that a later height does not move them.
    Returns the height they take (inches)."""
    placed, x, y, line_h = [], _LEGEND_X_IN * fig.dpi, 0.0, 0.0
    limit = (width_in - _LEGEND_X_IN) * fig.dpi
    for fam, items in entries.items():
        pix = _legend_pixels(fig.dpi, fam, items)
        h, w = pix.shape[:2]
        if x > _LEGEND_X_IN * fig.dpi and x + w > limit:     # wrap to a new line
            x, y, line_h = _LEGEND_X_IN * fig.dpi, y + line_h + 0.12 * fig.dpi, 0.0
        placed.append((fam, pix, x, y))
        x, line_h = x + w + _LEGEND_GAP_IN * fig.dpi, max(line_h, h)
    total = math.ceil(y + line_h + 0.05 * fig.dpi)
    for fam, pix, lx, ly in placed:      # ly: from the top of the legends' strip down
        fig.figimage(pix, xo=round(lx), yo=total - round(ly) - pix.shape[0], origin="upper").set_label(fam)
    return total / fig.dpi


def save_png(fig, path) -> None:
    """Save as an 8-bit palette PNG (no dithering), unhinted text; deterministic for equal input."""
    from PIL import Image
    canvas = fig.canvas if isinstance(fig.canvas, FigureCanvasAgg) else FigureCanvasAgg(fig)
    with matplotlib.rc_context({"text.hinting": "no_hinting"}):
        canvas.draw()
    w, h = canvas.get_width_height(physical=True)
    im = Image.frombuffer("RGBA", (w, h), canvas.buffer_rgba(), "raw", "RGBA", 0, 1).convert("RGB")
    q = im.quantize(colors=256, method=Image.Quantize.FASTOCTREE, dither=Image.Dither.NONE)
    q.save(path, format="PNG", compress_level=6)


def _dashes(ls, lw) -> tuple:
    """(offset, dash lengths in pt) of dash pattern ``ls`` at line width ``lw``, as a Line2D has them (the
    rc patterns, scaled by the width when ``lines.scale_dashes``)."""
    name = {"-": "solid", "--": "dashed", "-.": "dashdot", ":": "dotted"}.get(ls, ls)
    if name == "solid":
        return 0.0, None
    dashes = tuple(matplotlib.rcParams[f"lines.{name}_pattern"])
    if matplotlib.rcParams["lines.scale_dashes"]:
        dashes = tuple(d * lw for d in dashes)
    return 0.0, dashes


class _Curves(Line2D):
    """A panel's variants in one artist. ``parts``, drawn in their order: ``("line", x, y, rgba, dash
    pattern, width)`` and ``("marks", x, y, marker, size pt, face rgba, edge rgba)``, each with the
    renderer calls a Line2D of that style makes (caps, joins, dashes, marker snapping, 1 pt marker
    edges), clipped to the axes; with ``capstyle`` every line has those caps. As a Line2D of all their
    points (drawing nothing of its own) it gives the axes their data limits."""

    def __init__(self, parts, capstyle=None, **kwargs):
        pts = [np.column_stack([np.asarray(x, dtype=float), np.asarray(y, dtype=float)])
               for _, x, y, *_ in parts]
        xy = np.concatenate(pts) if pts else np.zeros((0, 2))
        super().__init__(xy[:, 0], xy[:, 1], ls="none", marker="none", **kwargs)
        self.parts, self.capstyle = parts, capstyle

    def draw(self, renderer):
        if not self.get_visible() or self.axes is None:
            return
        trans, clip = self.axes.transData, self.axes.bbox
        for what, x, y, *style in self.parts:
            gc = renderer.new_gc()
            gc.set_clip_rectangle(clip)
            gc.set_antialiased(True)
            path = MplPath(trans.transform(np.column_stack([x, y])))
            if what == "line":
                rgba, ls, lw = style
                gc.set_linewidth(lw)
                gc.set_joinstyle("round")
                gc.set_capstyle(self.capstyle or ("projecting" if ls == "-" else "butt"))
                gc.set_foreground(rgba, isRGBA=True)
                gc.set_dashes(*_dashes(ls, lw))
                renderer.draw_path(gc, path, IdentityTransform())
            else:
                marker, ms, face, edge = style
                mark = _marker_style(marker)
                w = renderer.points_to_pixels(ms)
                gc.set_linewidth(1.0)
                gc.set_foreground(edge, isRGBA=True)
                snap = mark.get_snap_threshold()
                gc.set_snap(w >= snap if isinstance(snap, (int, float)) else snap)
                gc.set_joinstyle(mark.get_joinstyle())
                gc.set_capstyle(mark.get_capstyle())
                renderer.draw_markers(gc, mark.get_path(), mark.get_transform().frozen().scale(w), path,
                                      IdentityTransform(), face)
            gc.restore()
        self.stale = False


_MARKER_STYLES: dict = {}


def _marker_style(marker) -> MarkerStyle:
    if marker not in _MARKER_STYLES:
        _MARKER_STYLES[marker] = MarkerStyle(marker)
    return _MARKER_STYLES[marker]


def _curves(ax, parts) -> None:
    """Add a panel's variants as one :class:`_Curves` (nothing when there are none)."""
    if parts:
        ax.add_line(_Curves(parts))


def _line(ax, x, y, **style):
    """One Line2D of the given style added to ``ax`` (not autoscaled: the panel is, when done)."""
    return ax.add_line(Line2D(np.asarray(x, dtype=float), np.asarray(y, dtype=float), **style))


def _positive(a):
    a = np.asarray(a, dtype=float)
    return np.where(a > 0, a, LOG_FLOOR)


def _diverged(res, sc, v):
    """The time a run at the default Δt diverged (s), or None."""
    d = res.default_row(sc, v)
    if d is None or d["status"] != "diverged":
        return None
    t = d.get("diverged_at_s", math.nan)
    return t if isinstance(t, float) and math.isfinite(t) else math.inf


def _robust_limits(curves, log):
    """y limits from the finite values of the runs that did not diverge (None when there are none)."""
    vals = [np.asarray(c, dtype=float) for c in curves]
    vals = [c[np.isfinite(c)] for c in vals]
    vals = [c[c > 0] if log else c for c in vals]
    vals = [c for c in vals if c.size]
    if not vals:
        return None
    lo, hi = min(float(c.min()) for c in vals), max(float(c.max()) for c in vals)
    if log:
        return lo / 3.0, hi * 10.0
    pad = 0.08 * (hi - lo) if hi > lo else 0.05 * max(1.0, abs(hi))
    return lo - pad, hi + pad


def _time_panels(axes, res, sc, fams, styles, rows, log, ser=None):
    """Draw ``rows`` = [(label, fn(series) -> y or None)] × family columns; diverged runs truncated and
    marked; a row's panels get one y range (from the runs that did not diverge). Curves that coincide
    (:func:`coinciding`) are drawn so that both are seen; returns them ["a = b (row)"] for the caption."""
    ser = res.series(sc) if ser is None else ser
    same = []
    for i, (label, get) in enumerate(rows):
        keep, every = [], []
        for j, (fam, vs) in enumerate(fams.items()):
            ax = axes[i, j]
            curves = []   # (xy, style): the panel's variants, drawn as one artist (_Curves)
            ref = ser.get("reference")
            if not log and ref is not None and get(ref) is not None:
                _line(ax, ref["t_s"], get(ref), color="black", lw=3.2, alpha=0.28)
                keep.append(get(ref))
            for v in vs:
                if v not in ser or get(ser[v]) is None:
                    continue
                t, y = ser[v]["t_s"], np.asarray(get(ser[v]), dtype=float)
                tdiv = _diverged(res, sc, v)
                ok = np.isfinite(y) & np.isfinite(t) & ((t > 0) if log else True)   # log t: no t = 0
                if tdiv is not None:
                    ok &= t <= tdiv
                y_draw = _positive(y) if log else y
                st = styles[v]
                if ok.any():
                    curves.append((np.column_stack([t[ok], y_draw[ok]]), {**st, "name": v}))
                every.append(y_draw[ok])
                if tdiv is not None and ok.any():
                    k = np.flatnonzero(ok)[-1]
                    _line(ax, [t[k]], [y_draw[k]], marker="x", ms=9, mew=2, color=st["color"], zorder=3)
                else:
                    keep.append(y[ok])
            if curves:
                span = np.ptp(np.concatenate([xy[:, 1] for xy, _ in curves])) if not log else None
                pairs = coinciding([(st["name"], xy[:, 0], xy[:, 1]) for xy, st in curves], log, span)
                halo = {b for _, b in pairs}
                same += [(a, b, label.split(" (")[0]) for a, b in pairs]
                wide = [(xy, st) for xy, st in curves if st["name"] in halo]
                if wide:    # under the others: a pale band around the curve it coincides with
                    ax.add_line(_Curves([("line", xy[:, 0], xy[:, 1], (*st["color"][:3], 0.5), "-", 3.6)
                                         for xy, st in wide], capstyle="butt", zorder=1.9))
                ax.add_line(_Curves([("line", xy[:, 0], xy[:, 1], (*st["color"][:3], 1.0), st["ls"], 1.1)
                                     for xy, st in curves], capstyle="butt"))
            if i == 0:
                _title(ax, fam)
            if ax.has_data():
                ax.autoscale_view()
        _same_limits(axes[i], "y", _robust_limits(keep, log) or _robust_limits(every, log))
        _ylabel(axes, i, label)
    _same_limits(axes.flat, "x")
    for ax in axes[-1]:
        ax.set_xlabel("time t (s)", fontsize=8)
    return same


def _families_with_series(res, ser) -> dict:
    """``{family: [variants]}`` of the variants that have saved series, families without any left out."""
    fams = {f: [v for v in vs if v in ser] for f, vs in families(res.variants).items()}
    return {f: vs for f, vs in fams.items() if vs}


def _moving_components(ser):
    """[(label, field, index)] of the components that move along the reference (or, without one,
    along any series); the rest is named in the returned note."""
    comps = ([(f"{c} (m)", "x_W", i) for i, c in enumerate("xyz")]
             + [(f"q{c}", "q_WB", i) for i, c in enumerate("wxyz")])
    src = [ser["reference"]] if "reference" in ser else list(ser.values())
    moving, still = [], []
    for label, fld, i in comps:
        vals = (np.concatenate([np.asarray(s[fld][:, i], dtype=float) for s in src if fld in s])
                if src else np.zeros(1))
        vals = vals[np.isfinite(vals)]
        span = float(vals.max() - vals.min()) if vals.size else 0.0
        if span > 1e-9 * max(1.0, float(np.abs(vals).max()) if vals.size else 1.0):
            moving.append((label, fld, i))
        else:
            still.append(f"{label.split()[0]} = {float(vals[0]) if vals.size else 0.0:.3g}")
    return moving, still


def _continuous_series(ser) -> dict:
    """The series with every q_WB sign-continuous, each starting on the reference's sign."""
    ref = ser.get("reference", {}).get("q_WB")
    first = None if ref is None or not len(ref) else sign_continuous(ref)[0]
    return {who: ({**f, "q_WB": sign_continuous(f["q_WB"], first)} if "q_WB" in f else f)
            for who, f in ser.items()}


def fig_trajectories(res, sc, styles, path):
    info = res.scenario(sc)
    ser = res.series(sc)
    fams = _families_with_series(res, ser)
    ser = _continuous_series(ser)
    moving, still = _moving_components(ser)
    if not fams or not moving:
        NOTES[(sc, "trajectories")] = "nothing moves" if not moving else "no series"
        return False
    rows = [(label, (lambda s, fld=fld, i=i: s[fld][:, i] if fld in s else None)) for label, fld, i in moving]
    fig, axes = _grid(len(rows), len(fams),
                      f"{sc}: trajectories at Δt = {info['dt_s']:g} s (thick grey: "
                      f"reference, {info['reference']})", panel_h=1.5,
                      legend=legend_entries(fams, styles, markers=False))
    same = _time_panels(axes, res, sc, fams, styles, rows, log=False, ser=ser)
    quat = (" Quaternions are drawn sign-continuous: q and −q are the same orientation, so each sample's "
            "sign is chosen to follow the previous one (a jump between them would be no motion)."
            if any(fld == "q_WB" for _, fld, _ in moving) else "")
    NOTES[(sc, "trajectories")] = ((("Not drawn, constant along the reference: " + ", ".join(still) + ".")
                                    if still else "") + quat + _same_note(same)).strip()
    save_png(fig, path)
    return True


def fig_errors(res, sc, styles, path):
    info = res.scenario(sc)
    ser = res.series(sc)
    fams = _families_with_series(res, ser)
    moving = [q for q in QUANTITIES if info.get("varies", {}).get(q, True)]
    nonzero = [q for q in moving if any(np.any(np.asarray(ser[v].get(f"err_{q}", [0.0])) > 0)
                                        for vs in fams.values() for v in vs)]
    exact = [q for q in nonzero if _series_at_roundoff(res, sc, q, [v for vs in fams.values() for v in vs])]
    shown = [q for q in nonzero if q not in exact]
    exact_note = (" Not drawn, every variant's error at or below its run's round-off floor all along (exact "
                  "to within what can be measured): " + ", ".join(LABELS[q] for q in exact)
                  + ".") if exact else ""
    if not fams or not shown:
        NOTES[(sc, "errors")] = ("every error is zero" if not exact else exact_note.strip())
        return False
    rows = [(f"{LABELS[q]} error ({UNITS[q]})", (lambda s, q=q: s.get(f"err_{q}"))) for q in shown]
    fig, axes = _grid(len(rows), len(fams),
                      f"{sc}: error against the reference vs time at Δt = {info['dt_s']:g} s "
                      f"(log scales; zero drawn at {LOG_FLOOR:g}; × marks a divergence)", log=True,
                      layout="time-log", legend=legend_entries(fams, styles, markers=False))
    same = _time_panels(axes, res, sc, fams, styles, rows, log=True)
    left = [LABELS[q] for q in QUANTITIES if q not in nonzero]
    NOTES[(sc, "errors")] = (("Not drawn: " + ", ".join(left)
                              + " (does not move, or zero error for every variant)."
                              if left else "") + exact_note + _same_note(same)).strip()
    save_png(fig, path)
    return True


def _series_at_roundoff(res, sc, q, variants) -> bool:
    """Whether every variant's error in ``q`` stays at or below its run's round-off floor at the default
    Δt (the floor of its free-running convergence record, cross_checks.analysis.metrics.roundoff_floor)
    for the whole run: a panel of such errors shows only round-off."""
    dt = res.scenario(sc)["dt_s"]
    ser = res.series(sc)
    for v in variants:
        rec = next(iter(res.records(sc, v, q)), None)
        if rec is None or dt not in rec["dt_s"] or f"err_{q}" not in ser.get(v, {}):
            return False
        e = np.asarray(ser[v][f"err_{q}"], dtype=float)
        if not (np.all(np.isfinite(e)) and float(e.max(initial=0.0)) <= rec["floors"][rec["dt_s"].index(dt)]):
            return False
    return bool(variants)


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


_DRIFT_LABEL = {"energy": "energy drift |ΔE|/|E₀|", "angular_momentum": "ang. momentum drift |ΔL|/|L₀|",
                "linear_momentum": "lin. momentum drift |Δp|/|p₀|"}


def fig_conservation(res, sc, styles, path):
    """Drift of the quantities the physics conserves; False when none is conserved or none drifts."""
    info = res.scenario(sc)
    ser = res.series(sc)
    fams = _families_with_series(res, ser)
    kinds = [k for k in ("energy", "angular_momentum", "linear_momentum")
             if info["conserved"][k]["conserved"]]
    moving = [k for k in kinds if any(np.any(np.abs(np.asarray(ser[v].get(f"drift_{k}", [0.0]))) > 0)
                                      for vs in fams.values() for v in vs)]
    exact = [k.replace("_", " ") for k in kinds if k not in moving]
    NOTES[(sc, "conservation")] = ("Not drawn: " + ", ".join(exact)
                                   + " (conserved exactly by every variant).") if exact else ""
    if not fams or not moving:
        if not kinds:
            NOTES[(sc, "conservation")] = "the physics of this scenario conserves nothing"
        return False
    rows = [(_DRIFT_LABEL[k], (lambda s, k=k: None if f"drift_{k}" not in s else np.abs(s[f"drift_{k}"])))
            for k in moving]
    fig, axes = _grid(len(rows), len(fams),
                      f"{sc}: relative drift of conserved quantities at Δt = {info['dt_s']:g} s "
                      f"(log scales; zero drawn at {LOG_FLOOR:g}; × marks a divergence)", log=True,
                      layout="time-log", legend=legend_entries(fams, styles, markers=False))
    same = _time_panels(axes, res, sc, fams, styles, rows, log=True)
    NOTES[(sc, "conservation")] = (NOTES[(sc, "conservation")] + _same_note(same)).strip()
    save_png(fig, path)
    return True


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
    _line(ax, xs, ys, color="0.45", lw=0.8)   # one line for the three triangles (one artist to draw)
    if labels:
        ax.add_artist(_DataStamps(texts))


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
        halo = _covered(drawn, (v, dt[ok], _positive(e[ok])), log=True)
        a = 0.45 if halo else 1.0
        parts += [("line", dt[ok], _positive(e[ok]), (*st["color"][:3], a), st["ls"], 3.2 if halo else 1.0),
                  ("marks", dt[ok], _positive(e[ok]), st["marker"], 7 if halo else 4, (1.0, 1.0, 1.0, a),
                   (*st["color"][:3], a))]
        drawn.append((v, dt[ok], _positive(e[ok])))
        rec = recs.get(v)
        if rec is not None and rec["order"] is not None:
            fitted = np.array(rec["fitted"], dtype=bool)
            c = (*st["color"][:3], 1.0)
            parts.append(("marks", np.array(rec["dt_s"], dtype=float)[fitted],
                          _positive(np.array(rec["errors"], dtype=float)[fitted]), st["marker"], 4, c, c))
        dts += dt[ok].tolist()
        vals.append(_positive(e[ok]))
    _curves(ax, parts)
    if recs:
        r0 = next(iter(recs.values()))
        _line(ax, r0["dt_s"], _positive(r0["floors"]), color="0.5", lw=4, alpha=0.22, solid_capstyle="butt")
    return dts, vals, drawn


#: Two curves coincide when they are drawn within this much of each other at every point: a fiftieth of
#: a decade on log axes (4.7 %), a two-hundredth of the panel's span on linear ones — less than a line's
#: width in a panel of 1.5–2 in spanning a few decades.
COINCIDE_LOG = 0.02
COINCIDE_LIN = 0.005


def coinciding(curves, log, span=None) -> list:
    """Pairs (a, b) of ``curves`` = [(name, x, y)] drawn over each other (the same x, y within
    COINCIDE_LOG decades or COINCIDE_LIN of ``span``); each later curve paired with the first it covers."""
    out = []
    for k, curve in enumerate(curves):
        a = _covered(curves[:k], curve, log, span)
        if a is not None:
            out.append((a, curve[0]))
    return out


def _covered(drawn, curve, log, span=None):
    """The name of the first of ``drawn`` that ``curve`` (name, x, y) would be drawn over, or None."""
    xb, yb = (np.asarray(z, dtype=float) for z in curve[1:])
    for a, xa, ya in drawn:
        xa, ya = np.asarray(xa, dtype=float), np.asarray(ya, dtype=float)
        if xa.shape != xb.shape or not xa.size:
            continue
        ok = np.isfinite(ya) & np.isfinite(yb) & np.isfinite(xa) & np.isfinite(xb)
        if not ok.any():
            continue
        if log:
            near = lambda u, w: float(np.abs(np.log10(np.maximum(u, LOG_FLOOR))     # noqa: E731
                                             - np.log10(np.maximum(w, LOG_FLOOR))).max()) <= COINCIDE_LOG
            hit = near(xa[ok], xb[ok]) and near(ya[ok], yb[ok])
        else:
            hit = (np.allclose(xa[ok], xb[ok], rtol=1e-9, atol=0)
                   and float(np.abs(ya[ok] - yb[ok]).max()) <= COINCIDE_LIN * (span or 1.0))
        if hit:
            return a
    return None


def _same_note(pairs) -> str:
    """The caption's sentence on coinciding curves ``pairs`` [(a, b, panel row)]: groups of variants drawn
    over each other, with the rows where they are (each later one drawn wide and pale under the first)."""
    rows_of = {}
    for row in dict.fromkeys(r for _, _, r in pairs):
        group_of = {}
        for a, b, r in pairs:
            if r != row:
                continue
            g = group_of.get(a) or group_of.get(b) or [a]
            for v in (a, b):
                if v not in g:
                    g.append(v)
                group_of[v] = g
        for g in {id(g): g for g in group_of.values()}.values():
            rows_of.setdefault(tuple(g), []).append(row)
    if not rows_of:
        return ""
    groups = [" = ".join(g) + f" ({', '.join(rows)})" for g, rows in rows_of.items()]
    shown = groups[:10]
    return (" Curves drawn over each other (the later wide and pale under the first, so that both are "
            "seen): " + "; ".join(shown) + (f"; and {len(groups) - 10} more" if len(groups) > 10 else "")
            + ".")


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
    fig, axes = _grid(len(qs), len(fams),
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
        lim = _robust_limits(vals, log=True)
        _same_limits(axes[i], "y", None if lim is None else (lim[0] / 10, lim[1]))
        for j, ax in enumerate(axes[i]):
            if lim is not None:
                _slope_triangles(ax, ladder, labels=j % _blocks(len(fams))[1] == 0)
        _ylabel(axes, i, f"{LABELS[q]} ({UNITS[q]})")
    _same_limits(axes.flat, "x")
    # every row: the same Δt grid lines; labels on the bottom row only, on at most 4 of them (they would
    # overlap at a panel's width)
    step = -(-len(ladder) // 4)
    asc = sorted(ladder)
    shown = {d for k, d in enumerate(asc) if k % step == 0}
    for ax in axes.flat:
        ax.xaxis.set_major_locator(FixedLocator(asc))
        ax.xaxis.set_major_formatter(FixedFormatter([f"{d:g}" if d in shown else "" for d in asc]))
    for ax in axes[-1]:
        _frame(ax).x_size = 7
        ax.set_xlabel("time step Δt (s)", fontsize=8)
    for ax, fam in zip(axes[0], fams):
        _title(ax, fam)
    left = [LABELS[q] for q in QUANTITIES if q not in moving]
    NOTES[(sc, kind)] = (("Not drawn: " + ", ".join(left) + " (does not move). ") if left else "") + \
        "Orders in the legends: " + " / ".join(LABELS[q] for q in qs) + "." + exact_note + _same_note(same)
    save_png(fig, path)
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
    fig, axes = _panels("work", 1, len(qs), (width, 4.0), log=True, outer=False)
    drawn_vs = [v for v in res.variants
                if any(r["in_ladder"] and r["status"] == "ok" for r in res.rows_for(sc, v))]
    leg_h = _figure_legend(fig, width, legend_entries(families(drawn_vs), styles)) if drawn_vs else 0.0
    axes_h = 3.6
    h = 0.75 + axes_h + 0.6 + leg_h + 0.15
    fig.set_size_inches(width, h)
    fig.suptitle(f"{sc}: work-precision — final error vs wall time of each run of the ladder", fontsize=11,
                 x=0.01, ha="left")
    same = []
    for ax, q in zip(axes[0], qs):
        col = f"{COLUMN_STEM[q]}_err_final"
        drawn, parts = [], []
        for v in drawn_vs:
            rows = sorted([r for r in res.rows_for(sc, v) if r["in_ladder"] and r["status"] == "ok"],
                          key=lambda r: -r["dt"])
            w = np.array([r["wall_s"] for r in rows], dtype=float)
            e = np.array([r[col] for r in rows], dtype=float)
            ok = np.isfinite(w) & np.isfinite(e) & (w > 0)
            if not ok.any():
                continue
            st = styles[v]
            halo = _covered(drawn, (v, w[ok], _positive(e[ok])), log=True)
            if halo:
                same.append((halo, v, LABELS[q]))
            c = (*st["color"][:3], 0.45 if halo else 0.9)
            parts += [("line", w[ok], _positive(e[ok]), c, st["ls"], 3.2 if halo else 1.0),
                      ("marks", w[ok], _positive(e[ok]), st["marker"], 7 if halo else 4, c, c)]
            drawn.append((v, w[ok], _positive(e[ok])))
        _curves(ax, parts)
        if ax.has_data():
            ax.autoscale_view()
        _title(ax, LABELS[q])
        ax.set_xlabel("wall time of the run (s)", fontsize=8)
        ax.set_ylabel(f"final {LABELS[q]} error ({UNITS[q]})", fontsize=8)
    fig.subplots_adjust(left=0.75 / width, right=1.0 - 0.2 / width, top=1.0 - 0.75 / h,
                        bottom=(0.6 + leg_h + 0.15) / h, wspace=0.22)
    save_png(fig, path)
    NOTES[(sc, "work")] = _same_note(same).strip()
    return True


#: What other figure modules of the report (reports.polhode, reports.animation) draw with, to look the same:
#: text stamps at data coordinates, the legends under the panels, the time a run diverged.
DataStamps = _DataStamps
figure_legend = _figure_legend
diverged_at = _diverged


_DRAW = {"trajectories": fig_trajectories, "errors": fig_errors, "conservation": fig_conservation,
         "convergence": lambda r, s, st, p: fig_ladder(r, s, st, p, "free_running"),
         "local": lambda r, s, st, p: fig_ladder(r, s, st, p, "one_step"), "work": fig_work}


def figure_name(sc, kind) -> str:
    from cross_checks.sweep.results_dir import safe_file_stem
    return f"{safe_file_stem(sc)}__{kind}.png"


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
