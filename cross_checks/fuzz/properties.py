"""The five properties checked on every case, each with an allowance derived as the sweep derives its own
(docs/fuzz.md §2). For a case (its measured :class:`Context`) and a variant's runs:

* ``free_running_order`` — the largest error over the run at h, h/2, h/4, per quantity, judged above its
  measured floor by the one judge (``analysis.judge.judge_ladder``) against ``analysis.expectations``;
* ``one_step_order`` — the one-step defect against the exact flow from reference states, at h … h/8,
  judged the same way against the local order p + 1;
* ``conservation`` — where the physics conserves energy or world angular momentum and the variant models
  that physics: the largest drift within ``analysis.flow.conservation_allowance`` plus the run's round-off;
* ``agreement`` — the pairs of ``analysis.expectations.EQUIVALENT_PAIRS`` agree to round-off over the
  run, within ``analysis.metrics.same_scheme_allowance`` (the sweep's rule too) relative to each quantity's
  scale.
* ``invariance`` — the case written another way (one transform of scenario.transforms drawn per case,
  :func:`case_transform`) moves the same once mapped back: the sweep's check (sweep.invariance,
  judged by ``analysis.judge.judge_invariance`` at h0, a broken one rerun finer); ``broken`` is a violation,
  ``cannot express`` and ``refused`` count as no claim.

Each function returns ``(violations, tally)``: violation records (with a sentence saying which property
failed and by how much) and ``{property: [checked, no_claim]}`` counts.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from cross_checks.analysis import metrics as M
from cross_checks.analysis.expectations import (
    EQUIVALENT_PAIRS,
    expectation,
    gyroscopic_clamp_acts,
    gyroscopic_term_matters,
    pair_is_same_arithmetic,
)
from cross_checks.analysis.judge import judge_ladder
from cross_checks.core import tolerances as tol
from cross_checks.core.quantities import QUANTITIES, UNITS, state_errors

__all__ = ["Context", "ladder_errors", "free_running_order", "case_floor", "one_step_order", "conservation",
           "agreement", "PROPERTIES", "equivalent_pairs", "invariance", "case_transform"]

PROPERTIES = ("free_running_order", "one_step_order", "conservation", "agreement", "invariance")
_EPS = 2.0 ** -52


@dataclass
class Context:
    """What one case's verdicts are measured against (all measured, see :mod:`cross_checks.fuzz.exact`).

    scenario : the parsed case. n0 : steps at the coarsest rung h0 = scenario.dt_s. y_ref : (4 n0 + 1, 13)
    the reference on the finest rung's grid. ref_err, amp, scales : {quantity: value} — the reference's
    measured error over the run, the measured error amplification, each quantity's scale. physics :
    analysis.physics.ScenarioPhysics. step_h : (S,) one-step rungs (s). step_err : {quantity: (S,)} the
    exact one-step flow's measured error at each rung. allowance : {"energy", "angular_momentum"} of a
    consistent scheme at h0 (analysis.flow.conservation_allowance); scales like h.
    """

    scenario: object
    n0: int
    y_ref: np.ndarray
    ref_err: dict
    amp: dict
    scales: dict
    physics: object
    step_h: np.ndarray
    step_err: dict
    allowance: dict
    lever: dict = None    # analysis.metrics.lever_arms along y_ref (None: no lever-arm term)


def case_floor(ctx, variant, q: str, n: int, h_s: float, reference_error,
               amplification: float = 1.0) -> float:
    """The round-off floor of a run of ``n`` steps of ``h_s`` of case ``ctx`` for quantity ``q``: the one
    rule of the sweep and the fuzz, :func:`cross_checks.analysis.metrics.run_floor`, with the case's
    measured scales and lever arms (``ctx.lever``)."""
    return M.run_floor(variant, q, n, h_s, ctx.scales, reference_error, amplification=amplification,
                       lever=ctx.lever)


def case_transform(name: str):
    """The transform drawn for the case called ``name`` (scenario.transforms.default_transforms, uniformly):
    from a generator seeded by the name alone, so a case and every shrunk version of it (which keeps its
    name) are checked under the same transform."""
    import hashlib

    from cross_checks.scenario.transforms import default_transforms
    seed = int.from_bytes(hashlib.sha256(f"invariance:{name}".encode()).digest()[:8], "little")
    options = default_transforms()
    return options[int(np.random.default_rng(seed).integers(len(options)))]


def invariance(ctx: Context, variant, row: dict) -> tuple:
    """The invariance property of one case from its check's row (sweep.invariance.check_invariance at the
    case's h0): a violation where it is ``broken``; checked where it holds, loses precision as expected or
    is the step's own; no claim where the engine cannot express it, rbcheck refuses it or the original's
    run failed (its order property says why)."""
    tally, out = _tally(), []
    verdict = row["verdict"]
    if verdict in ("cannot express", "refused", "not judged"):
        tally["invariance"][1] += 1
        return out, tally
    tally["invariance"][0] += 1
    if verdict == "broken":
        ratio = row["worst_ratio"]
        q = row["worst_quantity"] or "position"
        out.append({"property": "invariance", "variants": [variant], "quantity": q,
                    "transform": f"{row['transform']} {row['magnitude']}",
                    "ratio": float(ratio) if isinstance(ratio, float) and math.isfinite(ratio) else None,
                    "dt_s": float(ctx.scenario.dt_s),
                    "sentence": (f"{variant}: under {row['transform']} {row['magnitude']} the case does not "
                                 f"move the same: {row['assessment']}")})
    return out, tally


def _tally():
    return {p: [0, 0] for p in PROPERTIES}


def _fmt_list(values):
    return ", ".join("nan" if v is None or not np.isfinite(v) else f"{v:.3g}" for v in values)


def _fit_record(ctx, variant, quantity, dts, errors, floors, statuses, exp, prop):
    """(violation or None, claimed) from a ladder and an Expectation, judged by the one judge
    (:func:`cross_checks.analysis.judge.judge_ladder`)."""
    if exp.verdict != "converges":  # no claim: pre-asymptotic here, or the variant does not model this motion
        return None, False            # (see docs/fuzz.md) — nothing to fit
    j = judge_ladder(dts, errors, floors, statuses, exp)
    fit, phrase = j.fit, j.assessment
    if j.matches is not False:
        return None, j.claimed
    what = "free-running error (largest over the run)" if prop == "free_running_order" else "one-step defect"
    exp_txt = (f"order {exp.order:g}" if exp.order is not None else exp.verdict.replace("_", " "))
    errs = fit.errors
    sentence = (f"{variant}: {quantity} {what} {phrase} — errors {_fmt_list(errs)} "
                f"{UNITS[quantity]} at Δt = {_fmt_list(fit.dt_s)} s, floors "
                f"{_fmt_list(fit.floors)}; expected {exp_txt} ({exp.reason})")
    deficit = None if fit.order is None or exp.order is None else exp.order - fit.order
    claimed = True
    return {"property": prop, "variants": [variant], "quantity": quantity, "verdict": fit.verdict,
            "order": fit.order, "expected_order": exp.order, "expected_verdict": exp.verdict,
            "order_deficit": deficit, "dt_s": fit.dt_s, "errors": errs, "floors": fit.floors,
            "note": fit.note, "sentence": sentence}, claimed


def ladder_errors(ladder, y_ref, cols) -> list:
    """Per rung, {quantity: (n + 1, B)} the errors of the runs of cases ``cols`` (columns of the ladder's
    runs) against their references ``y_ref`` ((n_fine + 1, B, 13), the same cases in the same order):
    what :func:`free_running_order` measures case by case, for a whole batch in one call per rung."""
    n_fine = len(y_ref) - 1
    return [state_errors(runs.y[:, cols], y_ref[::n_fine // (len(runs.y) - 1)]) for runs in ladder]


def free_running_order(ctx: Context, variant, i: int, ladder, errors=None) -> tuple:
    """The free-running order property of case ``i`` (runs ``ladder``: [drivers.Runs] × rungs).
    ``errors``: case ``i``'s rows of :func:`ladder_errors` ([{quantity: (n + 1,)}] per rung), when
    measured for the batch at once; measured here otherwise."""
    sc = ctx.scenario
    tally, out = _tally(), []
    dts, errs, floors, statuses = [], {q: [] for q in QUANTITIES}, {q: [] for q in QUANTITIES}, []
    n_fine = len(ctx.y_ref) - 1
    for r, runs in enumerate(ladder):
        n = len(runs.y) - 1
        stride = n_fine // n
        e = state_errors(runs.y[:, i], ctx.y_ref[::stride]) if errors is None else errors[r]
        dts.append(float(runs.h_s[i]))
        statuses.append(runs.status[i])
        for q in QUANTITIES:
            v = e[q]
            errs[q].append(float(np.max(v))
                           if runs.status[i] == "ok" and np.all(np.isfinite(v)) else math.nan)
            floors[q].append(case_floor(ctx, variant, q, n, float(runs.h_s[i]), ctx.ref_err[q], ctx.amp[q]))
    for q in QUANTITIES:
        exp = expectation(sc, variant, q, "free_running", physics=ctx.physics, measure_physics=False)
        rec, claimed = _fit_record(ctx, variant, q, dts, errs[q], floors[q],
                                   statuses, exp, "free_running_order")
        tally["free_running_order"][0 if claimed else 1] += 1
        if rec is not None:
            out.append(rec)
    return out, tally


def one_step_order(ctx: Context, variant, i: int, defects) -> tuple:
    """The one-step order property of case ``i``; ``defects`` {quantity: (S,)} the largest defect per
    one-step rung (NaN where the engine failed), or None for an engine without a one-step mode."""
    tally, out = _tally(), []
    if defects is None:    # an engine without a one-step mode (an engine file)
        return out, tally
    dts = [float(h) for h in ctx.step_h]
    for q in QUANTITIES:
        floors = [case_floor(ctx, variant, q, 1, dts[k], float(ctx.step_err[q][k])) for k in range(len(dts))]
        errs = [float(v) for v in defects[q]]
        statuses = ["ok" if np.isfinite(v) else "failed" for v in errs]
        exp = expectation(ctx.scenario, variant, q, "one_step", physics=ctx.physics, measure_physics=False)
        rec, claimed = _fit_record(ctx, variant, q, dts, errs, floors, statuses, exp, "one_step_order")
        tally["one_step_order"][0 if claimed else 1] += 1
        if rec is not None:
            out.append(rec)
    return out, tally


def _models_physics(sc, variant, physics=None) -> bool:
    """The variant models the conserved motion: not the course update where the gyroscopic term matters, nor
    a step whose gyroscopic clamp acts on this motion (expectations.gyroscopic_clamp_acts)."""
    if variant.traits.gyroscopic_term and gyroscopic_clamp_acts(sc, variant, physics, physics is not None):
        return False
    return variant.traits.gyroscopic_term or not gyroscopic_term_matters(sc)


def conservation(ctx: Context, variant, i: int, ladder) -> tuple:
    """Energy and world angular momentum drift of case ``i``'s runs, where the physics conserves them."""
    sc = ctx.scenario
    p = sc.problem
    tally, out = _tally(), []
    cons = M.conserved(p.forces)
    kinds = [k for k in ("energy", "angular_momentum") if cons[k][0]]
    if not kinds:
        return out, tally
    if not _models_physics(sc, variant, ctx.physics):
        tally["conservation"][1] += len(kinds)
        return out, tally
    h0 = sc.dt_s
    # round-off is relative to the quantities' scales (at least 1 in SI units, as every floor of a sweep),
    # not to E or L themselves, which may be 0 (a body at rest) while their terms round at ε × scale
    I_max = float(np.linalg.eigvalsh(p.body.inertia_B)[-1])
    momentum_scale = I_max * ctx.scales["angular_velocity"]
    energy_scale = (p.body.mass_kg * ctx.scales["velocity"] ** 2 + I_max * ctx.scales["angular_velocity"] ** 2
                    + p.body.mass_kg * float(np.linalg.norm(p.forces.gravity_W)) * ctx.scales["position"]
                    + sum(s.stiffness_N_per_m * ctx.scales["position"] ** 2 for s in p.forces.springs))
    for kind in kinds:
        worst = None
        for runs in ladder:
            if runs.status[i] != "ok":
                continue    # a run that did not finish has its verdict in the order property
            y = runs.y[:, i]
            n = len(y) - 1
            if kind == "energy":
                E, terms = M.energy_J(p, y, with_scale=True)
                drift = float(np.max(np.abs(E - E[0])))
                size = max(float(np.max(terms)), energy_scale)
                unit = "J"
            else:
                L = M.angular_momentum_W(p, y)
                drift = float(np.max(np.linalg.norm(L - L[0], axis=1)))
                size = max(float(np.max(np.linalg.norm(L, axis=1))), momentum_scale)
                unit = "kg m²/s"
            allowed = (ctx.allowance[kind] * float(runs.h_s[i]) / h0
                       + n * tol.CHECK_ROUNDINGS_PER_STEP * variant.rounding_unit * size
                       + _lever_conservation(ctx, kind, I_max, float(runs.h_s[i]) * n, n, variant))
            ratio = drift / allowed if allowed > 0 else (math.inf if drift > 0 else 0.0)
            if worst is None or ratio > worst[0]:
                worst = (ratio, drift, allowed, float(runs.h_s[i]), unit)
        if worst is None:
            continue
        tally["conservation"][0] += 1
        ratio, drift, allowed, h, unit = worst
        if not ratio <= 1.0:
            what = "energy" if kind == "energy" else "world angular momentum"
            out.append({"property": "conservation", "variants": [variant], "quantity": kind, "value": drift,
                        "allowance": allowed, "ratio": ratio, "dt_s": h,
                        "sentence": (f"{variant}: {what} drifts by {drift:.3g} {unit} at "
                                     f"Δt = {h:.3g} s, {ratio:.3g}× the {allowed:.3g} {unit} a "
                                     "consistent scheme may accumulate over the run (its local "
                                     "defects weighted by the sensitivity, + round-off)")})
    return out, tally


