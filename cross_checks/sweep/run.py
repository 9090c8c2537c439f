"""``rbcheck sweep``: every (scenario, engine variant, Δt) run, its metrics, convergence verdicts, and
the results directory of docs/results.md, written atomically.

Data flow (one way): scenario → engine adapter (:func:`cross_checks.engines.run_variant`) →
Trajectory → :mod:`cross_checks.metrics` → results files → :mod:`reports` (HTML and PNG).

* A job is one (scenario, variant, Δt) run, measured by :func:`cross_checks.measure.run_job` in a
  worker process, which returns small summaries (and decimated series at the default Δt only); the
  reference of a scenario is computed once, before the runs. Job results are cached (see
  :mod:`cross_checks.measure`); ``--no-cache`` recomputes them.
* Jobs run longest first in a ``concurrent.futures.ProcessPoolExecutor`` (``--jobs``, default: all
  cores); ``--jobs 1`` runs in this process. A diverged run is a row with status ``diverged``; an
  engine exception (or a worker process that dies) is a row with status ``failed`` and the message;
  the sweep goes on.
* Everything is written into a temporary sibling of DIR, which replaces DIR only when complete, and
  only when DIR is rbcheck's own (:mod:`cross_checks.results_dir`: the marker, what a killed run leaves).

Results directory::

    .rbcheck-results.json  the marker: format, schema_version, every file rbcheck wrote here
    results.csv            one row per (scenario, engine, dt): RESULT_COLUMNS
    summary.json           provenance, scenarios, variants, convergence (+ local_convergence),
                           agreement of equivalent schemes, run statistics
    series/<scenario>.npz  decimated time series at the scenario's default Δt (float32)
    plots/*.png, index.html, scenario-<name>.html   (written by the caller's ``finish``: reports.render)
"""
from __future__ import annotations

import csv
import io
import json
import math
import os
import platform
import shutil
import sys
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from reference_sim.state import Q
from cross_checks.analysis import metrics as M
from cross_checks.core.quantities import UNITS, decimation_indices, state_errors
from cross_checks.analysis.convergence import compare_with_expectation, fit_convergence, measured_pre_asymptotic
from cross_checks.core import tolerances as tol
from cross_checks.analysis.expectations import EQUIVALENT_PAIRS, expectation
from cross_checks.core.quantities import QUANTITIES
from cross_checks.sweep.lifecycle import Terminated, worker_init
from cross_checks.sweep.results_dir import (ResultsDirError, check_output_dir, fix_permissions, remove_stale_siblings,
                                            replace_dir, staging_dir, write_marker)
from cross_checks.core.files import atomic_write_text, json_default, usable_cores
from cross_checks.core.quantities import COLUMN_STEM
from cross_checks.sweep.jobs import (LOCAL_SAMPLES, MAX_SERIES_POINTS, RESULT_COLUMNS, SCHEMA_VERSION, Job,
                                     cache_dir, code_fingerprint, failed_record, job_dts, load_reference,
                                     reference_job, run_job, clear_reference_memo)
from cross_checks.core.files import save_npz_atomic

__all__ = ["RESULT_COLUMNS", "SweepError", "SweepInterrupted", "Job", "plan_jobs", "run_sweep", "cache_dir",
           "MAX_SERIES_POINTS", "LOCAL_SAMPLES", "SCHEMA_VERSION"]

#: Rough cost per step (µs) of each variant, measured on the catalog (2 vCPU), only to order the
#: jobs longest first. MuJoCo/PyBullet cost ~5 µs/step unless the adapter evaluates the forces in
#: Python every step (state-dependent forces): then ~75 µs (~270 µs for MuJoCo RK4's four stages).
_COST_US = {"reference:course": 7, "reference:course_gyro": 7, "reference:expmap_gyro": 7,
            "reference:explicit_euler": 7, "reference:implicit_euler": 800, "reference:midpoint": 12,
            "reference:leapfrog": 40, "reference:rk4": 22}
_COST_ENGINE_STATE_DEPENDENT = {"mujoco:rk4": 270}
_COST_ENGINE_DEFAULT_US = (5, 75)  # (forces constant, forces state-dependent)


