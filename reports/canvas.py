"""Figures for the report, drawn cheaply: grids of panels reused within a drawing process, legends laid
out by hand, PNGs encoded once.

Why (docs/speed.md, "The report"): cProfile of a default sweep's report put ~40 % of the drawing time in
creating axes and their tick objects, ~20 % in matplotlib's Legend (offset boxes measured twice) and
~10 % in re-measuring tick labels to place the axis labels. So:

* :func:`panels` keeps one figure per layout (kind, columns) in each drawing process and hands
  it back emptied of its data (lines, texts, legends), its axes and their ticks intact, as many rows
  laid out as the figure has (the others hidden; rows are added when a figure has more). The panels
  share nothing (sharex/sharey would tie the pooled axes together): the callers set every limit
  explicitly, identical along a row or over the grid, which is what sharing gave. Drawing a figure in a
  reused grid gives the same pixels as in a fresh one (tests/reports/test_canvas.py).
* each axes' ticks, grid lines and tick labels are drawn by one artist (reports.ticks), not one Tick
  object of five artists per tick.
* Axis labels sit at fixed offsets from their axes (points), so matplotlib does not measure every tick
  label again to place them.
* :func:`legend_below` draws a legend as one short line (and marker) and one text per entry, placed in
  inches under its panel, without offset boxes.
* Text (horizontal or turned a quarter) is rasterized a whole string at a time (:class:`_StringRenderer`): matplotlib 3.11
  renders and places every glyph from Python, ~3 ms per label, the largest single cost left (half of
  the drawing time; the same labels drawn as one bitmap each take a third of that, same pixels).
* :func:`save_png` draws once and quantizes the canvas's own pixels into an 8-bit palette PNG (no RGBA
  PNG encoded and decoded on the way).
"""
from __future__ import annotations

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg, RendererAgg, get_hinting_flag
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from matplotlib.gridspec import GridSpec
from matplotlib.lines import Line2D
from matplotlib.text import Text
from matplotlib.transforms import offset_copy

from reports.ticks import decorate

__all__ = ["panels", "release", "legend_below", "legend_at", "legend_height_in", "save_png", "pad_limits", "LEGEND_LINE_IN",
           "TICK_LABEL_PT"]

#: Height of one legend line (7 pt text and its spacing), inches; the legends' strip below the panels is
#: sized from the longest legend so that no legend covers a curve.
LEGEND_LINE_IN = 0.15
#: Tick labels' font size (pt; matplotlib's default, "medium"); the axis labels' fixed offsets below are
#: derived from it.
TICK_LABEL_PT = 10.0
#: y label's distance left of its axes (pt): the widest tick label drawn ("1e-15", "−0.25": 5 characters
#: of ~0.6 em) plus the tick (3.5 pt) and its pad (3.5 pt) plus 4 pt of label pad.
YLABEL_OFFSET_PT = 5 * 0.6 * TICK_LABEL_PT + 3.5 + 3.5 + 4.0
#: x label's distance under its axes (pt): tick, pad, one line of tick labels, 3 pt of label pad.
XLABEL_OFFSET_PT = 3.5 + 3.5 + 1.2 * TICK_LABEL_PT + 3.0

