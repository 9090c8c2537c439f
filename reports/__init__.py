"""rbcheck reports: PNG figures and HTML pages rendered from a saved results directory only.

``render(DIR)`` reads ``DIR/results.csv``, ``DIR/summary.json`` and ``DIR/series/*.npz`` (written by
``rbcheck sweep``) and (re)writes ``DIR/plots/*.png``, ``DIR/index.html`` and one
``DIR/scenario-<name>.html`` per scenario. It never runs a simulation and never imports an engine;
rendering the same data twice gives the same HTML.
"""
from __future__ import annotations

import os
import shutil
import sys
import time
from pathlib import Path

from cross_checks.core.files import umask
from cross_checks.core.progress import Progress, is_tty, stage
from reports.data import Results, ResultsError, load_results
from reports.install import IncompleteInstallation, check_templates

__all__ = ["render", "load_results", "Results", "ResultsError",
           "check_installation", "IncompleteInstallation"]


def check_installation() -> None:
    """IncompleteInstallation (naming the file) when a template the pages need is not installed: the
    commands that end in a report call this before any work."""
    check_templates()


_SHARED: dict = {}   # the loaded results, inherited by forked drawing processes (not reloaded per figure)


def _draw(task):
    from reports import polhode
    from reports.plots import draw
    sc, kind, plot_dir = task
    res = _SHARED.get("res") or load_results(_SHARED["directory"])
    _SHARED["res"] = res
    if kind == polhode.KIND:
        return (sc, *polhode.draw(res, sc, Path(plot_dir)))
    return (sc, *draw(res, sc, kind, Path(plot_dir)))


def _cost(res, sc, kind) -> float:
    from reports import polhode
    from reports.plots import relative_cost
    return polhode.relative_cost(res, sc) if kind == polhode.KIND else relative_cost(res, sc, kind)


def _quiet_init(parent_pid, directory):
    from cross_checks.sweep.lifecycle import worker_init
    worker_init(parent_pid)
    _SHARED.setdefault("directory", directory)   # a spawned process loads the results once


#: Seconds between two progress lines while drawing (as the sweep's: a CI log never looks hung).
LINE_INTERVAL_S = 5.0


def render(directory, *, self_contained: bool = False,
           jobs: int | None = 1, progress: bool | None = None) -> list:
    """(Re)render the report of a results directory; returns the written page paths (HTML; the row
    extracts ``rows/<scenario>.csv`` are written beside them).

    self_contained : embed the PNGs in the pages (data: URIs) so each page stands alone (CI artifacts);
        the PNG files are kept beside them as well.
    jobs : processes drawing figures (one figure each, the loaded results inherited, not re-read);
        1 draws here.
    progress : a line on stderr every LINE_INTERVAL_S while drawing, and one when the pages are written
        (flushed: it reaches a CI log); default: only when stderr is a terminal (library calls stay quiet).
    Raises ResultsError when the directory is not a readable results directory. Every file name comes
    from a sanitised name and is checked to stay inside the directory. Only files the directory's
    marker lists are ever removed (stale plots, pages and row extracts); a directory without the marker
    (written before it existed) gets its pages and plots written, and nothing removed.
    """
    from cross_checks.sweep.results_dir import is_owned_stale, listed_files, owned_name, read_marker

    t0 = time.perf_counter()
    progress = is_tty(sys.stderr) if progress is None else progress
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
        from reports.integrators import draw_figures, integrators_view
        figures = _draw_all(res, names, new_plots, jobs, progress,   # and the integrators page's, meanwhile
                            meanwhile=lambda: draw_figures(res, integrators_view(res), new_plots))
        drawn = _move_plots(new_plots, d / "plots")
    finally:
        shutil.rmtree(new_plots, ignore_errors=True)
    written = _write_pages(res, figures, self_contained)
    _tidy(d, written, drawn, listed, marked)
    pages = [p for p in written if p.suffix == ".html"]
    if progress:   # a flushed line on stdout, like the sweep's (cross_checks.core.progress)
        n_figures = sum(len(kinds) for kinds in figures.values())
        noted = n_figures - len(drawn)
        why = f" ({len(drawn)} drawn, {noted} a note instead: a quantity that does not move)" if noted else ""
        stage("rbcheck report", f"{len(pages)} pages and {n_figures} figures written in "
                                f"{time.perf_counter() - t0:.1f} s{why}")
    return pages