class SweepError(Exception):
    """Bad sweep input (message names the option or file and the reason)."""


class SweepInterrupted(KeyboardInterrupt):
    """Ctrl-C (or SIGTERM: ``terminated``) during a sweep; the previous results directory is untouched."""

    def __init__(self, terminated: bool = False, replaced: bool = False):
        super().__init__()
        self.terminated, self.replaced = terminated, replaced


# --- planning --------------------------------------------------------------------------------------

def _cost(scenario, variant, dt):
    n = scenario.n_steps(dt)
    if variant in _COST_US:
        us = _COST_US[variant]
    elif scenario.problem.forces.state_dependent:
        us = _COST_ENGINE_STATE_DEPENDENT.get(variant, _COST_ENGINE_DEFAULT_US[1])
    else:
        us = _COST_ENGINE_DEFAULT_US[0]
    return n * us * 1e-6


def plan_jobs(scenarios, variants) -> list:
    """Every (scenario, variant, Δt) job, longest first."""
    jobs = []
    for i, sc in enumerate(scenarios):
        for v in variants:
            for dt in job_dts(sc):
                jobs.append(Job(i, sc.name, v, dt, any(d == dt for d in sc.dt_ladder_s), dt == sc.dt_s,
                                _cost(sc, v, dt)))
    jobs.sort(key=lambda j: -j.cost)
    return jobs


# --- worker plumbing --------------------------------------------------------------------------------



class _Runner:
    """Runs callables here (jobs == 1), in a process pool, or on any ``concurrent.futures.Executor``
    given by the caller (e.g. a Dask cluster's ``Client.get_executor()``), yielding results as they
    finish. An external executor is used as it is: never shut down or replaced here."""

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

    def map_unordered(self, fn, items, on_done=None, on_crash=None, in_flight=None):
        """``fn(item)`` for each item; returns ``[(item, result)]`` in completion order.

        A worker that dies (e.g. a crash inside an engine) breaks the pool, and every unfinished item
        fails with BrokenProcessPool. ``in_flight(item)`` says whether an item was running at that
        moment: those are re-run one at a time in a fresh pool, so a crash names its own item, whose
        result is then ``on_crash(item)``; the others are simply resubmitted.
        """
        out = []

        def record(it, r):
            out.append((it, r))
            if on_done:
                on_done(it, r)

        if self.pool is None:
            for it in items:
                record(it, fn(it))
            return out
        todo, isolate = list(items), []
        while todo or isolate:
            for it in isolate:
                try:
                    r = self.pool.submit(fn, it).result()
                except BrokenProcessPool:
                    self._renew()
                    if on_crash is None:
                        raise
                    r = on_crash(it)
                record(it, r)
            isolate = []
            futs = {self.pool.submit(fn, it): it for it in todo}
            if self.external:
                self.submitted.extend(futs)
            todo = []
            pending = set(futs)
            broken = False
            while pending:
                done, pending = wait(pending, return_when=FIRST_COMPLETED)
                for f in done:
                    it = futs[f]
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
        return out

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
            # Stop the workers this sweep started (they ignore SIGINT): by their own process ids.
            procs = list(getattr(self.pool, "_processes", {}).values())
            self.pool.shutdown(wait=False, cancel_futures=True)
            for p in procs:
                if p.is_alive():
                    p.terminate()
            for p in procs:
                p.join(timeout=5)
        else:
            self.pool.shutdown(wait=True)
        self.pool = None


class _RefTask:
    def __init__(self, scenarios, work_dir, cache_root, use_cache, time_limit_s):
        self.scenarios, self.work_dir, self.cache_root, self.use_cache = scenarios, work_dir, cache_root, use_cache
        self.time_limit_s = time_limit_s

    def path(self, i):
        return str(Path(self.work_dir) / f"ref_{i}.npz")

    def __call__(self, i):
        return reference_job(self.scenarios[i], self.path(i), self.cache_root, self.use_cache, self.time_limit_s)


