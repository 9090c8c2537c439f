"""``rbcheck fuzz``: the command around :func:`cross_checks.fuzz.campaign.run_campaign` (docs/fuzz.md).

Exit 0 when no property was violated, 1 with counterexamples, 2 on bad input (one line), 130/143 when
interrupted/terminated (DIR left as it was: it is replaced only at the end).
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

from cross_checks.cli.engines import dask_executor, resolve_engines
from cross_checks.cli.errors import BadInput, engine_file_inputs, refuse_inputs_as_outputs
from cross_checks.core.files import usable_cores

__all__ = ["cmd_fuzz", "run_fuzz"]


def cmd_fuzz(args) -> int:
    refuse_inputs_as_outputs([("--out", args.out, True)], engine_file_inputs(args))
    return run_fuzz(args)


def _print_result(summary, out, t0) -> None:
    c = summary["cases"]
    print(f"rbcheck fuzz: seed {summary['provenance']['seed']}: {c['judged']} cases judged "
          f"({c['skipped']} skipped as outside the fairness bounds) x {len(summary['variants'])} "
          f"variant(s) = {c['case_variant_runs']} case-variant judgments in {c['search_s']:.0f} s "
          f"({c['cases_per_s']:.2f} cases/s; {c['cached_batches']} of {c['batches']} batches "
          f"cached); {time.perf_counter() - t0:.0f} s in all -> {Path(out) / 'index.html'}")
    print(f"  {'variant':<24} {'cases':>7} {'cases/s':>9}   properties checked (no claim)")
    for v, d in summary["per_variant"].items():
        rate = f"{d['cases_per_s']:.1f}" if d["cases_per_s"] else "-"
        props = ", ".join(f"{p} {a} ({n})" for p, (a, n) in d["properties"].items() if a or n)
        if d.get("not_expressible"):
            props += f"; {d['not_expressible']} case(s) its engine cannot express, not run"
        print(f"  {v:<24} {d['cases']:>7} {rate:>9}   {props}")
    for pair, t in summary["pairs"].items():
        print(f"  {pair}: agreement {t['agreement'][0]} ({t['agreement'][1]})")


def run_fuzz(args) -> int:
    import reports.fuzz_page as page
    from cross_checks.fuzz.campaign import FuzzError, run_campaign
    from cross_checks.sweep.results_dir import ResultsDirError, check_output_dir
    from reports.install import check_templates
    check_templates()  # the summary page's templates, before the campaign
    try:
        check_output_dir(args.out)
    except ResultsDirError as exc:
        raise BadInput(str(exc)) from None
    variants, _ = resolve_engines(args.engines)
    if not variants:
        raise BadInput("--engines: no available engine variant to run")
    with dask_executor(args.dask) as executor:
        t0 = time.perf_counter()
        try:
            summary = run_campaign(variants, args.out, budget_s=args.budget, seed=args.seed,
                                   jobs=args.jobs or usable_cores(), use_cache=not args.no_cache,
                                   executor=executor, engine_files=list(args.engine_file or []),
                                   finish=page.render_fuzz)
        except FuzzError as exc:
            raise BadInput(str(exc)) from None
    _print_result(summary, args.out, t0)
    for e in summary["batch_errors"]:
        print(f"rbcheck fuzz: warning: batch {e['batch']} could not be judged ({e['error']}); "
              "its cases are not counted", file=sys.stderr)
    found = summary["counterexamples"] + summary["not_shrunk"]
    if not found:
        print("rbcheck fuzz: no property violated")
        return 0
    print(f"rbcheck fuzz: {len(found)} distinct failure(s):", file=sys.stderr)
    for cx in summary["counterexamples"]:
        note = "" if cx["confirmed_by_sweep"] else " [rbcheck sweep's gates pass on it]"
        print(f"  {cx['file']}: {cx['property']} — {cx['sentence']}{note}", file=sys.stderr)
        if cx["explanation"]:
            print(f"    explained: {cx['explanation']}", file=sys.stderr)
        print(f"    reproduce: {cx['reproduce']}", file=sys.stderr)
    for f in summary["not_shrunk"]:
        why = " (a documented engine behaviour explains each)" if f.get("explained") else ""
        print(f"  (not shrunk) {f['property']} of {' / '.join(f['variants'])}: {f['cases']} case(s){why}",
              file=sys.stderr)
    return 1
