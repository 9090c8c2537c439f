"""``rbcheck sweep``: every (scenario, engine variant, Δt) run, its metrics, convergence verdicts, and
the results directory of docs/results.md, written atomically. :func:`run_sweep` runs the stages:

1. plan (:mod:`.plan`): every job, longest first;
2. execute (:mod:`.execute`): each scenario's reference, then the jobs — here, in a process pool or on
   a given executor; a scenario's runs of one variant in one call, each job measured by
   :func:`.jobs.run_job_group` (cached: :mod:`.cache`, :mod:`.fingerprint`);
3. assemble (:mod:`.assemble`): rows, convergence and agreement records, scenario records, series,
   provenance (:mod:`.provenance`), summary;
4. the long runs (:mod:`.long_runs`), when any scenario is a long run (``kind = "long_run"``): every
   variant on each, at its one Δt, judged on what it conserves;
5. write: everything into a staging sibling of DIR, then the caller's ``finish`` (the report), the
   marker, and the swap that replaces DIR only when complete and only when it is rbcheck's own
   (:mod:`.results_dir`).

The files of the results directory: docs/results.md, "Files".
"""
from __future__ import annotations

import dataclasses
import shutil
import signal
import sys
import time
from concurrent.futures.process import BrokenProcessPool
from datetime import UTC, datetime

from cross_checks.core import tolerances as tol
from cross_checks.core.files import atomic_write_text, save_npz_atomic, usable_cores
from cross_checks.core.progress import stage
from cross_checks.sweep import assemble, refine
from cross_checks.sweep.cache import cache_dir
from cross_checks.sweep.execute import Runner, run_jobs, run_references, second_reference_jobs
from cross_checks.sweep.fingerprint import code_fingerprint
from cross_checks.sweep.jobs import (
    LOCAL_SAMPLES,
    MAX_SERIES_POINTS,
    RESULT_COLUMNS,
    SCHEMA_VERSION,
    Job,
    clear_reference_memo,
)
from cross_checks.sweep.lifecycle import (
    Terminated,
    await_group_signal,
    interrupted_by,
    interrupted_exception,
    signals_deferred,
)
from cross_checks.sweep.long_runs import (
    LONG_RUN_COLUMNS,
    judged_rows,
    long_run_scenario_record,
    run_long_runs,
)
from cross_checks.sweep.plan import inexpressible, plan_jobs
from cross_checks.sweep.provenance import provenance, variant_record
from cross_checks.sweep.results_dir import (
    ResultsDirError,
    check_output_dir,
    fix_permissions,
    remove_stale_siblings,
    replace_dir,
    staging_dir,
    write_marker,
)

__all__ = ["RESULT_COLUMNS", "SweepError", "SweepInterrupted", "ReportFailed", "Job", "plan_jobs",
           "run_sweep", "cache_dir", "MAX_SERIES_POINTS", "LOCAL_SAMPLES", "SCHEMA_VERSION", "warm_reference"]


class SweepError(Exception):
    """Bad sweep input (message names the option or file and the reason)."""


class SweepInterrupted(KeyboardInterrupt):
    """Ctrl-C (or SIGTERM: ``terminated``) during a sweep; the previous results directory is untouched."""

    def __init__(self, terminated: bool = False, replaced: bool = False):
        super().__init__()
        self.terminated, self.replaced = terminated, replaced


class ReportFailed(Exception):
    """The results were written, but the report drawn on them raised (a bug of the report): ``summary`` is the
    sweep's, ``error`` the report's exception."""

    def __init__(self, summary: dict, out, error: BaseException):
        super().__init__(f"the report could not be drawn (internal error: {type(error).__name__}: {error}); "
                         f"the results are written in {out}: 'rbcheck report {out}' draws it again")
        self.summary, self.error = summary, error


def _checked_output(out_dir, scenarios):
    """The absolute results directory, after removing what killed runs left beside it (SweepError for an
    output a sweep may not replace, or scenario names given twice)."""
    try:
        out = check_output_dir(str(out_dir))
    except ResultsDirError as exc:
        raise SweepError(str(exc)) from None
    for line in remove_stale_siblings(out):
        print(f"rbcheck sweep: {line} (left by a run that was killed)", file=sys.stderr)
    names = [s.name for s in scenarios]
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise SweepError(f"scenario name(s) given twice: {', '.join(dup)}")
    return out