class _StringRenderer(RendererAgg):
    """Agg renderer that rasterizes a plain-text string in one FreeType call (FT2Font.set_text +
    draw_glyphs_to_bitmap, placed as matplotlib 3.10 placed it) instead of glyph by glyph; a string
    turned a quarter (y labels) is the same bitmap turned. Other angles and mathtext are left to
    matplotlib. Any failure of the string path (a
    matplotlib whose internals differ) falls back to matplotlib's own drawing for good; the test
    tests/reports/test_canvas.py compares the two renderings pixel by pixel."""

    string_path = True

    def get_text_width_height_descent(self, s, prop, ismath):
        """matplotlib's measure, kept for the process (its own cache is per renderer, and a renderer
        per figure size: the same tick labels and legends were shaped again for every figure). The
        string is shaped once: its bitmap is kept from the same shaping (:meth:`_bitmap`)."""
        if ismath:
            return super().get_text_width_height_descent(s, prop, ismath)
        key = (s, hash(prop), self.dpi, get_hinting_flag())    # FontProperties compare by their hash
        if key not in _METRICS:
            if len(_METRICS) > _CACHE_MAX:
                _METRICS.clear()
            font = self._prepare_font(prop)      # RendererAgg.get_text_width_height_descent, shaped here
            font.set_text(s, 0.0, flags=get_hinting_flag())
            w, h = font.get_width_height()
            _METRICS[key] = (w / 64.0, h / 64.0, font.get_descent() / 64.0)
            if _StringRenderer.string_path:
                _keep_bitmap(font, (*key, 0, True), antialiased=True)
        return _METRICS[key]

    def _get_font_height_metrics(self, prop):
        """(ascent, descent, line gap) of ``prop``'s font in pixels, which matplotlib's Text layout asks
        of a renderer that has this method and otherwise reads from the font's tables for every text it
        lays out (font lookup and table reads: a tenth of the text time). The same tables and scale as
        matplotlib 3.11's Text._get_layout, kept per font and size; (None, None, None) leaves it to
        matplotlib."""
        key = (hash(prop), self.dpi)
        if key not in _HEIGHTS:
            _HEIGHTS[key] = _font_height_metrics(prop, self.dpi)
        return _HEIGHTS[key]

    def draw_text(self, gc, x, y, s, prop, angle, ismath=False, mtext=None):
        if ismath or angle not in (0, 90) or not _StringRenderer.string_path:
            return super().draw_text(gc, x, y, s, prop, angle, ismath=ismath, mtext=mtext)
        try:
            img, left, bottom = self._bitmap(s, prop, angle, gc.get_antialiased())
            self._renderer.draw_text_image(img, round(x + left), round(y + bottom), 0, gc)
        except (AttributeError, TypeError, ValueError):   # not the FreeType/Agg interface of matplotlib 3.11
            _StringRenderer.string_path = False
            return super().draw_text(gc, x, y, s, prop, angle, ismath=ismath, mtext=mtext)

    def _bitmap(self, s, prop, angle, antialiased):
        """The string's coverage bitmap and its left and bottom (pixels, y downwards) relative to the pen
        origin; the same for every position, so kept for the process (labels repeat across figures)."""
        flat = (s, hash(prop), self.dpi, get_hinting_flag(), 0, bool(antialiased))
        if flat not in _BITMAPS:
            font = self._prepare_font(prop)
            font.set_text(s, 0, flags=get_hinting_flag())
            _keep_bitmap(font, flat, antialiased)
        if angle != 90:
            return _BITMAPS[flat]
        turned = flat[:4] + (90, flat[5])
        if turned not in _BITMAPS:   # turned a quarter anticlockwise about the pen origin: (u, v) -> (v, -u)
            img, left, bottom = _BITMAPS[flat]
            img = np.ascontiguousarray(np.rot90(img))
            _BITMAPS[turned] = (img, bottom - img.shape[1], -left)
        return _BITMAPS[turned]


def _keep_bitmap(font, key, antialiased) -> None:
    """Rasterize the string ``font`` was just shaped with (FT2Font.set_text) and keep its bitmap and
    offsets (as matplotlib 3.10 placed them) under ``key``."""
    font.draw_glyphs_to_bitmap(antialiased=antialiased)
    xo, yo = font.get_bitmap_offset()
    if len(_BITMAPS) > _CACHE_MAX:
        _BITMAPS.clear()
    _BITMAPS[key] = (np.array(font.get_image()), xo / 64.0, yo / 64.0 + font.get_descent() / 64.0 + 1)


def _font_height_metrics(prop, dpi):
    """matplotlib 3.11's Text._get_layout reading of a font's vertical extent (OS/2 typographic
    metrics, else hhea), in pixels at ``dpi``; (None, None, None) when neither table is there."""
    try:
        from matplotlib.font_manager import fontManager, get_font
        font = get_font(fontManager._find_fonts_by_props(prop))
        for table_name, gap_key, ascent_key, descent_key in (("OS/2", "sTypoLineGap", "sTypoAscender", "sTypoDescender"),
                                                             ("hhea", "lineGap", "ascent", "descent")):
            table = font.get_sfnt_table(table_name)
            if table is None:
                continue
            scale = 1 / font.get_sfnt_table("head")["unitsPerEm"] * prop.get_size_in_points() * dpi / 72
            return table[ascent_key] * scale, -table[descent_key] * scale, table[gap_key] * scale
    except (AttributeError, TypeError, KeyError, ValueError):   # not matplotlib 3.11's font interface
        pass
    return None, None, None


