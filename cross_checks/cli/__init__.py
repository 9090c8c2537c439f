"""``rbcheck`` command line (README: the tour and the exit-code table; docs/ for every format).

Exit codes: 0 success; 1 a comparison or gate found a regression / disagreement, or a run diverged;
2 bad input or an output that cannot be written (one line naming the file, the field and the reason,
no traceback); 130 interrupted (Ctrl-C); 143 terminated (SIGTERM). The README has the table per command.

This module is the dispatch only: :func:`main` parses (``parser``), registers the ``--engine-file``
engines, runs the command's ``cmd_*`` (one module per command: ``listing``, ``show``, ``run``, ``sweep``,
``report``, ``check``, ``compare``, ``baseline``, ``bench``, ``fuzz``, ``repro``) and turns every error into
one line and its exit code (``errors``).
"""
from __future__ import annotations

import os
import sys

from cross_checks.cli.baseline import cmd_baseline
from cross_checks.cli.bench import cmd_bench
from cross_checks.cli.check import cmd_check
from cross_checks.cli.compare import cmd_compare
from cross_checks.cli.engines import use_engine_files
from cross_checks.cli.errors import EXIT_INTERRUPTED, EXIT_TERMINATED, BadInput, error
from cross_checks.cli.fuzz import cmd_fuzz
from cross_checks.cli.listing import cmd_list
from cross_checks.cli.parser import build_parser
from cross_checks.cli.report import cmd_report
from cross_checks.cli.repro import cmd_repro
from cross_checks.cli.run import cmd_run
from cross_checks.cli.show import cmd_show
from cross_checks.cli.sweep import cmd_sweep

__all__ = ["main"]


COMMANDS = {"list": cmd_list, "show": cmd_show, "run": cmd_run, "sweep": cmd_sweep, "report": cmd_report,
            "check": cmd_check, "compare": cmd_compare, "baseline": cmd_baseline, "bench": cmd_bench,
            "fuzz": cmd_fuzz, "repro": cmd_repro}


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
            use_engine_files(args.engine_file)
        return COMMANDS[args.command](args)
    except (ScenarioError, TrajectoryError, BadInput, IncompleteInstallation) as exc:
        return error(args.command, str(exc))
    except Terminated:
        print(f"rbcheck {args.command}: terminated", file=sys.stderr)
        return EXIT_TERMINATED
    except KeyboardInterrupt:
        print(f"rbcheck {args.command}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except OSError as exc:  # a file that could not be read or written: name it, no traceback
        where = f"{exc.filename}: " if exc.filename else ""
        return error(args.command, f"{where}{exc.strerror or exc}")
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
        return error(args.command, f"internal error: {type(exc).__name__}: {exc} "
                                    "(RBCHECK_DEBUG=1 shows the traceback)")


if __name__ == "__main__":
    sys.exit(main())
