"""Which engine variant is most accurate at a common cost, and which is cheapest at a common accuracy,
derived from the sweep's measured work-precision data only (results.csv: final errors, steps, wall
times; summary.json: scales, what moves, verdicts). The definitions (a run's error and cost, the
work-precision curve read between measured points only, the common cost and accuracy, the scores per
scenario family, the rule for variants whose verdicts contradict their expectations): docs/results.md,
"The ranking".
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from reports.findings import fmt
from reports.glance import relative_error

__all__ = ["Point", "Curve", "SCENARIO_FAMILIES", "scenario_family", "curves", "common_level", "at_cost",
           "cost_at", "ranking", "Ranking", "ordinal"]

#: Scenario families, from what moves along the reference (summary.json ``scenarios[].varies``).
SCENARIO_FAMILIES = ("translation only", "rotation only", "translation and rotation")
#: A variant is ranked in a family when its verdicts are as expected on at least this share of the family's
#: scenarios that it ran (where its curve does not reach a common level, the nearest measured value, a bound,
#: stands in: never a blank).
MIN_COVERAGE = 0.5
#: The long runs' drifts the "which engine?" answer names the best keepers of (summary.json ``long_runs``).
LONG_RUN_QUANTITIES = (("energy_drift_max", "energy", "largest relative energy drift"),
                       ("momentum_drift_max", "|L|", "largest relative |L| drift"),
                       ("direction_drift_max_rad", "the spin axis", "largest turn of L, rad"))


def scenario_family(s) -> str:
    """The family of a scenario: what moves along its reference (position, orientation or both)."""
    v = s.get("varies") or {}
    moves_x = v.get("position", True) or v.get("velocity", True)
    turns = v.get("orientation", True) or v.get("angular_velocity", True)
    if moves_x and not turns:
        return SCENARIO_FAMILIES[0]
    if turns and not moves_x:
        return SCENARIO_FAMILIES[1]
    return SCENARIO_FAMILIES[2]


@dataclass(frozen=True)
class Point:
    dt: float
    cost: float          # s: the run's steps × the variant's median cost per step
    error: float         # the largest final error relative to the scenario's scales


@dataclass
class Curve:
    """One variant's measured work-precision curve on one scenario (points ordered by cost)."""
    variant: str
    scenario: str
    cost_per_step: float
    points: list = field(default_factory=list)

    @property
    def cost_range(self):
        return self.points[0].cost, self.points[-1].cost

    @property
    def error_range(self):
        es = [p.error for p in self.points]
        return min(es), max(es)


def _log(x):
    return math.log10(max(x, 1e-300))


def run_cost_s(row) -> float:
    """A run's cost: the seconds inside the engine's own steps (``engine_s``) where the engine's loop is
    rbcheck's and so measured apart, else the whole run's wall time (an adapter that owns its loop)."""
    e = row.get("engine_s", math.nan)
    return e if isinstance(e, float) and math.isfinite(e) and e > 0 else row["wall_s"]


