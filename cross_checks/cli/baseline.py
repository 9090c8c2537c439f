"""``rbcheck baseline``: the compact, reviewable baseline of a results directory (docs/results.md)."""
from __future__ import annotations

from pathlib import Path

from cross_checks.cli.errors import EXIT_OK, BadInput, refuse_inputs_as_outputs


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