#: Strings measured / rasterized, kept per process (a report has a few thousand distinct ones).
_HEIGHTS: dict = {}
_METRICS: dict = {}
_BITMAPS: dict = {}
_CACHE_MAX = 20000


class _Canvas(FigureCanvasAgg):
    """The Agg canvas, drawing with :class:`_StringRenderer`."""

    def get_renderer(self):
        w, h = self.get_width_height(physical=True)
        key = w, h, self.figure.dpi
        if getattr(self, "_lastKey", None) != key or not isinstance(getattr(self, "renderer", None), _StringRenderer):
            self.renderer = _StringRenderer(w, h, self.figure.dpi)
            self._lastKey = key
        return self.renderer


_POOL: dict = {}    # (layout key) -> (fig, axes of every row made): per process (forked drawing workers each have theirs)


def panels(key, nrows: int, ncols: int, size_in, dpi: float, log: bool, outer_labels: bool = True):
    """A figure of ``nrows`` × ``ncols`` unshared panels for layout ``key``, emptied of any previous
    drawing and resized to ``size_in`` (w, h inches). Log panels have log x and y scales. With
    ``outer_labels`` only the bottom row shows x tick labels and only the first column y tick labels
    (the callers then give a row the same y limits and the grid the same x limits).

    The rows are pooled by layout whatever their number (creating an axes is the costliest part of a
    figure drawn for the first time): a figure of fewer rows than the pool has lays its rows out on
    its own grid (the positions ``fig.subplots(nrows, ncols)`` gives) and hides the others."""
    k = (key, ncols, bool(log), outer_labels)
    if k not in _POOL:
        fig = Figure(figsize=size_in, dpi=dpi)
        _Canvas(fig)
        fig._rb_extra = []
        _POOL[k] = (fig, np.empty((0, ncols), dtype=object))
    fig, pool = _POOL[k]
    while len(pool) < nrows:
        row = np.empty((1, ncols), dtype=object)
        for j in range(ncols):
            row[0, j] = fig.add_subplot(len(pool) + 1, ncols, j + 1)
            _new_panel(row[0, j], log, bottom=True, left=j == 0 or not outer_labels)
            row[0, j]._rb_labelbottom = True
        pool = np.vstack([pool, row])
        _POOL[k] = (fig, pool)
    grid = GridSpec(nrows, ncols, figure=fig)
    for (i, j), ax in np.ndenumerate(pool):
        ax.set_visible(i < nrows)
        if i < nrows:
            ax.set_subplotspec(grid[i, j])
            _show_x_labels(ax, i == nrows - 1 or not outer_labels)
    axes = pool[:nrows]
    _empty(fig, axes)
    fig.set_size_inches(*size_in)
    return fig, axes


def _show_x_labels(ax, show: bool) -> None:
    """x tick labels on or off (tick_params only when it changes: it restyles every tick)."""
    if getattr(ax, "_rb_labelbottom", None) != show:
        ax.tick_params(labelbottom=show)
        ax._rb_labelbottom = show


def release() -> None:
    """Drop the pooled figures (and their pixel buffers, ~6 MB each) of this process: a caller that drew
    in its own process (``jobs=1``) does not keep them after the report."""
    _POOL.clear()


def _new_panel(ax, log, bottom, left) -> None:
    if log:
        ax.set_xscale("log")
        ax.set_yscale("log")
    ax.grid(alpha=0.3, which="both")
    ax.tick_params(labelsize=TICK_LABEL_PT, labelbottom=bottom, labelleft=left)
    fig = ax.figure
    ax.yaxis.set_label_coords(0.0, 0.5, transform=offset_copy(ax.transAxes, fig=fig, x=-YLABEL_OFFSET_PT,
                                                              units="points"))
    ax.yaxis.label.set_verticalalignment("bottom")
    ax.xaxis.set_label_coords(0.5, 0.0, transform=offset_copy(ax.transAxes, fig=fig, y=-XLABEL_OFFSET_PT,
                                                              units="points"))
    ax.xaxis.label.set_verticalalignment("top")
    decorate(ax)