def run_sweep(scenarios, variants, out_dir, *, jobs: int | None = None, use_cache: bool = True,
              progress: bool | None = None, skipped=None, finish=None,
              executor=None, run_time_limit_s: float | None = tol.RUN_TIME_LIMIT_S,
              reference_time_limit_s: float | None = tol.REFERENCE_TIME_LIMIT_S,
              second_reference: bool = True, invariance: bool = False) -> dict:
    """Run the sweep and write the results directory ``out_dir`` (atomically).

    Parameters
    ----------
    scenarios : list of Scenario (distinct names).
    variants : list of available ``ENGINE:VARIANT`` names (resolved here once, engines.Resolved).
    jobs : worker processes (default: all cores); 1 runs everything in this process.
    use_cache : read cached job results (they are always written).
    skipped : ``{variant: reason}`` of variants left out (recorded in summary.json).
    progress : report progress on stderr (:mod:`cross_checks.core.progress`: a bar in a terminal, a line
        every few seconds elsewhere); default: only when stderr is a terminal.
    finish : ``finish(staging_dir)``, called on the complete results before they replace ``out_dir``
        (e.g. ``reports.render``: the report is then part of the atomic replacement). None: no report.
    run_time_limit_s, reference_time_limit_s : wall-time limits of one run and of one reference solve
        (None: none); a run or reference over its limit is a ``failed`` row saying so.
    second_reference : compute Drake's second reference of every scenario when Drake is installed (False:
        its records are None, as without Drake; `rbcheck bench` times the default sweep this way).
    executor : any ``concurrent.futures.Executor`` to run the jobs on instead of the local process
        pool (e.g. ``distributed.Client(address).get_executor()``); its workers must see the parent
        directory of ``out_dir`` and the cache directory (jobs exchange reference solutions as files).

    Returns the summary dict (as written to summary.json). Raises SweepError (bad input) or
    SweepInterrupted (Ctrl-C: nothing was replaced).
    """
    from cross_checks.engines import resolve
    out = _checked_output(out_dir, scenarios)
    variants = [resolve(v) for v in variants]   # once: every stage below reads what they declare from these
    jobs = max(1, int(jobs or usable_cores()))
    long_scenarios, scenarios = ([s for s in scenarios if getattr(s, "long_run", False) is long]
                                 for long in (True, False))
    cannot = inexpressible(scenarios, variants)
    cannot_long = inexpressible(long_scenarios, variants)
    planned = plan_jobs(scenarios, variants, cannot)
    if executor is None:   # local processes: never more than the runs to do, nor than 4 per core
        long_calls = len(variants) if long_scenarios else 0   # one simulate_many call per variant
        jobs = min(jobs, max(1, len(planned) + len(scenarios) + long_calls), 4 * usable_cores())
    started = datetime.now(UTC).replace(microsecond=0).isoformat()
    show = sys.stderr.isatty() if progress is None else progress
    cache_root = str(cache_dir())
    compile_s = _load_before_forking(variants, show)
    t_start = time.perf_counter()   # the runs and metrics (summary run.wall_s), the compilation apart
    staging = staging_dir(out)
    (work := staging / "_work").mkdir()
    runner = None
    try:
        runner = Runner(jobs, executor)
        refs = run_references(runner, scenarios, work, cache_root, use_cache,
                              reference_time_limit_s, show, variants)
        second = second_reference_jobs(scenarios, refs) if second_reference else []
        records = run_jobs(runner, planned, scenarios, refs, work, cache_root, use_cache,
                           run_time_limit_s, show, second=second, second_time_limit_s=reference_time_limit_s)
        refs = _with_second_references(refs, {s.scenario_index: records.pop(s) for s in second})
        long_records = (run_long_runs(runner, long_scenarios, variants, cache_root, use_cache,
                                      run_time_limit_s, show, cannot_long) if long_scenarios else {})
        stage("rbcheck sweep", "writing results.csv, summary.json and series/", enabled=show)
        summary = _write_results(staging, scenarios, variants, refs, records, started=started,
                                 skipped=skipped, jobs=jobs, t_start=t_start,
                                 cannot={**cannot, **cannot_long}, runner=runner,
                                 run_time_limit_s=run_time_limit_s,
                                 long_scenarios=long_scenarios, long_records=long_records,
                                 compile_s=compile_s, invariance=invariance, show=show)
        runner.close()
        runner = None
        report_error = _publish(staging, out, finish)
        staging = None
        if report_error is not None:
            raise ReportFailed(summary, out, report_error) from report_error
        return summary
    except BaseException as exc:
        _clean_up(exc, runner, staging)   # SweepInterrupted for a signal
        raise


def _publish(staging, out, finish):
    """Draw the report in the complete results ``staging`` (``finish``, from the saved files only), mark them
    and put them in place of ``out``. Returns the report's error, or None: a report-side bug never throws the
    results away (a signal's exception that Python turned into another, in an import, is the signal's)."""
    report_error = None
    if finish is not None:
        try:
            finish(staging)
        except Exception as exc:  # noqa: BLE001 - kept, raised by the caller once the results are in place
            if interrupted_by():
                raise interrupted_exception(interrupted_by()) from None
            report_error = exc
    write_marker(staging)
    fix_permissions(staging)
    replace_dir(staging, out)
    return report_error


