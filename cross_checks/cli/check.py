"""``rbcheck check``: refuse outputs that would replace an input, read the files, check each, fit a ladder,
print, write --json, --plot and --animate."""
from __future__ import annotations

import sys
from pathlib import Path

from cross_checks.cli.errors import (
    BadInput,
    check_out_path,
    engine_file_inputs,
    refuse_inputs_as_outputs,
    scenario_inputs,
)

__all__ = ["cmd_check", "run_check"]


def cmd_check(args) -> int:
    refuse_inputs_as_outputs([("--json", args.json, False), ("--plot", args.plot, False),
                              ("--animate", args.animate, False)],
                             [("trajectory", t, False) for t in args.trajectories]
                             + [("sidecar", Path(t).with_suffix(".json"), False) for t in args.trajectories]
                             + scenario_inputs([args.scenario]) + engine_file_inputs(args))
    if args.json:
        check_out_path(args.json, None, "--json")
    if args.plot:
        check_out_path(args.plot, ".png", "--plot")
    if args.animate:
        from reports.animation import AnimationError, check_animation_path
        check_out_path(args.animate, None, "--animate")
        try:
            check_animation_path(args.animate)
        except AnimationError as exc:
            raise BadInput(str(exc)) from None
    return run_check(args)


def run_check(args) -> int:
    from cross_checks.core.files import atomic_write_text
    from cross_checks.core.trajectory import Trajectory
    from cross_checks.gates.check import CheckError, check_trajectory
    from cross_checks.gates.check.ladder import LadderError, check_ladder
    from cross_checks.gates.check.report import format_ladder, format_report, to_json_text
    from cross_checks.scenario import load_scenario

    sc = load_scenario(args.scenario)
    if args.dt is not None:   # a step the limits allow over the scenario's duration (1e-300 s is not one)
        from cross_checks.scenario.limits import LimitExceeded, check_run_steps
        try:
            check_run_steps(sc.duration_s, args.dt, "--dt")
        except LimitExceeded as exc:
            raise BadInput(str(exc)) from None
    results = []
    compare_with = _user_variants()
    if args.scheme is not None:
        from cross_checks.engines import UnknownVariant, resolve
        try:
            args.scheme = resolve(args.scheme, strict=True)
        except UnknownVariant as exc:
            raise BadInput(f"--scheme: {exc}") from None
    for i, path in enumerate(args.trajectories):
        traj = Trajectory.read(path, require=())
        if i == 0:   # the reference's schemes, compiled once per machine: a cold first check says so
            import sys

            from cross_checks.sweep.run import warm_reference
            warm_reference("rbcheck check", True, stream=sys.stderr)
        try:
            results.append(check_trajectory(traj, sc, source=path, dt_s=args.dt, compare_with=compare_with,
                                            scheme=args.scheme))
        except CheckError as exc:
            raise BadInput(str(exc)) from None
    if args.animate and "orientation" not in results[0].series["present"]:
        raise BadInput(f"--animate: {args.trajectories[0]} has no orientation columns (qw, qx, qy, qz): "
                       "there is no motion of the body to animate")
    ladder = None
    if len(results) > 1:
        try:
            ladder = check_ladder(results, sc, scheme=args.scheme)
        except LadderError as exc:
            raise BadInput(str(exc)) from None
    texts = [format_report(r) for r in results]
    if ladder is not None:
        texts.insert(0, format_ladder(ladder))
    print(("\n\n" + "=" * 100 + "\n\n").join(texts))
    if args.plot:
        _write_plot(results, ladder, sc, args.plot)
    if args.animate:
        _write_animation(results[0], sc, args.animate)
    if args.json:
        obj = (results[0].as_dict() if ladder is None
               else {"ladder": ladder, "files": [r.as_dict() for r in results]})
        atomic_write_text(args.json, to_json_text(obj))
    passed = all(r.passed for r in results) and (ladder is None or ladder["passed"])
    return 0 if passed else 1


def _user_variants() -> list:
    """ENGINE:VARIANT of the engines given with --engine-file (registered by cli.main): each is run free at
    the file's Δt and compared with it, so the check can say the file IS one of them."""
    from cross_checks.engines import engine_variants, user_engines
    return [f"{a.name}:{v}" for a in user_engines() for v in engine_variants(a.name)]


def _write_animation(result, scenario, path):
    """Animate the (first) file's motion beside the reference into ``path`` (written whole or not at all)."""
    from reports.animation import write_check_animation
    got = write_check_animation(path, result, scenario)
    div = (f"; diverged at t = {got['diverged_at_s']:.4g} s: animated up to there"
           if got["diverged_at_s"] is not None else "")
    print(f"animation -> {path} ({got['caption']}{div})", file=sys.stderr)


def _write_plot(results, ladder, scenario, path):
    """Draw the check's figure into ``path`` atomically (never a half-written PNG)."""
    from cross_checks.core.files import atomic_write
    from reports.check_plot import check_figure, ladder_figure
    if ladder is None:
        atomic_write(path, lambda tmp: check_figure(results[0], scenario, tmp), suffix=".png")
    else:
        atomic_write(path, lambda tmp: ladder_figure(results, ladder, scenario, tmp), suffix=".png")
    print(f"plot -> {path}", file=sys.stderr)
