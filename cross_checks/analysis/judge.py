"""The one judge of a convergence ladder: from the errors over a Δt ladder, their round-off floors and what
the variant is expected to do (:mod:`cross_checks.analysis.expectations`) to a verdict, whether it matches,
and the sentence saying why.

Every entry point decides a ladder's verdict here and nowhere else: the sweep's convergence records
(:mod:`cross_checks.sweep.assemble`, and through it ``assert_engine``), the fuzz's order properties
(:mod:`cross_checks.fuzz.properties`) and ``rbcheck check``'s ladder mode
(:mod:`cross_checks.gates.check.ladder`).

The rules, in order (each a measured reason, never a tolerance widened; docs/verdicts.md §4):

1. The fit (:func:`~cross_checks.analysis.convergence.fit_convergence`) over the points resolved above
   their floors, compared with the expectation
   (:func:`~cross_checks.analysis.convergence.compare_with_expectation`).
2. An expectation that makes no claim on this ladder (``pre_asymptotic``) turns a fitted converges /
   does_not_converge into ``pre_asymptotic``.
3. A too-low order measured pre-asymptotic
   (:func:`~cross_checks.analysis.convergence.measured_pre_asymptotic`).
4. A too-low order that the errors, each allowed its round-off floor, do not refute
   (:func:`~cross_checks.analysis.convergence.order_within_floors`) — no claim.
5. Three halving rungs that fit ``a hᵖ + b hᵖ⁺¹`` within their floors (:func:`two_term_consistent`): no
   claim.

No excuse (rules 2 and 3, nor "every rung within its round-off floor" for the quantity concerned) is given to
runs whose own steps are not the scenario's equations: ``local`` is the worst one-step defect of the ladder's
runs on their recorded states (:func:`cross_checks.analysis.flow.run_local_defect`); above its allowance
(ratio > 1) the verdict is judged as fitted and the sentence says why the excuse was refused
(docs/verdicts.md, "No excuse for wrong equations").

An invariance check (docs/invariance.md) has no ladder either: :func:`judge_invariance` judges how far a
variant's run of a transformed scenario, mapped back, is from its run of the original, against the two runs'
round-off in the variant's precision grown by the motion's measured amplification
(:func:`invariance_allowance`).

A long run has no ladder: :func:`judge_long_run` judges what it conserved against what the variant's traits
say it keeps (:func:`~cross_checks.analysis.expectations.long_run_expectation`), with round-off floors from
:func:`cross_checks.core.tolerances.long_run_roundoff` (docs/verdicts.md §8).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from cross_checks.analysis.convergence import (
    ConvergenceFit,
    compare_with_expectation,
    fit_convergence,
    fmt_order,
    measured_pre_asymptotic,
    order_within_floors,
)
from cross_checks.core import tolerances as tol

__all__ = ["Judgement", "LocalEvidence", "judge_ladder", "judge_fit", "two_term_consistent",
           "LongRunJudgement", "judge_long_run", "LONG_RUN_VERDICTS", "INVARIANCE_VERDICTS",
           "InvarianceJudgement", "invariance_allowance", "judge_invariance"]


@dataclass(frozen=True)
class LocalEvidence:
    """The worst one-step defect over a ladder's runs: ``ratio`` (defect / what a consistent scheme leaves),
    in ``quantity``, at Δt ``dt_s``; ``declared_order``: the order the variant's engine declares (None:
    unknown)."""

    ratio: float
    quantity: str
    dt_s: float
    declared_order: float | None = None

    @property
    def wrong_equations(self) -> bool:
        return self.ratio > 1.0   # above the allowance of every consistent scheme (analysis.flow)

    def sentence(self) -> str:
        return ("its own steps are not the scenario's equations: from its recorded states, "
                f"one step leaves {self.ratio:.3g}× what a consistent scheme of order ≥ 1 "
                f"leaves in {self.quantity.replace('_', ' ')} (Δt = {self.dt_s:g} s)")


@dataclass(frozen=True)
class Judgement:
    """What the judge decided of one ladder.

    fit : the fit it judged.  verdict : the record's verdict (the fit's, or ``pre_asymptotic`` where no claim
    is made).  matches : True / False against the expectation, None where no claim is made.  assessment : the
    sentence.  claimed : whether an order claim was tested on this ladder (the fuzz counts claims).
    """

    fit: ConvergenceFit
    verdict: str
    matches: bool | None
    assessment: str
    claimed: bool


def judge_ladder(dts, errors, floors, statuses, exp, local: LocalEvidence | None = None,
                 quantity: str | None = None) -> Judgement:
    """Fit the ladder (Δt coarse to fine, errors, floors, statuses "ok"/...) and judge it against ``exp``
    (an :class:`~cross_checks.analysis.expectations.Expectation`); ``local``: the runs' own one-step defect;
    ``quantity``: the one whose errors these are."""
    factor = (tol.AMPLIFIED_ROUNDOFF_FACTOR_FLOAT32 if getattr(exp, "precision", "float64") == "float32"
              else tol.AMPLIFIED_ROUNDOFF_FACTOR)
    return judge_fit(fit_convergence(dts, errors, floors, statuses, factor), exp, local, quantity)


def judge_fit(fit: ConvergenceFit, exp, local: LocalEvidence | None = None,
              quantity: str | None = None) -> Judgement:
    """Judge a fit against the expectation ``exp`` (the module's rules, in order); no excuse where ``local``
    says the runs' equations are wrong. A variant of a precision other than float64 says which rungs were
    judged above its round-off floors."""
    j = _judged(fit, exp, local, quantity)
    prec = getattr(exp, "precision", "float64")
    if prec == "float64" or not fit.dt_s:
        return j
    if (j.matches is False and fit.verdict == "does_not_converge" and local is not None
            and not local.wrong_equations):
        # A consistent step's truncation errors shrink; its runs' steps are measured consistent (the one-step
        # check is sharp in any precision), so errors that do not shrink are round-off the motion grew past
        # the floors' linear estimate (docs/verdicts.md §7). No claim.
        j = Judgement(fit, "pre_asymptotic", None,
                      f"{j.assessment}, but every step of its runs is the scenario's equations (one-step "
                      f"defect at most {local.ratio:.2g}× what a consistent scheme leaves): errors that do "
                      "not shrink are round-off grown by the motion beyond the floors' estimate; no claim on "
                      "this ladder", False)
    judged = [h for h, used in zip(fit.dt_s, fit.fitted) if used]
    rungs = (f"rungs Δt = {judged[0]:g} … {judged[-1]:g} s judged" if len(judged) > 1 else
             "no two rungs resolved" if not judged else f"rung Δt = {judged[0]:g} s judged")
    factor = float(getattr(exp, "rounding_factor", 1.0))
    eps = factor * tol.MACHINE_EPSILON[prec]
    unit = (f"ε = {eps:.2g} per step" if factor == 1.0 else
            f"{factor:g} × ε = {eps:.2g} per step, its declared rounding factor")
    return Judgement(fit, j.verdict, j.matches, f"{j.assessment} ({prec}: {rungs} of {len(fit.dt_s)}, floors "
                     f"from {unit})", j.claimed)


def _judged(fit: ConvergenceFit, exp, local: LocalEvidence | None, quantity: str | None) -> Judgement:
    j = _judge(fit, exp)
    if local is None or not local.wrong_equations or j.verdict not in ("pre_asymptotic", "at_roundoff"):
        return j
    if j.verdict == "at_roundoff":
        if quantity != local.quantity or not j.matches:
            return j   # the defect is another quantity's (the course's missing term in ω leaves x exact)
        return Judgement(fit, fit.verdict, False, f"no round-off excuse (every rung within its floor): "
                         f"{local.sentence()}", True)
    p = local.declared_order
    if (fit.verdict == "converges" and p is not None and fit.order is not None
            and fit.order >= p - tol.SWEEP_ORDER_TOL):
        return j   # this quantity shows the declared order: nothing here needed an excuse
    fitted = (f"fitted order {fmt_order(fit.order)}" if fit.order is not None
              else fit.verdict.replace("_", " "))
    return Judgement(fit, fit.verdict, False, f"no pre-asymptotic excuse ({fitted}"
                     + (f", declared order {p:g}" if p is not None else "") + f"): {local.sentence()}", True)


def _judge(fit: ConvergenceFit, exp) -> Judgement:
    verdict = fit.verdict
    matches, phrase = compare_with_expectation(fit.verdict, fit.order, exp, fit.order_is_lower_bound)
    if exp.verdict == "pre_asymptotic":
        if verdict in ("converges", "does_not_converge"):
            verdict = "pre_asymptotic"
        return Judgement(fit, verdict, None, phrase, False)
    if exp.verdict != "converges":
        return Judgement(fit, verdict, matches, phrase, exp.verdict is not None)
    if matches is not False or exp.order is None:
        return Judgement(fit, verdict, matches, phrase, True)
    why = measured_pre_asymptotic(fit, exp.order)
    if why:
        return Judgement(fit, "pre_asymptotic", None, why, True)
    if fit.verdict == "converges" and fit.order is not None:
        best = order_within_floors(fit)
        if best is not None and best >= exp.order - tol.SWEEP_ORDER_TOL:
            return Judgement(fit, verdict, None,
                             f"order {fmt_order(fit.order)}, but the errors allow order "
                             f"{fmt_order(best)} within their round-off floors (expected {exp.order:g}): "
                             "no claim on this ladder", False)
    if two_term_consistent(fit.dt_s, fit.errors, fit.floors, exp.order):
        return Judgement(fit, verdict, None,
                         f"{phrase}, but the three rungs fit a hᵖ + b hᵖ⁺¹ (p = {exp.order:g}) within their "
                         "round-off floors: the next term of the error series, no claim on this ladder",
                         False)
    return Judgement(fit, verdict, False, phrase, True)


def two_term_consistent(dts, errors, floors, order) -> bool:
    """Whether three rungs h, h/2, h/4, each error allowed its round-off floor, fit
    e(h) = a h^p + b h^(p+1): the leading term of an order-p scheme plus the next one, of any sign.

    Then u = e / h^p is affine in h, so u0 − 3 u1 + 2 u2 = 0 (rungs halving). A leading coefficient a
    that happens to be small (two first-order contributions nearly cancelling) makes b h dominate at the
    coarse rungs and the fitted order meaningless, although the scheme has order p. An order q < p instead
    gives u ∝ h^(q−p), whose residual is ≥ 0.38 of max |u| for q ≤ p − 0.5 (0.75 for q = p − 1): above
    FUZZ_TWO_TERM_TOL.

    Each measured error is the truncation error plus round-off and the reference's error, which its floor
    bounds: the ladder is consistent when SOME truncation errors e'_i ∈ [max(0, e_i − f_i), e_i + f_i] give
    |u'0 − 3 u'1 + 2 u'2| ≤ FUZZ_TWO_TERM_TOL · max u' (a linear program per candidate maximum, SciPy's
    HiGHS). Errors far above their floors are judged as measured; a rung within its floor leaves two
    resolved rungs, on which a next term that cancels the leading one cannot be told from a lower order,
    so no claim either way. Only ladders of
    exactly three halving rungs qualify (the fuzz's); longer ladders are judged by the other rules."""
    from scipy.optimize import linprog
    h = np.asarray(dts, dtype=float)
    e = np.asarray(errors, dtype=float)
    fl = np.asarray(floors, dtype=float)
    if len(h) != 3 or not np.all(np.isfinite(e)) or not np.all(np.isfinite(fl)):
        return False
    if not np.allclose(h[1:] / h[:-1], 0.5, rtol=1e-9):
        return False
    scale = 1.0 / h ** float(order)                  # u = scale · e
    scale = scale / scale[0]                          # (a common factor: the test is homogeneous in u)
    third = np.array([1.0, -3.0, 2.0]) * scale        # u0 − 3 u1 + 2 u2 as a linear form in e'
    lo, hi = np.maximum(0.0, e - np.maximum(fl, 0.0)), e + np.maximum(fl, 0.0)
    if np.all(hi <= 0.0):
        return False
    for j in range(3):      # max u' = u'_j: |third · e'| ≤ TOL u'_j, and u'_j ≥ u'_k for every k
        unit = np.eye(3)[j] * scale[j]
        rows = [third - tol.FUZZ_TWO_TERM_TOL * unit, -third - tol.FUZZ_TWO_TERM_TOL * unit]
        rows += [np.eye(3)[k] * scale[k] - unit for k in range(3) if k != j]
        res = linprog(np.zeros(3), A_ub=np.array(rows), b_ub=np.zeros(len(rows)),
                      bounds=list(zip(lo / hi.max(), hi / hi.max())), method="highs")
        if res.status == 0:
            return True
    return False


#: The verdicts of a long run: what its separatrix distance did (analysis.long_run.DRIFT_KINDS), or the run
#: diverged or failed.
LONG_RUN_VERDICTS = ("crosses_separatrix", "toward_intermediate", "away_from_intermediate", "none",
                     "diverged", "failed")


@dataclass(frozen=True)
class LongRunJudgement:
    """What the judge decided of one long run: ``verdict`` (LONG_RUN_VERDICTS), ``matches`` (True / False
    against the variant's declared invariants, None where it declares none), ``assessment`` (the sentence)
    and ``finding`` (analysis.long_run.finding: "" when δ drifts neither way)."""

    verdict: str
    matches: bool | None
    assessment: str
    finding: str


def judge_long_run(variant: str, run_name: str, metrics, exp, status: str = "ok",
                   diverged_at_s: float | None = None) -> LongRunJudgement:
    """Judge a long run's :class:`~cross_checks.analysis.long_run.DriftMetrics` ``metrics`` (None when the
    run failed) against the :class:`~cross_checks.analysis.expectations.LongRunExpectation` ``exp``, by the
    rules of docs/verdicts.md §8, in order (round-off: tol.long_run_roundoff)."""
    from cross_checks.analysis.long_run import drift_kind, finding
    if status == "failed" or metrics is None:
        return LongRunJudgement("failed", None, "the run failed: nothing to judge", "")
    said = finding(variant, run_name, metrics)
    claims = bool(exp.keeps) or exp.separatrix is not None
    if status == "diverged":
        # a run that blew up has no separatrix distance worth naming (δ of a state beyond 1e8 is meaningless)
        when = f" at t = {diverged_at_s:.4g} s" if diverged_at_s is not None else ""
        grew = (f" (the energy grew by {metrics.energy_drift_max:.3g} of itself before)"
                if math.isfinite(metrics.energy_drift_max) else "")
        said = f"{variant} on {run_name}: diverged{when}{grew}"
        if claims:
            return LongRunJudgement("diverged", False, f"diverged{when}, although {exp.reason}", said)
        return LongRunJudgement("diverged", None, f"diverged{when} (no claim: {exp.reason})", said)
    floor = tol.long_run_roundoff(metrics.steps, tol.UNIT_ROUNDOFF[exp.precision], exp.rounding_factor)
    lost = []
    measured = {"energy": metrics.energy_drift_max, "angular_momentum_norm": metrics.momentum_drift_max,
                "angular_momentum": max(metrics.momentum_drift_max, metrics.direction_drift_max_rad)}
    for k in exp.keeps:
        if k == "energy_bounded":
            if metrics.energy_secular:
                lost.append(f"its energy drifts secularly ({metrics.energy_rate_per_s:+.3g}/s; largest drift "
                            f"{metrics.energy_drift_max:.3g}), although it declares a bounded energy error")
        elif measured[k] > floor:
            what = {"energy": "the energy drifted by", "angular_momentum_norm": "|L| drifted by",
                    "angular_momentum": "L drifted (norm or direction, relative or rad) by"}[k]
            lost.append(f"{what} {measured[k]:.3g}, beyond the round-off of {metrics.steps} steps "
                        f"({floor:.2g}), although it declares that it keeps it")
    kind = drift_kind(metrics)
    if exp.separatrix == "kept" and kind != "none":
        lost.append(f"its separatrix distance moved ({said.split(': ', 1)[-1]}), although {exp.reason}")
    elif exp.separatrix == "toward_intermediate" and kind not in ("none", "toward_intermediate"):
        lost.append(f"its separatrix distance moved another way than the step's ({said.split(': ', 1)[-1]}), "
                    f"although {exp.reason}")
    if lost:
        return LongRunJudgement(kind, False, "; ".join(lost), said)
    if not claims:
        return LongRunJudgement(kind, None, f"no claim: {exp.reason}", said)
    held = ", ".join(k.replace("_", " ") for k in exp.keeps) or "nothing"
    extra = (" — its drift toward the intermediate axis is the one its step makes (expected, named)"
             if kind == "toward_intermediate" else "")
    return LongRunJudgement(kind, True, f"keeps {held} as declared (within {floor:.2g}){extra}", said)


# --- invariance checks -----------------------------------------------------------------------------------

#: Verdicts of an invariance check: ``holds`` (within the round-off of the motion itself), ``precision loss``
#: (beyond it, within what the transform's larger magnitudes allow: expected, with its number), ``broken``
#: (beyond the allowance: the engine, or its adapter, does not move the same physics the same),
#: ``step-dependent`` (beyond it, but shrinking at a consistent scheme's order as Δt halves: the step is not
#: covariant under the transform, and its truncation error parts the runs: the scheme's own, said with its
#: numbers, never a failure; decided by cross_checks.sweep.invariance, which reruns the broken ones finer),
#: ``cannot express`` (the engine cannot take the transformed scenario: said, never a failure) and
#: ``refused`` (rbcheck refuses the transform on this scenario: it would leave the physical ranges),
#: ``not judged`` (the variant's run of the original failed or diverged: results.csv says why) and
#: ``known finding`` (broken as the variant declares it, beside its reason: engines.base.InvarianceFinding;
#: said with its number, never a failure; decided by cross_checks.sweep.invariance after the refinement).
INVARIANCE_VERDICTS = ("holds", "precision loss", "step-dependent", "broken", "known finding",
                       "cannot express", "refused", "not judged")


@dataclass(frozen=True)
class InvarianceJudgement:
    """What the judge decided of one invariance check: ``verdict`` (INVARIANCE_VERDICTS), per quantity the
    largest ``deviation`` over the run (its unit: m, rad, m/s, rad/s), the ``allowance`` (base + offset) and
    its ``base`` part (the motion's own round-off), the ``worst`` quantity (largest deviation / allowance) and
    the ``assessment`` sentence."""

    verdict: str
    deviation: dict
    allowance: dict
    base: dict
    worst: str
    assessment: str


def invariance_allowance(scales: dict, amplification: dict, n_steps: int, *, precision: str = "float64",
                         rounding_factor: float = 1.0, offset_m: float = 0.0, dt_s: float | None = None,
                         differenced: bool = False) -> tuple:
    """``(base, offset)`` allowances per quantity (its unit) for two runs of ``n_steps`` steps of one variant
    that differ only in how the same physics is written.

    Each run rounds as :func:`cross_checks.analysis.metrics.roundoff_floor` models it,
    ``ε·scale·(b N + √N A)``
    with ε = CHECK_ROUNDINGS_PER_STEP unit roundoffs (UNIT_ROUNDOFF[precision]: the roundings of a step's ~10
    operations per component) × ``rounding_factor`` and A the motion's measured amplification, and
    b = 1 for every quantity: a transform changes every rounding of the step (a turned frame rounds each
    component differently), so the two runs' roundings are not paired, and a step that renormalises (the
    quaternion, a rescaled |L|) rounds the same way every step — the worst case adds up linearly, as
    tolerances.long_run_roundoff takes it (measured: the Jolt and Bullet implicit gyroscopic steps of the
    reference part by 3e-11 rad over 1e4 steps of tennis_racket in a turned world, 2.4× the √N model with one
    rounding a step; by 1.9e-8 rad/s on tumbling_box, 5× it with the linear term; implicit Euler, whose Newton
    solve stops at its tolerance, by 2.7e-10 m/s on spring_oscillator scaled, 5.6× it). The
    two runs' difference is bounded by the sum (INVARIANCE_RUNS_COMPARED), and round-off scatters about its
    estimate by up to ROUNDOFF_NOISE_FACTOR. ``offset_m`` (a translation's |d|) makes every position
    |d| larger: its rounding ``ε |d|`` per step adds ``ε |d| (N + √N A_x)`` to the position and, through the
    motion (A_q per position perturbation of relative size ε), ``ε (|d| / scale_x) scale_q √N A_q`` to the
    others; a velocity recomputed from positions (``differenced``) adds their round-off over Δt."""
    from cross_checks.analysis.metrics import differencing_floor
    from cross_checks.core.quantities import QUANTITIES
    eps = tol.CHECK_ROUNDINGS_PER_STEP * tol.UNIT_ROUNDOFF[precision] * max(1.0, float(rounding_factor))
    k = tol.INVARIANCE_RUNS_COMPARED * tol.ROUNDOFF_NOISE_FACTOR
    n = max(int(n_steps), 1)
    base, offset = {}, {}
    x_scale = float(scales.get("position", 1.0))
    for q in QUANTITIES:
        a = max(1.0, float((amplification or {}).get(q, 1.0)))
        scale = float(scales.get(q, 1.0))
        base[q] = k * eps * scale * (n + math.sqrt(n) * a)
        if q == "position":
            offset[q] = k * eps * offset_m * (n + math.sqrt(n) * a)
        else:
            offset[q] = k * eps * (offset_m / x_scale) * scale * math.sqrt(n) * a
        if differenced and q == "velocity" and dt_s:
            base[q] += k * differencing_floor(x_scale, n, dt_s, eps, a)
            offset[q] += k * differencing_floor(offset_m, n, dt_s, eps, a)
    return base, offset


def judge_invariance(y_original, y_mapped, *, scales: dict, amplification: dict, n_steps: int,
                     precision: str = "float64", rounding_factor: float = 1.0, offset_m: float = 0.0,
                     dt_s: float | None = None, differenced: bool = False) -> InvarianceJudgement:
    """Judge the states ``y_mapped`` ((T, 13): a run of a transformed scenario, mapped back to the original's
    frames) against ``y_original`` ((T, 13): the same variant's run of the original) with the allowance of
    :func:`invariance_allowance`: ``holds`` within its base, ``precision loss`` within base + offset,
    ``broken`` beyond (or where one run left the finite numbers and the other did not)."""
    from cross_checks.core.quantities import QUANTITIES, UNITS, state_errors
    y0, y1 = np.asarray(y_original, dtype=float), np.asarray(y_mapped, dtype=float)
    base, offset = invariance_allowance(scales, amplification, n_steps, precision=precision,
                                        rounding_factor=rounding_factor, offset_m=offset_m, dt_s=dt_s,
                                        differenced=differenced)
    allowance = {q: base[q] + offset[q] for q in QUANTITIES}
    if y0.shape != y1.shape:
        dev = {q: math.inf for q in QUANTITIES}
        return InvarianceJudgement("broken", dev, allowance, base, "position",
                                   f"the transformed run recorded {len(y1)} states, the original {len(y0)}")
    errs = state_errors(y1, y0)
    finite0 = np.all(np.isfinite(y0), axis=-1)
    dev = {}
    for q in QUANTITIES:
        e = np.where(finite0, errs[q], 0.0)
        dev[q] = math.inf if not np.all(np.isfinite(e)) else float(np.max(e, initial=0.0))
    worst = max(QUANTITIES, key=lambda q: dev[q] / allowance[q] if allowance[q] > 0 else math.inf)
    what = (f"largest deviation {dev[worst]:.3g} {UNITS[worst]} in {worst.replace('_', ' ')}")
    if not math.isfinite(dev[worst]):
        return InvarianceJudgement("broken", dev, allowance, base, worst,
                                   f"the transformed run left the finite numbers where the original did not "
                                   f"({worst.replace('_', ' ')})")
    if all(dev[q] <= base[q] for q in QUANTITIES):
        return InvarianceJudgement("holds", dev, allowance, base, worst,
                                   f"holds: {what}, within its round-off {base[worst]:.2g}")
    if all(dev[q] <= allowance[q] for q in QUANTITIES):
        over = max((q for q in QUANTITIES if dev[q] > base[q]), key=lambda q: dev[q] / base[q])
        scale = float(scales.get(over, 1.0))
        blind = (f"; at this distance {precision}'s allowance exceeds the motion's own scale ({scale:.3g} "
                 f"{UNITS[over]}): this check cannot tell an error from round-off here"
                 if allowance[over] >= scale else "")
        return InvarianceJudgement("precision loss", dev, allowance, base, over,
                                   f"precision loss (expected): {dev[over]:.3g} {UNITS[over]} in "
                                   f"{over.replace('_', ' ')}, within the {allowance[over]:.2g} that "
                                   f"{precision} at |d| = {offset_m:g} m allows{blind}")
    return InvarianceJudgement("broken", dev, allowance, base, worst,
                               f"broken: {what}, {dev[worst] / allowance[worst]:.3g}× the allowance "
                               f"{allowance[worst]:.2g} of {precision} round-off")