def _write_pages(res, figures, self_contained) -> list:
    from cross_checks.core.files import atomic_write_text
    from cross_checks.sweep.results_dir import inside
    from reports.html import render_pages, rows_extracts
    d = res.directory
    written = []
    for name, text in {**rows_extracts(res),
                       **render_pages(res, figures, self_contained=self_contained)}.items():
        target = inside(d, *name.split("/"))
        target.parent.mkdir(exist_ok=True)
        atomic_write_text(target, text)
        written.append(d / name)
    return written


def _tidy(d, written, drawn, listed, marked) -> None:
    """Remove the plots, pages and extracts rbcheck wrote before that the data no longer has (listed in
    the marker only); list the new ones in the marker."""
    from cross_checks.sweep.results_dir import fix_permissions, write_marker
    keep = {p.relative_to(d).as_posix() for p in written} | {f"plots/{n}" for n in drawn}
    for rel in sorted(listed):
        stale_page = rel.startswith("scenario-") and rel.endswith(".html")
        stale_plot = rel.startswith("plots/") and rel.endswith(".png")
        stale_rows = rel.startswith("rows/") and rel.endswith(".csv")
        if (stale_page or stale_plot or stale_rows) and rel not in keep:
            (d / rel).unlink(missing_ok=True)
    if marked:
        write_marker(d, [f for f in listed | keep if (d / f).is_file()])
    fix_permissions(d)


def _draw_all(res, names, plot_dir: Path, jobs, progress, meanwhile=lambda: []) -> dict:
    """Draw every figure (in ``jobs`` processes, costliest first, each reported as it is done) and call
    ``meanwhile()`` here while they draw; returns ``{scenario: [(kind, file or None, note)]}`` in the
    order of plots.KINDS then the polhode, and ``meanwhile()``'s result under None."""
    # here: forked workers inherit matplotlib
    from reports import polhode
    from reports.plots import KINDS, figure_tasks, release
    kinds = (*KINDS, polhode.KIND)   # the polhode is reports.polhode's, drawn in the report's styles
    tasks = [(sc, kind, str(plot_dir)) for sc in names
             for kind in [k for _, k in figure_tasks(res, sc)] + [polhode.KIND]]
    # the costliest figures first, so that no process is left drawing a large one while the other idles
    tasks.sort(key=lambda t: -_cost(res, t[0], t[1]))
    _SHARED.clear()
    _SHARED.update(res=res, directory=str(res.directory))
    out = {sc: {} for sc in names}
    bar = Progress("rbcheck report", "figures", len(tasks), enabled=progress, interval_s=LINE_INTERVAL_S,
                   # time left follows the cost
                   total_work=sum(_cost(res, t[0], t[1]) for t in tasks))

    def done(item):
        sc, kind, fname, note = item
        out[sc][kind] = (kind, fname, note)
        bar.update(1, f"{sc} {kind}", work=_cost(res, sc, kind))

    try:
        if jobs and jobs > 1 and len(tasks) > 1:
            extra = _draw_in_processes(tasks, min(jobs, len(tasks)), done, res, meanwhile)
        else:
            for t in tasks:
                done(_draw(t))
            extra = meanwhile()
        bar.close()
    finally:
        bar.close(finished=False)   # after an error: the bar ends, no "done" line (a no-op after close())
        _SHARED.clear()
        release()
    return {**{sc: [figs[k] for k in kinds if k in figs] for sc, figs in out.items()}, None: extra}


def _draw_in_processes(tasks, jobs, done, res, meanwhile):
    """``done(_draw(task))`` for every task, drawn in ``jobs`` processes in the order given, and
    ``meanwhile()`` here (returned); forked processes inherit the loaded results and the grids and
    legends :func:`reports.plots.prepare` builds (spawned ones load the directory once each). A drawing
    process's exception is raised here."""
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor, as_completed

    from reports.plots import prepare, release
    ctx = mp.get_context("fork") if "fork" in mp.get_all_start_methods() else None
    if ctx is not None:
        prepare(res)
    with ProcessPoolExecutor(max_workers=jobs, mp_context=ctx, initializer=_quiet_init,
                             initargs=(os.getpid(), _SHARED["directory"])) as pool:
        try:
            futures = [pool.submit(_draw, t) for t in tasks]   # (a signal may land while they are forked)
            release()    # the processes are forked (all at the first submit): what prepare() built is theirs
            extra = meanwhile()
            for f in as_completed(futures):
                done(f.result())
        except KeyboardInterrupt:   # Ctrl-C, SIGTERM: stop the drawing processes now, without waiting
            from cross_checks.core.processes import kill_pool
            kill_pool(pool)
            raise
        finally:
            pool.shutdown(cancel_futures=True)   # after an error: the figures not begun are not drawn
    return extra


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
