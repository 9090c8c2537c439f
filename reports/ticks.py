"""An axes' ticks, grid lines and tick labels drawn as a few artists instead of one Tick object each.

Why (docs/speed.md, "The report"): cProfile of the report's figures drawn a second time in one process
(grids reused, reports.canvas) put ~36 % of the time in matplotlib's ``Axis.draw``: every tick is an
object of five artists (grid line, two marks, two labels), each drawn on its own with its own
transform and graphics context, every tick label measured once more to place an offset text; and a
grid drawn for the first time creates those tick objects (a third of a cold figure's cost).

:class:`AxisDecor` draws, for each axis of its axes, what matplotlib's ``Axis.draw`` draws, from the
same locator, formatter, transforms and tick styles (copied from the axis's first tick, which
``tick_params`` and ``grid`` keep up to date): all grid lines as one line (NaN-separated segments),
all tick marks as one line of markers, then the labels and the axis label. The ticks matplotlib
would draw are the ones kept here (the view-interval test of ``Axis._update_ticks``). An axis this
does not cover — minor ticks, ticks or labels on the second side, a formatter with an offset text
("1e-5", "+1.0"), an axis label placed from the tick labels (not by ``set_label_coords``) — is left to matplotlib's own ``Axis.draw``. The pixels are matplotlib's own
(tests/reports/test_ticks.py compares both renderings pixel by pixel).
"""
from __future__ import annotations

import numpy as np
from matplotlib.artist import Artist
from matplotlib.lines import Line2D
from matplotlib.text import Text
from matplotlib.ticker import NullLocator

__all__ = ["AxisDecor", "decorate"]

#: Relative slippage allowed at the ends of the view interval (matplotlib's, transforms._interval_contains_close).
_RTOL = 1e-10


def decorate(ax) -> AxisDecor:
    """Hide ``ax``'s own x and y axes and draw them with one :class:`AxisDecor` (kept in the axes: it is
    not data, so reports.canvas does not remove it between figures)."""
    decor = AxisDecor(ax)
    ax.add_artist(decor)
    ax.xaxis.set_visible(False)
    ax.yaxis.set_visible(False)
    return decor


class AxisDecor(Artist):
    """Draws the x and y axes of one axes (hidden themselves): grid, tick marks, tick labels, axis
    labels; the z order of matplotlib's axes (``axes.axisbelow`` "line": 1.5)."""

    zorder = 1.5

    def __init__(self, ax):
        super().__init__()
        self._ax = ax
        self._parts = {}   # axis name -> (grid line, marks line, [label texts])

    def draw(self, renderer):
        if not self.get_visible():
            return
        for name, axis in (("x", self._ax.xaxis), ("y", self._ax.yaxis)):
            _draw_axis(axis, name, self._parts, renderer)
        self.stale = False


def _draw_axis(axis, name, parts, renderer) -> None:
    """One axis as matplotlib's Axis.draw draws it (or by Axis.draw itself where this does not cover
    the axis's settings)."""
    tick = axis.majorTicks[0]   # the template tick: tick_params / grid keep its styles current
    fmt = axis.get_major_formatter()
    auto_label = getattr(axis, "_autolabelpos", True) and axis.label.get_text()   # placed from the tick labels
    simple = (isinstance(axis.get_minor_locator(), NullLocator) and not tick.tick2line.get_visible()
              and not tick.label2.get_visible() and not auto_label)
    drawn = tick.gridline.get_visible() or tick.tick1line.get_visible() or tick.label1.get_visible()
    locs = labels = ()
    if simple and drawn and not isinstance(axis.get_major_locator(), NullLocator):
        locs = np.asarray(axis.get_majorticklocs(), dtype=float)
        labels = fmt.format_ticks(locs)
        simple = not fmt.get_offset()
    if not simple:
        axis.set_visible(True)
        try:
            axis.draw(renderer)
        finally:
            axis.set_visible(False)
        return
    keep = _in_view(axis, locs)
    locs, labels = locs[keep], [s for s, k in zip(labels, keep) if k]
    if name not in parts:
        parts[name] = (Line2D([], []), Line2D([], []), [])
    grid, marks, texts = parts[name]
    if len(locs):
        _draw_lines(tick, grid, marks, locs, name, renderer)
        if tick.label1.get_visible():
            while len(texts) < len(locs):
                texts.append(Text())
            style = _text_style(tick.label1)
            for t, loc, s in zip(texts, locs, labels):
                if getattr(t, "_rb_style", None) != style:   # the template's style changed (tick_params)
                    t.update_from(tick.label1)
                    t.set_figure(axis.figure)
                    t._rb_style = style
                t.set_text(s)
                t.set_position((loc, 0.0) if name == "x" else (0.0, loc))
                t.draw(renderer)
    axis.label.draw(renderer)


def _in_view(axis, locs) -> np.ndarray:
    """Which tick locations Axis._update_ticks would draw: inside the view interval (in the axis's
    scale) within a relative 1e-10."""
    lo, hi = sorted(axis.get_view_interval())
    trans = axis.get_transform()
    a, b = sorted(trans.transform(np.array([lo, hi], dtype=float)))
    with np.errstate(invalid="ignore"):
        t = trans.transform(locs) if len(locs) else np.zeros(0)
        slip = (b - a) * _RTOL
        return (t >= a - slip) & (t <= b + slip)


def _draw_lines(tick, grid, marks, locs, name, renderer) -> None:
    """All grid lines as one NaN-separated line, all tick marks as one line of markers, in the styles
    and transforms of the template tick's grid line and first mark."""
    n = len(locs)
    along = np.column_stack([locs, locs, np.full(n, np.nan)]).ravel()
    across = np.tile([0.0, 1.0, np.nan], n)
    for line, src, data in ((grid, tick.gridline, (along, across)), (marks, tick.tick1line, (locs, np.zeros(n)))):
        if not src.get_visible():
            continue
        style = _line_style(src)
        if getattr(line, "_rb_style", None) != style:   # copied once, again only when tick_params changed it
            line.update_from(src)
            line.set_figure(tick.figure)
            line._rb_style = style
        line.set_data(*(data if name == "x" else data[::-1]))
        line.draw(renderer)


def _line_style(src) -> tuple:
    """What Line2D.update_from copies from a template tick's line that tick_params / grid can change
    (copying it every draw deep-copied the marker: a sixth of the axes' drawing time)."""
    return (id(src), id(src.get_transform()), src.get_visible(), src.get_alpha(), src.get_color(), src.get_linewidth(),
            src.get_linestyle(), src.get_marker(), src.get_markersize(), src.get_markeredgewidth(),
            src.get_zorder(), id(src.get_clip_path()), src.get_clip_on())


def _text_style(src) -> tuple:
    """What Text.update_from copies from a template tick's label that tick_params can change."""
    return (id(src), id(src.get_transform()), src.get_visible(), src.get_alpha(), str(src.get_color()),
            hash(src.get_fontproperties()), src.get_horizontalalignment(), src.get_verticalalignment(),
            src.get_rotation(), src.get_zorder())
