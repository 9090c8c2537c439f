"""Executing a sweep's work: the references (one per scenario, before the runs), then the jobs.

Work runs in this process (``jobs == 1``), in a ``concurrent.futures.ProcessPoolExecutor`` whose workers
die with the sweep (:func:`cross_checks.sweep.lifecycle.worker_init`), or on any executor the caller
gives (e.g. a Dask cluster's ``Client.get_executor()``). Jobs exchange reference solutions as files in
the sweep's work directory. A diverged run is a row with status ``diverged``; an engine exception, a
harness error, or a worker process that dies is a row with status ``failed`` and the message — the
sweep goes on.
"""
from __future__ import annotations

import itertools
import os
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from pathlib import Path

from cross_checks.core.processes import kill_pool
from cross_checks.sweep.jobs import (
    failed_record,
    failed_second_reference,
    reference_job,
    run_job_group,
    second_reference_job,
)
from cross_checks.sweep.lifecycle import worker_init

__all__ = ["Runner", "ScenarioReference", "SecondReference",
           "run_references", "run_jobs", "second_reference_jobs"]

#: The end of an iterable of items (``next(items, _END)``).
_END = object()


class Runner:
    """Runs callables here (jobs == 1), in a process pool, or on the caller's executor (used as it is:
    never shut down or replaced here), yielding results as they finish."""

    def __init__(self, jobs: int, executor=None):
        self.jobs = jobs
        self.external = executor is not None
        self.submitted = []
        self.pool = executor if self.external else (self._new_pool() if jobs > 1 else None)

    def _new_pool(self):
        import multiprocessing as mp
        ctx = mp.get_context("fork") if "fork" in mp.get_all_start_methods() else None
        return ProcessPoolExecutor(max_workers=self.jobs, mp_context=ctx, initializer=worker_init,
                                   initargs=(os.getpid(),))

    def map_unordered(self, fn, items, on_done=None, on_crash=None, in_flight=None, window=None):
        """``fn(item)`` for each item; returns ``[(item, result)]`` in completion order.

        ``items`` may be any iterable: it is read as work is submitted, at most ``window`` items in
        flight (None: all of them at once), so a generator can decide whether to yield more (e.g. while a
        time budget lasts). A worker that dies (e.g. a crash inside an engine) breaks the pool, and every
        unfinished item fails with BrokenProcessPool. ``in_flight(item)`` says whether an item was running
        at that moment: those are re-run one at a time in a fresh pool, so a crash names its own item,
        whose result is then ``on_crash(item)``; the others are simply resubmitted.
        """
        out = []

        def record(it, r):
            out.append((it, r))
            if on_done:
                on_done(it, r)

        items = iter(items)
        if self.pool is None:
            for it in items:
                record(it, fn(it))
            return out
        todo: list = []
        isolate: list = []
        while True:
            for it in isolate:
                record(it, self._run_alone(fn, it, on_crash))
            todo, isolate = self._round(fn, itertools.chain(todo, items), record, in_flight, window)
            if not todo and not isolate:
                return out

    def _run_alone(self, fn, item, on_crash):
        """``fn(item)`` with nothing else in the pool, so a crash is this item's: ``on_crash(item)``."""
        try:
            return self.pool.submit(fn, item).result()
        except BrokenProcessPool:
            self._renew()
            if on_crash is None:
                raise
            return on_crash(item)

    def _round(self, fn, items, record, in_flight, window):
        """Submit the items (at most ``window`` in flight) and record the results until the items run out or
        the pool breaks; returns ``(to resubmit, to run alone)``: the items a broken pool did not finish,
        split by whether they were running when it broke."""
        futs: dict = {}
        todo: list = []
        isolate: list = []
        broken = False
        while True:
            while not broken and (window is None or len(futs) < window):
                it = next(items, _END)
                if it is _END:
                    break
                try:
                    f = self.pool.submit(fn, it)
                except BrokenProcessPool:
                    broken = True
                    todo.append(it)
                    break
                futs[f] = it
                if self.external:
                    self.submitted.append(f)
            if not futs:
                break
            done, _ = wait(set(futs), return_when=FIRST_COMPLETED)
            for f in done:
                it = futs.pop(f)
                try:
                    r = f.result()
                except BrokenProcessPool:
                    broken = True
                    (isolate if in_flight is not None and in_flight(it) else todo).append(it)
                    continue
                record(it, r)
        if broken:
            if not isolate and in_flight is None:
                raise BrokenProcessPool("a worker process died")
            self._renew()
        return todo, isolate

    def _renew(self):
        if self.external:
            raise BrokenProcessPool("a worker of the external executor died")
        self.pool.shutdown(wait=True, cancel_futures=True)
        self.pool = self._new_pool()

    def close(self, kill=False):
        if self.pool is None:
            return
        if self.external:
            if kill:
                for f in self.submitted:
                    f.cancel()
            self.pool = None
            return
        if kill:
            kill_pool(self.pool)
        else:
            self.pool.shutdown(wait=True)
        self.pool = None


