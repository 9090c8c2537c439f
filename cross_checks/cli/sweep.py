"""``rbcheck sweep``: scenarios x variants x Δt ladders into a results directory and its report; the lines
that say what it did, and the gates that make it exit 1 (:func:`_gate_failures`)."""
from __future__ import annotations

import os
import sys
import time
from pathlib import Path

from cross_checks.cli.ci import ci_outputs
from cross_checks.cli.engines import dask_executor, resolve_engines
from cross_checks.cli.errors import (
    EXIT_FAIL,
    EXIT_INTERRUPTED,
    EXIT_OK,
    EXIT_TERMINATED,
    BadInput,
    check_out_path,
    engine_file_inputs,
    error,
    is_within,
    refuse_inputs_as_outputs,
    resolved,
    scenario_inputs,
)
from cross_checks.core.files import usable_cores


def _gate_failures(summary) -> list:
    """Lines naming what makes a sweep exit 1."""
    out = []
    for r in summary.get("convergence", []):
        if r.get("matches_expectation") is False:
            out.append(f"{r['engine']} on {r['scenario']}: "
                       f"{r['quantity'].replace('_', ' ')} {r['assessment']}")
    for a in summary.get("agreement", []):
        if not a.get("agrees"):
            out.append(f"{a['a']} and {a['b']} differ on {a['scenario']} (should be the same scheme)")
    for sc in summary.get("scenarios", []):   # every verdict rests on the reference: two that disagree fail
        sr = sc.get("second_reference") or {}
        if sr.get("agrees") is False:
            out.append(f"the references of {sc['name']} disagree: {sc['reference']} and {sr['label']} "
                       f"differ in {', '.join(sr.get('disagreeing', []))} beyond their measured accuracies")
    for r in summary.get("long_runs", []):
        if r.get("matches_expectation") is False:
            out.append(f"{r['engine']} on {r['scenario']} (long run): {r['assessment']}")
    from cross_checks.sweep.invariance import broken_lines
    out += broken_lines(summary)
    n_failed = summary.get("run", {}).get("failed_runs", 0)
    if n_failed:
        out.append(f"{n_failed} run(s) failed (status 'failed' in results.csv)")
    n_long_failed = (summary.get("run", {}).get("long_runs") or {}).get("failed_runs", 0)
    if n_long_failed:
        out.append(f"{n_long_failed} long run(s) failed (status 'failed' in long_runs.csv)")
    return out


def _time_limits(seconds) -> dict:
    return {} if seconds is None else {"run_time_limit_s": seconds, "reference_time_limit_s": seconds}


def cmd_sweep(args) -> int:
    import reports
    from cross_checks.scenario import catalog_names, load_scenario, long_run_names
    from cross_checks.sweep import ReportFailed, SweepError, SweepInterrupted
    from cross_checks.sweep.results_dir import ResultsDirError, check_output_dir
    reports.check_installation()  # the report's templates, before minutes of runs
    try:
        check_output_dir(args.out)  # before any work (run_sweep checks again just before it starts)
    except ResultsDirError as exc:
        raise BadInput(str(exc)) from None
    refuse_inputs_as_outputs([("--out", args.out, True), ("--junit", args.junit, False)],
                             scenario_inputs(args.scenarios) + engine_file_inputs(args))
    if args.junit:
        check_out_path(args.junit, ".xml", "--junit")
        if is_within(resolved(args.junit), resolved(args.out)):
            raise BadInput(f"--junit {args.junit}: lies inside --out {args.out}, which the sweep replaces "
                           "as a whole; choose a path outside it")
    names = list(args.scenarios or catalog_names())
    if args.long or not (args.scenarios or args.no_long):   # the default sweep has the long runs
        names += [n for n in long_run_names() if n not in names]
    scenarios = [load_scenario(s) for s in names]
    variants, skipped = resolve_engines(args.engines)
    if not variants:
        raise BadInput("--engines: no available engine variant to run")
    t0 = time.perf_counter()
    try:
        summary = _run_sweep(args, scenarios, variants, skipped)
    except SweepError as exc:
        raise BadInput(str(exc)) from None
    except ReportFailed as exc:   # the results are written; the report's bug is an internal error (exit 2)
        if os.environ.get("RBCHECK_DEBUG"):
            raise exc.error from None
        return error("sweep", f"{exc} (RBCHECK_DEBUG=1 shows the traceback)")
    except SweepInterrupted as exc:
        what = (f"after the new results were complete in {args.out}" if exc.replaced
                else f"{args.out} left as it was")
        print(f"rbcheck sweep: {'terminated' if exc.terminated else 'interrupted'}; {what}", file=sys.stderr)
        return EXIT_TERMINATED if exc.terminated else EXIT_INTERRUPTED
    code = _sweep_outcome(summary, args.out, len(scenarios), len(variants), time.perf_counter() - t0,
                          scenarios)
    _sweep_ci_outputs(args, summary)
    return code