def _clean_up(exc, runner, staging) -> None:
    """After ``exc`` stopped the sweep: the workers killed and the staging directory removed (``out`` as it
    was, or already the complete new results), to its end whatever signal comes meanwhile (timeout forwarding
    Ctrl-C, a worker killed by the same SIGTERM breaking the pool before the signal reached here). Raises
    SweepInterrupted for Ctrl-C or a signal; otherwise returns, for the caller to re-raise ``exc``."""
    with signals_deferred() as pending:
        if runner is not None:
            runner.close(kill=True)
        replaced = staging is None or not staging.exists()   # after the swap: the new results complete
        if staging is not None:
            shutil.rmtree(staging, ignore_errors=True)
        if isinstance(exc, BrokenProcessPool) and not pending:
            await_group_signal(pending)   # workers killed by a SIGTERM sent to the whole group
    if isinstance(exc, KeyboardInterrupt) or pending:
        terminated = isinstance(exc, Terminated) or (not isinstance(exc, KeyboardInterrupt)
                                                     and pending[0] == signal.SIGTERM)
        raise SweepInterrupted(terminated, replaced=replaced) from None


def _load_before_forking(variants, show: bool = False) -> float:
    """What every worker needs, computed once here so that forked workers inherit it: each engine's code
    fingerprint, when the reference runs, its compiled steps, and, when MuJoCo or MuJoCo Warp runs, the
    compiled conversion of their records (engines.packed_rows: a fraction of a second). Returns the seconds
    spent compiling the reference's (0 when they were cached); the first time on a machine a line says what
    is compiled and for about how long (:func:`warm_reference`)."""
    engines = list(dict.fromkeys(["reference", *(v.split(":", 1)[0] for v in variants)]))
    for engine in engines:
        code_fingerprint(engine)
    if {"mujoco", "mujoco_warp"} & set(engines):
        from cross_checks.engines import packed_rows
        packed_rows.warm()
    if any(v.startswith("reference:") for v in variants):
        return warm_reference("rbcheck sweep", show)
    return 0.0


def warm_reference(prefix: str, show: bool, notice_after_s: float = tol.COMPILE_NOTICE_AFTER_S,
                   stream=None) -> float:
    """Load (the first time on a machine: compile) the reference's numba kernels; returns the seconds it
    took when it compiled, else 0.

    Loading cached kernels takes well under ``notice_after_s``; when it takes longer, they are being
    compiled: one line then says so, what and for about how long, while it happens (a cold first run
    would otherwise say nothing for a minute), and one more when it is done."""
    from cross_checks.core.processes import with_timer
    from reference_sim import compiled
    t0 = time.perf_counter()

    def notice():
        stage(prefix, f"compiling the reference's {len(compiled.VARIANT_CODES)} integrators with numba, once "
                      f"per machine: {compiled.COMPILE_ESTIMATE_S}; cached for every later run", enabled=show,
              stream=stream)
    said = with_timer(compiled.warm, notice_after_s, notice)
    took = time.perf_counter() - t0
    if said:
        stage(prefix, f"compiled the reference's integrators in {took:.0f} s", enabled=show, stream=stream)
        return took
    return 0.0


def _with_second_references(refs, second: dict) -> list:
    """Each scenario's reference with ``measured["second_reference"]``: its record from ``second``
    {scenario index: record}, None when it has none (Drake not installed, or no reference)."""
    return [dataclasses.replace(r, measured={**(r.measured or {}), "second_reference": second.get(i)})
            for i, r in enumerate(refs)]