def overhead_per_step_s(res, v) -> float:
    """rbcheck's own seconds per step beside the engine's for variant ``v`` (the median over its runs whose
    engine time is measured), NaN where none is."""
    per = sorted((r["wall_s"] - r["engine_s"]) / r["steps"] for r in res.rows
                 if r["engine"] == v and r["steps"] > 0 and not r.get("cached")
                 and math.isfinite(r.get("engine_s", math.nan)) and math.isfinite(r["wall_s"]))
    return per[len(per) // 2] if per else math.nan


def curves(res, sc) -> dict:
    """``{variant: Curve}`` of a scenario, from its ladder runs that finished with a finite error and a
    measured cost (:func:`run_cost_s`; a variant without two such runs has no curve)."""
    s = res.scenario(sc)
    out = {}
    for v in res.variants:
        rows = [r for r in res.rows_for(sc, v) if r["in_ladder"] and r["status"] == "ok"
                and r["steps"] > 0 and math.isfinite(run_cost_s(r)) and run_cost_s(r) > 0]
        per_step = sorted(run_cost_s(r) / r["steps"] for r in rows)
        pts = []
        if per_step:
            n = len(per_step)
            c = per_step[n // 2] if n % 2 else math.sqrt(per_step[n // 2 - 1] * per_step[n // 2])
            for r in rows:
                e = relative_error(res, s, r)
                if math.isfinite(e):
                    pts.append(Point(r["dt"], c * r["steps"], max(e, 1e-300)))
        if len(pts) >= 2:
            out[v] = Curve(v, sc, c, sorted(pts, key=lambda p: (p.cost, -p.dt)))
    return out


def common_level(ranges) -> float | None:
    """The value (one of the ranges' ends) inside the most of the ``ranges`` [(lo, hi)]; a tie goes to the
    one nearest the median of the ends on a log scale. None without ranges."""
    ends = sorted({x for r in ranges for x in r})
    if not ends:
        return None
    med = sorted(_log(x) for r in ranges for x in r)
    mid = med[len(med) // 2]
    return max(ends, key=lambda x: (sum(lo <= x <= hi for lo, hi in ranges), -abs(_log(x) - mid)))


@dataclass(frozen=True)
class Value:
    """A variant's reading of its curve: ``value`` (None when not reachable), ``bound`` ("≤" when the
    value is a bound, "" when interpolated), ``why`` (words when not reachable or bounded)."""
    value: float | None
    bound: str = ""
    why: str = ""

    def text(self, unit="") -> str:
        if self.value is None:
            return "–"
        return f"{self.bound}{fmt(self.value, unit)}"


#: An error of 0 (an exact run) is drawn at 1e-300 on the log axes: no slope is read from such a point.
_ZERO = 1e-290


def _along(y0: float, ratio: float, slope: float) -> float:
    """``y0 · ratio^slope`` in log space, kept within floats (an exact scheme's error of 0 is drawn at 1e-300:
    a slope from it can be hundreds)."""
    return 10 ** min(300.0, max(-300.0, _log(y0) + slope * _log(ratio)))


def _slope(a: Point, b: Point) -> float:
    """d log(error) / d log(cost) between two measured points (0 where the costs are equal)."""
    if b.cost == a.cost:
        return 0.0
    return (_log(b.error) - _log(a.error)) / (_log(b.cost) - _log(a.cost))


def _interp(x, x0, x1, y0, y1):
    if x1 == x0:
        return min(y0, y1)
    f = (_log(x) - _log(x0)) / (_log(x1) - _log(x0))
    return 10 ** (_log(y0) + f * (_log(y1) - _log(y0)))


def at_cost(curve: Curve, cost: float) -> Value:
    """The curve's error at ``cost`` (log-log interpolation between the measured points)."""
    pts = curve.points
    lo, hi = curve.cost_range
    if cost < lo * (1 - 1e-12):
        # cheaper than its cheapest run: along its measured convergence (error ∝ cost^slope from its two
        # cheapest runs) when its error falls with cost there, else no less than its cheapest run's error
        slope = _slope(pts[0], pts[1]) if len(pts) > 1 and min(pts[0].error, pts[1].error) > _ZERO else 0.0
        if slope < 0:
            return Value(_along(pts[0].error, cost / pts[0].cost, slope), "≈",
                         f"its cheapest run costs ×{fmt(lo / cost)} the common cost: extrapolated along its "
                         f"measured slope ({slope:.2g}) from there")
        return Value(pts[0].error, "≥", f"its cheapest run costs ×{fmt(lo / cost)} the common cost: its "
                                        "error there, a lower bound")
    if cost >= hi:
        return Value(pts[-1].error, "≤" if cost > hi * (1 + 1e-12) else "",
                     "its costliest run is cheaper: its finest measured error" if cost > hi else "")
    for a, b in zip(pts, pts[1:]):
        if a.cost <= cost <= b.cost:
            return Value(_interp(cost, a.cost, b.cost, a.error, b.error))
    return Value(pts[-1].error)


def cost_at(curve: Curve, error: float) -> Value:
    """The cost at which the curve first comes down to ``error``."""
    pts = curve.points
    if pts[0].error <= error:
        return Value(pts[0].cost, "≤" if pts[0].error < error else "",
                     "its cheapest run is already this accurate" if pts[0].error < error else "")
    for a, b in zip(pts, pts[1:]):
        if b.error <= error:
            if a.error == b.error:
                return Value(b.cost)
            f = (_log(error) - _log(a.error)) / (_log(b.error) - _log(a.error))
            return Value(10 ** (_log(a.cost) + f * (_log(b.cost) - _log(a.cost))))
    # not reached: along its measured convergence from its two finest runs when its error still falls with
    # cost there, else at least its costliest run's cost
    slope = _slope(pts[-2], pts[-1]) if len(pts) > 1 and min(pts[-2].error, pts[-1].error) > _ZERO else 0.0
    if slope < 0 and pts[-1].error > error:
        return Value(_along(pts[-1].cost, error / pts[-1].error, 1.0 / slope), "≈",
                     f"beyond its finest run ({fmt(pts[-1].error)}): extrapolated along its measured slope "
                     f"({slope:.2g}) from there")
    return Value(max(p.cost for p in pts), "≥",
                 f"not reached: its smallest error is {fmt(min(p.error for p in pts))}; its costliest run's "
                 "cost, a lower bound")


@dataclass
class ScenarioRanking:
    scenario: str
    family: str
    common_cost: float | None
    common_error: float | None
    n_cost: int            # variants whose measured cost range holds the common cost
    n_error: int
    accuracy: dict         # variant -> Value (error at the common cost)
    cost: dict             # variant -> Value (cost at the common accuracy)
    per_step: dict         # variant -> cost per step (s)

    def ratios(self, what: str) -> dict:
        """``{variant: value / the best value}`` (≥ 1) of ``accuracy`` or ``cost``, reachable ones only."""
        vals = {v: x.value for v, x in getattr(self, what).items() if x.value is not None}
        if not vals:
            return {}
        best = min(vals.values())
        return {v: (x / best if best > 0 else (1.0 if x == 0 else math.inf)) for v, x in vals.items()}


def rank_scenario(res, sc, variants=None) -> ScenarioRanking:
    cs = curves(res, sc)
    if variants is not None:
        cs = {v: c for v, c in cs.items() if v in variants}
    c_star = common_level([c.cost_range for c in cs.values()])
    e_star = common_level([c.error_range for c in cs.values()])
    return ScenarioRanking(
        sc, scenario_family(res.scenario(sc)), c_star, e_star,
        sum(c.cost_range[0] <= c_star <= c.cost_range[1] for c in cs.values()) if c_star else 0,
        sum(c.error_range[0] <= e_star <= c.error_range[1] for c in cs.values()) if e_star else 0,
        {v: at_cost(c, c_star) for v, c in cs.items()} if c_star else {},
        {v: cost_at(c, e_star) for v, c in cs.items()} if e_star else {},
        {v: c.cost_per_step for v, c in cs.items()})


@dataclass
class Standing:
    """One variant in one scenario family (or overall)."""
    variant: str
    acc_score: float | None      # geometric mean of error-at-common-cost / best
    acc_n: int                   # scenarios with a value
    cost_score: float | None     # geometric mean of cost-at-common-accuracy / cheapest
    cost_n: int
    n_scenarios: int             # scenarios of the family the variant ran
    acc_rank: int | None = None
    cost_rank: int | None = None
    per_step_us: float | None = None   # median cost per step over the family's scenarios (µs)
    overhead_us: float | None = None   # rbcheck's own time per step beside the engine's (µs; None: not split)
    verdicts: dict = field(default_factory=dict)   # as_expected, contradicts, noconv, pre, exact
    contradicts_on: list = field(default_factory=list)
    failed: int = 0
    diverged: int = 0
    energy: str = ""             # conservation at the default Δt, in words
    energy_sort: float | None = None


def _gmean(xs):
    xs = [x for x in xs if x is not None and math.isfinite(x) and x > 0]
    return math.exp(sum(math.log(x) for x in xs) / len(xs)) if xs else None


def _rank(standings, score, n, ranked_attr, tie):
    """Rank by ``score`` (a tie — schemes equally exact — goes to the better ``tie`` score, then the name)
    every variant with a value whose verdicts are as expected on at least MIN_COVERAGE of its scenarios."""
    order = sorted((s for s in standings if getattr(s, score) is not None and getattr(s, n) >= 1
                    and s.n_scenarios - len(s.contradicts_on) >= MIN_COVERAGE * s.n_scenarios),
                   key=lambda s: (round(math.log10(getattr(s, score)), 6),
                                  getattr(s, tie) if getattr(s, tie) is not None else math.inf, s.variant))
    for i, s in enumerate(order, start=1):
        setattr(s, ranked_attr, i)


_KIND_ORDER = {"secular": 3, "bounded": 2, "roundoff": 1}


def _standing(res, v, scs, per_sc) -> Standing:
    acc = [per_sc[sc].ratios("accuracy").get(v) for sc in scs]
    cost = [per_sc[sc].ratios("cost").get(v) for sc in scs]
    ran = [sc for sc in scs if res.rows_for(sc, v)]
    st = Standing(v, _gmean(acc), sum(a is not None for a in acc), _gmean(cost),
                  sum(c is not None for c in cost), len(ran))
    steps = [per_sc[sc].per_step[v] for sc in scs if v in per_sc[sc].per_step]
    st.per_step_us = sorted(steps)[len(steps) // 2] * 1e6 if steps else None
    over = overhead_per_step_s(res, v)
    st.overhead_us = over * 1e6 if math.isfinite(over) else None
    counts = {"as_expected": 0, "contradicts": 0, "noconv": 0, "pre": 0}
    bad_on = []
    for sc in scs:
        for r in res.records(sc, v):
            if r["matches_expectation"] is False:
                counts["contradicts"] += 1
                bad_on.append(sc)
            elif r["verdict"] == "pre_asymptotic":
                counts["pre"] += 1
            elif r["expected_verdict"] == "does_not_converge":
                counts["noconv"] += 1
            elif r["matches_expectation"]:
                counts["as_expected"] += 1
        rows = res.rows_for(sc, v)
        st.failed += sum(r["status"] == "failed" for r in rows)
        st.diverged += sum(r["status"] == "diverged" for r in rows)
    st.verdicts = counts
    st.contradicts_on = list(dict.fromkeys(bad_on))
    drifts, kinds = [], []
    for sc in scs:
        s = res.scenario(sc)
        d = res.default_row(sc, v)
        if d is None or d["status"] != "ok" or not s["conserved"]["energy"]["conserved"]:
            continue
        if math.isfinite(d["energy_drift_max"]):
            drifts.append(abs(d["energy_drift_max"]))
            kinds.append(d["energy_drift_kind"])
    if drifts:
        med = sorted(drifts)[len(drifts) // 2]
        sec = sum(k == "secular" for k in kinds)
        st.energy = f"median {fmt(med)}" + (f", secular on {sec} of {len(kinds)}" if sec else "")
        st.energy_sort = med
    return st


@dataclass
class Ranking:
    scenarios: dict          # scenario -> ScenarioRanking
    groups: dict             # "overall" / family -> {"scenarios": [...], "standings": [Standing]}

    def best(self, group, what):
        """(the first-ranked variant, the first-ranked one whose verdicts are all as expected) of ``what``
        ("acc" or "cost") in ``group``; either None."""
        ranked = sorted((s for s in self.groups[group]["standings"] if getattr(s, f"{what}_rank")),
                        key=lambda s: getattr(s, f"{what}_rank"))
        first = ranked[0] if ranked else None
        clean = next((s for s in ranked if not s.contradicts_on and not s.failed), None)
        return first, clean


def ranking(res, variants=None) -> Ranking:
    """The ranking of ``variants`` (default: every variant of the sweep), its common levels chosen among
    their own curves."""
    per_sc = {s["name"]: rank_scenario(res, s["name"], variants) for s in res.scenarios}
    groups = {}
    fams = {"overall": list(per_sc)}
    for f in SCENARIO_FAMILIES:
        scs = [sc for sc, r in per_sc.items() if r.family == f]
        if scs:
            fams[f] = scs
    for g, scs in fams.items():
        standings = [_standing(res, v, scs, per_sc) for v in (res.variants if variants is None else variants)]
        standings = [s for s in standings if s.n_scenarios]
        _rank(standings, "acc_score", "acc_n", "acc_rank", "cost_score")
        _rank(standings, "cost_score", "cost_n", "cost_rank", "acc_score")
        groups[g] = {"scenarios": scs, "standings": standings}
    return Ranking(per_sc, groups)


# --- words ---------------------------------------------------------------------------------------------

def ratio_text(x) -> str:
    """A ratio to the best as the pages show it: "×1.3", "×49", "×160", "×1.6e5"."""
    if x is None or not math.isfinite(x):
        return "–"
    if x < 9.95:
        return f"×{x:.2g}"
    if x < 1e4:
        return f"×{x:.0f}" if x < 100 else f"×{float(f'{x:.2g}'):.0f}"
    m, e = f"{x:.1e}".split("e")
    return f"×{m}e{int(e)}"


def ordinal(n: int) -> str:
    """``1st``, ``2nd``, ``3rd``, ``4th``, ``11th``, ``21st``."""
    suffix = "th" if 10 <= n % 100 <= 20 else {1: "st", 2: "nd", 3: "rd"}.get(n % 10, "th")
    return f"{n}{suffix}"


def best_sentences(rk: Ranking, group: str) -> list:
    """Two lines for a first screen: the most accurate at a common cost and the cheapest at a common
    accuracy in ``group``, with the runners-up; a first-ranked variant with a contradicted verdict is
    named with that said."""
    out = []
    for what, label, unit in (("acc", "Most accurate at a common cost", "the best one's error"),
                              ("cost", "Cheapest at a common accuracy", "the cheapest one's cost")):
        st = rk.groups[group]["standings"]
        ranked = sorted((s for s in st if getattr(s, f"{what}_rank")),
                        key=lambda s: getattr(s, f"{what}_rank"))
        if not ranked:
            continue
        names = []
        for s in ranked[:3]:
            score = getattr(s, f"{what}_score")
            flag = (f" — but its verdicts contradict the expectations on {', '.join(s.contradicts_on[:3])}"
                    if s.contradicts_on else "")
            names.append(f"{s.variant} ({ratio_text(score)}){flag}")
        first, clean = rk.best(group, what)
        tail = ""
        if first is not None and first is not clean:
            tail = (f"; the first with every verdict as expected: {clean.variant}" if clean is not None
                    else "; none of those ranked has every verdict as expected")
        out.append((label, "; ".join(names) + tail,
                    f"×N: N times {unit} (the geometric mean over the scenarios of the ratio)"))
    return out


def _where(groups, rk) -> str:
    fams = [g for g in groups if g != "overall"]
    if "overall" in groups and len(fams) == len(rk.groups) - 1:
        return "overall and on every scenario family"
    where = ("overall" if "overall" in groups else "") + (" and " if "overall" in groups and fams else "")
    return where + ("on " + " and ".join(f"{f} scenarios" for f in fams) if fams else "")


def engine_sentence(rk: Ranking, v: str) -> str:
    """One sentence per variant: where it ranks first (or its overall places), its verdicts, energy."""
    parts = []
    firsts = {"acc": [], "cost": []}
    for g, grp in rk.groups.items():
        for s in grp["standings"]:
            if s.variant != v:
                continue
            for what in firsts:
                if getattr(s, f"{what}_rank") == 1:
                    firsts[what].append(g)
    overall = next((s for s in rk.groups["overall"]["standings"] if s.variant == v), None)
    for what, where, best, unranked in (
            ("acc", "accuracy at a common cost", "the best error", "its cheapest run costs more"),
            ("cost", "cost at a common accuracy", "the cheapest's cost", "no run is that accurate")):
        n = sum(1 for s in rk.groups["overall"]["standings"] if getattr(s, f"{what}_rank"))
        if firsts[what]:
            first = "most accurate" if what == "acc" else "cheapest"
            parts.append(f"{first} at {where.split(' at ')[1]} " + _where(firsts[what], rk))
        elif overall and getattr(overall, f"{what}_rank"):
            parts.append(f"{ordinal(getattr(overall, f'{what}_rank'))} of {n} ranked in {where} "
                         f"({ratio_text(getattr(overall, f'{what}_score'))} {best})")
        elif overall:
            parts.append(f"not ranked in {where} (a value on {getattr(overall, f'{what}_n')} of its "
                         f"{overall.n_scenarios} scenarios: elsewhere {unranked}, or it has no "
                         "work-precision curve)")
    if overall is not None:
        c = overall.verdicts
        if overall.contradicts_on:
            parts.append(f"CONTRADICTS its expectations on {', '.join(overall.contradicts_on)}")
        elif overall.failed:
            parts.append(f"{overall.failed} failed run(s)")
        else:
            extra = []
            if c["noconv"]:
                extra.append(f"{c['noconv']} expected non-convergence(s)")
            if c["pre"]:
                extra.append(f"{c['pre']} pre-asymptotic")
            parts.append("every verdict as expected" + (f" ({', '.join(extra)})" if extra else ""))
        if overall.energy:
            parts.append(f"energy drift {overall.energy}")
    return f"{v}: " + "; ".join(parts) + "."


def family_lines(rk: Ranking) -> list:
    """One short line per scenario family: its most accurate and cheapest variants (flagged when
    contradicted)."""
    out = []
    for g, grp in rk.groups.items():
        if g == "overall":
            continue
        names = []
        for what, label in (("acc", "most accurate"), ("cost", "cheapest")):
            first, clean = rk.best(g, what)
            if first is None:
                continue
            text = f"{label} {first.variant}"
            if first.contradicts_on:
                text += " (its verdicts contradict the expectations" + \
                    (f"; first as expected: {clean.variant})" if clean else ")")
            names.append(text)
        if names:
            out.append((f"{g.capitalize()} ({len(grp['scenarios'])})", ", ".join(names)))
    return out


# --- "which engine?": engines only, apart from the reference's schemes ---------------------------------

def is_engine(variant: str) -> bool:
    """An engine's variant (not one of the reference's schemes, which are rbcheck's own)."""
    return not variant.startswith("reference:")


def long_run_keepers(res, variants) -> list:
    """``(label, sentence)`` per quantity of LONG_RUN_QUANTITIES: the variants (of ``variants``) that keep it
    best over the long runs, by the geometric mean over the long runs of its largest drift (a run that
    diverged or failed puts a variant last), the best three named with their numbers."""
    recs = [r for r in res.summary.get("long_runs") or [] if r["engine"] in variants]
    names = [s["name"] for s in res.summary.get("long_run_scenarios") or []]
    out = []
    for key, what, unit in LONG_RUN_QUANTITIES:
        scores = {}
        for v in variants:
            mine = [r for r in recs if r["engine"] == v and r["scenario"] in names]
            if not mine:
                continue
            vals = [float(r[key]) if r.get("status") == "ok" and isinstance(r.get(key), (int, float))
                    and math.isfinite(r[key]) else math.inf for r in mine]
            if any(math.isinf(x) for x in vals):
                scores[v] = (math.inf, len(mine))
            else:
                scores[v] = (math.exp(sum(math.log(max(x, 1e-300)) for x in vals) / len(vals)), len(mine))
        if not scores:
            continue
        best = sorted(scores, key=lambda v: (scores[v][0], v))[:3]
        words = {v: "diverged on a long run" if math.isinf(scores[v][0]) else fmt(scores[v][0]) for v in best}
        text = "; ".join(f"{v} ({words[v]})" for v in best)
        caveat = ("; a step without the gyroscopic term keeps E and |L| too, ω fixed in body axes: read "
                  "these with the spin axis" if key != "direction_drift_max_rad" else "")
        out.append((f"Keeps {what} best over the long runs", f"{text} ({unit}, geometric mean over "
                    f"{max(n for _, n in scores.values())} long runs{caveat})"))
    return out


def engine_answer(res) -> dict:
    """The answer to "which engine?": among the engines' variants only, overall and per scenario family, the
    most accurate at a common cost and the cheapest at a common accuracy (their own common levels), and the
    best keepers of energy, |L| and the spin axis over the long runs. Empty lists without an engine."""
    engines_ = [v for v in res.variants if is_engine(v)]
    if not engines_:
        return {"overall": [], "families": [], "long": [], "ranking": None}
    rk = ranking(res, engines_)
    fams = [(g, [(label, text) for label, text, _ in best_sentences(rk, g)]) for g in rk.groups
            if g != "overall"]
    return {"overall": [(label, text) for label, text, _ in best_sentences(rk, "overall")],
            "families": fams, "long": long_run_keepers(res, engines_), "ranking": rk}
