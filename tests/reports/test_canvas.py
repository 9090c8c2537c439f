"""reports.canvas: what makes the report cheap to draw must not change what it shows.

A grid reused within a drawing process draws the same pixels as a fresh one, whatever the previous
figure left in it; labels rasterized a string at a time land on matplotlib's own pixels; a row of errors
that are all at round-off is said in the caption instead of drawn, and a row with one error above its
floor is drawn.
"""
import io
import json
import shutil

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from PIL import Image

from reports import canvas, plots
from reports.data import load_results
from tests.helpers.sweeps import built_once
from tests.reports.test_browser import _browser_sweep
from tests.reports.test_report import _hostile_sweep


@pytest.fixture(scope="module")
def browser_results(tmp_path_factory):
    """The browser tests' sweep (built once per run, shared): a divergence, a spin, one Δt only."""
    return built_once(tmp_path_factory, "browser_report", _browser_sweep) / "res"


@pytest.fixture(scope="module")
def hostile_results(tmp_path_factory):
    """test_report's sweep: a projectile that spins, velocity exact under gravity for every scheme."""
    return built_once(tmp_path_factory, "hostile_report", _hostile_sweep) / "res"


def _pixels(path):
    with Image.open(path) as im:
        return np.asarray(im.convert("RGB"), dtype=np.int16)


def _litter(rng):
    """Leave in every pooled grid what a previous figure could: other data, limits, texts, legends."""
    for fig, axes in canvas._POOL.values():
        for ax in axes.flat:
            ax.plot(rng.uniform(1e-9, 1e3, 50), rng.uniform(1e-9, 1e3, 50), color="red", lw=3)
            ax.set_ylim(1e-3, 1e2)
            ax.set_xlabel("junk x")
            ax.set_ylabel("junk y")
            ax.text(0.5, 0.5, "junk", transform=ax.transAxes)
        canvas.legend_at(fig, 1.0, 2.0, "junk legend", [("junk", {"color": "red", "marker": "o"})])
        fig.legend(handles=axes.flat[0].lines[:1], loc="center")
        fig.set_size_inches(3.0, 2.0)


@pytest.mark.parametrize("sc, kind", [("stiff_spring", "errors"), ("stiff_spring", "convergence"),
                                      ("spin_only", "trajectories"), ("spin_only", "work")])
def test_a_figure_drawn_in_a_reused_grid_has_the_pixels_of_a_fresh_one(browser_results, tmp_path, sc, kind):
    res = load_results(browser_results)
    canvas._POOL.clear()
    fresh, again = tmp_path / "fresh", tmp_path / "again"
    fresh.mkdir()
    again.mkdir()
    name = plots.draw(res, sc, kind, fresh)[1]
    assert name is not None
    _litter(np.random.default_rng(0))
    assert plots.draw(res, sc, kind, again)[1] == name
    a, b = _pixels(fresh / name), _pixels(again / name)
    assert a.shape == b.shape and np.array_equal(a, b)


@pytest.mark.parametrize("first, then", [(("spin_only", "trajectories"), ("stiff_spring", "trajectories")),
                                         (("stiff_spring", "trajectories"), ("spin_only", "trajectories")),
                                         (("spin_only", "errors"), ("drop_once", "conservation"))])
