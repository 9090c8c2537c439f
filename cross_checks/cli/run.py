"""``rbcheck run``: one scenario with one engine variant, the trajectory CSV and its sidecar."""
from __future__ import annotations

import sys

from cross_checks.cli.errors import (
    EXIT_FAIL,
    EXIT_OK,
    BadInput,
    check_out_path,
    engine_file_inputs,
    refuse_inputs_as_outputs,
    scenario_inputs,
)


def step_and_duration(args, sc) -> tuple:
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


def _did_you_mean(name: str) -> str:
    """For a bare name that is no engine but some engine's variant (``course``): the full names."""
    if ":" in name:
        return ""
    from cross_checks.engines import all_variants
    hits = [v.name for v in all_variants() if v.variant == name]
    return f"; did you mean {' or '.join(hits)}? (ENGINE:VARIANT)" if hits else ""


def cmd_run(args) -> int:
    from cross_checks.engines import EngineError, EngineUnavailable, UnknownVariant, resolve, run_variant
    from cross_checks.scenario import load_scenario

    try:
        args.engine = resolve(args.engine, strict=True, engine_alone=True)   # a name alone: its default
    except UnknownVariant as exc:
        raise BadInput(f"--engine: {exc}{_did_you_mean(args.engine)}") from None
    out = check_out_path(args.out)
    from cross_checks.core.trajectory import sidecar_path
    refuse_inputs_as_outputs([("--out", args.out, False),
                              ("--out (its sidecar)", sidecar_path(args.out), False)],
                             scenario_inputs([args.scenario]) + engine_file_inputs(args))
    sc = load_scenario(args.scenario)
    dt, T = step_and_duration(args, sc)
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
