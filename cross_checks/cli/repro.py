"""``rbcheck repro VARIANT SCENARIO --claim CLAIM [WORD ...] --out FILE.py``: a standalone reproducer
(cross_checks.sweep.repro; docs/repro.md)."""
from __future__ import annotations

import sys

from cross_checks.cli.errors import (
    BadInput,
    check_out_path,
    engine_file_inputs,
    refuse_inputs_as_outputs,
    scenario_inputs,
)

__all__ = ["add_repro", "cmd_repro"]


def add_repro(sub, engine_file_option) -> None:
    r = sub.add_parser(
        "repro",
        help="write a standalone Python script (the engine and NumPy only) that reproduces a claim about a "
             "variant on a scenario, for the engine's maintainers",
        description="Write FILE.py: one Python script that imports only the engine and NumPy (never "
                    "rbcheck), builds the model as rbcheck's adapter does (its code, without its docstrings, "
                    "comments and what the script never reaches), embeds the "
                    "scenario's numbers and the reference values, runs the ladder or the long run, prints "
                    "the engine's, NumPy's and Python's versions and the platform, then the measured value "
                    "beside the expected one, and exits 1 while the defect holds, 0 when it does not. "
                    "CLAIM: 'order QUANTITY' (the fitted order against the declared one; QUANTITY: "
                    "position, orientation, velocity, angular_velocity), 'drift' (a long run's energy, |L| "
                    "and separatrix distance), 'gyroscopic' (the torque-free flip is missing), 'invariance "
                    "TRANSFORM' (the transformed scenario, mapped back, moves as the original within the "
                    "sweep's allowance; TRANSFORM as invariance.csv names it, e.g. 'scale k=0.01 mu=0.01', "
                    "'translation 1e4', 'rotation', 'com_offset' (a body off its COM: MuJoCo, Drake, DART, "
                    "PyBullet), 'welded_split' (welded parts: MuJoCo, Drake, DART)). A claim that does not "
                    "hold here is written anyway and said so. Every built-in engine can write one (not "
                    "reference: it is rbcheck's own); engine files cannot (their command is the "
                    "reproducer). Exit 0: written; 2: bad "
                    "input (one line, nothing written). See docs/repro.md.")
    r.add_argument("variant", metavar="VARIANT", help="ENGINE:VARIANT, e.g. mujoco:rk4")
    r.add_argument("scenario", metavar="SCENARIO", help="catalog name or scenario TOML file")
    r.add_argument("--claim", nargs="+", required=True, metavar="WORD",
                   help="order QUANTITY | drift | gyroscopic | invariance TRANSFORM")
    r.add_argument("--out", required=True, metavar="FILE.py", help="the script to write")
    engine_file_option(r)


def cmd_repro(args) -> int:
    from cross_checks.scenario import load_scenario
    from cross_checks.sweep.repro import ReproError, reproducer, write_reproducer
    out = check_out_path(args.out, ".py", "--out")
    refuse_inputs_as_outputs([("--out", out, False)],
                             scenario_inputs([args.scenario]) + engine_file_inputs(args))
    sc = load_scenario(args.scenario)
    command = f"rbcheck repro {args.variant} {args.scenario} --claim {' '.join(args.claim)}"
    try:
        r = reproducer(args.variant, sc, args.claim, command=command)
    except ReproError as exc:
        raise BadInput(str(exc)) from None
    write_reproducer(r, out)
    said = r.summary
    if r.holds:
        print(f"{args.variant} on {sc.name}, {r.claim}: {said}\nwrote {out} (it exits 1 while the defect "
              "holds, 0 once fixed)")
    else:
        print(f"{args.variant} on {sc.name}, {r.claim}: no defect here: {said}\nwrote {out} anyway (it exits "
              "0 here)", file=sys.stdout)
    return 0
