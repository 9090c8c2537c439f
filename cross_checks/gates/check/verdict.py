"""``rbcheck check TRAJ.csv --scenario SCENARIO``: a true verdict on any simulator's trajectory.

Two questions, never mixed (docs/check.md). By default: is this a correct simulation of the scenario's
physics? PASS when the trajectory is consistent with the equations of motion within what a consistent
scheme of order ≥ 1 leaves at its Δt, or IS a reference variant step for step whose own step is right on
this scenario; a trajectory that is exactly a scheme whose step is wrong here FAILS. With
``scheme="ENGINE:VARIANT"``: is this exactly that scheme? Either way FAIL when the run diverged, ended
early or did not start at the scenario's initial state. Bad input is a :class:`CheckError` (exit 2).
Every allowance is derived in :mod:`cross_checks.analysis.flow` / :mod:`cross_checks.gates.check.evidence`,
its constants in ``cross_checks/core/tolerances.py``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from cross_checks.analysis.expectations import expectation
from cross_checks.analysis.flow import (
    distances,
    exact_flow,
    flow_rhs,
    local_allowances,
    majorant,
    motion_rate,
    quantity_distance,
)
from cross_checks.core import tolerances as tol
from cross_checks.core.quantities import BLOCKS, QUANTITIES, UNITS
from cross_checks.gates.check.diagnosis import (
    diagnose_mistakes,
    fit_step_scale,
    initial_state_slips,
    score_variants,
    written_slips,
)
from cross_checks.gates.check.evidence import (
    Evidence,
    conserved_evidence,
    evidence_row,
    free_running_evidence,
    pose_consistency,
    ratio,
    reconstruct_states,
)
from cross_checks.gates.check.input import CheckError, describe_time, prepare_input

__all__ = ["CheckError", "CheckResult", "check_trajectory"]


@dataclass
class CheckResult:
    """Everything ``rbcheck check`` says about one trajectory (see :func:`check_trajectory`)."""

    source: str
    scenario: str
    reference_label: str
    input: dict
    passed: bool
    verdict: str
    reasons: list
    evidence: list
    identity: list
    closest: str | None
    closest_correct: str | None
    candidates: list
    likely_causes: list
    mistakes: list
    caveats: list
    notes: list
    cannot_tell: list
    engines: list
    series: dict = field(default_factory=dict, repr=False)
    tied: list = field(default_factory=list)   # the schemes as close as the closest (CHECK_CLOSEST_TIE_RATIO)

    @property
    def exit_code(self) -> int:
        return 0 if self.passed else 1

    def as_dict(self) -> dict:
        return {
            "source": self.source, "scenario": self.scenario, "reference": self.reference_label,
            "passed": self.passed, "exit_code": self.exit_code,
            "verdict": ("PASS: " if self.passed else "FAIL: ") + self.verdict,
            "reasons": self.reasons, "input": self.input,
            "evidence": [e.as_dict() for e in self.evidence],
            "identity": self.identity, "closest_scheme": self.closest, "closest_tied": self.tied,
            "closest_correct_scheme": self.closest_correct, "schemes": [c.as_dict() for c in self.candidates],
            "likely_causes": self.likely_causes, "mistakes": self.mistakes, "caveats": self.caveats,
            "notes": self.notes, "cannot_tell": self.cannot_tell, "engines": self.engines,
        }


# --- pieces -----------------------------------------------------------------------------------------

def _initial_state(inp, scenario):
    """(rows failing, words, slips) comparing the first row with the scenario's initial state."""
    y_init = scenario.problem.initial_packed()
    y0 = inp.y[0]
    tol_q = {q: inp.print_floor[q][0] + tol.CHECK_ROUNDINGS_PER_STEP * inp.unit_roundoff
             * max(1.0, float(np.linalg.norm(y_init[BLOCKS[q]])))
             for q in inp.present}
    bad = {q: float(quantity_distance(y0, y_init, q)) for q in inp.present}
    off = [q for q in inp.present if not bad[q] <= tol_q[q]]
    if not off:
        return [], "", []
    words = ", ".join(f"{q.replace('_', ' ')} off by {bad[q]:.3g} {UNITS[q]}" for q in off)
    return off, words, initial_state_slips(y0, y_init, tol_q, inp.present)


