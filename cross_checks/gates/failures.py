"""What made a sweep fail, in the sentences every output shares (the terminal, ``assert_engine``, the JUnit
and GitHub formats): failed runs grouped by the command's own words (one sentence per distinct reason, naming
every run it hit), verdicts that contradict their expectation, and the likely cause of a user engine's
contradiction from ``rbcheck check``'s catalog of mistakes.
"""
from __future__ import annotations

import math

from cross_checks.sweep.assemble import normalise_message

__all__ = ["failed_run_sentences", "verdict_sentence", "likely_causes", "normalise_message", "runs_hit"]

def runs_hit(rows) -> str:
    """``2 runs (tennis_racket at Δt = 0.01, 0.005 s; projectile at Δt = 0.02 s)``: the runs one failure
    hit."""
    by = {}
    for r in rows:
        by.setdefault(r["scenario"], []).append(f"{float(r['dt']):g}")
    n = len(rows)
    return (f"{n} run{'s' if n > 1 else ''} ("
            + "; ".join(f"{sc} at Δt = {', '.join(d)} s" for sc, d in by.items()) + ")")


def failed_run_sentences(rows, statuses=("failed", "diverged")) -> list:
    """``[(status, variant, sentence, rows)]``: one per distinct (status, variant, reason) of the rows
    (results.csv's, as dicts), in the order of ``statuses``; the sentence is ``VARIANT STATUS on N runs (…):
    the command's words``."""
    out = []
    for status in statuses:
        groups: dict = {}
        for r in rows:
            if r["status"] == status:
                groups.setdefault((r["engine"], normalise_message(r.get("message"))), []).append(r)
        out += [(status, engine, f"{engine} {status} on {runs_hit(hit)}: {message}", hit)
                for (engine, message), hit in groups.items()]
    return out


def verdict_sentence(rec: dict) -> str:
    """A convergence verdict that contradicts its expectation, with the final errors over the ladder."""
    pts = [(d, e) for d, e in zip(rec.get("dt_s") or [], rec.get("errors") or [])
           if e is not None and math.isfinite(e)]
    what = f"{rec['engine']} on {rec['scenario']}: {rec['quantity'].replace('_', ' ')} {rec['assessment']}"
    if pts:
        errs = ", ".join(f"{e:.3g}" for _, e in pts)
        dts = ", ".join(f"{d:g}" for d, _ in pts)
        text = f"{what} — final errors {errs} {rec.get('unit', '')}".rstrip() + f" at Δt = {dts} s"
    else:
        text = f"{what} — no run of the ladder gave a final error"
    if rec.get("expected_verdict") == "does_not_converge" and rec.get("reason"):
        text += f"; expected not to converge: {rec['reason']}"
    if rec.get("note"):
        text += f" ({rec['note']})"
    return text


def likely_causes(scenarios: dict, problems_of) -> dict:
    """``{(scenario name, variant): likely cause}`` for the failing verdicts (``scenarios``:
    name -> Scenario), from the same catalog of mistakes ``rbcheck check`` uses: the variant's
    run at the scenario's coarsest ladder Δt, checked step for step (a cause is said only
    where one explains every step)."""
    from cross_checks.engines import run_variant
    from cross_checks.gates.check import check_trajectory
    out = {}
    for sc_name, variant in problems_of:
        try:
            sc = scenarios[sc_name]
            traj = run_variant(sc, variant, max(sc.dt_ladder_s))
            res = check_trajectory(traj, sc, f"{variant} on {sc_name}")
        except Exception:  # noqa: BLE001
            # a cause is a courtesy: an engine that cannot run again has its failure said
            continue
        if res.likely_causes and not res.likely_causes[0].startswith("no catalogued mistake"):
            out[(sc_name, variant)] = res.likely_causes[0]
    return out