def _run_job_item(item):
    """``item`` = (job, scenario, ref_path, cache_root, use_cache, user_engines, time_limit_s, marker): one
    small pickle per job.

    ``user_engines`` are the parent's engine-file adapters (a worker that was not forked from the
    parent, e.g. on Dask, registers them here). ``marker`` (a file path) exists while the job runs,
    so after a worker crash the parent knows which jobs were in flight. Any error of the harness
    itself becomes a failed row, so one bad job never stops the sweep.
    """
    job, scenario, ref_path, cache_root, use_cache, user_engines, time_limit_s, marker = item
    Path(marker).touch()
    try:
        from cross_checks.engines import adopt_user_engines
        adopt_user_engines(user_engines)
        return run_job(job, scenario, ref_path, cache_root, use_cache, time_limit_s)
    except (KeyboardInterrupt, SystemExit):
        raise
    except Exception as exc:  # noqa: BLE001
        return failed_record(job, scenario, f"internal error while measuring the run: {type(exc).__name__}: {exc}")
    finally:
        Path(marker).unlink(missing_ok=True)


def _in_flight(item) -> bool:
    return Path(item[-1]).exists()


# --- assembling the results -------------------------------------------------------------------------

def _fmt(v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (float, np.floating)):
        v = float(v)
        return "" if math.isnan(v) else repr(v)
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    return "" if v is None else str(v)


def results_csv_text(rows) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(RESULT_COLUMNS)
    for r in rows:
        w.writerow([_fmt(r.get(c)) for c in RESULT_COLUMNS])
    return buf.getvalue()


def _floors(ladder, q, scales, mode, label, measured):
    """Round-off floor of each ladder point for quantity ``q`` (metrics.roundoff_floor): the reference's
    MEASURED error (at the final time, or of one step in the one-step mode) plus the run's own
    round-off, amplified by the scenario's measured error amplification."""
    scale = scales.get(q, 1.0)
    if mode == "free_running":
        ref = (measured.get("reference_error") or {}).get(q)
        amp = measured.get("amplification", {}).get(q, 1.0)
        return [M.roundoff_floor(scale, max(int(r["steps"]), 1), label, reference_error=ref, amplification=amp,
                                 quantity=q) for r in ladder]
    local = measured.get("local_reference_error") or {}
    return [M.roundoff_floor(scale, 1, label, reference_error=(local.get(repr(float(r["dt"]))) or {}).get(q),
                             quantity=q) for r in ladder]


def _convergence_records(scenario, variant, rows, scales, mode, measured=None):
    """Convergence records of one (scenario, variant): the fit over the ladder against floors from
    measurement (:func:`_floors`), and the expectation decided from the scenario's measured physics.
    Where the expectation makes no claim on this ladder (pre-asymptotic), a fitted converges /
    does_not_converge becomes the verdict ``pre_asymptotic`` (the fit's own verdict is kept in
    ``fit_verdict``)."""
    from cross_checks.analysis.physics import physics_from_dict
    measured = measured or {}
    phys = physics_from_dict(measured["physics"]) if measured.get("physics") else None
    ladder = sorted([r for r in rows if r["in_ladder"]], key=lambda r: -r["dt"])
    out = []
    if len(ladder) < 2:
        return out
    dts = [r["dt"] for r in ladder]
    label = next((r["reference"] for r in ladder if r["reference"]), "analytic")
    for q in QUANTITIES:
        stem = COLUMN_STEM[q]
        if mode == "free_running":
            errs = [r[f"{stem}_err_final"] for r in ladder]
            statuses = [r["status"] for r in ladder]
        else:
            errs = [r[f"{stem}_local_err"] for r in ladder]
            statuses = ["ok" if r["status"] in ("ok", "diverged") and np.isfinite(r[f"{stem}_local_err"])
                        else "failed" for r in ladder]
        fit = fit_convergence(dts, errs, _floors(ladder, q, scales, mode, label, measured), statuses)
        exp = expectation(scenario, variant, q, mode, physics=phys, measure_physics=False)
        verdict = fit.verdict
        matches, phrase = compare_with_expectation(fit.verdict, fit.order, exp, fit.order_is_lower_bound)
        if exp.verdict == "pre_asymptotic" and verdict in ("converges", "does_not_converge"):
            verdict = "pre_asymptotic"
        elif matches is False and exp.verdict == "converges":
            why = measured_pre_asymptotic(fit, exp.order)
            if why:
                verdict, matches, phrase = "pre_asymptotic", None, why
        out.append({
            "scenario": scenario.name, "engine": variant, "quantity": q, "mode": mode,
            "order": fit.order, "pairwise_orders": fit.pairwise_orders, "verdict": verdict,
            "fit_verdict": fit.verdict,
            "dt_s": fit.dt_s, "errors": [None if not np.isfinite(e) else e for e in fit.errors],
            "floors": fit.floors, "fitted": fit.fitted, "order_is_lower_bound": fit.order_is_lower_bound,
            "note": fit.note, "unit": UNITS[q],
            **exp.as_dict(), "matches_expectation": matches, "assessment": phrase,
        })
    return out