@dataclass
class _Local:
    """The local evidence of a file: its rows, the allowances per row interval, scheme scores."""

    rows: list
    allow: object            # analysis.flow.Allowances per row interval
    per_row: dict            # quantity -> (K−1,) physics + arithmetic allowances
    candidates: list         # CandidateScore of every reference variant (full-state files)
    notes: list
    ratios: dict             # quantity -> local value / allowance over time (for the plot)
    undecided_rows: int = 0  # rows where the one-step error model does not hold (h L > CHECK_MAX_HL)


def _one_step(inp, scenario):
    """``(exact flow over each row interval, allowances, distances of the next rows from it)`` of a
    full-state file's rows ``inp.y``."""
    y0, y1 = inp.y[:-1], inp.y[1:]

    def allowance_fn(M2, rate):
        return local_allowances(inp, y0, M2, rate, y_end=y1, scenario=scenario).total
    flow = exact_flow(scenario, y0, inp.span_s, allowance_fn=allowance_fn, span_steps=inp.span_steps)
    allow = local_allowances(inp, y0, flow.M2, flow.rate, flow.roundoff, y_end=y1, scenario=scenario)
    return flow, allow, distances(y1, flow.y_end)


def _local_full(inp, scenario, refs) -> _Local:
    """One-step defects of a full-state file, scheme scores and (lazily) mistake scores."""
    y0, y1 = inp.y[:-1], inp.y[1:]
    flow, allow, d = _one_step(inp, scenario)
    h = inp.span_s / inp.span_steps
    hl = h * flow.rate
    model_ok = hl <= tol.CHECK_MAX_HL
    notes = []
    if not model_ok.all():
        notes.append(f"Δt × the motion's rate reaches {np.max(hl):.2g} "
                     f"(> {tol.CHECK_MAX_HL:g}) on {int(np.sum(~model_ok))} rows: the one-step "
                     "error model does not hold there, those rows are reported, not decisive")
    source = ("C h Δ |y''| (what a consistent scheme of order ≥ 1 leaves "
              "over a row; y'' from the exact flow) + the data's precision")
    t1 = inp.t_s[1:]
    rows = [evidence_row("one-step defect", q, t1, d[q], allow.total[q], source,
                         decisive=None if model_ok.all() else model_ok) for q in QUANTITIES]
    cands = score_variants(inp, scenario, y0, y1, flow.y_end, allow, refs)
    per_row = {q: allow.physics[q] + allow.arith[q] for q in QUANTITIES}
    return _Local(rows, allow, per_row, cands, notes, {q: ratio(d[q], allow.total[q]) for q in QUANTITIES},
                  int(np.sum(~model_ok)))


def _local_pose(inp, scenario, y_ref) -> _Local:
    """Acceleration consistency of a pose-only file, and the allowances carried by the free run."""
    y_hat = reconstruct_states(inp, y_ref)
    rows = pose_consistency(inp, scenario, y_hat)
    F = flow_rhs(scenario)
    rate = motion_rate(scenario, y_hat[:-1])
    M2 = majorant(F, y_hat[:-1], rate)
    allow = local_allowances(inp, y_hat[:-1], M2, rate, y_end=y_hat[1:], scenario=scenario)
    per_row = {q: allow.physics[q] + allow.arith[q] for q in QUANTITIES}
    ratios = {r.quantity: ratio(r.series["value"], r.series["allowance"]) for r in rows}
    return _Local(rows, allow, per_row, [], [], ratios)


def _pose_candidates(inp, scenario, growth, per_arith, refs):
    """Free-running comparison of a pose-only file with every reference variant from the initial state."""
    from cross_checks.engines import run_variant
    from reference_sim.integrators import VARIANTS
    if inp.h_s is None:
        return []
    out = []
    tol_same = {q: sum(growth[(p, q)] * per_arith[p] for p in QUANTITIES) + inp.print_floor[q]
                for q in inp.present}
    for v in VARIANTS:
        name = refs[v]
        run = run_variant(scenario, name, inp.h_s, float(inp.t_s[-1]))
        idx = inp.n_steps
        if len(run.t_s) <= idx[-1]:
            out.append(_free_score(name, None, None, inp))
            continue
        d = distances(inp.y, run.y[idx], [q for q in inp.present])
        out.append(_free_score(name, d, tol_same, inp))
    return out


