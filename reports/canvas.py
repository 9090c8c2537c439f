"""The report's canvas: the figure machinery every figure of rbcheck draws on (the scenario figures of
reports.plots, the polhodes of reports.polhode, the integrators page's, ``rbcheck check --plot`` and the
animations), so that they look alike and none goes through pyplot.

What is here:

- figures on the Agg canvas (:func:`new_figure`), and the report's grids of panels, kept per drawing
  process and emptied for the next figure (:func:`panel_figure`, :func:`family_grid`: one column per
  engine family, more than MAX_COLUMNS wrap into blocks of rows, one row per quantity sharing its y axis);
- each variant's colour, dash pattern and marker (:func:`variant_styles`), the same in every figure;
- log axes (plain decade labels, no minor ticks; zeros drawn at LOG_FLOOR: :func:`positive`);
- the panels' frames, tick labels and titles, and every text, drawn once per process as bitmaps
  (:class:`Frame`, :func:`stamp`, :class:`DataStamps`);
- the legends under the panels, one per family (:func:`legend_entries`, :func:`figure_legend`);
- a panel's variants as one artist (:class:`Curves`), and curves drawn over each other (:func:`coinciding`);
- saving a PNG atomically (:func:`save_png`: a palette PNG, deterministic for equal input, or the full
  colours of ``Figure.savefig``).

Drawn with matplotlib's public API on the Agg canvas, margins in inches; a drawing process keeps one
figure per layout and empties it for the next (same pixels as a fresh one: tests/reports/test_plots.py).
How the drawing is kept fast (``Frame``, ``stamp``, ``Curves``): docs/speed.md, "The report".
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
from matplotlib.ticker import LogFormatter, LogLocator, MaxNLocator, NullLocator
from matplotlib.transforms import Bbox, IdentityTransform

from reports.glance import families

__all__ = ["DPI", "REPORT_DPI", "LOG_FLOOR", "NOTES", "MAX_COLUMNS", "TICK_PT", "FAMILY_HUES",
           "variant_styles", "short_name", "figure_name", "new_figure", "save_png", "release",
           "stamp", "DataStamps", "Frame", "frame_of", "panel_title", "panel_figure", "family_grid",
           "family_blocks", "same_limits", "row_ylabel",
           "legend_entries", "legend_figure", "LegendBoxes", "legend_pixels", "figure_legend",
           "Curves", "add_curves", "add_line", "positive", "robust_limits", "diverged_at",
           "COINCIDE_LOG", "COINCIDE_LIN", "coinciding", "covered_by", "same_note"]

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


def short_name(v):
    return v.split(":", 1)[1] if ":" in v else v



# --- text drawn once per process ------------------------------------------------------------------------
#: Text bitmaps by (dpi, text, size, alignment, rotation, weight, colour), each drawn once by matplotlib.
_STAMPS: dict = {}
_SCRATCH: dict = {}   # dpi -> (figure the Text artists belong to, a renderer to measure them with)


def stamp(dpi, text, size, ha="left", va="baseline", rotation=0, weight="normal", color="black"):
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
    """Draw ``text`` (:func:`stamp`) with its anchor at display pixel (x, y); returns its extent."""
    img, x0, y0, w, h = stamp(dpi, text, size, **style)
    left, bottom = round(x) + x0, round(y) + y0
    renderer.draw_image(gc, left, bottom, img)
    return Bbox.from_bounds(left + 2, bottom + 2, w, h)


class _Stamps(Artist):
    """Texts (:func:`stamp`) at display pixels: ``items`` [(x, y, text, size, style)]."""

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


class DataStamps(Artist):
    """Texts (:func:`stamp`) at data coordinates of their axes, over the curves as an ``ax.text`` is:
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


class Frame(Artist):
    """A panel's grid lines (one path at the major ticks), tick labels, axis labels and title, drawn by
    one artist as :func:`stamp` images at matplotlib's places (the axes' axis artists are hidden). Tick
    labels where the tick parameters say (``labelbottom``, ``labelleft``); the labels' texts and sizes
    are the axes' own (``set_xlabel``, ``set_ylabel``)."""

    zorder = 0.5

    def __init__(self):
        super().__init__()
        self.title = ""
        self.x_size = TICK_PT

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
                _place(renderer, gc, dpi, box.x0 - _TICK_PAD_PT * pt, y, text, TICK_PT, ha="right",
                       va="center_baseline")
        x_offset = (box.x1, box.y0 - (_TICK_PAD_PT + 1.2 * self.x_size) * pt, "right", "top")
        for axis, offset in ((ax.xaxis, x_offset), (ax.yaxis, (box.x0, box.y1 + _TITLE_PAD_PT * pt, "left",
                                                               "baseline"))):
            shown = bottom if axis is ax.xaxis else left
            extra = axis.get_major_formatter().get_offset() if shown else ""
            if extra:
                _place(renderer, gc, dpi, offset[0], offset[1], extra, TICK_PT, ha=offset[2], va=offset[3])
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