def _agreement_records(scenarios, records_by_key):
    """Final-state differences of the pairs that implement the same scheme, at each default Δt."""
    out = []
    for a, b, reason in EQUIVALENT_PAIRS:
        for sc in scenarios:
            ra = records_by_key.get((sc.name, a, sc.dt_s))
            rb = records_by_key.get((sc.name, b, sc.dt_s))
            if ra is None or rb is None:
                continue
            ta, tb = ra["row"].get("diverged_at_s"), rb["row"].get("diverged_at_s")
            if ra["row"]["status"] == "diverged" == rb["row"]["status"] and ta is not None and tb is not None:
                # The same scheme blows up at the same step; detection may differ by a step (MuJoCo flags
                # its instability warning during the step that starts the blow-up): allow 2 steps.
                agrees = abs(float(ta) - float(tb)) <= 2.0 * sc.dt_s + 1e-12
                out.append({"a": a, "b": b, "scenario": sc.name, "dt_s": sc.dt_s, "differences": None,
                            "max_rel": None, "agrees": bool(agrees), "reason": reason,
                            "note": f"both diverged, at t = {float(ta):.6g} s and {float(tb):.6g} s"})
                continue
            if ra["y_final"] is None or rb["y_final"] is None:
                out.append({"a": a, "b": b, "scenario": sc.name, "dt_s": sc.dt_s, "differences": None,
                            "max_rel": None, "agrees": False, "reason": reason,
                            "note": "one of the runs did not finish"})
                continue
            ya, yb = np.array([ra["y_final"]]), np.array([rb["y_final"]])
            d = {q: float(v[0]) for q, v in state_errors(ya, yb).items()}
            scale = {"position": max(1.0, float(np.linalg.norm(yb[0, 0:3]))),
                     "velocity": max(1.0, float(np.linalg.norm(yb[0, 3:6]))),
                     "orientation": 1.0,
                     "angular_velocity": max(1.0, float(np.linalg.norm(yb[0, 10:13])))}
            mx = max(d[q] / scale[q] for q in QUANTITIES)
            out.append({"a": a, "b": b, "scenario": sc.name, "dt_s": sc.dt_s, "differences": d,
                        "max_rel": mx, "agrees": bool(mx <= tol.SAME_SCHEME_REL), "reason": reason,
                        "tolerance": tol.SAME_SCHEME_REL, "note": ""})
    return out


def _git_commit() -> str:
    """The commit of the source checkout, read from .git without running git ("" when unknown)."""
    root = Path(__file__).resolve().parents[1] / ".git"
    try:
        head = (root / "HEAD").read_text().strip()
        if not head.startswith("ref:"):
            return head
        ref = head.split(None, 1)[1]
        p = root / ref
        if p.is_file():
            return p.read_text().strip()
        packed = root / "packed-refs"
        if packed.is_file():
            for line in packed.read_text().splitlines():
                if line.endswith(" " + ref):
                    return line.split()[0]
    except OSError:
        pass
    return ""


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor()


