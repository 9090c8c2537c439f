"""``rbcheck`` command line (DESIGN.md contract).

Exit codes: 0 success; 1 a comparison or gate found a regression / disagreement, or a run diverged;
2 bad input (file, field and reason on stderr, no traceback); 130 interrupted (Ctrl-C).
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

__all__ = ["main"]

EXIT_OK, EXIT_FAIL, EXIT_BAD_INPUT, EXIT_INTERRUPTED = 0, 1, 2, 130


class BadInput(Exception):
    """Input the user must fix; the message names the file/option, the field and the reason."""


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


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(
        prog="rbcheck",
        description="Validate rigid-body simulators: a NumPy reference of the GAMES103 course equations, "
                    "MuJoCo and PyBullet on identical free-body scenarios, against analytic or DOP853 references.",
        epilog="SCENARIO is a catalog name (see `rbcheck list`) or a path to a scenario TOML file. "
               "Exit codes: 0 ok; 1 regression/disagreement or a diverged run; 2 bad input; 130 interrupted.",
    )
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND", parser_class=_Parser)

    sub.add_parser("list", help="list catalog scenarios and engine variants (with availability)")

    r = sub.add_parser("run", help="run one scenario with one engine variant and write the trajectory CSV")
    r.add_argument("scenario", metavar="SCENARIO")
    r.add_argument("--engine", required=True, metavar="ENGINE:VARIANT", help="e.g. reference:course, mujoco:rk4")
    r.add_argument("--dt", type=_positive_float, metavar="DT", help="time step, s (default: the scenario's dt)")
    r.add_argument("--duration", type=_positive_float, metavar="T", help="simulated time, s (default: the scenario's)")
    r.add_argument("--out", required=True, metavar="FILE.csv", help="trajectory CSV (sidecar FILE.json beside it)")
    return p


def cmd_list(args) -> int:
    from .engines import all_variants
    from .scenario import catalog_names, load_scenario

    print("Scenarios (catalog):")
    for name in catalog_names():
        sc = load_scenario(name)
        print(f"  {name:<18} {sc.description}")
    print("\nEngine variants:")
    for v in all_variants():
        state = f"available ({v.engine} {v.version})" if v.available else f"UNAVAILABLE: {v.reason}"
        print(f"  {v.name:<26} {state}")
        if v.description:
            print(f"  {'':<26} {v.description}")
    return EXIT_OK


def _check_out_path(out: str, suffix: str = ".csv") -> Path:
    path = Path(out)
    if path.suffix != suffix:
        raise BadInput(f"--out {out}: must end in {suffix}")
    if not path.parent.exists():
        raise BadInput(f"--out {out}: directory {path.parent} does not exist")
    if path.exists() and path.is_dir():
        raise BadInput(f"--out {out}: is a directory")
    return path


def cmd_run(args) -> int:
    from .engines import EngineUnavailable, UnknownVariant, run_variant, split_variant
    from .scenario import load_scenario

    try:
        split_variant(args.engine)
    except UnknownVariant as exc:
        raise BadInput(f"--engine: {exc}") from None
    out = _check_out_path(args.out)
    sc = load_scenario(args.scenario)
    dt = args.dt if args.dt is not None else sc.dt_s
    T = args.duration if args.duration is not None else sc.duration_s
    if dt > T:
        raise BadInput(f"--dt {dt:g}: must be <= the duration ({T:g} s)")
    try:
        traj = run_variant(sc, args.engine, dt, T)
    except EngineUnavailable as exc:
        raise BadInput(f"--engine {args.engine}: {exc}") from None
    traj.write(out)
    n = len(traj.t_s) - 1
    if traj.meta["status"] == "diverged":
        print(f"{sc.name} with {args.engine}: {traj.meta['message']}; wrote the {n} steps before it to {out}",
              file=sys.stderr)
        return EXIT_FAIL
    print(f"{sc.name} with {args.engine} ({traj.meta['engine_version']}): {n} steps of {dt:g} s "
          f"in {traj.meta['wall_s']:.3g} s -> {out}")
    return EXIT_OK


COMMANDS = {"list": cmd_list, "run": cmd_run}


def main(argv=None) -> int:
    from .scenario import ScenarioError
    from .trajectory import TrajectoryError

    try:
        args = build_parser().parse_args(argv)
    except SystemExit as exc:  # usage errors (exit 2) and --help (exit 0) return instead of raising
        return int(exc.code or 0)
    try:
        return COMMANDS[args.command](args)
    except (ScenarioError, TrajectoryError, BadInput) as exc:
        print(f"rbcheck {args.command}: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print(f"rbcheck {args.command}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED


if __name__ == "__main__":
    sys.exit(main())