def _lever_conservation(ctx, kind, I_max, t, n, variant) -> float:
    """What the lever-arm round-off (metrics.lever_roundoff) may move world angular momentum (I_max × the ω it
    adds) or energy (that ω error against I_max |ω|max, and the spurious torque's work) by over time ``t``,
    for a ``variant`` that pays it (Traits.lever_arms)."""
    if not ctx.lever or not variant.traits.lever_arms:
        return 0.0
    lv = M.lever_roundoff(ctx.lever, _EPS)   # in float64's ε, scaled to the variant's rounding unit
    scale = variant.rounding_unit / _EPS
    dw = scale * (lv.get("acc_rad_s2", 0.0) * t + lv.get("omega_rad_s", 0.0) * (1.0 + math.sqrt(n)))
    if kind == "angular_momentum":
        return I_max * dw
    w_max = float(np.max(np.linalg.norm(ctx.y_ref[:, 10:13], axis=1)))
    return I_max * dw * (w_max + dw)


def equivalent_pairs(variants) -> list:
    """The EQUIVALENT_PAIRS whose two variants are both among ``variants``: [(a, b, reason)]."""
    have = {v: v for v in variants}   # the batch's own (Resolved) variants, looked up by name
    return [(have[a], have[b], why) for a, b, why in EQUIVALENT_PAIRS if a in have and b in have]


