"""``rbcheck show``: a scenario resolved exactly as every engine receives it (``--json``: the engine-file
JSON)."""
from __future__ import annotations

import sys

from cross_checks.cli.errors import EXIT_OK
from cross_checks.cli.run import step_and_duration


def cmd_show(args) -> int:
    from cross_checks.scenario import load_scenario
    from cross_checks.scenario.resolved import format_resolved, resolved_json, resolved_scenario

    sc = load_scenario(args.scenario)
    dt, T = step_and_duration(args, sc)
    if args.json:
        sys.stdout.write(resolved_json(sc, dt, T))
    else:
        print(format_resolved(resolved_scenario(sc, dt, T)))
    return EXIT_OK