def frame_of(ax) -> Frame:
    return next(a for a in ax.artists if isinstance(a, Frame))


_FIGURES: dict = {}   # (layout, columns, log, outer) -> (figure, rows of axes): kept per drawing process
#: Tick labels' size (pt) and the axis labels' fixed distances from their axes (pt), so that no tick
#: label need be measured to place them: y label left of the widest tick label drawn ("1e-15",
#: "−0.25": 5 characters of ~0.6 em) plus tick (3.5 pt), pad (3.5 pt) and 4 pt; x label under the tick,
#: pad, one line of tick labels (1.2 em) and 3 pt. Tick labels sit tick + pad (7 pt) off their axes, a
#: title 4 pt above its panel (matplotlib's places).
TICK_PT = 10.0
_TICK_PAD_PT = 3.5 + 3.5
_TITLE_PAD_PT = 4.0
_YLABEL_PT = 5 * 0.6 * TICK_PT + 3.5 + 3.5 + 4.0
_XLABEL_PT = 3.5 + 3.5 + 1.2 * TICK_PT + 3.0


def panel_figure(layout, nrows, ncols, size_in, log, outer=True, block_rows=None, used=None, spacer=0.0):
    """A figure of ``nrows`` × ``ncols`` panels (log x and y scales when ``log``), emptied of any previous
    drawing and resized to ``size_in`` (w, h inches); kept per layout, surplus rows hidden. With
    ``outer`` only the bottom row has x tick labels and the first column y tick labels (callers then
    share limits: :func:`same_limits`). ``block_rows``: the rows are blocks of that many (the bottom row
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
                        *[a for a in ax.artists if isinstance(a, DataStamps)]):
                art.remove()
            ax.set(xlabel="", ylabel="")
            frame = frame_of(ax)
            frame.title, frame.x_size = "", TICK_PT
            ax.relim()
            ax.set_autoscale_on(True)
    for art in (*fig.images, *fig.texts, *fig.legends):   # titles, legends
        art.remove()
    fig.set_size_inches(*size_in)
    return fig, np.array(rows[:nrows], dtype=object)


def _style(ax, log, left) -> None:
    """Plain decade labels ("1e-06", not mathtext) and no minor ticks on log axes, at most 5 ticks on
    linear ones; no tick marks; grid, labels and title drawn by a :class:`Frame`."""
    ax.patch.set_visible(False)   # white on the figure's white
    ax.tick_params(labelsize=TICK_PT, labelleft=left, bottom=False, left=False)
    ax.xaxis.set_visible(False)
    ax.yaxis.set_visible(False)
    ax.add_artist(Frame())
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


def same_limits(axes, which, lim=None) -> None:
    """One range over ``axes``, as shared axes would have: ``lim``, or the union of the panels' own."""
    axes = list(axes)
    lims = [lim] if lim is not None else [ax.get_xlim() if which == "x" else ax.get_ylim() for ax in axes
                                          if ax.has_data()]
    if not lims:
        return
    lo, hi = min(lo for lo, _ in lims), max(hi for _, hi in lims)
    for ax in axes:
        ax.set_xlim(lo, hi) if which == "x" else ax.set_ylim(lo, hi)


def panel_title(ax, text) -> None:
    """A panel's title at the left, at a fixed height (:class:`Frame`)."""
    frame_of(ax).title = text



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


def family_blocks(nfam) -> tuple:
    """(blocks, columns) of a grid of ``nfam`` family columns: as few blocks as MAX_COLUMNS allows, the
    families spread evenly over them."""
    blocks = max(1, math.ceil(nfam / MAX_COLUMNS))
    return blocks, max(1, math.ceil(nfam / blocks))


