"""Plain words for the symbols the verdicts use (docs/verdicts.md): on each page, the first sentence that
uses a symbol says what it means, right after it; the later ones use it as it is.

The sentences come from summary.json (the reasons, assessments and notes the sweep wrote); the pages show
them as written, with the explanations inserted here.
"""
from __future__ import annotations

import re

__all__ = ["GLOSSARY", "explain"]

#: Symbol -> what it means, in words a student knows (with no symbol of its own: the first use of each
#: symbol on the page stays the one explained).
GLOSSARY = {
    "Δt": "the time step",
    "ω_c": "the motion's characteristic rate, measured on the reference",
    "ω_W": "the angular velocity in world axes",
    "−ω × (I ω)": "the gyroscopic term: the spinning body's own angular momentum I ω turning its rotation",
    "δ": "how close the spin is to the separatrix — the boundary between tumbling and spinning about the "
         "unstable middle axis of inertia, the tennis-racket effect; 0 on it",
    "χ": "how much a first-order step changes an oscillation's amplitude over the whole run: half the "
         "square of the motion's rate, times the time step, times the run's duration",
}
_TRAIL = ".,;:)]"


def explain(texts) -> list:
    """``texts`` (in the order a page shows them) with each GLOSSARY symbol explained in parentheses at its
    first occurrence on the page: right after the symbol when it stands alone ("δ (how close …) = …"),
    after the expression that holds it otherwise ("e^(−χ) (χ: how much …)")."""
    seen = set()
    out = []
    for text in texts:
        for sym, meaning in GLOSSARY.items():
            if sym in seen or sym not in text:
                continue
            seen.add(sym)
            text = _insert(text, sym, meaning)
        out.append(text)
    return out


def _insert(text, sym, meaning) -> str:
    i = text.index(sym)
    if " " in sym:      # an expression: explained after it
        j = i + len(sym)
        return f"{text[:j]} ({meaning}){text[j:]}"
    m = re.compile(r"\S+").match(text, text.rfind(" ", 0, i) + 1)
    word_end = m.end()
    core_end = word_end
    while core_end > i + len(sym) and text[core_end - 1] in _TRAIL:
        w = text[m.start():core_end]
        if w.endswith((")", "]")) and w.count("(") + w.count("[") >= w.count(")") + w.count("]"):
            break           # a bracket the expression itself opened
        core_end -= 1
    word = text[m.start():core_end].lstrip("([")
    if word == sym:     # the symbol alone: explained right after it
        j = i + len(sym)
        return f"{text[:j]} ({meaning}){text[j:]}"
    # inside an expression (e^(−χ), ω_c²ΔtT/2): after the expression, naming the symbol
    return f"{text[:core_end]} ({sym}: {meaning}){text[core_end:]}"
