"""Names and keys users write: the rule every scenario, engine and variant name follows (names become
file names and ``ENGINE:VARIANT`` cells), and the reason an unknown key is refused with."""
from __future__ import annotations

import difflib
import re

__all__ = ["NAME_RE", "unknown_key_reason", "did_you_mean"]

#: Scenario, engine and variant names: lower-case letters, digits and underscores.
NAME_RE = re.compile(r"^[a-z0-9_]+$")


def unknown_key_reason(key: str, allowed) -> str:
    """``unknown key (did you mean 'x'?); allowed: a, b, c`` — the hint only for a close match."""
    return f"unknown key{did_you_mean(key, allowed)}; allowed: {', '.join(sorted(allowed))}"


def did_you_mean(name: str, known) -> str:
    """`` (did you mean 'x'?)`` for the closest of ``known`` to a mistyped name ("" when none is close)."""
    close = difflib.get_close_matches(name, list(known), n=1, cutoff=0.6)
    return f" (did you mean {close[0]!r}?)" if close else ""