def _write_results(staging, scenarios, variants, refs, records, *, started, skipped, jobs, t_start,
                   cannot=None, runner, run_time_limit_s=tol.RUN_TIME_LIMIT_S, long_scenarios=(),
                   long_records=None, compile_s: float = 0.0, invariance: bool = False,
                   show: bool = False) -> dict:
    """Assemble the job records and write results.csv, series/ and summary.json into ``staging`` (its
    work directory removed) — and, with long runs, long_runs.csv and their series; returns the summary. The
    continued ladders of :mod:`.refine` run on ``runner``."""
    from cross_checks.engines import all_variants
    rows = assemble.result_rows(records, [s.name for s in scenarios], variants)
    atomic_write_text(staging / "results.csv", assemble.results_csv_text(rows))
    assemble.write_scenario_files(staging, scenarios)
    by_key = {(j.scenario, j.variant, j.dt_s): rec for j, rec in records.items()}
    local, scenario_records, free = [], [], []
    (staging / "series").mkdir()
    for sc, ref in zip(scenarios, refs):
        scenario_records.append(assemble.scenario_record(sc, ref))
        for v in variants:
            if (sc.name, v) in (cannot or {}):
                continue
            vrows = [r for r in rows if r["scenario"] == sc.name and r["engine"] == v]
            recs = assemble.convergence_records(sc, v, vrows, ref.scales, "free_running", ref.measured)
            free.append((sc, v, vrows, ref, recs, refine.requests(sc, v, vrows, ref, recs)))
            if v.one_step:  # engines without a one-step mode have no local errors to fit
                local += assemble.convergence_records(sc, v, vrows, ref.scales, "one_step", ref.measured)
        save_npz_atomic(staging / "series" / f"{sc.name}.npz",
                        assemble.series_arrays(sc, ref, by_key, variants))
    fine = refine.run_refinements(runner, [f[-1] for f in free if f[-1] is not None], run_time_limit_s)
    convergence = [rec for sc, v, vrows, ref, recs, _ in free
                   for rec in refine.rejudge(sc, v, vrows, ref, recs, fine.get((sc.name, v)))]
    clear_reference_memo()
    infos = {v.name: v for v in all_variants()}
    shutil.rmtree(staging / "_work")
    summary = assemble.build_summary(
        provenance=provenance(started, variants), scenarios=scenario_records,
        variants=[variant_record(v, infos.get(v)) for v in variants], skipped=skipped,
        convergence=convergence, local=local,
        agreement=assemble.agreement_records(scenarios, variants, by_key, refs), rows=rows, jobs=jobs,
        wall_s=time.perf_counter() - t_start, cannot=cannot)
    summary["run"]["compile_s"] = round(compile_s, 3)   # before the runs (wall_s): the reference's kernels
    if long_scenarios:
        _write_long_runs(staging, summary, long_scenarios, variants, long_records or {})
    if invariance:
        _write_invariance(staging, summary, scenarios, variants, refs, cannot or {}, show, runner)
    from cross_checks.sweep.repro import write_sweep_reproducers  # each finding's standalone script
    summary["reproducers"] = write_sweep_reproducers(staging, summary, [*scenarios, *long_scenarios])
    if summary["reproducers"]:
        summary["files"]["repro"] = "repro/*.py: a standalone reproducer of each finding (docs/repro.md)"
    assemble.write_json(staging / "summary.json", summary)
    return summary


def _write_invariance(staging, summary, scenarios, variants, refs, cannot, show, runner) -> None:
    """invariance.csv, summary.json's ``invariance`` and ``run.invariance`` (docs/invariance.md): every
    variant on every convergence scenario it can express, on the sweep's workers, with the scales and error
    amplification the sweep measured for the scenario's floors."""
    from cross_checks.sweep import invariance as inv
    from cross_checks.sweep.invariance import INVARIANCE_COLUMNS, invariance_summary, run_invariance
    rows = run_invariance(runner, scenarios, variants, refs, cannot, show)
    atomic_write_text(staging / "invariance.csv", assemble.results_csv_text(rows, INVARIANCE_COLUMNS))
    summary["invariance"], summary["run"]["invariance"] = invariance_summary(rows)
    summary["invariance_declared"] = inv.declared_summary(rows)
    summary["files"]["invariance"] = "invariance.csv (docs/invariance.md)"


def _write_long_runs(staging, summary, long_scenarios, variants, long_records) -> None:
    """long_runs.csv, series/<long run>.npz and the summary's ``long_run_scenarios``, ``long_runs`` and
    ``run.long_runs`` (docs/results.md, "Long runs")."""
    import math
    rows, recs = judged_rows(long_records, long_scenarios, variants)
    atomic_write_text(staging / "long_runs.csv", assemble.results_csv_text(rows, LONG_RUN_COLUMNS))
    for sc in long_scenarios:
        arrays = {f"{v}::{k}": a for v in variants for k, a in
                  ((long_records.get((sc.name, v)) or {}).get("series") or {}).items()}
        if arrays:
            save_npz_atomic(staging / "series" / f"{sc.name}.npz", arrays)
    summary["long_run_scenarios"] = [long_run_scenario_record(sc) for sc in long_scenarios]
    summary["long_runs"] = recs
    summary["files"]["long_runs"] = ("long_runs.csv; series/<long run>.npz: keys '<ENGINE:VARIANT>::<field>' "
                                     "(t_s, energy_rel, momentum_rel, direction_rad, separatrix), float32, "
                                     f"<= {tol.LONG_RUN_SERIES_POINTS} points")
    summary["run"]["long_runs"] = {
        "runs": len(rows), "cached_runs": sum(bool(r["cached"]) for r in rows),
        "diverged_runs": sum(r["status"] == "diverged" for r in rows),
        "failed_runs": sum(r["status"] == "failed" for r in rows),
        "wall_s_in_runs": float(sum(r["wall_s"] for r in rows
                                    if isinstance(r["wall_s"], float) and math.isfinite(r["wall_s"])))}