# --- the references ---------------------------------------------------------------------------------

@dataclass(frozen=True)
class ScenarioReference:
    """The reference of one scenario in a sweep: its file (npz: t_s, y, label, in the work directory)
    and what :func:`cross_checks.sweep.jobs.reference_job` returned for it (``error`` "" unless the
    solve failed, in which case every job of the scenario is a failed row saying why)."""

    path: str
    label: str
    error: str
    scales: dict
    varies: dict
    measured: dict


class _ReferenceTask:
    """One scenario's reference solve, by index (a small pickle for the workers)."""

    def __init__(self, scenarios, work_dir, cache_root, use_cache, time_limit_s, variants=()):
        self.scenarios, self.work_dir, self.cache_root, self.use_cache = (scenarios, work_dir,
                                                                          cache_root, use_cache)
        self.time_limit_s, self.variants = time_limit_s, tuple(variants)

    def path(self, i):
        return str(Path(self.work_dir) / f"ref_{i}.npz")

    def __call__(self, i):
        return reference_job(self.scenarios[i], self.path(i), self.cache_root, self.use_cache,
                             self.time_limit_s, self.variants)


def _reference_cost(scenario):
    """Sort key, most expensive first: a DOP853 reference (many solves: the reference, its check, the
    amplification, the one-step starts) before a closed form, then the longer union grid. In a pool the
    slowest solve then starts at once instead of last, and the others share the remaining workers."""
    from cross_checks.scenario.references import analytic_available
    dop853 = scenario.reference == "ground_truth" or not analytic_available(scenario)[0]
    return (not dop853, -scenario.duration_s / min(scenario.dt_ladder_s + (scenario.dt_s,)))


def run_references(runner: Runner, scenarios, work_dir, cache_root, use_cache, time_limit_s,
                   show_progress: bool = False, variants=()) -> list:
    """The :class:`ScenarioReference` of every scenario, in the order of ``scenarios``, on the time grids of
    every Δt the ``variants`` run."""
    from cross_checks.core.progress import Progress
    task = _ReferenceTask(scenarios, str(work_dir), cache_root, use_cache, time_limit_s, variants)
    with Progress("rbcheck sweep", "references", len(scenarios), enabled=show_progress) as bar:
        order = sorted(range(len(scenarios)), key=lambda i: _reference_cost(scenarios[i]))
        results = dict(runner.map_unordered(task, order, lambda i, _r: bar.update(1, scenarios[i].name)))
    return [ScenarioReference(task.path(i), *results[i]) for i in range(len(scenarios))]


# --- the jobs ---------------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)  # hashed by identity: the parent keys its records by its own items
class SecondReference:
    """The job of a scenario's second reference (Drake's;
    :func:`cross_checks.sweep.jobs.second_reference_job`), run among the runs, longest first: nothing
    waits for it but the summary."""

    scenario_index: int
    scenario: str
    measured: dict
    cost: float = 0.0  # not counted in the runs' progress


def _run_job_item(item):
    """``item`` = (jobs, scenario, ref_path, cache_root, use_cache, user_engines, time_limit_s, marker): one
    small pickle per group of jobs — the jobs of one scenario and variant, whose records are returned in
    order (:func:`cross_checks.sweep.jobs.run_job_group`: their runs in one ``simulate_many`` call) — or
    per :class:`SecondReference` (``jobs``: that scenario's second reference, its record returned).

    ``user_engines`` are the parent's engine-file adapters (a worker that was not forked from the
    parent, e.g. on Dask, registers them here). ``marker`` (a file path) exists while the item runs,
    so after a worker crash the parent knows which items were in flight. Any error of the harness
    itself becomes failed rows, so one bad job never stops the sweep.
    """
    jobs, scenario, ref_path, cache_root, use_cache, user_engines, time_limit_s, marker = item
    Path(marker).touch()
    if isinstance(jobs, SecondReference):
        try:
            return second_reference_job(scenario, ref_path, jobs.measured,
                                        cache_root, use_cache, time_limit_s)
        except Exception as exc:  # noqa: BLE001 - said in the scenario's record, the sweep goes on
            return failed_second_reference(f"internal error: {type(exc).__name__}: {exc}")
        finally:
            Path(marker).unlink(missing_ok=True)
    try:
        from cross_checks.engines import adopt_user_engines
        adopt_user_engines(user_engines)
        return run_job_group(list(jobs), scenario, ref_path, cache_root, use_cache, time_limit_s)
    except Exception as exc:  # noqa: BLE001
        why = f"internal error while measuring the run: {type(exc).__name__}: {exc}"
        return [failed_record(job, scenario, why) for job in jobs]
    finally:
        Path(marker).unlink(missing_ok=True)