def _variant_info(name: str, info) -> dict:
    """summary.json's record of a variant: description, version, declared order, whether it has a
    one-step mode, and where its engine comes from (an engine file with its SHA-256)."""
    from cross_checks.engines import engine_provenance, has_one_step
    out = {"name": name, "description": info.description if info else "", "version": info.version if info else "",
           "declared_order": info.order if info else None, "one_step": has_one_step(name)}
    try:
        out.update({k: v for k, v in engine_provenance(name.split(":", 1)[0]).items() if k != "version"})
    except Exception:  # noqa: BLE001 - an engine that vanished from the registry keeps its basic record
        pass
    return out


def provenance(started_at: str, variants=()) -> dict:
    import numpy
    import scipy

    import reference_sim
    from cross_checks.engines import all_variants
    engines = {}
    for v in all_variants():
        engines.setdefault(v.engine, v.version if v.available else f"unavailable ({v.reason})")
    return {
        "rbcheck": reference_sim.__version__, "numpy": numpy.__version__, "scipy": scipy.__version__,
        "mujoco": engines.get("mujoco", ""), "pybullet": engines.get("pybullet", ""), "drake": engines.get("drake", ""),
        "python": platform.python_version(), "platform": platform.platform(),
        "machine": f"{platform.machine()}, {os.cpu_count()} CPUs, {_cpu_model()}",
        "git_commit": _git_commit(), "started_at": started_at,
        "command": "rbcheck " + " ".join(sys.argv[1:]) if sys.argv and sys.argv[0].endswith("rbcheck") else "",
        "engines": _engines_provenance(variants),
    }


def _engines_provenance(variants) -> dict:
    """Version and origin of every engine the sweep ran (an engine file's SHA-256 included)."""
    from cross_checks.engines import engine_provenance
    out = {}
    for v in variants:
        engine = v.split(":", 1)[0]
        if engine not in out:
            try:
                out[engine] = engine_provenance(engine)
            except Exception:  # noqa: BLE001
                out[engine] = {}
    return out


def _scenario_info(sc, label, scales):
    cons = M.conserved(sc.problem.forces)
    return {"name": sc.name, "description": sc.description, "source": sc.source, "content_hash": sc.content_hash,
            "duration_s": sc.duration_s, "dt_s": sc.dt_s, "dt_ladder_s": list(sc.dt_ladder_s),
            "reference": label, "scales": scales,
            "conserved": {k: {"conserved": v[0], "why_not": v[1]} for k, v in cons.items()}}