def family_grid(nrows, nfam, title, panel_h=2.1, log=False, layout="time", legend=None):
    """A grid of ``nrows`` quantity rows × ``nfam`` family columns under a title (families wrap into blocks
    of at most MAX_COLUMNS columns), with the figure's legend (:func:`figure_legend` entries) under it;
    margins in inches. Returns (figure, axes[row, family])."""
    blocks, cols = family_blocks(nfam)
    w = min(13.0, 2.2 + 3.6 * cols)
    axes_h = (panel_h * nrows - 0.15) / (nrows + 0.35 * (nrows - 1))
    gap = 0.35 * axes_h
    spacer = max(_BLOCK_GAP_IN - 2 * gap, 0.05) if blocks > 1 else 0.0    # between blocks: x labels, titles
    fig, phys = panel_figure(layout, nrows * blocks, cols, (w, 4.0), log, block_rows=nrows, used=nfam,
                        spacer=spacer / axes_h)
    leg_h = figure_legend(fig, w, legend) if legend else 0.0
    strip = leg_h + 0.15 if legend else 0.0
    n_grid = nrows * blocks + blocks - 1
    area = axes_h * nrows * blocks + spacer * (blocks - 1) + gap * (n_grid - 1)
    # wrapped to the figure's width (≈ 12 characters per inch at 11 pt): a one-column figure is 5.8 in wide
    title = textwrap.fill(title, width=int(w * _TITLE_CHARS_PER_IN))
    extra = 0.2 * title.count("\n")
    h = 0.75 + extra + area + 0.5 + strip
    fig.set_size_inches(w, h)
    # its top 0.1 in below the figure's (matplotlib's default, 2 % of the height, put a tall figure's title
    # over the first row's panel titles)
    fig.suptitle(title, fontsize=11, x=0.01, y=1.0 - 0.1 / h, ha="left", va="top")
    mean_cell = (area - gap * (n_grid - 1)) / n_grid
    fig.subplots_adjust(left=0.09 if w > 8 else 0.14, right=0.98, top=1.0 - (0.75 + extra) / h,
                        bottom=(0.5 + strip) / h, hspace=gap / mean_cell, wspace=0.08)
    axes = np.empty((nrows, nfam), dtype=object)
    for j in range(nfam):
        b, c = divmod(j, cols)
        axes[:, j] = phys[b * nrows:(b + 1) * nrows, c]
    return fig, axes


def row_ylabel(axes, i, text) -> None:
    """Row ``i``'s y label on the first panel of each block of family columns."""
    for j in range(0, axes.shape[1], family_blocks(axes.shape[1])[1]):
        axes[i, j].set_ylabel(text, fontsize=8)



#: The legend's font size (pt) and the figure's left margin for it (inches).
_LEGEND_PT = 8.5
_LEGEND_X_IN = 0.1