def _free_score(name, d, tol_same, inp):
    from cross_checks.gates.check.diagnosis import CandidateScore
    if d is None:
        return CandidateScore(name, math.nan, math.nan, False)
    r = np.stack([ratio(d[q], tol_same[q]) for q in d])
    mx = float(np.max(r)) if not np.any(np.isnan(r)) else math.nan
    same = bool(mx <= 1.0)
    s = CandidateScore(name, mx, float(np.max(np.percentile(r, 99, axis=1))), same)
    s.max_rel_diff = max(float(np.max(d[q])) for q in d)
    return s


def _engines(inp, scenario, names, growth, per_arith):
    """Free-running comparison with extra ENGINE:VARIANT runs (e.g. user engines)."""
    from cross_checks.engines import run_variant
    out = []
    if inp.h_s is None:
        return [{"engine": n, "error": "variable steps: cannot run at the file's Δt"} for n in names]
    tol_same = {q: sum(growth[(p, q)] * per_arith[p] for p in QUANTITIES) + inp.print_floor[q]
                for q in inp.present}
    for name in names:
        try:
            run = run_variant(scenario, name, inp.h_s, float(inp.t_s[-1]))
        except Exception as exc:  # noqa: BLE001 - an engine that fails is reported, the check goes on
            out.append({"engine": name, "error": f"{type(exc).__name__}: {exc}"})
            continue
        n = min(len(run.t_s), int(inp.n_steps[-1]) + 1)
        keep = inp.n_steps < n
        d = distances(inp.y[keep], run.y[inp.n_steps[keep]], list(inp.present))
        diff = {q: float(np.max(d[q])) if d[q].size else math.nan for q in d}
        same = all(np.all(d[q] <= tol_same[q][keep]) for q in d) and n == int(inp.n_steps[-1]) + 1
        out.append({"engine": name, "max_difference": diff, "same_to_roundoff": bool(same),
                    "status": run.meta.get("status", "ok")})
    return out


def _caveat_for(variant, scenario, own_defect):
    """Why a variant's own step is not the true dynamics here (None when it is). ``own_defect``: its
    measured one-step defect ratio (NaN when not measured: then the expectations module says)."""
    # only "does_not_converge" is used
    exp = expectation(scenario, variant, "angular_velocity", measure_physics=False)
    why = exp.reason if exp.verdict == "does_not_converge" else "its step departs from the true dynamics here"
    if own_defect > 1.0:
        return (f"{variant}'s own step is not the true dynamics of {scenario.name} at this Δt (its "
                f"one-step defect reaches {own_defect:.3g}× the allowance of a consistent scheme): {why}")
    if math.isnan(own_defect) and exp.verdict == "does_not_converge":
        return f"{variant} does not converge to the true motion of {scenario.name}: {why}"
    return None


def _failure_words(e: Evidence) -> str:
    what = {"one-step defect": "one-step defect", "acceleration": "acceleration residual",
            "conserved": "drift", "free-running": "free-running error"}[e.kind]
    name = {"quaternion_norm": "|q| − 1",
            "angular_momentum": "angular momentum"}.get(e.quantity, e.quantity.replace("_", " "))
    if math.isnan(e.max_ratio):
        return f"{name} {what}: not a number (NaN) in the comparison"
    when = f" from t = {e.first_over_s:.4g} s" if e.first_over_s is not None else ""
    unit = f" {e.unit}" if e.unit else ""
    return (f"{name} {what} over its allowance{when}: {e.max_ratio:.3g}× at t = {e.t_worst_s:.4g} s "
            f"({e.value_at_worst:.3g} vs {e.allowance:.3g}{unit}; largest {e.max_value:.3g}{unit})")


