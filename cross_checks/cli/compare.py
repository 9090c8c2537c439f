"""``rbcheck compare``: a results directory against a baseline (docs/results.md); text, ``--markdown`` and
the CI formats."""
from __future__ import annotations

from pathlib import Path

from cross_checks.cli.ci import ci_outputs
from cross_checks.cli.errors import BadInput, check_out_path, refuse_inputs_as_outputs


def cmd_compare(args) -> int:
    from cross_checks.core.files import atomic_write_text
    from cross_checks.gates.compare import (
        CompareInputError,
        compare_dirs,
        read_results_dir,
        to_markdown,
        to_text,
    )

    refuse_inputs_as_outputs([("--markdown", args.markdown, False), ("--junit", args.junit, False)],
                             [("baseline directory", args.baseline, True),
                              ("results directory", args.new, True)])
    if args.markdown:
        check_out_path(args.markdown, None, "--markdown")
    if args.junit:
        check_out_path(args.junit, ".xml", "--junit")
    try:
        c = compare_dirs(args.baseline, args.new, require=args.require)
        _, new_summary = read_results_dir(args.new)
    except CompareInputError as exc:
        raise BadInput(str(exc)) from None
    ran = _variants_ran(args.new)
    print(to_text(c, args.allow_missing, ran, args.fail_on_change))

    from cross_checks.core.progress import shown

    def markdown():
        return to_markdown(c, args.baseline, args.new, args.allow_missing, ran, args.fail_on_change)
    if args.markdown:
        atomic_write_text(args.markdown, shown(markdown()) + "\n")
    from cross_checks.gates import ci
    ci_outputs("compare", args.junit,
                lambda: ci.compare_junit(c, new_summary, args.allow_missing, args.fail_on_change),
                ci.compare_annotations(c, new_summary, args.allow_missing, args.fail_on_change)
                if args.github_annotations else [], lambda: shown(markdown()))
    return c.exit_code(args.allow_missing, args.fail_on_change)


def _variants_ran(new_dir) -> list:
    """The variants NEW_DIR's summary lists (to name the ones that did not change)."""
    import json
    try:
        return [v["name"]
                for v in json.loads((Path(new_dir) / "summary.json").read_text()).get("variants", [])]
    except (OSError, ValueError, KeyError, TypeError):
        return []