def _sweep_ci_outputs(args, summary) -> None:
    from cross_checks.gates import ci
    rows, long_rows = _result_rows(args.out, "results.csv"), _result_rows(args.out, "long_runs.csv")
    ci_outputs("sweep", args.junit, lambda: ci.sweep_junit(summary, rows, long_rows),
                ci.sweep_annotations(summary, rows, long_rows) if args.github_annotations else [],
                lambda: ci.sweep_markdown(summary, args.out, rows, long_rows))


def _run_sweep(args, scenarios, variants, skipped) -> dict:
    """run_sweep with the command's options; the report is drawn inside the atomic replacement."""
    import reports
    from cross_checks.sweep import run_sweep

    jobs = args.jobs or usable_cores()
    with dask_executor(args.dask) as executor:
        return run_sweep(scenarios, variants, args.out, jobs=jobs, use_cache=not args.no_cache, progress=True,
                         finish=lambda d: reports.render(d, self_contained=args.self_contained, jobs=jobs,
                                                        progress=True),
                         skipped=skipped, **_time_limits(args.time_limit), executor=executor,
                         **({"invariance": True} if getattr(args, "invariance", False) else {}))


def verdict_count(summary) -> tuple:
    """``(verdicts, not as expected)``: :func:`cross_checks.sweep.assemble.verdict_count`."""
    from cross_checks.sweep.assemble import verdict_count as count
    return count(summary)


def _result_rows(out, name: str) -> list:
    """The rows of DIR/NAME (results.csv, long_runs.csv) as dicts ([] for a file the sweep did not write)."""
    import csv
    try:
        with open(Path(out) / name, newline="", encoding="utf-8") as fh:
            return list(csv.DictReader(fh))
    except OSError:
        return []


def _failed_rows(out) -> list:
    """The failed rows of DIR/results.csv and DIR/long_runs.csv (as dicts)."""
    return [r for name in ("results.csv", "long_runs.csv") for r in _result_rows(out, name)
            if r.get("status") == "failed"]


#: What an engine-file command's words most often mean (docs/engines.md, "When a run fails").
_FAILURE_HINTS = (
    (("can't open file", "No such file or directory", "cannot find", "not found"),
     "a file the command names is not where it runs: each run has a private working directory, so name your "
     "files relative to the engine file (found in its folder) or through {engine_dir}"),
    (("ModuleNotFoundError", "ImportError"),
     "a module the command imports is not installed for the interpreter the command runs"),
    (("Permission denied",), "the program or a file it needs is not executable or readable"),
)


def _failure_hint(sentence: str) -> str:
    return next((hint for needles, hint in _FAILURE_HINTS if any(n in sentence for n in needles)), "")


def _say_failed_runs(out, n_failed: int) -> None:
    """Every distinct reason the failed runs give, in the command's own words (as `run` and assert_engine
    print them), with what it most likely means."""
    from cross_checks.core.progress import say
    from cross_checks.gates.failures import failed_run_sentences
    groups = failed_run_sentences(_failed_rows(out), statuses=("failed",))
    say(f"rbcheck sweep: {n_failed} run(s) failed, for {len(groups)} distinct reason(s):", sys.stderr)
    for _, _, sentence, _ in groups[:10]:
        say(f"  {sentence}", sys.stderr)
        if _failure_hint(sentence):
            say(f"    likely cause: {_failure_hint(sentence)}", sys.stderr)
    if len(groups) > 10:
        say(f"  ... and {len(groups) - 10} more reason(s) (results.csv's message column)", sys.stderr)


#: The most user-engine contradictions the sweep explains by `rbcheck check`'s catalog (each reruns the
#: variant at the scenario's coarsest Δt and checks it: a few seconds each).
MAX_LIKELY_CAUSES = 4


