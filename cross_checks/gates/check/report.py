"""What ``rbcheck check`` prints and writes: the verdict line first, then the evidence table, the closest
scheme and the likely cause; the same as JSON (``--json``)."""
from __future__ import annotations

import json
import math

from cross_checks.core.files import json_default
from cross_checks.core.tolerances import CHECK_CLOSEST_TIE_RATIO

__all__ = ["format_report", "format_ladder", "to_json_text"]

#: A quantity's name in the report, where it is not the quantity's own.
_NAMES = {"quaternion_norm": "|q| - 1", "angular_momentum": "angular momentum L",
          "angular_velocity": "angular velocity"}


def _num(v, unit=""):
    if v is None:
        return "–"
    if isinstance(v, float) and math.isnan(v):
        return "NaN"
    if isinstance(v, float) and math.isinf(v):
        return "inf"
    return f"{v:.3g}" + (f" {unit}" if unit else "")


def _status(e):
    if not e.decisive:
        return "info"
    until = "" if e.decisive_until_s is None else f" (decisive to t = {e.decisive_until_s:.3g} s)"
    return ("ok" if e.passed else "OVER") + until


def _still(e) -> bool:
    """A row of a quantity that does not move (value and allowance both zero): one line, not a table row."""
    return e.max_value == 0.0 and e.allowance == 0.0 and e.max_ratio == 0.0


def _evidence_table(res) -> list:
    """One row per measured quantity: the worst ratio with the value and the allowance AT THAT TIME, when it
    happened and when the allowance was first exceeded; quantities that do not move in one line."""
    rows = [e for e in res.evidence if not _still(e)]
    still = list(dict.fromkeys(_NAMES.get(e.quantity, e.quantity) for e in res.evidence if _still(e)))
    out = []
    if rows:
        out += ["", f"  {'evidence':<17}{'quantity':<29}{'worst ×allowed':>15}{'value':>11}{'allowed':>11}"
                    f"{'at t (s)':>10}{'first over':>12}  status"]
        for e in sorted(rows, key=lambda e: (e.passed or not e.decisive, -_key(e.max_ratio))):
            first = "–" if e.first_over_s is None else f"{e.first_over_s:.4g}"
            name = _NAMES.get(e.quantity, e.quantity) + (f" ({e.unit})" if e.unit else "")
            worst = e.value_at_worst if not math.isnan(e.value_at_worst) else e.max_value
            out.append(f"  {e.kind:<17}{name:<29}{_num(e.max_ratio):>15}{_num(worst):>11}"
                       f"{_num(e.allowance):>11}{_num(e.t_worst_s):>10}{first:>12}  {_status(e)}")
    if still:
        out.append(f"  not moving in this scenario (nothing to judge): {', '.join(still)}")
    return out


def _key(v) -> float:
    return -1.0 if v is None or (isinstance(v, float) and math.isnan(v)) else float(v)