def _explain(local, candidates, scenario, inp):
    """Likely causes (sentences) of a failing trajectory, and the mistake scores kept for the JSON.

    Explanations: a reference variant that is wrong here, or a catalogued mistake, that reproduces every
    step within the allowance and CHECK_MISTAKE_MARGIN times better than any correct scheme (the exact
    motion included); the best is said in full, the others equally consistent are named. Else a Δt
    mismatch, else "resembles" (99 % of the steps within CHECK_MISTAKE_RESEMBLES allowances)."""
    correct = [c.max_ratio for c in candidates if c.correct and not math.isnan(c.max_ratio)]
    flow_ratio = max((e.max_ratio for e in local.rows), default=math.inf)
    best_correct = min(correct + ([flow_ratio] if not math.isnan(flow_ratio) else []), default=math.inf)

    def explains(c):
        return c.max_ratio <= 1.0 and c.max_ratio * tol.CHECK_MISTAKE_MARGIN <= best_correct
    found = []
    for c in candidates:
        if not c.correct and explains(c):
            why = (_caveat_for(c.name, scenario, c.own_defect) or "").split(": ", 1)[-1]
            found.append((c.max_ratio, c.name,
                          f"it matches {c.name} step for step within the allowance "
                          f"({c.max_ratio:.2g} of it), a step that is wrong here: {why}"))
    mistakes = diagnose_mistakes(inp, scenario, inp.y[:-1], inp.y[1:], local.allow)
    kept = [{"mistake": m.name, "max_ratio": m.max_ratio, "p99_ratio": m.p99_ratio} for m in mistakes[:5]]
    for m in mistakes:
        if explains(m):
            found.append((m.max_ratio, m.mistake,
                          f"{m.sentence} — that mistake explains every step "
                          f"within the allowance ({m.max_ratio:.2g} of it; the "
                          f"closest correct scheme needs {best_correct:.3g}×)"))
    for words, worst in written_slips(inp, scenario, lambda i: _one_step(i, scenario)):
        if worst <= 1.0 and worst * tol.CHECK_MISTAKE_MARGIN <= best_correct:
            found.append((worst, words, f"{words} — read back that way, every row is a consistent step of "
                                        f"the scenario's motion ({worst:.2g} of the one-step allowance; the "
                                        f"closest correct scheme needs {best_correct:.3g}× as written)"))
    found.sort(key=lambda f: f[0])
    causes = [found[0][2]] if found else []
    others = list(dict.fromkeys(f[1] for f in found[1:] if f[1] != found[0][1]))
    if others:
        causes.append("equally consistent with: " + ", ".join(others[:4]) + (" …" if len(others) > 4 else ""))
    if not causes:
        causes = _dt_mismatch(local, scenario, inp)
    best = mistakes[0] if mistakes else None
    if not causes and best is not None and best.p99_ratio <= tol.CHECK_MISTAKE_RESEMBLES \
            and best.p99_ratio * tol.CHECK_MISTAKE_MARGIN <= best_correct:
        causes.append(f"it resembles: {best.sentence} (that mistake explains 99 % "
                      f"of the steps within {best.p99_ratio:.2g}× the allowance, "
                      "not all of them: perhaps combined with another mistake)")
    return causes, kept


def _dt_mismatch(local, scenario, inp):
    """["a Δt mismatch: …"] when the true motion over s × the row interval explains every row."""
    flow_end = exact_flow(scenario, inp.y[:-1], inp.span_s, span_steps=inp.span_steps).y_end
    s, score = fit_step_scale(inp, scenario, inp.y[:-1], inp.y[1:], flow_end, local.allow)
    if score is None or not score.max_ratio <= 1.0:
        return []
    h = inp.span_s[0] / inp.span_steps[0]
    return [f"a Δt mismatch: the simulator advances {s:.4g} × the recorded Δt per row (it "
            f"steps {s * h:.4g} s while the times say {h:.4g} s) — the true motion over that "
            f"step explains every row within the allowance ({score.max_ratio:.2g} of it)"]


# --- the check ---------------------------------------------------------------------------------------

