"""The CI formats ``rbcheck sweep`` and ``rbcheck compare`` write (docs/cli.md, "CI formats"): the JUnit
file, GitHub annotations and the job summary."""
from __future__ import annotations

import os
import sys


def ci_outputs(command: str, junit_path, root, annotations: list, markdown) -> None:
    """Write the JUnit file, print the annotations and append the markdown to $GITHUB_STEP_SUMMARY (a
    summary that cannot be appended to is said on stderr; the command's result stands)."""
    from cross_checks.core.progress import say
    from cross_checks.gates.ci import STEP_SUMMARY_ENV, append_step_summary, write_junit
    if junit_path:
        write_junit(junit_path, root())
    for line in annotations:
        say(line)
    if os.environ.get(STEP_SUMMARY_ENV):
        try:
            append_step_summary(markdown())
        except OSError as exc:
            say(f"rbcheck {command}: warning: ${STEP_SUMMARY_ENV} {os.environ[STEP_SUMMARY_ENV]}: cannot "
                f"append the summary: {exc.strerror or exc}", sys.stderr)
