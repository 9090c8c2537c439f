"""``rbcheck report``: the plots and HTML of a results directory, drawn again from its saved data."""
from __future__ import annotations

from pathlib import Path

from cross_checks.cli.errors import EXIT_OK, BadInput
from cross_checks.core.files import usable_cores


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
