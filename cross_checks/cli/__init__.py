"""``rbcheck`` command line (README: the tour and the exit-code table; docs/ for every format).

Exit codes: 0 success; 1 a comparison or gate found a regression / disagreement, or a run diverged;
2 bad input or an output that cannot be written (one line naming the file, the field and the reason,
no traceback); 130 interrupted (Ctrl-C); 143 terminated (SIGTERM). The README has the table per command.
"""
from __future__ import annotations

import argparse
import contextlib
import math
import os
import sys
import time
from pathlib import Path

from cross_checks.core.files import usable_cores

__all__ = ["main"]

EXIT_OK, EXIT_FAIL, EXIT_BAD_INPUT, EXIT_INTERRUPTED, EXIT_TERMINATED = 0, 1, 2, 130, 143


class BadInput(Exception):
    """Input the user must fix; the message names the file/option, the field and the reason."""


#: The largest time an option takes (--time-limit, --budget): 1e6 s, 11.6 days; beyond it timers overflow.
MAX_OPTION_SECONDS = 1e6
#: The most worker processes an option may ask for (--jobs): far more than any machine's cores; workers are
#: also capped by the runs to do.
MAX_OPTION_JOBS = 1024


def _at_most(parse, limit, unit: str = ""):
    """An option type: ``parse(text)``, then refused above ``limit`` (said with its unit)."""
    def option(text: str):
        v = parse(text)
        if v > limit:
            raise argparse.ArgumentTypeError(f"must be at most {limit:g}{unit}, got {text!r}")
        return v
    return option