def format_report(res) -> str:
    """Human-readable report of one check: the verdict and its cause first, then the likely mistake, the
    evidence table, the schemes, and where each allowance comes from last."""
    lines = [("PASS: " if res.passed else "FAIL: ") + res.verdict]
    for cause in res.likely_causes:
        lines.append(f"likely cause: {cause}")
    for c in res.caveats:
        lines.append(f"caveat: {c}")
    lines += ["", f"{res.source}: {res.input['description']}",
              f"scenario {res.scenario} ({res.input['duration_s']:g} s); "
              f"reference: {res.reference_label or '–'}"
              + ("; values look single precision" if res.input.get("single_precision") else "")]
    lines += _evidence_table(res)
    lines += _schemes(res)
    lines.append("")
    if res.identity:
        lines.append(f"scheme: IS {', '.join(res.identity)}")
    elif res.closest:
        c = next(c for c in res.candidates if c.name == res.closest)
        how = ("its steps differ from the file's by up to " f"{_num(c.max_ratio)}× the local allowance"
               if res.input["quantities"] and len(res.input["quantities"]) == 4
               else f"largest free-running difference {_num(c.max_rel_diff)}")
        also = (f"; as close: {', '.join(n for n in res.tied if n != res.closest)}"
                if len(res.tied) > 1 else "")
        lines.append(f"closest scheme: {res.closest} ({how}){also}"
                     + (f"; closest correct scheme: {res.closest_correct}"
                        if res.closest_correct and res.closest_correct != res.closest else ""))
    elif res.tied:
        lines.append(f"closest scheme: none — all {len(res.tied)} schemes are as far from the file (within "
                     f"×{CHECK_CLOSEST_TIE_RATIO:g} of each other): what differs is not a choice of scheme")
    for e in res.engines:
        if "error" in e:
            lines.append(f"engine {e['engine']}: {e['error']}")
        else:
            diff = ", ".join(f"{k.replace('_', ' ')} {_num(v)}" for k, v in e["max_difference"].items())
            lines.append(f"engine {e['engine']}: "
                         f"{'same to round-off' if e['same_to_roundoff'] else 'differs'} (max "
                         f"difference run free: {diff})")
    for n in res.cannot_tell:
        lines.append(f"cannot tell: {n}")
    for n in res.notes:
        lines.append(f"note: {n}")
    if res.evidence:
        lines += ["", "allowances (where each comes from):"]
        seen = set()
        for e in res.evidence:
            if (e.kind, e.source) not in seen and not _still(e):
                seen.add((e.kind, e.source))
                lines.append(f"  {e.kind}: {e.source}")
        for e in res.evidence:
            if e.note and not _still(e):
                lines.append(f"  {e.kind} {_NAMES.get(e.quantity, e.quantity)}: {e.note}")
    return "\n".join(lines)


def _schemes(res) -> list:
    """Every reference variant stepped from the file's own states: how far its steps are from the
    file's next rows, and how far from the exact motion (its own defect), both over the allowance."""
    rows = [c for c in res.candidates if not math.isnan(c.own_defect)]
    if not rows:
        return []
    out = ["",
           f"  {'scheme (stepped from the file’s states)':<42}{'vs the file':>13}"
           f"{'vs exact motion':>17}  here",
           f"  {'':<42}{'(× allowance)':>13}{'(× allowance)':>17}"]
    for c in rows:
        tag = "IS the file" if c.same else ("correct" if c.correct else "NOT correct here")
        out.append(f"  {c.name:<42}{_num(c.max_ratio):>13}{_num(c.own_defect):>17}  {tag}")
    return out


def format_ladder(lad) -> str:
    """The ladder section: fitted orders per quantity and their verdicts."""
    lines = [("PASS: " if lad["passed"] else "FAIL: ") + lad["verdict"], "",
             f"ladder of {len(lad['files'])} files (Δt = {', '.join(f'{d:g}' for d in lad['dt_s'])} s), "
             f"expected: {lad['expected']}",
             f"  {'quantity':<20}{'order':>8}  {'pairwise orders':<28}verdict"]
    for r in lad["convergence"]:
        pw = ", ".join("–" if p is None else f"{p:.2f}" for p in r["pairwise_orders"])
        order = "–" if r["order"] is None else f"{r['order']:.2f}"
        lines.append(f"  {r['quantity']:<20}{order:>8}  {pw:<28}{r['assessment']}")
    for n in lad["notes"]:
        lines.append(f"note: {n}")
    return "\n".join(lines)


def to_json_text(obj) -> str:
    """Strict JSON: NaN is written as null and ±inf as the strings "inf" / "-inf"."""
    return json.dumps(_finite(json.loads(json.dumps(obj, default=_json_default))),
                      indent=2, allow_nan=False) + "\n"


def _json_default(o):
    if hasattr(o, "as_dict"):
        return o.as_dict()
    return json_default(o)


def _finite(o):
    if isinstance(o, float):
        return None if math.isnan(o) else ("inf" if o == math.inf else "-inf" if o == -math.inf else o)
    if isinstance(o, dict):
        return {k: _finite(v) for k, v in o.items()}
    if isinstance(o, list):
        return [_finite(v) for v in o]
    return o
