"""Bad input and the exit codes of the ``rbcheck`` command line (the package docstring has the table).

:class:`BadInput` is what the user must fix; :func:`error` prints it (or any error) as one line naming the
file or option, the field and the reason, and gives exit 2. The checks every command makes of its outputs
before any work live here too: the right suffix, a directory that exists and can be written in, and never a
path that would replace or land inside one of the command's own inputs.
"""
from __future__ import annotations

import os
import sys
from pathlib import Path

EXIT_OK, EXIT_FAIL, EXIT_BAD_INPUT, EXIT_INTERRUPTED, EXIT_TERMINATED = 0, 1, 2, 130, 143


class BadInput(Exception):
    """Input the user must fix; the message names the file/option, the field and the reason."""


def error(command: str, message: str) -> int:
    message = " ".join(str(message).split())  # one line, whatever the message holds
    print(f"rbcheck {command}: error: {message}", file=sys.stderr)
    return EXIT_BAD_INPUT


def engine_file_inputs(args) -> list:
    """The --engine-file files a command reads (its outputs may not replace them)."""
    return [("engine file", f, False) for f in getattr(args, "engine_file", None) or []]


def check_out_path(out: str, suffix: str | None = ".csv", option: str = "--out") -> Path:
    """An output file the user named, checked before any work: the right suffix (when given), a
    directory that exists and can be written in (tried for real), not itself a directory."""
    from cross_checks.sweep.results_dir import ResultsDirError, check_writable_dir
    if not str(out).strip():
        raise BadInput(f"{option}: empty path; name a file")
    path = Path(out)
    if suffix is not None and path.suffix != suffix:
        raise BadInput(f"{option} {out}: must end in {suffix}")
    parent = path.parent
    if not parent.is_dir():
        what = "is not a directory" if parent.exists() else "does not exist"
        raise BadInput(f"{option} {out}: directory {parent} {what}")
    if path.is_dir():
        raise BadInput(f"{option} {out}: is a directory")
    try:
        check_writable_dir(parent, option, out)
    except ResultsDirError as exc:
        raise BadInput(str(exc)) from None
    return path


def resolved(path) -> Path:
    try:
        return Path(path).expanduser().resolve()
    except (OSError, RuntimeError):
        return Path(os.path.abspath(path))


def is_within(path: Path, folder: Path) -> bool:
    return path == folder or folder in path.parents


def refuse_inputs_as_outputs(outputs, inputs) -> None:
    """BadInput, before any work, when an output would replace or land inside what the command reads.

    ``outputs``: ``[(option, path, is_dir)]``; ``inputs``: ``[(what, path, is_dir)]``. An output file may not
    be an input file (the same file after resolving links) nor lie inside an input directory (a results
    directory or baseline the command reads); an output directory may not hold an input."""
    ins = [(what, resolved(p), is_dir, p) for what, p, is_dir in inputs if p is not None and str(p).strip()]
    for option, out, out_is_dir in outputs:
        if out is None or not str(out).strip():
            continue
        o = resolved(out)
        for what, i, in_is_dir, given in ins:
            same = o == i or (o.exists() and i.exists() and _samefile(o, i))
            inside = (not out_is_dir and in_is_dir and is_within(o, i)) or (out_is_dir and is_within(i, o))
            if same or inside:
                how = "is" if same else ("lies inside" if not out_is_dir else "holds")
                raise BadInput(f"{option} {out}: {how} the {what} {given} this command reads; "
                               "writing there would destroy its input — choose another path")


def _samefile(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def scenario_inputs(specs) -> list:
    """``[("scenario file", path, False)]`` of the SCENARIO arguments that are
    files (catalog names are not)."""
    return [("scenario file", s, False) for s in specs if s and Path(s).exists()]