def check_trajectory(traj, scenario, source: str = "TRAJ.csv", *, dt_s: float | None = None,
                     compare_with=(), scheme: str | None = None) -> CheckResult:
    """Check ``traj`` (a Trajectory read by name, possibly pose-only) against ``scenario``.

    ``dt_s``: the simulator's integration step when the rows are written less often than every step.
    ``compare_with``: extra ENGINE:VARIANT names run free at the file's Δt and compared (e.g. user
    engines). ``scheme``: ask "is this exactly ENGINE:VARIANT?" instead of "is this a correct
    simulation?" (a reference variant is compared step for step, any other engine run free and compared).
    Raises CheckError for input that cannot be checked.
    """
    from cross_checks.engines import resolve
    from reference_sim.integrators import VARIANTS
    # every name the check asks about, resolved once: the reference's schemes, the extra engines, the scheme
    named = {n: resolve(n) for n in [*(f"reference:{v}" for v in VARIANTS), *compare_with,
                                     *([] if scheme is None else [scheme])]}
    refs = {v: named[f"reference:{v}"] for v in VARIANTS}
    compare_with, scheme = [named[n] for n in compare_with], None if scheme is None else named[scheme]
    if scheme is not None and not scheme.startswith("reference:") and scheme not in compare_with:
        compare_with = [*compare_with, scheme]
    with np.errstate(all="ignore"):   # blown-up or NaN states are judged, never warned about
        inp = prepare_input(traj, scenario, source, dt_s)
        if inp.n_rows < 2:
            return _no_step_result(inp, scenario)
        return _check(inp, scenario, compare_with, refs, scheme)


def _check(inp, scenario, compare_with, refs, scheme=None) -> CheckResult:
    from cross_checks.scenario.references import reference_solution

    y_ref, label = reference_solution(scenario, inp.t_s)
    local = _local_full(inp, scenario, refs) if inp.full_state else _local_pose(inp, scenario, y_ref)
    cons = conserved_evidence(inp, scenario, local.allow)
    free, growth, _ = free_running_evidence(inp, scenario, y_ref, label, local.per_row)
    arith = {q: np.concatenate([[0.0], np.cumsum(local.allow.arith[q])]) for q in QUANTITIES}
    candidates = local.candidates if inp.full_state else _pose_candidates(inp, scenario, growth, arith, refs)
    engines = _engines(inp, scenario, list(compare_with), growth, arith) if compare_with else []
    off, init_words, slips = _initial_state(inp, scenario)
    evidence = local.rows + cons + free
    return _compose(inp, scenario, label, y_ref, local, evidence, candidates, engines, off, init_words, slips,
                    scheme)


def _no_step_result(inp, scenario):
    why = (f"diverged at t = {inp.diverged_at_s:g} s: non-finite values from the first step on"
           if inp.diverged_at_s is not None else "the quaternion is zero from the first step on")
    return CheckResult(inp.source, scenario.name, "", _input_dict(inp, scenario), False, why, [why], [], [],
                       None, None, [], [], [], [], list(inp.notes), [], [])


def _input_dict(inp, scenario):
    return {"rows": inp.n_rows, "t_end_s": float(inp.t_s[-1]), "dt_s": inp.h_s,
            "rows_per_step": inp.decimation, "description": describe_time(inp),
            "quantities": list(inp.present), "single_precision": inp.single_precision,
            "duration_s": scenario.duration_s, "time_drift_bound_s": inp.time_bound_s,
            # where the rows stop being usable (the rows from there are dropped): what --animate stops at
            "diverged_at_s": inp.diverged_at_s, "lost_orientation_at_s": inp.lost_orientation_at_s}


def _cannot_tell(inp, scenario):
    out = []
    missing = [g for g in ("position", "velocity", "orientation", "angular_velocity") if g not in inp.present]
    if missing:
        out.append(f"the file has no {', '.join(m.replace('_', ' ') for m in missing)} columns: those "
                   "are not checked, the one-step defect and the energy / angular momentum balance "
                   "need them, and the scheme is identified only from the free-running poses")
    if inp.h_s is None:
        out.append("the steps are not uniform: no reference variant can be run at the file's Δt")
    return out


def _wrong_here(variant, scenario, candidates) -> str:
    """Why ``variant``'s own step is not the true dynamics of ``scenario`` ("" when it is)."""
    c = next((c for c in candidates if c.name == variant), None)
    return _caveat_for(variant, scenario, c.own_defect if c is not None else math.nan) or ""


def _physics_reason(variant, scenario) -> str:
    """The one-sentence physics a variant misses on ``scenario`` (from the expectations), or ""."""
    exp = expectation(scenario, variant, "angular_velocity", measure_physics=False)
    return exp.reason if exp.verdict == "does_not_converge" else ""