def test_a_figure_drawn_after_one_of_more_or_fewer_rows_has_the_pixels_of_a_fresh_one(browser_results, tmp_path,
                                                                                     first, then):
    """A layout's rows are pooled whatever their number: a figure of 1 row drawn after one of 4 (rows
    hidden, its grid laid out anew, the bottom row's x labels moved) and one of 4 after one of 1 (rows
    added) draw what they draw in a fresh grid."""
    res = load_results(browser_results)
    canvas._POOL.clear()
    fresh, again = tmp_path / "fresh", tmp_path / "again"
    fresh.mkdir()
    again.mkdir()
    name = plots.draw(res, *then, fresh)[1]
    canvas._POOL.clear()
    assert plots.draw(res, *first, again)[1] is not None
    _litter(np.random.default_rng(1))
    assert plots.draw(res, *then, again)[1] == name
    a, b = _pixels(fresh / name), _pixels(again / name)
    assert a.shape == b.shape and np.array_equal(a, b)
    (fig, pool), = [v for v in canvas._POOL.values() if v[1][0, 0].get_visible()]
    shown = [row for row in pool if row[0].get_visible()]
    assert [[ax.xaxis.majorTicks[0].label1.get_visible() for ax in row] for row in shown] == \
        [[False] * pool.shape[1]] * (len(shown) - 1) + [[True] * pool.shape[1]]   # x labels under the bottom row only


def _render_texts(canvas_class):
    fig = Figure(figsize=(5.0, 2.5), dpi=90)
    canvas_class(fig)
    for k, (size, ha, va) in enumerate([(7, "left", "center"), (8, "left", "top"), (10, "right", "baseline"),
                                        (11, "center", "bottom"), (7, "left", "bottom")]):
        fig.text(0.1 + 0.4 * (k % 2), 0.15 + 0.17 * k, f"gyp 1e-03 Δt {k} (s) — µ", fontsize=size, ha=ha, va=va)
    fig.text(0.9, 0.5, "a y label, turned a quarter", rotation=90, fontsize=8)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    buf.seek(0)
    return _pixels(buf)


def _mismatch(ours, theirs):
    """(rows, columns): the ink profiles' L1 distance over the ink, down the rows and across the columns
    (columns smoothed over 3 px). Sub-pixel glyph placement moves a label by under half a pixel; a whole
    pixel moves these by ~0.4."""
    a, b = 255.0 - ours.mean(axis=2), 255.0 - theirs.mean(axis=2)
    rows = np.abs(a.sum(axis=1) - b.sum(axis=1)).sum() / b.sum()
    k = np.ones(3) / 3.0
    cols = np.abs(np.convolve(a.sum(axis=0), k, "same") - np.convolve(b.sum(axis=0), k, "same")).sum() / b.sum()
    return rows, cols


def test_labels_rasterized_a_string_at_a_time_land_on_matplotlibs_own_pixels():
    canvas._StringRenderer.string_path = True
    ours, theirs = _render_texts(canvas._Canvas), _render_texts(FigureCanvasAgg)
    assert canvas._StringRenderer.string_path, "the string path fell back to matplotlib's: nothing was measured"
    assert abs((255.0 - ours).sum() / (255.0 - theirs).sum() - 1.0) < 0.01   # the same ink: no glyph lost or doubled
    for part in (np.s_[:, :380], np.s_[:, 380:]):               # horizontal labels; the turned one
        rows, cols = _mismatch(ours[part], theirs[part])
        assert rows < 0.15 and cols < 0.15, (part, rows, cols)
        for shift in ((1, 0), (0, 1)):                           # a label one pixel off is caught
            assert max(_mismatch(np.roll(ours, shift, axis=(0, 1))[part], theirs[part])) > 0.3, (part, shift)


def test_texts_are_laid_out_where_matplotlib_lays_them_out():
    """The report's renderer answers matplotlib's font height question from a per-process cache: every
    text's box (single and multi-line, sizes and turns of the report) is matplotlib's own, to the bit."""
    canvas._HEIGHTS.clear()
    boxes = []
    for canvas_class in (canvas._Canvas, FigureCanvasAgg):
        fig = Figure(figsize=(5.0, 2.5), dpi=90)
        canvas_class(fig)
        texts = [fig.text(0.1, 0.2 + 0.1 * k, s, fontsize=size, rotation=rot, va=va)
                 for k, (s, size, rot, va) in enumerate([("1e-06", 10, 0, "baseline"), ("gyp Δt", 7, 0, "top"),
                                                        ("two\nlines", 8, 0, "center"), ("qw", 8, 90, "bottom"),
                                                        ("tumbling_box: x", 11, 0, "center_baseline")])]
        renderer = fig.canvas.get_renderer()
        boxes.append([t.get_window_extent(renderer).bounds for t in texts])
    assert boxes[0] == boxes[1]
    assert canvas._HEIGHTS and all(None not in v for v in canvas._HEIGHTS.values())   # the cache was asked


