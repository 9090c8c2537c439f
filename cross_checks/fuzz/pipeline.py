"""One batch of cases, from draws to property verdicts.

1. :func:`prepare` — each draw's coarsest step h: from a first estimate of the fastest rate, then from a
   pilot solve of the exact motion (all cases, each with its 12 perturbed copies, in one DOP853 solve):
   ``h L_max ≤ √(2χ / n0)`` (≤ FUZZ_HL_MAX) and ``A χ ≤ FUZZ_LINEAR_MAX``.
2. :func:`measure` — every case's :class:`~cross_checks.fuzz.properties.Context`, measured: the reference
   on the finest grid and its error, the amplification, the physics the expectations use, the exact
   one-step flows from reference states and their error, the conservation allowance. A case whose
   measured h L or A χ still exceeds its bound (× FUZZ_BOUND_SLACK) is skipped, never judged.
3. :func:`evaluate` — every variant's runs (:mod:`cross_checks.fuzz.drivers`) and the five properties (the
   invariance one under the transform drawn for the case: properties.case_transform).

All cases of a batch share n0, the number of steps at their coarsest rung, so that they share the
normalised time grid of the batched solves.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
from numpy.linalg import LinAlgError

from cross_checks.analysis import flow
from cross_checks.analysis import metrics as M
from cross_checks.analysis.physics import ScenarioPhysics, motion_rates, separatrix_proximity
from cross_checks.analysis.refinement import refined_ladder_shows_the_order, worth_refining
from cross_checks.core import tolerances as tol
from cross_checks.core.quantities import QUANTITIES, quantity_scales, state_errors
from cross_checks.fuzz import drivers, exact
from cross_checks.fuzz import properties as P
from cross_checks.fuzz.generate import to_toml

__all__ = ["ONE_STEP_RUNGS", "ONE_STEP_STARTS", "Case", "prepare", "measure", "evaluate", "CaseOutcome",
           "scenario_of", "evaluate_specs", "steps_of"]

#: One-step rungs: h, h/2, h/4, h/8 (one step is cheap; four points resolve the local order).
ONE_STEP_RUNGS = 4
#: Reference states each one-step measurement starts from, evenly spread over the run.
ONE_STEP_STARTS = 6


@dataclass
class Case:
    """A drawn case at its chosen step: the scenario file (``spec``), the parsed scenario, and n0."""

    draw: object
    spec: dict
    scenario: object
    n0: int
    numbers: dict = field(default_factory=dict)
    index: int = -1

    def __post_init__(self):
        if self.index < 0 and self.draw is not None:
            self.index = self.draw.index


def scenario_of(spec: dict, source: str = "<fuzz>"):
    """The validated Scenario of a scenario dict (through the TOML parser, like any user's file)."""
    from cross_checks.scenario import parse_scenario
    return parse_scenario(to_toml(spec), source=source)


def _rate_estimate(sc, omega) -> float:
    """A first estimate of the fastest rate (1/s): analysis.flow.motion_rate at the initial state, the
    rate √(|τ| / I_min) at which torques (applied, or of forces off the COM) spin the body up, and at
    least the draw's base rate ``omega`` (a motion without a rate of its own is timed by it)."""
    p = sc.problem
    rate = float(flow.motion_rate(sc, p.initial_packed()[None, :])[0])
    I_min = float(np.linalg.eigvalsh(p.body.inertia_B)[0])
    tau = sum(float(np.linalg.norm(t.torque)) for t in p.forces.torques)
    tau += sum(float(np.linalg.norm(f.force) * np.linalg.norm(f.point_B)) for f in p.forces.point_forces)
    return max(rate, math.sqrt(tau / I_min), omega)


def _hl_target(draw, n0) -> float:
    return min(tol.FUZZ_HL_MAX, max(tol.FUZZ_HL_MIN, math.sqrt(2.0 * draw.chi / n0)))


def prepare(draws, n0: int) -> list:
    """Each draw at its fair coarsest step (see the module docstring): [Case]."""
    first = []
    for d in draws:
        sc = scenario_of(d.spec(1e-4, n0))   # a short run only to read the physics (the decay needs a step)
        h = _hl_target(d, n0) / _rate_estimate(sc, d.omega)
        spec = d.spec(h, n0)
        first.append((d, spec, scenario_of(spec)))
    scs = [s for _, _, s in first]
    y_pilot = exact.solve_members([sc.problem for sc in scs], [sc.duration_s for sc in scs],
                                  np.linspace(0.0, 1.0, 33), rtol=tol.FUZZ_PILOT_RTOL)
    scales = [quantity_scales(y_pilot[:, i]) for i in range(len(scs))]
    amp = exact.amplification(scs, scales, rtol=tol.FUZZ_PILOT_RTOL)
    out = []
    for i, (d, spec, sc) in enumerate(first):
        L = max(float(np.max(flow.motion_rate(sc, y_pilot[:, i]))), d.omega)
        A = max(float(amp[q][i]) for q in QUANTITIES)
        hl = min(_hl_target(d, n0), math.sqrt(2.0 * tol.FUZZ_LINEAR_MAX / (A * n0)))
        h = min(sc.dt_s, hl / L)
        if h < sc.dt_s:
            spec = d.spec(h, n0)
            sc = scenario_of(spec)
        out.append(Case(d, spec, sc, n0))
    return out


def _numbers(case, y_ref, amp_i) -> dict:
    """The controlled dimensionless numbers of a case, as measured on its reference."""
    sc = case.scenario
    p = sc.problem
    h, T = sc.dt_s, sc.duration_s
    L = float(np.max(flow.motion_rate(sc, y_ref)))
    ev = np.linalg.eigvalsh(p.body.inertia_B)
    A = max(amp_i.values())
    chi = 0.5 * L * L * h * T
    kdt2 = max([s.stiffness_N_per_m * h * h / p.body.mass_kg for s in p.forces.springs], default=0.0)
    return {"hL": h * L, "chi": chi, "amplification": A, "A_chi": A * chi,
            "anisotropy": float((ev[-1] - ev[0]) / ev[-1]), "separatrix_proximity": separatrix_proximity(p),
            "stiffness_dt2_per_m": kdt2, "n0": case.n0, "dt_s": h, "duration_s": T,
            **(case.draw.kinds if case.draw is not None else {})}


def _fair(numbers) -> str:
    """"" when the measured numbers are within their bounds (× FUZZ_BOUND_SLACK), else why not."""
    if numbers["hL"] > tol.FUZZ_HL_MAX * tol.FUZZ_BOUND_SLACK:
        return f"measured h·L = {numbers['hL']:.3g} > {tol.FUZZ_HL_MAX:g}"
    if numbers["A_chi"] > tol.FUZZ_LINEAR_MAX * tol.FUZZ_BOUND_SLACK and numbers["chi"] > 0:
        return f"measured A·χ = {numbers['A_chi']:.3g} > {tol.FUZZ_LINEAR_MAX:g}"
    return ""


def _one_step_members(cases, y_ref):
    """(scenario, h, start state, case, rung) of every one-step member."""
    members = []
    n_fine = y_ref.shape[0] - 1
    starts = np.unique(np.round(np.linspace(0, n_fine - 1, ONE_STEP_STARTS)).astype(int))
    for i, c in enumerate(cases):
        for r in range(ONE_STEP_RUNGS):
            for k in starts:
                members.append((c.scenario, c.scenario.dt_s / 2 ** r, y_ref[k, i], i, r))
    return members


def measure(cases) -> tuple:
    """Contexts of the cases (None for a case skipped as unfair) and the one-step members' exact ends."""
    n0 = cases[0].n0
    scs = [c.scenario for c in cases]
    y_ref, ref_err = exact.reference([sc.problem for sc in scs], [sc.duration_s for sc in scs], 4 * n0)
    scales = [quantity_scales(y_ref[:, i]) for i in range(len(scs))]
    amp = exact.amplification(scs, scales)
    members = _one_step_members(cases, y_ref)
    y_end, flow_err = exact.step_flows([m[0].problem for m in members], [m[1] for m in members],
                                       np.array([m[2] for m in members]))
    contexts = []
    rows = _rung_rows(members, range(len(cases)))
    for i, c in enumerate(cases):
        amp_i = {q: float(amp[q][i]) for q in QUANTITIES}
        c.numbers = _numbers(c, y_ref[:, i], amp_i)
        why = _fair(c.numbers)
        if why:
            c.numbers["skipped"] = why
            contexts.append(None)
            continue
        step_h = np.array([c.scenario.dt_s / 2 ** r for r in range(ONE_STEP_RUNGS)])
        step_err = {q: np.array([float(np.max(flow_err[q][rr])) for rr in rows[i]]) for q in QUANTITIES}
        sc = c.scenario
        phys = ScenarioPhysics(motion_rates(sc.problem, y_ref[:, i]), separatrix_proximity(sc.problem), amp_i,
                               sc.duration_s)
        cons = M.conserved(sc.problem.forces)
        allowance = (flow.conservation_allowance(sc, y_ref[:, i], sc.dt_s, sc.duration_s)
                     if cons["energy"][0] or cons["angular_momentum"][0] else {})
        contexts.append(P.Context(sc, c.n0, y_ref[:, i], {q: float(ref_err[q][i]) for q in QUANTITIES}, amp_i,
                                  scales[i], phys, step_h, step_err, allowance,
                                  M.lever_arms(sc.problem, y_ref[:, i])))
    return contexts, members, y_end


@dataclass
class CaseOutcome:
    """What one case gave: its violations (records of :mod:`cross_checks.fuzz.properties`) and the
    count of properties checked per variant: {variant: {property: [checked, no_claim]}}."""

    index: int
    numbers: dict
    violations: list
    tally: dict
    not_expressible: dict = field(default_factory=dict)   # variant -> why its engine cannot run this case


def _add(tally, variant, t):
    into = tally.setdefault(variant, {p: [0, 0] for p in P.PROPERTIES})
    for k, (a, b) in t.items():
        into[k][0] += a
        into[k][1] += b


def _rung_rows(members, cases_idx) -> dict:
    """{case: [rows of its one-step members at rung r for r in 0..ONE_STEP_RUNGS-1]} over ``members``."""
    out = {i: [[] for _ in range(ONE_STEP_RUNGS)] for i in cases_idx}
    for j, m in enumerate(members):
        if m[3] in out:
            out[m[3]][m[4]].append(j)
    return {i: [np.array(r, dtype=int) for r in rr] for i, rr in out.items()}


def _defects(e, rows):
    """{quantity: (ONE_STEP_RUNGS,)} the largest one-step defect of a case at each rung, from the errors
    ``e`` ({quantity: (M,)}, every member of the variant's one-step run) and the case's rows per rung."""
    out = {}
    for q in QUANTITIES:
        v = []
        for r in rows:
            vals = e[q][r]
            v.append(float(np.max(vals)) if np.all(np.isfinite(vals)) else math.nan)
        out[q] = np.array(v)
    return out


def _refined_ladder_shows_the_order(ctx, variant: str, k: int, rec) -> bool:
    """Whether a free-running order that came out too low (or errors that shrink, but not at every halving)
    on (h, h/2, h/4) shows the claimed order when the ladder goes on to h/2^(2 + tol.REFINE_HALVINGS): the
    rungs h/4 … h/32 judged by :func:`cross_checks.analysis.refinement.refined_ladder_shows_the_order`."""
    from cross_checks.analysis.expectations import expectation
    sc, q = ctx.scenario, rec["quantity"]
    dts, errs, floors = list(rec["dt_s"]), list(rec["errors"]), list(rec["floors"])  # h, h/2, h/4
    first = 2 ** len(dts)   # the rung after the ladder's finest: h/8
    fine = drivers.run_ladder(variant, [sc], [dts[0] / first], ctx.n0 * first)[:tol.REFINE_HALVINGS]
    n_ref = len(ctx.y_ref) - 1
    for runs in fine:
        n = len(runs.y) - 1
        if runs.status[0] != "ok" or n % n_ref:
            return False
        e = state_errors(runs.y[:: n // n_ref, 0], ctx.y_ref)[q]
        h = float(runs.h_s[0])
        dts.append(h)
        errs.append(float(np.max(e)))
        floors.append(P.case_floor(ctx, variant, q, n, h, ctx.ref_err[q], ctx.amp[q]))
    # judged on the finest original rung and the refined ones (analysis.refinement)
    dts, errs, floors = dts[2:], errs[2:], floors[2:]
    exp = expectation(sc, variant, q, "free_running", physics=ctx.physics, measure_physics=False)
    shows, _ = refined_ladder_shows_the_order(dts, errs, floors, ["ok"] * len(dts), exp)
    return shows


def _too_low_free_running_order(rec) -> bool:
    """A free-running order violation whose errors do shrink from the coarsest rung to the finest, only
    slower than claimed or not at every halving (a plateau, a growth or a wrong motion does not qualify);
    three finite errors (h, h/2, h/4), as :func:`_refined_ladder_shows_the_order` needs."""
    if rec.get("property") != "free_running_order" or len(rec.get("errors") or []) != 3:
        return False
    return worth_refining(rec.get("verdict", ""), rec["errors"])


def _judge(ctx, variant, k, ladder, defects, tally, errors=None) -> list:
    """The violations of one variant on one case. rbcheck's own verdict code failing on a valid scenario is a
    finding too (``rbcheck sweep`` would stop with an internal error there): property "internal_error"."""
    found = []
    try:
        for recs, t in (P.free_running_order(ctx, variant, k, ladder, errors),
                        P.conservation(ctx, variant, k, ladder), P.one_step_order(ctx, variant, k, defects)):
            found += [r for r in recs if not (_too_low_free_running_order(r)
                                              and _refined_ladder_shows_the_order(ctx, variant, k, r))]
            _add(tally, variant, t)
    except (ArithmeticError, ValueError, LinAlgError) as exc:
        found.append({"property": "internal_error", "variants": [variant], "quantity": None,
                      "error": f"{type(exc).__name__}: {exc}",
                      "sentence": (f"{variant}: rbcheck's own verdict code failed on this "
                                   f"valid scenario ({type(exc).__name__}: {exc}); rbcheck "
                                   "sweep stops there with an internal error (exit 2)")})
    return found


def _invariance(ctx, variant, tally) -> list:
    """The invariance property of one variant on one case: the sweep's check of the case under its drawn
    transform (properties.case_transform), with the case's measured scales and amplification."""
    from cross_checks.sweep.invariance import check_invariance
    t = P.case_transform(ctx.scenario.name)
    (row,) = check_invariance(ctx.scenario, variant, [t], scales=ctx.scales, amplification=ctx.amp)
    recs, t_ = P.invariance(ctx, variant, row)
    _add(tally, variant, t_)
    return recs


def evaluate(cases, contexts, members, y_end, variants) -> tuple:
    """Run every variant on the judged cases and check the properties: ([CaseOutcome], {variant: seconds})."""
    judged = [i for i, ctx in enumerate(contexts) if ctx is not None]
    outcomes = {i: CaseOutcome(cases[i].index, cases[i].numbers, [], {}) for i in range(len(cases))}
    seconds = {}
    if not judged:
        return list(outcomes.values()), seconds
    scs = [cases[i].scenario for i in judged]
    h0s = [sc.dt_s for sc in scs]
    n0 = cases[0].n0
    m_sel = [j for j, m in enumerate(members) if contexts[m[3]] is not None]
    rows = _rung_rows([members[j] for j in m_sel], judged)
    y_refs = np.stack([contexts[i].y_ref for i in judged], axis=1)
    ladders = {}
    for v in variants:
        t0 = time.perf_counter()
        ladder = drivers.run_ladder(v, scs, h0s, n0)
        y1 = drivers.one_step(v, [members[j][0] for j in m_sel], [members[j][1] for j in m_sel],
                              np.array([members[j][2] for j in m_sel]))
        e = None if y1 is None else state_errors(y1, y_end[m_sel])
        e_ladder = P.ladder_errors(ladder, y_refs, slice(None))
        for k, i in enumerate(judged):
            if ladder[0].status[k] == drivers.NOT_EXPRESSIBLE:
                outcomes[i].not_expressible[v] = ladder[0].message[k]
                continue
            d = None if e is None else _defects(e, rows[i])
            e_case = [{q: er[q][:, k] for q in QUANTITIES} for er in e_ladder]
            outcomes[i].violations += _judge(contexts[i], v, k, ladder, d, outcomes[i].tally, e_case)
        ladders[v] = ladder
        for k, i in enumerate(judged):
            if ladder[0].status[k] != drivers.NOT_EXPRESSIBLE:
                outcomes[i].violations += _invariance(contexts[i], v, outcomes[i].tally)
        seconds[v] = time.perf_counter() - t0
    for pair in P.equivalent_pairs(variants):
        t0 = time.perf_counter()
        for k, i in enumerate(judged):
            recs, t = P.agreement(contexts[i], pair, k, ladders[pair[0]], ladders[pair[1]])
            outcomes[i].violations += recs
            _add(outcomes[i].tally, f"{pair[0]} = {pair[1]}", t)
        for v in pair[:2]:
            seconds[v] = seconds.get(v, 0.0) + 0.5 * (time.perf_counter() - t0)
    return list(outcomes.values()), seconds


def steps_of(spec: dict) -> int:
    """n0 of a scenario dict: steps at its coarsest rung (duration / dt)."""
    return int(round(spec["duration"] / spec["dt"]))


def evaluate_specs(specs, variants) -> list:
    """Judge scenario dicts as they are (their own dt, ladder [dt, dt/2, dt/4] and duration): one
    CaseOutcome each, in order; None for a dict that is not a valid scenario (its ScenarioError)."""
    from cross_checks.scenario import ScenarioError
    out = [None] * len(specs)
    groups: dict = {}
    for j, spec in enumerate(specs):
        try:
            sc = scenario_of(spec)
        except ScenarioError:
            continue
        n0 = steps_of(spec)
        groups.setdefault(n0, []).append((j, Case(None, spec, sc, n0, index=j)))
    for members in groups.values():
        cases = [c for _, c in members]
        contexts, one_step_members, y_end = measure(cases)
        outcomes, _ = evaluate(cases, contexts, one_step_members, y_end, variants)
        for (j, _), o in zip(members, outcomes):
            out[j] = o
    return out
