"""reports.ticks: an axes decorated by AxisDecor draws exactly matplotlib's own axis pixels.

Each case draws the same panel twice on the report's canvas, once with matplotlib's Axis.draw and once
with the axes decorated, and compares every pixel; cases cover what the report's figures set (linear
and log scales, fixed Δt ladders with their labels at 7 pt, labels off on inner panels, grid lines,
limits that cut a tick at the edge) and what AxisDecor hands back to matplotlib (minor ticks, an
offset text, labels on the second side, an axis label placed by matplotlib). The decoration must also really be in use: a figure it did
not draw would pass the comparison trivially.
"""
import numpy as np
import pytest
from matplotlib.figure import Figure
from matplotlib.ticker import FixedFormatter, FixedLocator, LogFormatter, LogLocator, MaxNLocator, NullLocator

from reports import canvas, ticks


def _linear(ax):
    ax.plot([0.0, 10.0], [-0.9, 0.95])
    ax.yaxis.set_major_locator(MaxNLocator(nbins=4))
    ax.set_xlim(-0.5, 10.5)
    ax.set_ylim(-1.0, 1.0)
    ax.set_xlabel("time t (s)", fontsize=8)
    ax.set_ylabel("qw", fontsize=8)
    ax.xaxis.set_label_coords(0.5, -0.15)     # as reports.canvas places them
    ax.yaxis.set_label_coords(-0.15, 0.5)


def _auto_label(ax):                 # an axis label placed from the tick labels: handed to matplotlib
    ax.plot([0.0, 10.0], [-0.9, 0.95])
    ax.set_xlabel("time t (s)")


def _log(ax):
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.plot([1e-3, 10.0], [1e-17, 1e-2])
    for axis in (ax.xaxis, ax.yaxis):
        axis.set_major_locator(LogLocator(base=10.0, numticks=6))
        axis.set_major_formatter(LogFormatter(labelOnlyBase=True))
        axis.set_minor_locator(NullLocator())
    ax.set_ylim(3e-18, 1e-1)


def _ladder(ax):
    dts = [0.0005, 0.001, 0.002, 0.004, 0.008]
    _log(ax)
    ax.set_xlim(0.0004, 0.01)
    ax.xaxis.set_major_locator(FixedLocator(dts))
    ax.xaxis.set_major_formatter(FixedFormatter([f"{d:g}" for d in dts]))
    ax.tick_params(axis="x", labelsize=7)


def _inner(ax):
    _linear(ax)
    ax.tick_params(labelbottom=False, labelleft=False)


def _edge_tick(ax):
    _linear(ax)
    ax.set_xlim(0.0, 10.0)          # ticks exactly on both ends: drawn
    ax.set_ylim(-0.5 + 1e-13, 0.5)  # a tick a hair outside the view: matplotlib's tolerance keeps it


def _offset(ax):                     # ScalarFormatter with an offset text: handed to matplotlib
    ax.plot([0.0, 1.0], [1000.0001, 1000.0002])
    ax.set_ylim(1000.0001, 1000.0002)


def _minor(ax):                      # minor ticks: handed to matplotlib
    _log(ax)
    ax.xaxis.set_minor_locator(LogLocator(base=10.0, subs=(2.0, 5.0)))


def _second_side(ax):                # ticks and labels on the right: handed to matplotlib
    _linear(ax)
    ax.tick_params(right=True, labelright=True)


def _render(setup, decorated):
    fig = Figure(figsize=(4.0, 3.0), dpi=90)
    canvas._Canvas(fig)
    ax = fig.subplots()
    ax.grid(alpha=0.3, which="both")
    ax.tick_params(labelsize=canvas.TICK_LABEL_PT)
    decor = ticks.decorate(ax) if decorated else None
    setup(ax)
    fig.subplots_adjust(left=0.2, bottom=0.2)
    fig.canvas.draw()
    return np.asarray(fig.canvas.buffer_rgba()).copy(), decor


@pytest.mark.parametrize("setup", [_linear, _log, _ladder, _inner, _edge_tick, _offset, _minor, _second_side,
                                   _auto_label])
def test_a_decorated_axes_draws_matplotlibs_own_axis_pixels(setup):
    theirs, _ = _render(setup, decorated=False)
    ours, decor = _render(setup, decorated=True)
    assert (255 - theirs[..., :3]).sum() > 0
    diff = np.abs(ours.astype(int) - theirs.astype(int)).max(axis=2)
    assert not diff.any(), f"{setup.__name__}: {(diff > 0).sum()} pixels differ"
    assert not decor.axes.xaxis.get_visible() and not decor.axes.yaxis.get_visible()   # hidden after drawing too


def test_the_decoration_draws_the_axes_when_it_covers_them():
    """The common cases are drawn by AxisDecor itself (matplotlib creates no tick object for them), and
    a planted fault in its grid is visible: the comparison above compares something."""
    fig = Figure(figsize=(4.0, 3.0), dpi=90)
    canvas._Canvas(fig)
    ax = fig.subplots()
    ax.grid(alpha=0.3)
    decor = ticks.decorate(ax)
    _linear(ax)
    fig.canvas.draw()
    assert len(ax.xaxis.majorTicks) == 1 and len(ax.yaxis.majorTicks) == 1   # only the style template
    before = np.asarray(fig.canvas.buffer_rgba()).copy()
    ax.xaxis.majorTicks[0].gridline.set_color("red")   # the template's style is what is drawn
    fig.canvas.draw()
    after = np.asarray(fig.canvas.buffer_rgba())
    assert (np.abs(after.astype(int) - before.astype(int)).max(axis=2) > 0).sum() > 100
    assert decor.get_zorder() == 1.5