def test_a_legend_draws_the_pixels_of_one_line_per_entry():
    """legend_at draws its solid handles as one collection: the same pixels as one Line2D per entry (the
    drawing it replaced), with dashed handles and markers among them."""
    entries = [("course", {"color": "C0"}), ("rk4  p 4.00", {"color": "C1", "marker": "o"}),
               ("dashed", {"color": "C2", "ls": "--", "marker": "s"}), ("thin", {"color": "C3", "lw": 0.9})]

    def draw(own):
        fig = Figure(figsize=(3.0, 1.5), dpi=90)
        canvas._Canvas(fig)
        if own:
            canvas.legend_at(fig, 0.2, 1.3, "reference", entries)
        else:
            from matplotlib.lines import Line2D
            inch, em, y = fig.dpi_scale_trans, 7.0 / 72.0, 1.1
            fig.text(0.2, 1.3, "reference", transform=inch, fontsize=8, va="top", ha="left")
            for label, st in entries:
                xs = [0.25, 0.25 + 1.8 * em]
                fig.add_artist(Line2D(xs, [y, y], transform=inch, color=st["color"], ls=st.get("ls", "-"),
                                      lw=st.get("lw", 1.4)))
                if st.get("marker"):
                    fig.add_artist(Line2D([sum(xs) / 2], [y], transform=inch, color=st["color"], marker=st["marker"],
                                          ms=4, ls="none"))
                fig.text(xs[1] + 0.8 * em, y, label, transform=inch, fontsize=7, va="center", ha="left")
                y -= canvas.LEGEND_LINE_IN
        fig.canvas.draw()
        return np.asarray(fig.canvas.buffer_rgba()).copy()

    ours, theirs = draw(True), draw(False)
    assert (255 - theirs[..., :3]).sum() > 0 and np.array_equal(ours, theirs)


def test_a_ladder_row_at_round_off_is_said_and_a_row_above_its_floor_is_drawn(hostile_results, tmp_path):
    res = load_results(hostile_results)
    kind, fname, note = plots.draw(res, "hostile_spin", "convergence", tmp_path)
    assert fname is not None and "at or below its round-off floor at every Δt" in note and "velocity." in note
    assert "Orders in the legends: position / orientation / angular velocity." in note
    # planted: one variant's coarsest velocity error ten times its floor -> the row is drawn again
    d = tmp_path / "planted"
    shutil.copytree(hostile_results, d)
    s = json.loads((d / "summary.json").read_text())
    rec = next(r for r in s["convergence"] if r["quantity"] == "velocity" and r["engine"] == "reference:rk4")
    rec["errors"][0] = 10 * rec["floors"][0]
    (d / "summary.json").write_text(json.dumps(s))
    note = plots.draw(load_results(d), "hostile_spin", "convergence", tmp_path)[2]
    assert "round-off" not in note and "position / orientation / velocity / angular velocity" in note


def test_pad_limits_widen_like_matplotlib_autoscaling():
    assert canvas.pad_limits(0.0, 10.0, log=False) == pytest.approx((-0.5, 10.5))
    assert canvas.pad_limits(1e-3, 1e1, log=True) == pytest.approx((10 ** -3.2, 10 ** 1.2))
    lo, hi = canvas.pad_limits(2.0, 2.0, log=False)
    assert lo < 2.0 < hi


def test_a_report_drawn_in_this_process_keeps_no_figure(browser_results, tmp_path):
    import reports
    d = tmp_path / "res"
    shutil.copytree(browser_results, d)
    reports.render(d, jobs=1, progress=False)
    assert canvas._POOL == {}