def _positive_float(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number, got {text!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"must be a positive finite number, got {text!r}")
    return v


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # argparse exits 2 already; keep the one-line style
        self.print_usage(sys.stderr)
        sys.stderr.write(f"rbcheck: error: {message}\n")
        raise SystemExit(EXIT_BAD_INPUT)


def _version_text() -> str:
    """``rbcheck X.Y.Z``; the libraries every result records; then every registered engine: its version
    where it imports, else why not (each engine is imported to tell)."""
    from importlib import metadata

    import reference_sim
    from cross_checks.engines import all_variants
    parts = [f"Python {sys.version.split()[0]}"]
    for dist in ("numpy", "scipy"):
        try:
            parts.append(f"{dist} {metadata.version(dist)}")
        except metadata.PackageNotFoundError:
            parts.append(f"{dist} not installed")
    engines = {}
    for v in all_variants():
        engines.setdefault(v.engine, f"{v.engine} {v.version}" if v.available else f"{v.engine}: {v.reason}")
    return (f"rbcheck {reference_sim.__version__}\n" + ", ".join(parts) + "\nengines: "
            + "; ".join(engines.values()))


class _VersionAction(argparse.Action):
    """``--version``: the lines of :func:`_version_text` as they are (argparse's own action re-wraps them)."""

    def __call__(self, parser, namespace, values, option_string=None):
        print(_version_text())
        raise SystemExit(EXIT_OK)


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(
        prog="rbcheck",
        description="Validate rigid-body simulators: a NumPy reference of the "
                    "GAMES103 course equations, MuJoCo and PyBullet on identical "
                    "free-body scenarios, against analytic or DOP853 references.",
        epilog="SCENARIO is a catalog name (see `rbcheck list`) or a path to a scenario TOML file. "
               "Exit codes: 0 ok; 1 regression/disagreement, a failed or a diverged run; 2 bad input or an "
               "unwritable output (one line); 130 interrupted (Ctrl-C); 143 terminated (SIGTERM). "
               "Your own engines: --engine-file (docs/engines.md).",
    )
    p.add_argument("--version", action=_VersionAction, nargs=0,
                   help="print rbcheck's version, those of Python, NumPy and SciPy, "
                        "and every engine's (or why it cannot run), then exit")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND", parser_class=_Parser)
    # One declaration per command, in the order `rbcheck --help` lists them (alike in shape only: each
    # says its own command's arguments).
    for add in (_add_list, _add_show, _add_run, _add_sweep, _add_report, _add_check, _add_compare,
                _add_baseline, _add_bench, _add_fuzz):
        add(sub)
    return p


def _add_list(sub) -> None:
    ls = sub.add_parser("list", help="list catalog scenarios and engine variants (with availability)")
    ls.add_argument("--json", action="store_true",
                    help="print the list as JSON: scenarios (name, description, reference, duration_s, dt_s, "
                         "dt_ladder_s) and variants (name, engine, variant, available, reason, version, "
                         "declared_order, description, source, default)")
    _add_engine_file_option(ls)


def _add_show(sub) -> None:
    sh = sub.add_parser(
        "show",
        help="a scenario's body, initial conditions and forces, exactly as every "
             "engine receives them (what you need to set it up in your own simulator)",
        description="Print the scenario with every alternative resolved (inertia 3x3 about the COM in body "
                    "axes, orientation as a unit quaternion w x y z, angular velocity in WORLD axes, body "
                    "points from the COM, velocity-decay factors per step at the run's dt). --json prints "
                    "the exact JSON an engine-file command receives as {scenario_json} (docs/engines.md).")
    sh.add_argument("scenario", metavar="SCENARIO")
    sh.add_argument("--json", action="store_true",
                    help="print the resolved scenario JSON instead of the text")
    sh.add_argument("--dt", type=_positive_float, metavar="DT",
                    help="resolve at this time step, s (default: the scenario's dt)")
    sh.add_argument("--duration", type=_positive_float, metavar="T",
                    help="simulated time, s (default: the scenario's)")


def _add_run(sub) -> None:
    r = sub.add_parser("run", help="run one scenario with one engine variant and write the trajectory CSV")
    r.add_argument("scenario", metavar="SCENARIO")
    r.add_argument("--engine", required=True, metavar="ENGINE[:VARIANT]",
                   help="e.g. reference:course, mujoco:rk4; an engine name alone runs its default "
                        "variant (the first `rbcheck list` shows: reference:course, mujoco:euler, "
                        "pybullet:multibody)")
    r.add_argument("--dt", type=_positive_float, metavar="DT",
                   help="time step, s (default: the scenario's dt)")
    r.add_argument("--duration", type=_positive_float, metavar="T",
                   help="simulated time, s (default: the scenario's)")
    r.add_argument("--out", required=True, metavar="FILE.csv",
                   help="trajectory CSV (sidecar FILE.json beside it)")
    _add_engine_file_option(r)


def _add_sweep(sub) -> None:
    s = sub.add_parser(
        "sweep",
        help="run scenarios x engine variants x dt ladders; write "
             "results, convergence verdicts and the report",
        description="Run every scenario (default: the whole catalog) with every engine variant (default: "
                    "all available) at every dt of its ladder, in parallel; write DIR/results.csv, "
                    "DIR/summary.json, DIR/series/, DIR/plots/ and the HTML report. DIR is replaced only "
                    "when the sweep is complete. Exit 1 when a result contradicts the expectations "
                    "(cross_checks/analysis/expectations.py), a run fails, two schemes that must be "
                    "identical disagree, or a scenario's two references (its closed form or DOP853, and "
                    "Drake's, when Drake is installed) disagree beyond their measured accuracies.")
    s.add_argument("scenarios", nargs="*", metavar="SCENARIO",
                   help="catalog names or TOML paths (default: the catalog and its long runs); a long "
                        "run (kind = \"long_run\", e.g. long_tennis_racket) runs in the long-run stage")
    s.add_argument("--long", action="store_true",
                   help="add the catalog's long runs to the SCENARIOs named (rbcheck list: every variant "
                        "over 1000 spin periods, judged on the energy, |L| and the drift toward the "
                        "intermediate axis; docs/scenario.md \"Long runs\"); the default sweep has them")
    s.add_argument("--no-long", action="store_true",
                   help="leave the long runs out of the default sweep (the Δt ladders only)")
    s.add_argument("--invariance", action="store_true",
                   help="also run every variant on each scenario translated (10 m, 1 km, 10 km), in a "
                        "rotated "
                        "world, with a non-principal body frame, scaled (k, mu = 0.01 and 100), with its "
                        "frame origin off its COM and split into two welded parts, each "
                        "mapped back and judged against its own run of the original: DIR/invariance.csv; "
                        "exit 1 on a broken invariance (docs/invariance.md)")
    s.add_argument("--engines", nargs="+", metavar="ENGINE[:VARIANT]",
                   help="variants to run, e.g. reference:rk4 mujoco (an engine name means all its variants); "
                        "default: every available variant")
    s.add_argument("--jobs", type=_jobs_option, metavar="N", help="worker processes (default: all cores)")
    s.add_argument("--out", required=True, metavar="DIR",
                   help="results directory, replaced atomically and only "
                        "when absent, empty or rbcheck's own (its marker)")
    s.add_argument("--no-cache", action="store_true",
                   help="recompute every run instead of reusing cached "
                        "results ($RBCHECK_CACHE_DIR or ~/.cache/rbcheck)")
    s.add_argument("--self-contained", action="store_true",
                   help="embed the plots in the HTML pages (for CI artifacts)")
    _add_engine_file_option(s)
    s.add_argument("--time-limit", type=_seconds_option, metavar="S",
                   help="wall-time limit of each run and of each reference solve, s; one over "
                        "it is a failed row (default: 900, cross_checks/core/tolerances.py)")
    _add_ci_options(s)
    s.add_argument("--dask", metavar="ADDRESS",
                   help="run the jobs on a Dask cluster (scheduler address, e.g. "
                        "tcp://host:8786) through distributed's Client.get_executor(); needs "
                        "the optional extra: pip install 'rbcheck[dask]'. Workers must share "
                        "this machine's filesystem for DIR's parent and the cache")


def _add_report(sub) -> None:
    rp = sub.add_parser("report",
                        help="re-render the plots and HTML of a results directory from its saved data")
    rp.add_argument("dir", metavar="DIR")
    rp.add_argument("--self-contained", action="store_true", help="embed the plots in the HTML pages")
    rp.add_argument("--jobs", type=_jobs_option, metavar="N",
                    help="processes drawing figures (default: all cores)")


def _add_check(sub) -> None:
    c = sub.add_parser(
        "check",
        help="a true verdict on any simulator's trajectory CSV: correct "
             "simulation of the scenario or not, and why",
        description="Judge TRAJ.csv (trajectory CSV, columns by name; pose-only files too) against "
                    "SCENARIO: from every recorded state the exact motion over the row's interval is "
                    "compared with the next row (one-step defect), conserved quantities are checked "
                    "where the physics conserves them, and the run is compared with the scenario's "
                    "reference within a capped, derived allowance; every reference variant and a catalog "
                    "of classic mistakes are compared step for step. Several files of the same scenario "
                    "at different dt: each is checked and the convergence order is fitted (ladder). Exit "
                    "0: it is a correct simulation of the scenario's physics at its dt (or, "
                    "with --scheme, exactly that scheme); 1: it is not (the output says which quantity, "
                    "from when, by how much, and the likely cause: a trajectory that is exactly the "
                    "course's step where that step is wrong fails); 2: bad input. See docs/check.md.")
    c.add_argument("trajectories", nargs="+", metavar="TRAJ.csv", help="trajectory CSV file(s)")
    c.add_argument("--scenario", required=True, metavar="SCENARIO", help="catalog name or scenario TOML file")
    c.add_argument("--dt", type=_positive_float, metavar="DT",
                   help="the simulator's integration step, s, when rows are written "
                        "less often than every step (default: inferred from the times)")
    c.add_argument("--scheme", metavar="ENGINE:VARIANT",
                   help="ask a different question: is this trajectory exactly that scheme (e.g. "
                        "reference:course, for a student checking a faithful implementation of the "
                        "course)? PASS says what the scheme gets wrong on this scenario, if "
                        "anything. Without it: is it a correct simulation of the scenario's physics?")
    c.add_argument("--json", metavar="FILE", help="also write everything the check found as JSON")
    c.add_argument("--plot", metavar="FILE.png",
                   help="draw the trajectory, the reference, the closest "
                        "correct scheme, the polhode and the one-step defect over time")
    c.add_argument("--animate", metavar="FILE.gif",
                   help="animate the body (a box with its principal axes) beside the reference's, with the "
                        "time and the current error in each frame: .gif (always), .mp4 or .webm (where "
                        "ffmpeg is installed); at most 200 frames sampled uniformly in time. With several "
                        "files: the first")
    _add_engine_file_option(c)


def _add_compare(sub) -> None:
    cmp_ = sub.add_parser(
        "compare",
        help="compare a new results directory with a baseline: regressions, improvements, new/missing rows",
        description="Match rows of BASELINE_DIR/results.csv and NEW_DIR/results.csv by (scenario, "
                    "engine, dt). Errors and drifts are better when lower, orders when closer to the "
                    "expected order; each metric has an absolute + relative tolerance "
                    "(cross_checks/core/tolerances.py). Either directory may be a full results "
                    "directory or a compact baseline (rbcheck baseline). NEW_DIR of a subset sweep "
                    "is compared on the scenarios and variants it ran (its summary.json lists them); "
                    "the baseline's other rows are counted in one line, not compared; so are, one "
                    "line per engine, the rows of an optional engine (drake) that was not installed "
                    "where NEW_DIR was made, unless --require names it. Each variant is judged as a "
                    "whole — regression, improvement, scheme changed (orders kept, errors both ways "
                    "within x4) — with its causes first (orders, one-step orders, agreements, "
                    "energy-drift kind); every row follows (folded in --markdown). Exit 0: no "
                    "regression (a stale baseline is said in one line); 1: a regression (or rows of "
                    "what NEW_DIR ran missing from it, unless --allow-missing; a variant NEW_DIR's "
                    "sweep skipped because its engine is installed but broken counts as missing; "
                    "with --fail-on-change any change); 2: unusable input. See docs/results.md.")
    cmp_.add_argument("baseline", metavar="BASELINE_DIR")
    cmp_.add_argument("new", metavar="NEW_DIR")
    cmp_.add_argument("--markdown", metavar="FILE",
                      help="also write the comparison as a markdown table (CI job summary)")
    cmp_.add_argument("--allow-missing", action="store_true",
                      help="rows absent from NEW_DIR (e.g. a variant unavailable "
                           "there) are reported but not a regression")
    cmp_.add_argument("--fail-on-change", action="store_true",
                      help="exit 1 on any change, improvements and changed schemes "
                           "included (a CI job that insists the committed baseline be "
                           "regenerated); without it a stale baseline is said in one line")
    _add_ci_options(cmp_)
    cmp_.add_argument("--require", action="append", default=[], metavar="ENGINE",
                      help="an engine NEW_DIR must have run (repeatable): an optional "
                           "engine (e.g. drake) that was not installed there is then "
                           "a failure instead of one line of rows not compared")


def _add_baseline(sub) -> None:
    bl = sub.add_parser(
        "baseline",
        help="write the compact, reviewable baseline of a results directory (what baselines/default holds)",
        description="Write OUT_DIR/results.csv (RESULTS_DIR's rows without the timing columns "
                    "wall_s and cached, cells copied exactly) and OUT_DIR/summary.json (provenance "
                    "and one line per scenario, variant, convergence, local-convergence and "
                    "agreement record, reduced to what compare reads and a reviewer needs to see a "
                    "verdict change). rbcheck compare reads it like a results directory. OUT_DIR "
                    "is replaced as a whole, and only when absent, empty or holding nothing but "
                    "those two files. Exit 0: written; 2: RESULTS_DIR damaged or not a results "
                    "directory, OUT_DIR refused or not writable. See docs/results.md.")
    bl.add_argument("results", metavar="RESULTS_DIR", help="a results directory written by rbcheck sweep")
    bl.add_argument("out", metavar="OUT_DIR", help="the baseline directory to write, e.g. baselines/default")


def _add_bench(sub) -> None:
    b = sub.add_parser("bench",
                       help="throughput of the reference vs MuJoCo and PyBullet, and "
                            "the cold sweep against its floor, measured in one run",
                       description="Step the same N free bodies (gravity + a body torque; the same N "
                                   "in every row) in the batched reference, MuJoCo (N bodies in one "
                                   "model; rollout) and PyBullet, and a single trajectory in the "
                                   "reference and mj_step; then time a cold sweep (--no-cache: the "
                                   "catalog with every reference, MuJoCo and PyBullet variant, its run "
                                   "stage and its report apart) against its floor: total engine steps "
                                   "x one bare mj_step measured here / cores. Every measurement is "
                                   "repeated: median and [min, max] (cross_checks/bench.py); and "
                                   "rbcheck fuzz's cases/s per engine (docs/fuzz.md).")
    b.add_argument("--quick", action="store_true",
                   help="fewer bodies and steps, and a sweep of 3 "
                        "scenarios (about a minute instead of several)")
    b.add_argument("--repeats", type=_repeats_option, default=3, metavar="N",
                   help="repeats of every measurement (default 3, at most 100)")
    b.add_argument("--no-sweep", action="store_true", help="leave out the sweep against its floor")
    b.add_argument("--json", metavar="FILE", help="write the measurements as JSON")


def _add_fuzz(sub) -> None:
    fz = sub.add_parser(
        "fuzz",
        help="search random valid scenarios for engine disagreements; "
             "shrink each failure to a scenario file",
        description="Draw random valid scenarios (every body, initial-state and force kind) with the "
                    "dimensionless numbers under control so that a correct engine of its declared order "
                    "must pass, and check on each: same-scheme pairs agree to round-off, each variant's "
                    "one-step defect and free-running error have its declared order, conserved quantities "
                    "drift no more than the scheme allows. Each distinct failure is shrunk to a minimal "
                    "scenario, DIR/counterexamples/*.toml, which `rbcheck sweep` with the same engines "
                    "confirms (exit 1). DIR/fuzz.json and DIR/index.html summarise. Deterministic for a "
                    "seed. Exit 0: nothing found; 1: counterexamples; 2: bad input. See docs/fuzz.md.")
    fz.add_argument("--engines", nargs="+", metavar="ENGINE[:VARIANT]",
                    help="variants to check (an engine name means all its "
                         "variants); default: every available variant")
    fz.add_argument("--budget", type=_seconds_option, default=60.0, metavar="SECONDS",
                    help="seconds of searching (default 60); shrinking the failures found comes after it")
    fz.add_argument("--seed", type=_nonnegative_int, default=0, metavar="N", help="campaign seed (default 0)")
    fz.add_argument("--jobs", type=_jobs_option, metavar="N", help="worker processes (default: all cores)")
    fz.add_argument("--no-cache", action="store_true",
                    help="recompute every batch instead of reusing cached outcomes")
    fz.add_argument("--dask", metavar="ADDRESS",
                    help="run the batches on a Dask cluster (as rbcheck sweep --dask)")
    fz.add_argument("--out", required=True, metavar="DIR",
                    help="output directory, replaced atomically and only when absent, empty or rbcheck's own")
    _add_engine_file_option(fz)


def _add_ci_options(p) -> None:
    """``--junit FILE`` and ``--github-annotations`` of sweep and compare (docs/cli.md, "CI formats"); with
    $GITHUB_STEP_SUMMARY set, both also append their markdown summary to it."""
    p.add_argument("--junit", metavar="FILE.xml",
                   help="also write JUnit XML: one test case per verdict (variant x scenario x quantity, the "
                        "runs, each long run and agreement), a failure for each contradiction, failed run "
                        "or regression with the verdict sentence as its message")
    p.add_argument("--github-annotations", action="store_true",
                   help="print GitHub workflow commands (::error title=...::sentence, ::warning ...) for "
                        "every failure, so that they annotate the run")


def _ci_outputs(command: str, junit_path, root, annotations: list, markdown) -> None:
    """Write the JUnit file, print the annotations and append the markdown to $GITHUB_STEP_SUMMARY (a
    summary that cannot be appended to is said on stderr; the command's result stands)."""
    from cross_checks.core.progress import say
    from cross_checks.gates.ci import STEP_SUMMARY_ENV, append_step_summary, write_junit
    if junit_path:
        write_junit(junit_path, root())
    for line in annotations:
        say(line)
    if os.environ.get(STEP_SUMMARY_ENV):
        try:
            append_step_summary(markdown())
        except OSError as exc:
            say(f"rbcheck {command}: warning: ${STEP_SUMMARY_ENV} {os.environ[STEP_SUMMARY_ENV]}: cannot "
                f"append the summary: {exc.strerror or exc}", sys.stderr)


def _add_engine_file_option(p) -> None:
    """``--engine-file FILE`` (repeatable): engines main() registers before the command runs."""
    p.add_argument("--engine-file", action="append", metavar="FILE", default=[],
                   help="add the engine of this engine file (TOML: name, version, [variants.X] order, "
                        "description, command; docs/engines.md); repeatable. Its variants are NAME:VARIANT")


def _engine_file_inputs(args) -> list:
    """The --engine-file files a command reads (its outputs may not replace them)."""
    return [("engine file", f, False) for f in getattr(args, "engine_file", None) or []]


def _use_engine_files(paths) -> None:
    from cross_checks.engines import load_engine_files
    from cross_checks.engines.external import EngineFileError
    try:
        load_engine_files(paths)
    except EngineFileError as exc:
        raise BadInput(str(exc)) from None


def _whole_number(least: int):
    """An option type: a whole number, refused below ``least``."""
    def option(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be a whole number, got {text!r}") from None
        if v < least:
            raise argparse.ArgumentTypeError(f"must be >= {least}, got {v}")
        return v
    return option


_positive_int = _whole_number(1)
_nonnegative_int = _whole_number(0)
_seconds_option = _at_most(_positive_float, MAX_OPTION_SECONDS, " s (11.6 days)")
_jobs_option = _at_most(_positive_int, MAX_OPTION_JOBS)
_repeats_option = _at_most(_positive_int, 100)


def _default_or_none(engine: str):
    """The default ``ENGINE:VARIANT`` of an engine, None for one that cannot be loaded."""
    from cross_checks.engines import UnknownVariant, default_variant
    try:
        return default_variant(engine)
    except UnknownVariant:
        return None


def _list_json() -> str:
    """``rbcheck list --json``: the catalog and every variant, machine-readable."""
    import json

    from cross_checks.engines import all_variants
    from cross_checks.scenario import catalog_names, load_scenario, long_run_names

    scenarios = []
    for name in catalog_names():
        sc = load_scenario(name)
        scenarios.append({"name": sc.name, "description": sc.description, "reference": sc.reference,
                          "duration_s": sc.duration_s, "dt_s": sc.dt_s, "dt_ladder_s": list(sc.dt_ladder_s)})
    defaults = {}
    variants = []
    for v in all_variants():
        if v.engine not in defaults:
            defaults[v.engine] = _default_or_none(v.engine)
        variants.append({"name": v.name, "engine": v.engine, "variant": v.variant, "available": v.available,
                         "reason": v.reason, "version": v.version, "declared_order": v.order,
                         "description": v.description, "source": v.source,
                         "default": v.name == defaults[v.engine]})
    long_runs = []
    for name in long_run_names():
        sc = load_scenario(name)
        long_runs.append({"name": sc.name, "description": sc.description, "kind": sc.kind,
                          "duration_s": sc.duration_s, "dt_s": sc.dt_s})
    return json.dumps({"scenarios": scenarios, "long_runs": long_runs, "variants": variants}, indent=1)


def cmd_list(args) -> int:
    from cross_checks.engines import all_variants
    from cross_checks.scenario import catalog_names, load_scenario, long_run_names

    if args.json:
        print(_list_json())
        return EXIT_OK
    print("Scenarios (catalog):")
    for name in catalog_names():
        sc = load_scenario(name)
        print(f"  {name:<18} {sc.description}")
    print("\nLong runs (in the default sweep; with SCENARIOs named: rbcheck sweep --long, or by name):")
    for name in long_run_names():
        sc = load_scenario(name)
        print(f"  {name:<22} {sc.description}")
    print("\nEngine variants:")
    shown, defaults = set(), {}
    for v in all_variants():
        if v.engine not in shown and not v.source.endswith("(rbcheck)"):
            print(f"  {v.engine}: from {v.source}")
        shown.add(v.engine)
        state = f"available ({v.engine} {v.version})" if v.available else f"UNAVAILABLE: {v.reason}"
        if v.engine not in defaults:
            defaults[v.engine] = _default_or_none(v.engine)
        if v.name == defaults[v.engine]:
            state += f"; the default: run --engine {v.engine}"
        print(f"  {v.name:<26} {state}")
        text = v.description + (f" (order {v.order:g})" if v.order is not None else "")
        if text:
            print(f"  {'':<26} {text.strip()}")
    from cross_checks.engines import unusable_required_engines
    for engine, why in unusable_required_engines().items():
        print(f"rbcheck list: warning: {engine} is required by rbcheck and cannot run here ({why}): "
              "sweep and fuzz exit 2 until it is reinstalled", file=sys.stderr)
    return EXIT_OK


def _step_and_duration(args, sc) -> tuple:
    """``(Δt, duration)`` of ``run``/``show``: the options or the scenario's, Δt within the duration and the
    steps within the limit (BadInput naming the option otherwise)."""
    from cross_checks.scenario.limits import LimitExceeded, check_run_steps
    dt = args.dt if args.dt is not None else sc.dt_s
    T = args.duration if args.duration is not None else sc.duration_s
    if dt > T:
        raise BadInput(f"--dt {dt:g}: must be <= the duration ({T:g} s)")
    try:
        check_run_steps(T, dt, "--dt" if args.dt is not None else "--duration")
    except LimitExceeded as exc:
        raise BadInput(str(exc)) from None
    return dt, T


def cmd_show(args) -> int:
    from cross_checks.scenario import load_scenario
    from cross_checks.scenario.resolved import format_resolved, resolved_json, resolved_scenario

    sc = load_scenario(args.scenario)
    dt, T = _step_and_duration(args, sc)
    if args.json:
        sys.stdout.write(resolved_json(sc, dt, T))
    else:
        print(format_resolved(resolved_scenario(sc, dt, T)))
    return EXIT_OK


def _check_out_path(out: str, suffix: str | None = ".csv", option: str = "--out") -> Path:
    """An output file the user named, checked before any work: the right suffix (when given), a
    directory that exists and can be written in (tried for real), not itself a directory."""
    from cross_checks.sweep.results_dir import ResultsDirError, check_writable_dir
    if not str(out).strip():
        raise BadInput(f"{option}: empty path; name a file")
    path = Path(out)
    if suffix is not None and path.suffix != suffix:
        raise BadInput(f"{option} {out}: must end in {suffix}")
    parent = path.parent
    if not parent.is_dir():
        what = "is not a directory" if parent.exists() else "does not exist"
        raise BadInput(f"{option} {out}: directory {parent} {what}")
    if path.is_dir():
        raise BadInput(f"{option} {out}: is a directory")
    try:
        check_writable_dir(parent, option, out)
    except ResultsDirError as exc:
        raise BadInput(str(exc)) from None
    return path


def _resolved(path) -> Path:
    try:
        return Path(path).expanduser().resolve()
    except (OSError, RuntimeError):
        return Path(os.path.abspath(path))


def _is_within(path: Path, folder: Path) -> bool:
    return path == folder or folder in path.parents


def refuse_inputs_as_outputs(outputs, inputs) -> None:
    """BadInput, before any work, when an output would replace or land inside what the command reads.

    ``outputs``: ``[(option, path, is_dir)]``; ``inputs``: ``[(what, path, is_dir)]``. An output file may not
    be an input file (the same file after resolving links) nor lie inside an input directory (a results
    directory or baseline the command reads); an output directory may not hold an input."""
    ins = [(what, _resolved(p), is_dir, p) for what, p, is_dir in inputs if p is not None and str(p).strip()]
    for option, out, out_is_dir in outputs:
        if out is None or not str(out).strip():
            continue
        o = _resolved(out)
        for what, i, in_is_dir, given in ins:
            same = o == i or (o.exists() and i.exists() and _samefile(o, i))
            inside = (not out_is_dir and in_is_dir and _is_within(o, i)) or (out_is_dir and _is_within(i, o))
            if same or inside:
                how = "is" if same else ("lies inside" if not out_is_dir else "holds")
                raise BadInput(f"{option} {out}: {how} the {what} {given} this command reads; "
                               "writing there would destroy its input — choose another path")


def _samefile(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def _scenario_inputs(specs) -> list:
    """``[("scenario file", path, False)]`` of the SCENARIO arguments that are
    files (catalog names are not)."""
    return [("scenario file", s, False) for s in specs if s and Path(s).exists()]


def _did_you_mean(name: str) -> str:
    """For a bare name that is no engine but some engine's variant (``course``): the full names."""
    if ":" in name:
        return ""
    from cross_checks.engines import all_variants
    hits = [v.name for v in all_variants() if v.variant == name]
    return f"; did you mean {' or '.join(hits)}? (ENGINE:VARIANT)" if hits else ""


def cmd_run(args) -> int:
    from cross_checks.engines import (
        EngineError,
        EngineUnavailable,
        UnknownVariant,
        default_variant,
        run_variant,
        split_variant,
    )
    from cross_checks.scenario import load_scenario

    try:
        if ":" not in args.engine:  # an engine name alone: its default variant
            args.engine = default_variant(args.engine)
        split_variant(args.engine)
    except UnknownVariant as exc:
        raise BadInput(f"--engine: {exc}{_did_you_mean(args.engine)}") from None
    out = _check_out_path(args.out)
    from cross_checks.core.trajectory import sidecar_path
    refuse_inputs_as_outputs([("--out", args.out, False),
                              ("--out (its sidecar)", sidecar_path(args.out), False)],
                             _scenario_inputs([args.scenario]) + _engine_file_inputs(args))
    sc = load_scenario(args.scenario)
    dt, T = _step_and_duration(args, sc)
    if args.engine.startswith("reference:"):   # a cold first run compiles for a minute: say so (stderr)
        from cross_checks.sweep.run import warm_reference
        warm_reference("rbcheck run", True, stream=sys.stderr)
    try:
        traj = run_variant(sc, args.engine, dt, T)
    except EngineUnavailable as exc:
        raise BadInput(f"--engine {args.engine}: {exc}") from None
    except EngineError as exc:  # the engine refused or failed: its own words, nothing written
        print(f"rbcheck run: {sc.name} with {args.engine} failed: {exc}", file=sys.stderr)
        return EXIT_FAIL
    rows = len(traj.t_s)
    if traj.meta["status"] == "diverged" and rows == 0:
        print(f"{sc.name} with {args.engine}: {traj.meta['message']}; no state before it, nothing written",
              file=sys.stderr)
        return EXIT_FAIL
    traj.write(out)
    n = rows - 1
    if traj.meta["status"] == "diverged":
        what = "the initial state" if n == 0 else f"the initial state and the {n} step(s)"
        print(f"{sc.name} with {args.engine}: {traj.meta['message']}; wrote {what} before it to {out}",
              file=sys.stderr)
        return EXIT_FAIL
    print(f"{sc.name} with {args.engine} ({traj.meta['engine_version']}): {n} steps of {dt:g} s "
          f"in {traj.meta['wall_s']:.3g} s -> {out}")
    return EXIT_OK


def _resolve_engines(specs):
    """``--engines`` values -> (variants to run, {variant: why skipped}) ; BadInput for unknown or
    explicitly requested unavailable ones."""
    from cross_checks.engines import UnknownVariant, all_variants, engine_variants, split_variant

    _refuse_unusable_required_engines()
    infos = {v.name: v for v in all_variants()}
    if not specs:
        run = [n for n, v in infos.items() if v.available]
        skipped = {n: v.reason for n, v in infos.items() if not v.available}
        return run, skipped
    out = []
    for spec in (x for s in specs for x in s.split(",") if x):
        try:
            names = [f"{spec}:{v}" for v in engine_variants(spec)] if ":" not in spec else [spec]
        except UnknownVariant as exc:
            raise BadInput(f"--engines: {exc}") from None
        if not names:
            raise BadInput(f"--engines {spec}: {infos[spec + ':*'].reason}")
        for n in names:
            try:
                split_variant(n)
            except UnknownVariant as exc:
                raise BadInput(f"--engines: {exc}") from None
            if not infos[n].available:
                raise BadInput(f"--engines {n}: {infos[n].reason}")
            if n not in out:
                out.append(n)
    return out, {}


def _refuse_unusable_required_engines() -> None:
    """BadInput when an engine rbcheck depends on (MuJoCo, PyBullet) cannot run here: a broken installation
    is repaired, never reported as "not installed" nor swept around."""
    from cross_checks.engines import unusable_required_engines
    broken = unusable_required_engines()
    if broken:
        engine, why = next(iter(broken.items()))
        raise BadInput(f"{engine} is required by rbcheck and cannot run here: {why}; "
                       "reinstall it (pip install --force-reinstall rbcheck, or pip "
                       "install -e . in a clone, installs the tested versions)")


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


@contextlib.contextmanager
def _dask_executor(address: str | None):
    """The executor of a client of the Dask scheduler at ``address`` (None without one), closed after."""
    if not address:
        yield None
        return
    try:
        from distributed import Client
    except ImportError:
        raise BadInput("--dask: the 'distributed' package is not installed; install the optional extra: "
                       "pip install -e '.[dask]'") from None
    try:
        client = Client(address, timeout=10)
    except (OSError, TimeoutError, ValueError) as exc:
        raise BadInput(f"--dask {address}: cannot connect to the Dask scheduler: {exc}") from None
    try:
        yield client.get_executor()
    finally:
        client.close()


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
                             _scenario_inputs(args.scenarios) + _engine_file_inputs(args))
    if args.junit:
        _check_out_path(args.junit, ".xml", "--junit")
        if _is_within(_resolved(args.junit), _resolved(args.out)):
            raise BadInput(f"--junit {args.junit}: lies inside --out {args.out}, which the sweep replaces "
                           "as a whole; choose a path outside it")
    names = list(args.scenarios or catalog_names())
    if args.long or not (args.scenarios or args.no_long):   # the default sweep has the long runs
        names += [n for n in long_run_names() if n not in names]
    scenarios = [load_scenario(s) for s in names]
    variants, skipped = _resolve_engines(args.engines)
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
        return _error("sweep", f"{exc} (RBCHECK_DEBUG=1 shows the traceback)")
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
    _ci_outputs("sweep", args.junit, lambda: ci.sweep_junit(summary, rows, long_rows),
                ci.sweep_annotations(summary, rows, long_rows) if args.github_annotations else [],
                lambda: ci.sweep_markdown(summary, args.out, rows, long_rows))


def _run_sweep(args, scenarios, variants, skipped) -> dict:
    """run_sweep with the command's options; the report is drawn inside the atomic replacement."""
    import reports
    from cross_checks.sweep import run_sweep

    jobs = args.jobs or usable_cores()
    with _dask_executor(args.dask) as executor:
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
    if not wrong and not failed and not inv.get("broken"):
        say(f"rbcheck sweep: all {total} verdicts as expected")
    else:
        say(f"rbcheck sweep: {wrong} of {total} verdicts not as expected"
            + (f", {failed} run(s) failed" if failed else "")
            + (f", {inv['broken']} broken invariance(s)" if inv.get("broken") else "")
            + f" (see {Path(out) / 'index.html'})")
    return EXIT_FAIL if fails else EXIT_OK


def cmd_report(args) -> int:
    import reports
    from cross_checks.sweep.results_dir import ResultsDirError, check_writable_dir
    from reports import ResultsError

    jobs = args.jobs or usable_cores()
    reports.check_installation()
    if not Path(args.dir).is_dir():
        raise BadInput(f"{args.dir}: no such directory")
    try:
        check_writable_dir(Path(args.dir), "DIR", args.dir)
        written = reports.render(args.dir, self_contained=args.self_contained, jobs=jobs, progress=True)
    except (ResultsError, ResultsDirError) as exc:
        raise BadInput(str(exc)) from None
    print(f"rbcheck report: wrote {len(written)} page(s) -> {Path(args.dir) / 'index.html'}")
    return EXIT_OK


def cmd_check(args) -> int:
    from cross_checks.cli.check import run_check
    refuse_inputs_as_outputs([("--json", args.json, False), ("--plot", args.plot, False),
                              ("--animate", args.animate, False)],
                             [("trajectory", t, False) for t in args.trajectories]
                             + [("sidecar", Path(t).with_suffix(".json"), False) for t in args.trajectories]
                             + _scenario_inputs([args.scenario]) + _engine_file_inputs(args))
    if args.json:
        _check_out_path(args.json, None, "--json")
    if args.plot:
        _check_out_path(args.plot, ".png", "--plot")
    if args.animate:
        from reports.animation import AnimationError, check_animation_path
        _check_out_path(args.animate, None, "--animate")
        try:
            check_animation_path(args.animate)
        except AnimationError as exc:
            raise BadInput(str(exc)) from None
    return run_check(args, BadInput)


def cmd_compare(args) -> int:
    from cross_checks.core.files import atomic_write_text
    from cross_checks.gates.compare import (
        CompareInputError,
        compare_dirs,
        read_results_dir,
        to_markdown,
        to_text,
    )

    refuse_inputs_as_outputs([("--markdown", args.markdown, False), ("--junit", args.junit, False)],
                             [("baseline directory", args.baseline, True),
                              ("results directory", args.new, True)])
    if args.markdown:
        _check_out_path(args.markdown, None, "--markdown")
    if args.junit:
        _check_out_path(args.junit, ".xml", "--junit")
    try:
        c = compare_dirs(args.baseline, args.new, require=args.require)
        _, new_summary = read_results_dir(args.new)
    except CompareInputError as exc:
        raise BadInput(str(exc)) from None
    ran = _variants_ran(args.new)
    print(to_text(c, args.allow_missing, ran, args.fail_on_change))

    from cross_checks.core.progress import shown

    def markdown():
        return to_markdown(c, args.baseline, args.new, args.allow_missing, ran, args.fail_on_change)
    if args.markdown:
        atomic_write_text(args.markdown, shown(markdown()) + "\n")
    from cross_checks.gates import ci
    _ci_outputs("compare", args.junit,
                lambda: ci.compare_junit(c, new_summary, args.allow_missing, args.fail_on_change),
                ci.compare_annotations(c, new_summary, args.allow_missing, args.fail_on_change)
                if args.github_annotations else [], lambda: shown(markdown()))
    return c.exit_code(args.allow_missing, args.fail_on_change)


def _variants_ran(new_dir) -> list:
    """The variants NEW_DIR's summary lists (to name the ones that did not change)."""
    import json
    try:
        return [v["name"]
                for v in json.loads((Path(new_dir) / "summary.json").read_text()).get("variants", [])]
    except (OSError, ValueError, KeyError, TypeError):
        return []


def cmd_baseline(args) -> int:
    from cross_checks.gates.baseline import BaselineError, write_baseline
    from cross_checks.gates.compare import CompareInputError

    refuse_inputs_as_outputs([("OUT_DIR", args.out, True)], [("results directory", args.results, True)])
    try:
        written = write_baseline(args.results, args.out)
    except (BaselineError, CompareInputError) as exc:
        raise BadInput(str(exc)) from None
    counts = ", ".join(f"{len(written.summary.get(k, []))} {k.replace('_', ' ')} records"
                       for k in ("convergence", "local_convergence", "agreement"))
    print(f"rbcheck baseline: {written.rows} rows, {counts} -> {Path(args.out) / 'results.csv'}, "
          f"{Path(args.out) / 'summary.json'}")
    return EXIT_OK


def cmd_bench(args) -> int:
    from cross_checks.bench import main as bench_main
    if args.json:
        _check_out_path(args.json, None, "--json")
    import reports
    from cross_checks.fuzz.throughput import format_fuzz, fuzz_throughput
    jobs = usable_cores()
    return bench_main(args.quick, args.json, extra={"fuzz": (fuzz_throughput, format_fuzz)},
                      repeats=args.repeats, sweep=not args.no_sweep,
                      render=lambda d: reports.render(d, jobs=jobs))


def cmd_fuzz(args) -> int:
    from cross_checks.cli.fuzz import run_fuzz
    refuse_inputs_as_outputs([("--out", args.out, True)], _engine_file_inputs(args))
    return run_fuzz(args, BadInput, _resolve_engines, _dask_executor)


COMMANDS = {"list": cmd_list, "show": cmd_show, "run": cmd_run, "sweep": cmd_sweep, "report": cmd_report,
            "check": cmd_check, "compare": cmd_compare, "baseline": cmd_baseline, "bench": cmd_bench,
            "fuzz": cmd_fuzz}


def main(argv=None) -> int:
    """The ``rbcheck`` command; its output shows control characters escaped (docs/hardening.md)."""
    from cross_checks.core.progress import escaped_output
    from cross_checks.sweep.lifecycle import exit_at_once, interrupted_by
    with escaped_output():
        code = _main(argv)
    if code in (EXIT_INTERRUPTED, EXIT_TERMINATED) and interrupted_by() and argv is None:
        exit_at_once(code)   # the command line's rbcheck only (argv None), not a caller's main([...])
    return code


def _main(argv=None) -> int:
    from cross_checks.core.progress import degrade_unencodable
    from cross_checks.core.trajectory import TrajectoryError
    from cross_checks.scenario import ScenarioError
    from cross_checks.sweep.lifecycle import Terminated, handle_sigterm, interrupted_by
    from reports.install import IncompleteInstallation
    degrade_unencodable(sys.stdout, sys.stderr)   # Δt -> dt where the locale cannot write it
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as exc:  # usage errors (exit 2) and --help (exit 0) return instead of raising
        return int(exc.code or 0)
    handle_sigterm()
    try:
        if getattr(args, "engine_file", None):
            _use_engine_files(args.engine_file)
        return COMMANDS[args.command](args)
    except (ScenarioError, TrajectoryError, BadInput, IncompleteInstallation) as exc:
        return _error(args.command, str(exc))
    except Terminated:
        print(f"rbcheck {args.command}: terminated", file=sys.stderr)
        return EXIT_TERMINATED
    except KeyboardInterrupt:
        print(f"rbcheck {args.command}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except OSError as exc:  # a file that could not be read or written: name it, no traceback
        where = f"{exc.filename}: " if exc.filename else ""
        return _error(args.command, f"{where}{exc.strerror or exc}")
    except (MemoryError, RecursionError, Exception) as exc:  # noqa: BLE001
        signum = interrupted_by()
        if signum:   # a signal's exception turned into another on its way (e.g. raised inside an import)
            import signal
            what = "terminated" if signum == signal.SIGTERM else "interrupted"
            print(f"rbcheck {args.command}: {what}", file=sys.stderr)
            return EXIT_TERMINATED if signum == signal.SIGTERM else EXIT_INTERRUPTED
        # every error path: one line, exit 2
        if os.environ.get("RBCHECK_DEBUG"):
            raise
        return _error(args.command, f"internal error: {type(exc).__name__}: {exc} "
                                    "(RBCHECK_DEBUG=1 shows the traceback)")


def _error(command: str, message: str) -> int:
    message = " ".join(str(message).split())  # one line, whatever the message holds
    print(f"rbcheck {command}: error: {message}", file=sys.stderr)
    return EXIT_BAD_INPUT


if __name__ == "__main__":
    sys.exit(main())
