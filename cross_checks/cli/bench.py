"""``rbcheck bench``: the command around :func:`cross_checks.bench.main`, with rbcheck fuzz's throughput."""
from __future__ import annotations

from cross_checks.cli.errors import check_out_path
from cross_checks.core.files import usable_cores


def cmd_bench(args) -> int:
    from cross_checks.bench import main as bench_main
    if args.json:
        check_out_path(args.json, None, "--json")
    import reports
    from cross_checks.fuzz.throughput import format_fuzz, fuzz_throughput
    jobs = usable_cores()
    return bench_main(args.quick, args.json, extra={"fuzz": (fuzz_throughput, format_fuzz)},
                      repeats=args.repeats, sweep=not args.no_sweep,
                      render=lambda d: reports.render(d, jobs=jobs))
