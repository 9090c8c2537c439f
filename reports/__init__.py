"""rbcheck reports: PNG figures and HTML pages rendered from a saved results directory only.

``render(DIR)`` reads ``DIR/results.csv``, ``DIR/summary.json`` and ``DIR/series/*.npz`` (written by
``rbcheck sweep``) and (re)writes ``DIR/plots/*.png``, ``DIR/index.html`` and one
``DIR/scenario-<name>.html`` per scenario. It never runs a simulation and never imports an engine;
rendering the same data twice gives the same HTML.
"""
from __future__ import annotations

import os
import shutil
from pathlib import Path

from cross_checks.core.files import umask
from reports.data import Results, ResultsError, load_results

__all__ = ["render", "load_results", "Results", "ResultsError"]


def _draw(directory: str, scenario: str, plot_dir: str):
    from reports.plots import scenario_figures
    res = load_results(directory)
    return scenario, scenario_figures(res, scenario, Path(plot_dir))


def _quiet_init(parent_pid):
    from cross_checks.sweep.lifecycle import worker_init
    worker_init(parent_pid)


def render(directory, *, self_contained: bool = False, jobs: int | None = 1) -> list:
    """(Re)render the report of a results directory; returns the written page paths.

    self_contained : embed the PNGs in the pages (data: URIs) so each page stands alone (CI artifacts);
        the PNG files are kept beside them as well.
    jobs : processes drawing figures (one scenario each); 1 draws here.
    Raises ResultsError when the directory is not a readable results directory. Every file name comes
    from a sanitised name and is checked to stay inside the directory. Only files the directory's
    marker lists are ever removed (stale plots and pages); a directory without the marker (written
    before it existed) gets its pages and plots written, and nothing removed.
    """
    from reports.html import render_pages
    from cross_checks.core.files import atomic_write_text
    from cross_checks.sweep.results_dir import (fix_permissions, inside, is_owned_stale, listed_files, owned_name,
                                                read_marker, write_marker)

    d = Path(directory)
    res = load_results(d)
    names = [s["name"] for s in res.scenarios]
    for p in d.iterdir():  # drawing folders of a report that was killed
        if p.is_dir() and is_owned_stale(p.name, ".", "plots"):
            shutil.rmtree(p, ignore_errors=True)
    marked = read_marker(d) is not None
    listed = listed_files(d)
    new_plots = d / owned_name(".", "plots")
    new_plots.mkdir()
    try:
        figures = _draw_all(d, names, new_plots, jobs)
        drawn = _move_plots(new_plots, d / "plots")
    finally:
        shutil.rmtree(new_plots, ignore_errors=True)
    pages = render_pages(res, figures, self_contained=self_contained)
    written = []
    for name, html in pages.items():
        atomic_write_text(inside(d, name), html)
        written.append(d / name)
    # plots and pages rbcheck wrote before that the data no longer has (listed in the marker only)
    keep = {p.name for p in written} | {f"plots/{n}" for n in drawn}
    for rel in sorted(listed):
        stale_page = rel.startswith("scenario-") and rel.endswith(".html") and rel not in keep
        stale_plot = rel.startswith("plots/") and rel.endswith(".png") and rel not in keep
        if stale_page or stale_plot:
            (d / rel).unlink(missing_ok=True)
    if marked:
        write_marker(d, [f for f in listed | keep if (d / f).is_file()])
    fix_permissions(d)
    return written


def _draw_all(d: Path, names, plot_dir: Path, jobs) -> dict:
    figures = {}
    if jobs and jobs > 1 and len(names) > 1:
        import multiprocessing as mp
        from concurrent.futures import ProcessPoolExecutor
        ctx = mp.get_context("fork") if "fork" in mp.get_all_start_methods() else None
        with ProcessPoolExecutor(max_workers=min(jobs, len(names)), mp_context=ctx,
                                 initializer=_quiet_init, initargs=(os.getpid(),)) as pool:
            for sc, figs in pool.map(_draw, [str(d)] * len(names), names, [str(plot_dir)] * len(names)):
                figures[sc] = figs
    else:
        for sc in names:
            figures[sc] = _draw(str(d), sc, str(plot_dir))[1]
    return figures


def _move_plots(src: Path, plots: Path) -> list:
    """Move the freshly drawn PNGs into ``plots/`` one by one (a file there that the user put in
    stays); returns their names."""
    if plots.is_symlink() or (plots.exists() and not plots.is_dir()):
        raise ResultsError(f"{plots}: exists and is not a directory")
    plots.mkdir(exist_ok=True)
    names = sorted(p.name for p in src.glob("*.png"))
    for n in names:
        os.chmod(src / n, 0o666 & ~umask())
        os.replace(src / n, plots / n)
    return names