def agreement(ctx: Context, pair, i: int, ladder_a, ladder_b) -> tuple:
    """Two variants that implement the same arithmetic agree to round-off on case ``i``, at every rung."""
    a, b, reason = pair
    tally, out = _tally(), []
    if not pair_is_same_arithmetic(ctx.scenario, a, b):   # documented: not the same numbers on this case
        tally["agreement"][1] += 1
        return out, tally
    amp = max(ctx.amp.values())
    worst = None
    for ra, rb in zip(ladder_a, ladder_b):
        n = len(ra.y) - 1
        h = float(ra.h_s[i])
        eps = max(a.rounding_unit, b.rounding_unit)   # the coarser of the pair's roundings
        allowed = M.same_scheme_allowance(n, eps, amp)
        sa, sb = ra.status[i], rb.status[i]
        if "failed" in (sa, sb) or "not_expressible" in (sa, sb):
            continue    # a failed run is its own finding (the order property); an inexpressible one none
        if sa == "diverged" or sb == "diverged":
            ta, tb = ra.diverged_at_s[i], rb.diverged_at_s[i]
            same = sa == sb and M.diverged_together(ta, tb, h)
            rel = 0.0 if same else math.inf
            why = f"{a} {sa}" + (f" at t = {ta:.6g} s" if sa == "diverged" else "") + f", {b} {sb}" + (
                f" at t = {tb:.6g} s" if sb == "diverged" else "")
        else:
            d = state_errors(ra.y[:, i], rb.y[:, i])
            rel, q_worst = M.same_scheme_difference({q: np.max(d[q]) for q in QUANTITIES}, ctx.scales)
            why = f"largest in {q_worst}"
        if worst is None or rel / allowed > worst[0]:
            worst = (rel / allowed, rel, allowed, h, why)
    if worst is None:
        return out, tally
    tally["agreement"][0] += 1
    ratio, rel, allowed, h, why = worst
    if not ratio <= 1.0:
        out.append({"property": "agreement", "variants": [a, b], "quantity": None, "value": rel,
                    "allowance": allowed, "ratio": ratio, "dt_s": h,
                    "sentence": (f"{a} and {b} should implement the same arithmetic ({reason}) but differ by "
                                 f"{rel:.3g} relative at Δt = {h:.3g} s ({why}), {ratio:.3g}× the round-off "
                                 f"allowance {allowed:.3g}")})
    return out, tally