def _say_likely_causes(summary, scenarios) -> None:
    """The likely cause of each contradicting (scenario, variant) of a user engine (an engine file or an
    entry point), as assert_engine gives it."""
    from cross_checks.core.progress import say
    from cross_checks.engines import all_variants
    from cross_checks.gates.failures import likely_causes
    builtin = {v.name for v in all_variants() if v.source.endswith("(rbcheck)")}
    failed = {(r["scenario"], r["engine"])
              for r in summary.get("convergence", []) if r["verdict"] == "failed"}
    pairs = list(dict.fromkeys((r["scenario"], r["engine"]) for r in summary.get("convergence", [])
                               if r.get("matches_expectation") is False and r["engine"] not in builtin
                               and (r["scenario"], r["engine"]) not in failed))
    by_name = {s.name: s for s in scenarios}
    for (sc, v), cause in likely_causes(by_name, pairs[:MAX_LIKELY_CAUSES]).items():
        say(f"  likely cause ({v} on {sc}): {cause}", sys.stderr)


def _sweep_outcome(summary, out, n_scenarios, n_variants, elapsed_s, scenarios=None) -> int:
    """Print what the sweep did and every result that contradicts the expectations (then exit 1); the last
    line says whether every verdict was as expected."""
    from cross_checks.core.progress import say
    run = summary["run"]
    lr = run.get("long_runs") or {}
    long_text = (f" and {lr['runs']} long runs ({lr['cached_runs']} cached, {lr['diverged_runs']} diverged, "
                 f"{lr['failed_runs']} failed)" if lr.get("runs") else "")
    compiled = (f"compiling the reference's integrators {run['compile_s']:.1f} s, "
                if run.get("compile_s") else "")
    say(f"rbcheck sweep: {n_scenarios} scenario(s) x {n_variants} variant(s): {run['runs']} runs "
          f"({run['cached_runs']} cached, {run['diverged_runs']} diverged, {run['failed_runs']} failed)"
          f"{long_text} in {elapsed_s:.1f} s on {run['jobs']} worker(s) ({compiled}runs and metrics "
          f"{run['wall_s']:.1f} s, then the report) -> {Path(out) / 'index.html'}")
    skipped = summary.get("skipped_variants") or []
    if skipped:
        reasons = dict.fromkeys(v["reason"] for v in skipped)   # one per engine, in the order skipped
        engines = dict.fromkeys(v["name"].split(":", 1)[0] for v in skipped)
        say(f"rbcheck sweep: skipped {len(skipped)} variant(s) of {', '.join(engines)}: {'; '.join(reasons)}")
    cannot = summary.get("not_expressible") or []
    if cannot:
        say(f"rbcheck sweep: {len(cannot)} (scenario, variant) pair(s) not run because the engine cannot "
            "express the scenario (summary.json not_expressible; the report lists them):")
        for r in cannot[:10]:   # each with its engine's reason
            say(f"  {r['engine']} on {r['scenario']}: {r['reason']}")
    fails = _gate_failures(summary)
    total, wrong = verdict_count(summary)
    failed = run.get("failed_runs", 0) + lr.get("failed_runs", 0)
    contra = [f for f in fails if not f.endswith("(status 'failed' in results.csv)")
              and not f.endswith("(status 'failed' in long_runs.csv)")]
    if contra:   # the count of the last line, of the report's badge and of the CI formats: verdicts
        say(f"rbcheck sweep: {wrong} of {total} verdicts not as expected:", sys.stderr)
        for line in contra[:20]:
            say(f"  {line}", sys.stderr)
        if len(contra) > 20:
            say(f"  ... and {len(contra) - 20} more (see the findings in index.html)", sys.stderr)
        _say_likely_causes(summary, scenarios or [])
    if failed:
        _say_failed_runs(out, failed)
    inv = run.get("invariance") or {}
    if inv:
        say(f"rbcheck sweep: {inv['checks']} invariance checks: "
            + ", ".join(f"{n} {v}" for v, n in inv.items() if v != "checks" and n)
            + f" ({Path(out) / 'invariance.csv'})")
        from cross_checks.sweep.invariance import no_longer_broken_lines
        for line in no_longer_broken_lines(summary):
            say(f"rbcheck sweep: {line}")
    if not wrong and not failed and not inv.get("broken"):
        say(f"rbcheck sweep: all {total} verdicts as expected")
    else:
        say(f"rbcheck sweep: {wrong} of {total} verdicts not as expected"
            + (f", {failed} run(s) failed" if failed else "")
            + (f", {inv['broken']} broken invariance(s)" if inv.get("broken") else "")
            + f" (see {Path(out) / 'index.html'})")
    return EXIT_FAIL if fails else EXIT_OK