def _reproduces_wrong_scheme(variant, scenario, why) -> str:
    """The verdict sentence of a file that is exactly ``variant``, a step that is wrong on this scenario."""
    missing = _physics_reason(variant, scenario)
    ask = f"(`--scheme {variant}` asks whether it is exactly that scheme)"
    if variant == "reference:course" and missing:
        return ("it reproduces the course's update exactly; the course omits the gyroscopic term "
                f"−ω × (I ω), {missing.split(', ', 1)[1] if ', ' in missing else 'which matters here'}, "
                f"so on this body the motion is wrong {ask}")
    if missing:
        return f"it reproduces {variant} exactly; {missing}, so on this body the motion is wrong {ask}"
    return f"it reproduces {variant} exactly, whose step is wrong here: {why.split(': ', 1)[0]} {ask}"


def _likely_mistake(variant, why) -> str:
    """The cause line of a file that is exactly a scheme that is wrong here: what to change."""
    if variant == "reference:course":
        return ("the rotational update has no gyroscopic torque: Euler's "
                "equations need dω/dt = I⁻¹(τ − ω × (I ω)); add the −ω × (I ω) "
                "term (reference:course_gyro is the course's step with it)")
    return f"it matches {variant} step for step, a step that is wrong here: {why.split(': ', 1)[-1]}"


def _scheme_outcome(scheme, identity, candidates, engines):
    """``(is it that scheme, how far from it in words)`` for ``--scheme``."""
    if scheme in identity:
        return True, ""
    c = next((c for c in candidates if c.name == scheme), None)
    if c is not None:
        return False, (f"it is not {scheme}: stepped from the file's own states, that scheme lands up to "
                       f"{c.max_ratio:.3g}× the one-step allowance away from the next rows")
    e = next((e for e in engines if e.get("engine") == scheme), None)
    if e is not None and e.get("same_to_roundoff"):
        return True, ""
    if e is not None and "error" in e:
        return False, f"{scheme} could not be run at the file's Δt: {e['error']}"
    if e is not None:
        worst = max(e["max_difference"].items(), key=lambda kv: kv[1] if not math.isnan(kv[1]) else -1.0)
        return False, (f"it is not {scheme}: run free at the file's Δt, "
                       f"it differs by {worst[1]:.3g} in {worst[0]}")
    return False, f"{scheme} cannot be compared with this file"