def _nan_to_none(o):
    if isinstance(o, float) and not math.isfinite(o):
        return None
    if isinstance(o, dict):
        return {k: _nan_to_none(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_nan_to_none(v) for v in o]
    return o


def write_json(path, obj) -> None:
    atomic_write_text(path, json.dumps(_nan_to_none(obj), indent=1, sort_keys=False, default=json_default,
                                       allow_nan=False) + "\n")


# --- the sweep --------------------------------------------------------------------------------------

def run_sweep(scenarios, variants, out_dir, *, jobs: int | None = None, use_cache: bool = True,
              progress: bool | None = None, skipped=None, finish=None,
              executor=None, run_time_limit_s: float | None = tol.RUN_TIME_LIMIT_S,
              reference_time_limit_s: float | None = tol.REFERENCE_TIME_LIMIT_S) -> dict:
    """Run the sweep and write the results directory ``out_dir`` (atomically).

    Parameters
    ----------
    scenarios : list of Scenario (distinct names).
    variants : list of available ``ENGINE:VARIANT`` names.
    jobs : worker processes (default: all cores); 1 runs everything in this process.
    use_cache : read cached job results (they are always written).
    skipped : ``{variant: reason}`` of variants left out (recorded in summary.json).
    progress : show a progress bar (default: when stderr is a terminal).
    finish : ``finish(staging_dir)``, called on the complete results before they replace ``out_dir``
        (e.g. ``reports.render``: the report is then part of the atomic replacement). None: no report.
    run_time_limit_s, reference_time_limit_s : wall-time limits of one run and of one reference solve
        (None: none); a run or reference over its limit is a ``failed`` row saying so.
    executor : any ``concurrent.futures.Executor`` to run the jobs on instead of the local process
        pool (e.g. ``distributed.Client(address).get_executor()``); its workers must see the parent
        directory of ``out_dir`` and the cache directory (jobs exchange reference solutions as files).

    Returns the summary dict (as written to summary.json). Raises SweepError (bad input) or
    SweepInterrupted (Ctrl-C: nothing was replaced).
    """
    from tqdm import tqdm

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
    if not jobs:
        jobs = usable_cores()
    jobs = max(1, int(jobs))
    started = datetime.now(timezone.utc).replace(microsecond=0).isoformat()
    t_start = time.perf_counter()
    cache_root = str(cache_dir())
    for v in variants:  # fingerprint the code once, here: forked workers inherit it
        code_fingerprint(v.split(":", 1)[0])
    code_fingerprint("reference")
    staging = staging_dir(out)
    work = staging / "_work"
    work.mkdir()
    runner = None
    show = sys.stderr.isatty() if progress is None else progress
    bar = None
    try:
        runner = _Runner(jobs, executor)
        # 1. references (one per scenario)
        ref_task = _RefTask(scenarios, str(work), cache_root, use_cache, reference_time_limit_s)
        ref_results = dict(runner.map_unordered(ref_task, range(len(scenarios))))
        ref_paths = [ref_task.path(i) for i in range(len(scenarios))]
        labels = {i: ref_results[i][0] for i in range(len(scenarios))}
        ref_fail = {i: ref_results[i][1] for i in range(len(scenarios)) if ref_results[i][1]}
        ref_scales = {i: ref_results[i][2] for i in range(len(scenarios))}
        ref_varies = {i: ref_results[i][3] for i in range(len(scenarios))}
        ref_measured = {i: ref_results[i][4] for i in range(len(scenarios))}

        # 2. the runs, longest first
        all_jobs = plan_jobs(scenarios, variants)
        todo = [j for j in all_jobs if j.scenario_index not in ref_fail]
        records = {}
        for j in all_jobs:
            if j.scenario_index in ref_fail:
                records[j] = failed_record(j, scenarios[j.scenario_index], ref_fail[j.scenario_index])
        bar = tqdm(total=len(todo), disable=not show, unit="run", desc="rbcheck sweep", file=sys.stderr,
                   dynamic_ncols=True)

        def done(job, rec):
            records[job] = rec
            bar.update(1)
            bar.set_postfix_str(f"{job.scenario} {job.variant}", refresh=False)

        (work / "inflight").mkdir()
        from cross_checks.engines import user_engines
        extra_engines = user_engines()
        items = [(j, scenarios[j.scenario_index], ref_paths[j.scenario_index], cache_root, use_cache,
                  extra_engines, run_time_limit_s, str(work / "inflight" / str(k))) for k, j in enumerate(todo)]

        def crashed(item):
            Path(item[-1]).unlink(missing_ok=True)
            return failed_record(item[0], item[1], "the worker process died running this job, alone "
                                                    "(a crash inside the engine?)")

        runner.map_unordered(_run_job_item, items, lambda item, rec: done(item[0], rec),
                             on_crash=crashed, in_flight=_in_flight)
        bar.close()
        runner.close()
        runner = None

        # 3. assemble
        order_v = {v: i for i, v in enumerate(variants)}
        rows = sorted((rec["row"] for rec in records.values()),
                      key=lambda r: (names.index(r["scenario"]), order_v.get(r["engine"], 1e9), -r["dt"]))
        atomic_write_text(staging / "results.csv", results_csv_text(rows))

        by_key = {(j.scenario, j.variant, j.dt_s): rec for j, rec in records.items()}
        from cross_checks.engines import has_one_step
        convergence, local = [], []
        scenario_info = []
        (staging / "series").mkdir()
        for i, sc in enumerate(scenarios):
            scales = ref_scales[i]
            scenario_info.append(_scenario_info(sc, labels.get(i, ""), scales))
            meas = ref_measured.get(i) or {}
            scenario_info[-1]["error_amplification"] = meas.get("amplification", {})
            scenario_info[-1]["reference_error"] = meas.get("reference_error")
            scenario_info[-1]["physics"] = meas.get("physics")
            scenario_info[-1]["second_reference"] = meas.get("second_reference")
            scenario_info[-1]["varies"] = ref_varies[i]
            for v in variants:
                vrows = [r for r in rows if r["scenario"] == sc.name and r["engine"] == v]
                convergence += _convergence_records(sc, v, vrows, scales, "free_running", ref_measured.get(i))
                if has_one_step(v):  # engines without a one-step mode have no local errors to fit
                    local += _convergence_records(sc, v, vrows, scales, "one_step", ref_measured.get(i))
            # series for the plots at the default Δt
            arrays = {}
            if i not in ref_fail:
                t_ref, y_ref, _ = load_reference(ref_paths[i])
                grid = np.searchsorted(t_ref, sc.dt_s * np.arange(sc.n_steps() + 1))
                k = grid[decimation_indices(len(grid), MAX_SERIES_POINTS)]
                arrays["reference::t_s"] = t_ref[k].astype(np.float32)
                arrays["reference::x_W"] = y_ref[k, 0:3].astype(np.float32)
                arrays["reference::q_WB"] = y_ref[k][:, Q].astype(np.float32)
            for v in variants:
                rec = by_key.get((sc.name, v, sc.dt_s))
                for key, a in ((rec or {}).get("series") or {}).items():
                    arrays[f"{v}::{key}"] = np.asarray(a, dtype=np.float32)
            save_npz_atomic(staging / "series" / f"{sc.name}.npz", arrays)
        clear_reference_memo()
        from cross_checks.engines import all_variants

        agreement = _agreement_records(scenarios, by_key)
        infos = {v.name: v for v in all_variants()}
        n_cached = sum(1 for rec in records.values() if rec["row"].get("cached"))
        summary = {
            "schema_version": SCHEMA_VERSION,
            "provenance": provenance(started, variants),
            "scenarios": scenario_info,
            "variants": [_variant_info(v, infos.get(v)) for v in variants],
            "skipped_variants": [{"name": k, "reason": r} for k, r in (skipped or {}).items()],
            "convergence": convergence,
            "local_convergence": local,
            "agreement": agreement,
            "run": {"jobs": jobs, "runs": len(records), "cached_runs": n_cached,
                    "diverged_runs": sum(1 for r in rows if r["status"] == "diverged"),
                    "failed_runs": sum(1 for r in rows if r["status"] == "failed"),
                    "wall_s": round(time.perf_counter() - t_start, 3),
                    "cpu_s_in_runs": round(float(np.nansum([r["wall_s"] for r in rows
                                                            if not r.get("cached")] or [0.0])), 3),
                    "tolerances": {"same_scheme_rel": tol.SAME_SCHEME_REL, "order_tol": tol.SWEEP_ORDER_TOL,
                                   "converges_min_order": tol.CONVERGES_MIN_ORDER}},
            "files": {"results": "results.csv", "series": "series/<scenario>.npz: keys '<ENGINE:VARIANT>::<field>' "
                      "(t_s, x_W, q_WB, err_<quantity>, drift_<quantity>) and 'reference::<field>', float32, "
                      "at the scenario's default dt, decimated to <= %d points" % MAX_SERIES_POINTS},
        }
        shutil.rmtree(work)
        summary["run"]["wall_s"] = round(time.perf_counter() - t_start, 3)
        write_json(staging / "summary.json", summary)

        # 4. whatever the caller adds to the complete results (the report, drawn from the saved files only)
        if finish is not None:
            finish(staging)
        write_marker(staging)
        fix_permissions(staging)
        replace_dir(staging, out)
        staging = None
        return summary
    except KeyboardInterrupt as exc:  # after the swap (staging is None) the new results are complete
        raise SweepInterrupted(isinstance(exc, Terminated), replaced=staging is None or not staging.exists()) from None
    finally:
        if bar is not None:
            bar.close()
        if runner is not None:
            runner.close(kill=True)
        if staging is not None:
            shutil.rmtree(staging, ignore_errors=True)
