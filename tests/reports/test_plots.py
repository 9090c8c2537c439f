"""reports.plots: what makes the report cheap to draw must not change what it shows.

A figure drawn in a grid kept from earlier figures (of the same layout, more or fewer rows, littered
with data, labels and legends) has the pixels of one drawn in a fresh grid; a row of errors that are
all at round-off is said in the caption instead of drawn, and a row with one error above its floor is
drawn; a report drawn in the caller's process keeps no figure; a drawing process's error reaches the
caller.
"""
import gc
import json
import shutil
import weakref

import numpy as np
import pytest
from PIL import Image

import reports
from reports import canvas, plots
from reports.data import load_results
from reports.ranking import run_cost_s
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


def _draw_keeping(res, sc, kind, folder, monkeypatch):
    """Draw one figure into ``folder``; returns its file name and the figure it was drawn in."""
    kept = {}

    def save(fig, path):
        kept["fig"] = fig
        save_png(fig, path)

    save_png = canvas.save_png
    monkeypatch.setattr(canvas, "save_png", save)
    folder.mkdir(exist_ok=True)
    name = plots.draw(res, sc, kind, folder)[1]
    monkeypatch.setattr(canvas, "save_png", save_png)
    assert name is not None
    return name, kept["fig"]


def _litter(fig, rng):
    """Leave in a kept grid what a previous figure could: other data, limits, labels, texts, a legend."""
    for ax in fig.axes:
        ax.plot(rng.uniform(1e-9, 1e3, 50), rng.uniform(1e-9, 1e3, 50), color="red", lw=3)
        ax.set_ylim(1e-3, 1e2)
        ax.set_xlabel("junk x")
        ax.set_ylabel("junk y")
        ax.text(0.5, 0.5, "junk", transform=ax.transAxes)
    fig.text(0.5, 0.5, "junk legend")
    fig.set_size_inches(3.0, 2.0)


@pytest.mark.parametrize("sc, kind", [("stiff_spring", "errors"), ("stiff_spring", "convergence"),
                                      ("spin_only", "trajectories"), ("spin_only", "work")])
def test_a_figure_drawn_in_a_kept_grid_has_the_pixels_of_a_fresh_one(browser_results, tmp_path, monkeypatch,
                                                                     sc, kind):
    res = load_results(browser_results)
    plots.release()
    name, fig = _draw_keeping(res, sc, kind, tmp_path / "fresh", monkeypatch)
    _litter(fig, np.random.default_rng(0))
    again, fig_again = _draw_keeping(res, sc, kind, tmp_path / "again", monkeypatch)
    assert again == name and fig_again is fig          # the grid was kept
    a, b = _pixels(tmp_path / "fresh" / name), _pixels(tmp_path / "again" / name)
    assert a.shape == b.shape and np.array_equal(a, b)


@pytest.mark.parametrize("first, then", [(("spin_only", "trajectories"), ("stiff_spring", "trajectories")),
                                         (("stiff_spring", "trajectories"), ("spin_only", "trajectories")),
                                         (("spin_only", "errors"), ("drop_once", "conservation"))])
def test_a_figure_drawn_after_one_of_more_or_fewer_rows_has_the_pixels_of_a_fresh_one(
        browser_results, tmp_path, monkeypatch, first, then):
    """A layout's panels are kept whatever the number of rows: a figure of 1 row drawn after one of 4
    (rows hidden, its grid laid out anew, the bottom row's x labels moved) and one of 4 after one of 1
    (rows added) draw what they draw in a fresh grid, x tick labels under the bottom row only."""
    res = load_results(browser_results)
    plots.release()
    name, _ = _draw_keeping(res, *then, tmp_path / "fresh", monkeypatch)
    plots.release()
    _, fig = _draw_keeping(res, *first, tmp_path / "first", monkeypatch)
    _litter(fig, np.random.default_rng(1))
    again, fig_again = _draw_keeping(res, *then, tmp_path / "again", monkeypatch)
    assert again == name and fig_again is fig
    a, b = _pixels(tmp_path / "fresh" / name), _pixels(tmp_path / "again" / name)
    assert a.shape == b.shape and np.array_equal(a, b)
    shown = [ax for ax in fig.axes if ax.get_visible()]
    bottom = min(ax.get_position().y0 for ax in shown)
    assert [ax.xaxis.get_tick_params()["labelbottom"] for ax in shown] == \
        [ax.get_position().y0 == bottom for ax in shown]      # x labels under the bottom row only


def test_the_work_figure_puts_each_run_at_the_engines_own_time_as_the_ranking_does(browser_results, tmp_path,
                                                                                   monkeypatch):
    """Issue 43: a run's cost is the time inside the engine (ranking.run_cost_s: ``engine_s``), not its wall
    time, which holds rbcheck's own; a scenario's work-precision figure reads the cost the ranking reads."""
    res = load_results(browser_results)
    plots.release()
    _, fig = _draw_keeping(res, "spin_only", "work", tmp_path, monkeypatch)
    rows = [r for v in res.variants for r in res.rows_for("spin_only", v)
            if r["in_ladder"] and r["status"] == "ok"]
    assert all(r["wall_s"] > run_cost_s(r) for r in rows)   # the two differ: the figure tells which it drew
    cost = [run_cost_s(r) for r in rows]
    for ax in fig.axes[:1]:
        assert (ax.dataLim.x0, ax.dataLim.x1) == (pytest.approx(min(cost)), pytest.approx(max(cost)))
        assert ax.get_xlabel().startswith("time inside the engine")


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


def test_a_report_drawn_in_this_process_keeps_no_figure(browser_results, tmp_path, monkeypatch):
    figures = []
    save_png = canvas.save_png
    monkeypatch.setattr(canvas, "save_png",
                        lambda fig, path, **kw: (figures.append(weakref.ref(fig)), save_png(fig, path, **kw)))
    d = tmp_path / "res"
    shutil.copytree(browser_results, d)
    reports.render(d, jobs=1, progress=False)
    gc.collect()
    gc.collect()   # the integrators page's shared axes: weak references whose callbacks free the rest
    assert figures and all(ref() is None for ref in figures)


def _fail_on_spin(res, sc, kind, plot_dir):
    if sc == "spin_only":
        raise ValueError("planted failure on spin_only")
    return kind, None, ""


def test_a_drawing_process_error_reaches_the_caller(browser_results, tmp_path, monkeypatch):
    """The figures are drawn in forked processes that inherit the planted failure."""
    d = tmp_path / "res"
    shutil.copytree(browser_results, d)
    monkeypatch.setattr(plots, "draw", _fail_on_spin)
    with pytest.raises(ValueError, match="planted failure on spin_only"):
        reports.render(d, jobs=2, progress=False)