def _compose(inp, scenario, label, y_ref, local, evidence, candidates,
             engines, off, init_words, slips, scheme=None):
    reasons, caveats, causes, kept = [], [], [], []
    if inp.diverged_at_s is not None:
        reasons.append(f"diverged at t = {inp.diverged_at_s:.6g} s (non-finite "
                       "values from there; the rows before are judged below)")
    if inp.lost_orientation_at_s is not None:
        reasons.append("the quaternion is zero from "
                       f"t = {inp.lost_orientation_at_s:.6g} s: the orientation is lost")
    if inp.ended_early_s is not None:
        reasons.append(f"the run ends at t = {inp.ended_early_s:.6g} s, before the scenario's duration "
                       f"{scenario.duration_s:g} s")
    if off:
        reasons.append(f"does not start at the scenario's initial state ({init_words})")
        causes += [f"{s}" for s in slips]
    ranked = sorted((c for c in candidates if not math.isnan(c.p99_ratio)), key=lambda c: c.p99_ratio)
    # the closest scheme, unless others are as close (then all of them; none when every scheme ties)
    tied = [c.name for c in ranked if c.p99_ratio <= ranked[0].p99_ratio * tol.CHECK_CLOSEST_TIE_RATIO]
    closest = ranked[0].name if ranked and (len(tied) < len(ranked) or len(ranked) == 1) else None
    # pose-only files have no one-step evidence per variant: a variant is taken as correct there unless
    # the expectations say it does not converge on this scenario
    correct = [c for c in ranked if (c.correct if inp.full_state
                                     else _caveat_for(c.name, scenario, math.nan) is None)]
    closest_correct = correct[0].name if correct else None
    identity = [c.name for c in candidates if c.same]
    wrong = {v: _wrong_here(v, scenario, candidates) for v in identity}
    failing = [e for e in evidence if not e.passed]
    if scheme is not None:   # the question "is this exactly SCHEME?"
        is_it, words = _scheme_outcome(scheme, identity, candidates, engines)
        if is_it:
            if wrong.get(scheme):
                caveats.append(wrong[scheme])
        else:
            reasons.append(words)
    elif identity and not all(wrong.values()):   # exactly a scheme whose step is right here
        caveats += [w for w in wrong.values() if w]
    elif identity:   # exactly a scheme (or several) whose step is wrong here: not the scenario's physics
        first = identity[0]
        reasons.append(_reproduces_wrong_scheme(first, scenario, wrong[first]))
        causes.append(_likely_mistake(first, wrong[first]))
    elif failing:
        reasons += [_failure_words(e) for e in failing]
        if inp.full_state:
            more, kept = _explain(local, candidates, scenario, inp)
            causes += [m for m in more if not any(m.startswith(s) for s in slips)]   # a slip said once
        if not causes:
            causes.append("no catalogued mistake explains it (docs/check.md lists the catalog)"
                          if inp.full_state else
                          "not diagnosed: the catalog of mistakes is compared step "
                          "for step from full states, and the file has no velocities")
    passed = not reasons
    verdict = _verdict_line(inp, scenario, passed, reasons, identity, local, closest, candidates, scheme)
    series = _series(inp, scenario, y_ref, local, closest_correct)
    return CheckResult(inp.source, scenario.name, label, _input_dict(inp, scenario), passed, verdict, reasons,
                       evidence, identity, closest, closest_correct, candidates, causes, kept, caveats,
                       list(inp.notes) + local.notes, _cannot_tell(inp, scenario), engines, series,
                       tied if len(tied) > 1 else [])


def _verdict_line(inp, scenario, passed, reasons, identity, local, closest, candidates, scheme=None):
    h = f"Δt = {inp.h_s:g} s" if inp.h_s is not None else "its steps"
    if not passed:
        return "; ".join(reasons[:3]) + (f"; and {len(reasons) - 3} more" if len(reasons) > 3 else "")
    if scheme is not None:
        return (f"is {scheme}: it reproduces that scheme at {h} within the rounding of the data"
                + ("" if scheme in identity else " (compared free-running)"))
    if identity:
        also = f" (indistinguishable here from {', '.join(identity[1:])})" if len(identity) > 1 else ""
        return (f"is {identity[0]}{also}: it reproduces that scheme's "
                f"every step at {h} within the rounding of the data")
    worst = max((e.max_ratio for e in local.rows), default=math.nan)
    kind = "one-step defect" if inp.full_state else "acceleration residual"
    close = f"; closest scheme {closest}" if closest else ""
    undecided = (f" (on {local.undecided_rows} of {inp.n_rows - 1} rows Δt is too coarse for the "
                 f"one-step error model: not decisive there)") if local.undecided_rows else ""
    return (f"consistent with the equations of motion of {scenario.name} at {h}: every {kind} "
            f"within what a consistent scheme of order ≥ 1 leaves (largest {worst:.2g} of its "
            f"allowance){undecided}, and the free-running error within its allowance{close}")


def _series(inp, scenario, y_ref, local, closest_correct):
    """Arrays for the plot: the user's rows, the reference, the closest correct scheme run free, and
    the local evidence ratio over time."""
    out = {"t_s": inp.t_s, "y": inp.y, "y_ref": y_ref, "ratios_t_s": inp.t_s[1:] if inp.full_state else None,
           "ratios": local.ratios, "present": list(inp.present)}
    if not inp.full_state and local.rows:
        out["ratios_t_s"] = local.rows[0].series["t_s"]
    if closest_correct and inp.h_s is not None:
        from cross_checks.engines import run_variant
        run = run_variant(scenario, closest_correct, inp.h_s, float(inp.t_s[-1]))
        n = min(len(run.t_s), int(inp.n_steps[-1]) + 1)
        keep = inp.n_steps < n
        out["closest"] = (closest_correct, inp.t_s[keep], run.y[inp.n_steps[keep]])
    return out