def _empty(fig, axes) -> None:
    """Remove what the previous figure drew; axes, ticks and scales stay."""
    for ax in axes.flat:
        for art in (*ax.lines, *ax.texts, *ax.collections, *ax.patches):
            art.remove()
        if ax.legend_ is not None:
            ax.legend_.remove()
        ax.set_xlabel("")
        ax.set_ylabel("")
        ax.relim()
        ax.set_autoscale_on(True)
    for lg in list(fig.legends):
        lg.remove()
    for art in fig._rb_extra:
        art.remove()
    fig._rb_extra = []
    fig._rb_legends = []


def pad_limits(lo: float, hi: float, log: bool, margin: float = 0.05):
    """(lo, hi) widened by ``margin`` of the span on each side (in log space on a log axis), as
    matplotlib's autoscaling does; a zero span gets a small symmetric one."""
    if log:
        a, b = np.log10(lo), np.log10(hi)
        pad = margin * (b - a) if b > a else 0.5
        return 10.0 ** (a - pad), 10.0 ** (b + pad)
    pad = margin * (hi - lo) if hi > lo else 0.05 * max(1.0, abs(hi))
    return lo - pad, hi + pad


def legend_below(fig, ax, title: str, entries, below_in: float) -> None:
    """A legend under ``ax``, its top ``below_in`` inches under the panel (:func:`legend_at`)."""
    W, H = fig.get_size_inches()
    pos = ax.get_position()
    legend_at(fig, pos.x0 * W, pos.y0 * H - below_in, title, entries)


def legend_height_in(n_entries: int) -> float:
    """Height of a legend of ``n_entries`` drawn by :func:`legend_at` (inches)."""
    return 0.2 + LEGEND_LINE_IN * n_entries


def legend_at(fig, x0: float, top: float, title: str, entries) -> None:
    """A legend whose top left corner is at (x0, top) inches from the figure's lower left: the title,
    then one entry per line: ``(label, line style dict)`` with keys color, ls, lw, and optionally
    marker (drawn filled in the middle of a 1.8 em handle). Entries are LEGEND_LINE_IN apart. Removed
    with the rest of the drawing when :func:`panels` hands the figure out again."""
    inch = fig.dpi_scale_trans
    em = 7.0 / 72.0
    art = [fig.text(x0, top, title, transform=inch, fontsize=8, va="top", ha="left")]
    solid = []    # (segment, colour, width) of the solid handles: one collection for the legend
    y = top - 0.2
    for label, st in entries:
        xs = [x0 + 0.05, x0 + 0.05 + 1.8 * em]
        ls, lw = st.get("ls", "-"), st.get("lw", 1.4)
        if ls in ("-", "solid"):
            solid.append((list(zip(xs, [y, y])), st["color"], lw))
        else:
            art.append(Line2D(xs, [y, y], transform=inch, color=st["color"], ls=ls, lw=lw))
        if st.get("marker"):
            art.append(Line2D([sum(xs) / 2], [y], transform=inch, color=st["color"], marker=st["marker"], ms=4,
                              ls="none"))
        art.append(fig.text(xs[1] + 0.8 * em, y, label, transform=inch, fontsize=7, va="center", ha="left"))
        y -= LEGEND_LINE_IN
    if solid:   # drawn as Line2D draws a solid line (projecting caps), below the markers (z order 2, first)
        art.insert(0, LineCollection([seg for seg, _, _ in solid], colors=[c for _, c, _ in solid],
                                     linewidths=[w for _, _, w in solid], capstyle="projecting", transform=inch,
                                     zorder=2))
    for a in art:
        if not isinstance(a, Text):
            fig.add_artist(a)
    fig._rb_extra = getattr(fig, "_rb_extra", []) + art


def save_png(fig, path) -> None:
    """Save as an 8-bit palette PNG: the figures use a few dozen colours, and a palette makes the
    files ~3× smaller than RGBA at no visible cost (no dithering). Deterministic for equal input. The
    canvas is drawn once and its pixels quantized directly."""
    from PIL import Image
    canvas = fig.canvas if isinstance(fig.canvas, FigureCanvasAgg) else FigureCanvasAgg(fig)
    canvas.draw()
    w, h = canvas.get_width_height(physical=True)
    im = Image.frombuffer("RGBA", (w, h), canvas.buffer_rgba(), "raw", "RGBA", 0, 1).convert("RGB")
    q = im.quantize(colors=256, method=Image.Quantize.FASTOCTREE, dither=Image.Dither.NONE)
    q.save(path, format="PNG", compress_level=6)