def legend_entries(fams, styles, extra=None, markers=True) -> dict:
    """The entries of a figure's legends: ``{family: [(label, style)]}``, each variant's short name (and
    ``extra[v]``) with its colour, dash pattern and (when ``markers``) marker."""
    out = {}
    for fam, vs in fams.items():
        out[fam] = [(short_name(v) + (f"  {extra[v]}" if extra and extra.get(v) else ""),
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
    between columns, 0.25 em between rows), laid out from the texts' measured extents (:func:`stamp`)
    on a transparent figure sized to them plus _LEGEND_PAD_PX, so nothing is cut. Returns (figure,
    :class:`LegendBoxes`)."""
    pt = dpi / 72.0
    em = _LEGEND_PT * pt
    pad = _LEGEND_PAD_PX
    title = stamp(dpi, fam, 9, va="top", weight="bold")
    # a label "name  extra" is drawn as two texts, the extra (a ladder's orders) where it would be in the
    # whole label: texts' widths add up (advances), the two spaces measured once
    parts = [label.partition("  ")[::2] for label, _ in items]
    text = lambda t: stamp(dpi, t, _LEGEND_PT, va="center_baseline")   # noqa: E731
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
        _, x0, y0, bw, bh = stamp(dpi, text, size, **style)
        boxes.append((text, Bbox.from_bounds(round(tx) + x0 + 2, round(ty) + y0 + 2, bw, bh)))
    extent = Bbox.union([b for _, b in boxes])
    return fig, LegendBoxes(boxes, extent)


def legend_pixels(dpi, fam, items) -> np.ndarray:
    """The pixels of :func:`legend_figure`, drawn once per process."""
    key = (dpi, fam, tuple((label, st["color"], st["ls"], st.get("marker")) for label, st in items))
    if key not in _LEGENDS:
        with matplotlib.rc_context({"text.hinting": "no_hinting"}):
            fig, _ = legend_figure(dpi, fam, items)
            fig.canvas.draw()
        _LEGENDS[key] = np.asarray(fig.canvas.buffer_rgba()).copy()
    return _LEGENDS[key]


def figure_legend(fig, width_in, entries) -> float:
    """The figure's legends under its panels, one per family (:func:`legend_figure`), left to right and
    wrapped to ``width_in``, none cut or overlapping; placed as images (FigureImage, labelled with the
    family's name) in pixels from the figure's bottom, so that a later height does not move them.
    Returns the height they take (inches)."""
    placed, x, y, line_h = [], _LEGEND_X_IN * fig.dpi, 0.0, 0.0
    limit = (width_in - _LEGEND_X_IN) * fig.dpi
    for fam, items in entries.items():
        pix = legend_pixels(fig.dpi, fam, items)
        h, w = pix.shape[:2]
        if x > _LEGEND_X_IN * fig.dpi and x + w > limit:     # wrap to a new line
            x, y, line_h = _LEGEND_X_IN * fig.dpi, y + line_h + 0.12 * fig.dpi, 0.0
        placed.append((fam, pix, x, y))
        x, line_h = x + w + _LEGEND_GAP_IN * fig.dpi, max(line_h, h)
    total = math.ceil(y + line_h + 0.05 * fig.dpi)
    for fam, pix, lx, ly in placed:      # ly: from the top of the legends' strip down
        fig.figimage(pix, xo=round(lx), yo=total - round(ly) - pix.shape[0], origin="upper").set_label(fam)
    return total / fig.dpi



def _dashes(ls, lw) -> tuple:
    """(offset, dash lengths in pt) of dash pattern ``ls`` at line width ``lw``, as a Line2D has them (the
    rc patterns, scaled by the width when ``lines.scale_dashes``)."""
    name = {"-": "solid", "--": "dashed", "-.": "dashdot", ":": "dotted"}.get(ls, ls)
    if name == "solid":
        return 0.0, None
    rc: dict = matplotlib.rcParams   # (an RcParams is a dict; its keys are typed as literals)
    dashes = tuple(rc[f"lines.{name}_pattern"])
    if matplotlib.rcParams["lines.scale_dashes"]:
        dashes = tuple(d * lw for d in dashes)
    return 0.0, dashes


class Curves(Line2D):
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


def add_curves(ax, parts) -> None:
    """Add a panel's variants as one :class:`Curves` (nothing when there are none)."""
    if parts:
        ax.add_line(Curves(parts))


def add_line(ax, x, y, **style):
    """One Line2D of the given style added to ``ax`` (not autoscaled: the panel is, when done)."""
    return ax.add_line(Line2D(np.asarray(x, dtype=float), np.asarray(y, dtype=float), **style))


def positive(a):
    a = np.asarray(a, dtype=float)
    return np.where(a > 0, a, LOG_FLOOR)


def diverged_at(res, sc, v):
    """The time a run at the default Δt diverged (s), or None."""
    d = res.default_row(sc, v)
    if d is None or d["status"] != "diverged":
        return None
    t = d.get("diverged_at_s", math.nan)
    return t if isinstance(t, float) and math.isfinite(t) else math.inf


def robust_limits(curves, log):
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
        a = covered_by(curves[:k], curve, log, span)
        if a is not None:
            out.append((a, curve[0]))
    return out


def covered_by(drawn, curve, log, span=None):
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


def same_note(pairs) -> str:
    """The caption's sentence on coinciding curves ``pairs`` [(a, b, panel row)]: groups of variants drawn
    over each other, with the rows where they are (each later one drawn wide and pale under the first)."""
    rows_of: dict = {}
    for row in dict.fromkeys(r for _, _, r in pairs):
        group_of: dict = {}
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


def figure_name(sc, kind) -> str:
    """The file name of scenario ``sc``'s figure ``kind`` (``<scenario>__<kind>.png``, the scenario's name
    made safe for a file name)."""
    from cross_checks.sweep.results_dir import safe_file_stem
    return f"{safe_file_stem(sc)}__{kind}.png"


def new_figure(size_in, dpi=DPI, **kwargs) -> Figure:
    """A figure of ``size_in`` (w, h inches) on the Agg canvas, for a figure drawn once (no pyplot: no
    global figure manager, nothing to close; the same pixels as ``pyplot.figure`` under Agg)."""
    fig = Figure(figsize=size_in, dpi=dpi, **kwargs)
    FigureCanvasAgg(fig)
    return fig


def save_png(fig, path, *, palette: bool = True, dpi=None) -> None:
    """Save ``fig`` as a PNG at ``path`` atomically (a reader never sees half a file; an interrupted save
    leaves the old one). ``palette``: an 8-bit palette PNG (no dithering), unhinted text, deterministic
    for equal input (the report's figures); otherwise ``Figure.savefig``'s full colours at ``dpi``."""
    from cross_checks.core.files import atomic_write
    if palette:
        from PIL import Image
        canvas = fig.canvas if isinstance(fig.canvas, FigureCanvasAgg) else FigureCanvasAgg(fig)
        with matplotlib.rc_context({"text.hinting": "no_hinting"}):
            canvas.draw()
        w, h = canvas.get_width_height(physical=True)
        im = Image.frombuffer("RGBA", (w, h), canvas.buffer_rgba(), "raw", "RGBA", 0, 1).convert("RGB")
        q = im.quantize(colors=256, method=Image.Quantize.FASTOCTREE, dither=Image.Dither.NONE)
        atomic_write(path, lambda tmp: q.save(tmp, format="PNG", compress_level=6), suffix=".png")
    else:
        atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=dpi, format="png"), suffix=".png")
