"""rbcheck reports: PNG figures and HTML pages rendered from a saved results directory only.

``render(DIR)`` reads ``DIR/results.csv``, ``DIR/summary.json`` and ``DIR/series/*.npz`` (written by
``rbcheck sweep``) and (re)writes ``DIR/plots/*.png``, ``DIR/index.html`` and one
``DIR/scenario-<name>.html`` per scenario. It never runs a simulation and never imports an engine;
rendering the same data twice gives the same HTML.
"""
from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

from .data import Results, ResultsError, load_results

__all__ = ["render", "load_results", "Results", "ResultsError"]


def _draw(directory: str, scenario: str, plot_dir: str):
    from .plots import scenario_figures
    res = load_results(directory)
    return scenario, scenario_figures(res, scenario, Path(plot_dir))


def _quiet_init():
    import signal
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def render(directory, *, self_contained: bool = False, jobs: int | None = 1) -> list:
    """(Re)render the report of a results directory; returns the written page paths.

    self_contained : embed the PNGs in the pages (data: URIs) so each page stands alone (CI artifacts);
        the PNG files are kept beside them as well.
    jobs : processes drawing figures (one scenario each); 1 draws here.
    Raises ResultsError when the directory is not a readable results directory.
    """
    from .html import page_name, render_pages
    from cross_checks.trajectory import atomic_write_text

    d = Path(directory)
    res = load_results(d)
    names = [s["name"] for s in res.scenarios]
    new_plots = Path(tempfile.mkdtemp(prefix=".plots.", dir=d))
    try:
        figures = {}
        if jobs and jobs > 1 and len(names) > 1:
            import multiprocessing as mp
            from concurrent.futures import ProcessPoolExecutor
            ctx = mp.get_context("fork") if "fork" in mp.get_all_start_methods() else None
            with ProcessPoolExecutor(max_workers=min(jobs, len(names)), mp_context=ctx,
                                     initializer=_quiet_init) as pool:
                for sc, figs in pool.map(_draw, [str(d)] * len(names), names, [str(new_plots)] * len(names)):
                    figures[sc] = figs
        else:
            for sc in names:
                figures[sc] = _draw(str(d), sc, str(new_plots))[1]
        os.chmod(new_plots, 0o777 & ~_umask())
        old = d / "plots"
        if old.exists():
            trash = Path(tempfile.mkdtemp(prefix=".plots-old.", dir=d))
            trash.rmdir()
            os.replace(old, trash)
            os.replace(new_plots, old)
            shutil.rmtree(trash, ignore_errors=True)
        else:
            os.replace(new_plots, old)
        new_plots = None
    finally:
        if new_plots is not None:
            shutil.rmtree(new_plots, ignore_errors=True)
    pages = render_pages(res, figures, self_contained=self_contained)
    written = []
    for name, html in pages.items():
        atomic_write_text(d / name, html)
        written.append(d / name)
    # pages of scenarios that are no longer in the results
    keep = {page_name(n) for n in names}
    for p in d.glob("scenario-*.html"):
        if p.name not in keep:
            p.unlink()
    fix_permissions(d)
    return written


def _umask() -> int:
    m = os.umask(0)
    os.umask(m)
    return m


def fix_permissions(directory) -> None:
    """Give files written through temporary files (mode 0600) the usual modes under the umask."""
    m = _umask()
    for root, dirs, files in os.walk(directory):
        os.chmod(root, 0o777 & ~m)
        for f in files:
            os.chmod(os.path.join(root, f), 0o666 & ~m)
