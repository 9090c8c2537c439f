"""``rbcheck``'s argument parser: every command's options, their types and their ``--help`` text, and
``--version``. A usage error is one line and exit 2 (:class:`_Parser`)."""
from __future__ import annotations

import argparse
import math
import sys

from cross_checks.cli.errors import EXIT_BAD_INPUT, EXIT_OK

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
                _add_baseline, _add_bench, _add_fuzz, _add_repro):
        add(sub)
    return p


def _add_repro(sub) -> None:
    from cross_checks.cli.repro import add_repro
    add_repro(sub, _add_engine_file_option)


def _add_list(sub) -> None:
    ls = sub.add_parser("list", help="list catalog scenarios and engine variants (with availability)")
    ls.add_argument("--json", action="store_true",
                    help="print the list as JSON: scenarios (name, description, reference, duration_s, dt_s, "
                         "dt_ladder_s) and variants (name, engine, variant, available, reason, version, "
                         "declared_order, description, source, default)")
    _add_engine_file_option(ls)


def _add_dt_duration(p, dt_words: str) -> None:
    """``--dt`` (``dt_words``, default the scenario's dt) and ``--duration``: the step and the simulated time
    of a command that runs or resolves one scenario (show, run)."""
    p.add_argument("--dt", type=_positive_float, metavar="DT",
                   help=f"{dt_words} (default: the scenario's dt)")
    p.add_argument("--duration", type=_positive_float, metavar="T",
                   help="simulated time, s (default: the scenario's)")


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
    _add_dt_duration(sh, "resolve at this time step, s")


def _add_run(sub) -> None:
    r = sub.add_parser("run", help="run one scenario with one engine variant and write the trajectory CSV")
    r.add_argument("scenario", metavar="SCENARIO")
    r.add_argument("--engine", required=True, metavar="ENGINE[:VARIANT]",
                   help="e.g. reference:course, mujoco:rk4; an engine name alone runs its default "
                        "variant (the first `rbcheck list` shows: reference:course, mujoco:euler, "
                        "pybullet:multibody)")
    _add_dt_duration(r, "time step, s")
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
                        "exit 1 on a broken invariance, not on a finding the variant declares "
                        "(docs/invariance.md)")
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
                                   "reference and mj_step; each installed engine's own batched run at "
                                   "the same N (PhysX and Rapier scenes of N bodies; MJX, Brax and "
                                   "jaxsim vmapped in one compiled loop, compilation apart; MuJoCo Warp "
                                   "with N worlds) beside rbcheck's simulate_many, the two timed "
                                   "alternately in rounds; per installed "
                                   "engine, one trajectory: the time inside its step, its own minimal "
                                   "loop (apply + step + read in its own API; the CPU engines) and the "
                                   "whole cost through rbcheck; then time a cold sweep (--no-cache: the "
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


def _add_engine_file_option(p) -> None:
    """``--engine-file FILE`` (repeatable): engines main() registers before the command runs."""
    p.add_argument("--engine-file", action="append", metavar="FILE", default=[],
                   help="add the engine of this engine file (TOML: name, version, [variants.X] order, "
                        "description, command; docs/engines.md); repeatable. Its variants are NAME:VARIANT")


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