def _in_flight(item) -> bool:
    return Path(item[-1]).exists()


def _crashed(item):
    """The result of an item whose worker died with nothing else running: the second reference's record,
    the job's failed record (a group of one), or None for a group of several (its jobs then run one by
    one, so that the crash is one job's)."""
    Path(item[-1]).unlink(missing_ok=True)
    if isinstance(item[0], SecondReference):
        return failed_second_reference("the worker process died computing it (a crash inside Drake?)")
    if len(item[0]) > 1:
        return None
    return [failed_record(item[0][0], item[1],
                          "the worker process died running this job, alone (a crash inside the engine?)")]


def second_reference_jobs(scenarios, references) -> list:
    """A :class:`SecondReference` per scenario whose reference exists, when Drake is installed (else none:
    the records stay None)."""
    try:
        import cross_checks.engines.drake_reference  # noqa: F401
    except ImportError:
        return []
    return [SecondReference(i, sc.name, ref.measured)
            for i, (sc, ref) in enumerate(zip(scenarios, references))
            if not ref.error]


def _groups(jobs) -> list:
    """The jobs in groups of one scenario and variant (its Δt ladder: one ``simulate_many`` call), the
    longest group first."""
    groups: dict = {}
    for j in jobs:
        groups.setdefault((j.scenario_index, j.variant), []).append(j)
    return sorted((tuple(g) for g in groups.values()), key=lambda g: -sum(j.cost for j in g))


def run_jobs(runner: Runner, jobs, scenarios, references, work_dir, cache_root, use_cache, time_limit_s,
             show_progress: bool, second=(), second_time_limit_s=None) -> dict:
    """``{Job: record}`` of every job (:func:`cross_checks.sweep.jobs.run_job_group`, by group of one scenario
    and variant), after the :class:`SecondReference` jobs ``second`` (their records: the summary's
    ``second_reference``); a job whose scenario has no reference is a failed row carrying the reason."""
    from cross_checks.core.progress import Progress
    from cross_checks.engines import user_engines
    records = {j: failed_record(j, scenarios[j.scenario_index], references[j.scenario_index].error)
               for j in jobs if references[j.scenario_index].error}
    inflight = Path(work_dir) / "inflight"
    inflight.mkdir()
    extra_engines = user_engines()
    made = [0]

    def items(todo):
        out = []
        for g in todo:
            i = g.scenario_index if isinstance(g, SecondReference) else g[0].scenario_index
            limit = second_time_limit_s if isinstance(g, SecondReference) else time_limit_s
            out.append((g, scenarios[i], references[i].path, cache_root, use_cache, extra_engines, limit,
                        str(inflight / str(made[0] + len(out)))))
        made[0] += len(out)
        return out

    todo = list(second) + _groups([j for j in jobs if j not in records])
    crashed: list = []
    # what the summary's run count counts
    n_runs = sum(len(g) for g in todo if not isinstance(g, SecondReference))
    with Progress("rbcheck sweep", "runs", n_runs, enabled=show_progress,
                  total_work=sum(j.cost for g in todo if not isinstance(g, SecondReference)
                                 for j in g)) as bar:
        def done(item, recs):
            if isinstance(item[0], SecondReference):   # among the runs, not one of them
                records[item[0]] = recs
                bar.update(0, f"{item[0].scenario} second reference")
                return
            if recs is None:
                crashed.extend((j,) for j in item[0])
                return
            for j, rec in zip(item[0], recs):
                records[j] = rec
                bar.update(1, f"{j.scenario} {j.variant} dt={j.dt_s:g}", work=j.cost)

        runner.map_unordered(_run_job_item, items(todo), done, on_crash=_crashed, in_flight=_in_flight)
        if crashed:
            runner.map_unordered(_run_job_item, items(crashed), done, on_crash=_crashed, in_flight=_in_flight)
    return records
