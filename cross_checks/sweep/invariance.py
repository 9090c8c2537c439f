"""The invariance checks of a sweep (``rbcheck sweep --invariance``, ``assert_engine(..., invariance=True)``;
docs/invariance.md): each variant runs each scenario and its transforms
(:mod:`cross_checks.scenario.transforms`) in one ``simulate_many`` call at the scenario's dt; each transformed
run, mapped back to the original's frames,
is judged against the variant's run of the original by :func:`cross_checks.analysis.judge.judge_invariance`.

Rows (invariance.csv, :data:`INVARIANCE_COLUMNS`): variant, scenario, transform, magnitude, the Δt and steps,
per quantity the largest deviation over the run and its allowance, the verdict and its sentence.
"""
from __future__ import annotations

import math

import numpy as np

from cross_checks.analysis.judge import invariance_allowance, judge_invariance
from cross_checks.core.quantities import COLUMN_STEM, QUANTITIES, quantity_scales
from cross_checks.scenario.transforms import TransformRefused, apply, default_transforms

__all__ = ["INVARIANCE_COLUMNS", "DECLARED", "check_invariance", "run_invariance", "invariance_summary",
           "broken_lines", "no_longer_broken_lines", "declared_summary", "step_order"]

INVARIANCE_COLUMNS = (["engine", "scenario", "transform", "magnitude", "dt", "steps", "verdict",
                       "worst_quantity", "worst_ratio"]
                      + [f"{COLUMN_STEM[q]}_dev" for q in QUANTITIES]
                      + [f"{COLUMN_STEM[q]}_allowance" for q in QUANTITIES]
                      + ["declared", "assessment"])

#: What the ``declared`` column says of a check the variant declares a finding for (engines.base.
#: InvarianceFinding): "known finding" (it breaks as declared: verdict ``known finding``), "not broken here"
#: (it does not break on this scenario), "beyond the declaration" (it breaks in a quantity the declaration
#: does not name: still ``broken``); "" where nothing is declared. A declaration that breaks on none of the
#: checks it covers is "no longer broken" (:func:`declared_summary`).
DECLARED = ("known finding", "not broken here", "beyond the declaration")


def _row(variant, scenario, transform, verdict, assessment, dt="", steps="", judgement=None) -> dict:
    row = {"engine": variant, "scenario": scenario.name, "transform": transform.kind,
           "magnitude": transform.magnitude, "dt": dt, "steps": steps, "verdict": verdict,
           "worst_quantity": "", "worst_ratio": math.nan, "declared": "",
           "assessment": " ".join(str(assessment).split())}   # an engine's multi-line message on one line
    for q in QUANTITIES:
        row[f"{COLUMN_STEM[q]}_dev"] = math.nan if judgement is None else judgement.deviation[q]
        row[f"{COLUMN_STEM[q]}_allowance"] = math.nan if judgement is None else judgement.allowance[q]
    if judgement is not None:
        w = judgement.worst
        row["worst_quantity"] = w
        a = judgement.allowance[w]
        row["worst_ratio"] = judgement.deviation[w] / a if a > 0 else math.inf
    return row


def check_invariance(scenario, variant, transforms=None, *, scales: dict | None = None,
                     amplification: dict | None = None) -> list:
    """The invariance rows of ``variant`` (a Resolved ENGINE:VARIANT) on ``scenario`` for ``transforms``
    (default: :func:`~cross_checks.scenario.transforms.default_transforms`). ``scales`` and
    ``amplification`` (per quantity, as the sweep measures them for its floors); measured here when not given
    (the scales from the variant's own run of the original, the amplification by
    references.error_amplification)."""
    from cross_checks.engines import EngineError, NotExpressible, run_requests
    from cross_checks.engines.base import RunRequest
    transforms = list(default_transforms() if transforms is None else transforms)
    dt, n = scenario.dt_s, scenario.n_steps()
    rows, todo = [], []
    for t in transforms:
        try:
            todo.append((t, apply(t, scenario)))
        except TransformRefused as exc:
            rows.append(_row(variant, scenario, t, "refused", f"refused: {exc.field}: {exc.reason}"))
    runs = run_requests(variant, [RunRequest(s, dt, n) for s in [scenario] + [s for _, s in todo]])
    original, transformed = runs[0], runs[1:]
    if isinstance(original, NotExpressible):
        return rows + [_row(variant, scenario, t, "cannot express",
                            f"cannot express the scenario: {original}")
                       for t, _ in todo]
    if isinstance(original, EngineError) or original.meta.get("status") != "ok":
        why = (original if isinstance(original, EngineError)
               else f"diverged at {original.meta['diverged_at_s']} s")
        return rows + [_row(variant, scenario, t, "not judged",
                            f"not judged: the run of the original failed ({why}); see results.csv")
                       for t, _ in todo]
    traits, precision = variant.traits, variant.precision
    if scales is None:
        scales = quantity_scales(original.y)
    if amplification is None:
        from cross_checks.scenario.references import error_amplification
        amplification = error_amplification(scenario, scales)
    refine, judged = [], []
    for (t, tsc), run in zip(todo, transformed):
        clamp = _clamped(traits, original, scenario, tsc)
        if clamp:
            rows.append(_row(variant, scenario, t, "cannot express", f"cannot express: {clamp}", dt, n))
            continue
        if isinstance(run, NotExpressible):
            rows.append(_row(variant, scenario, t, "cannot express", f"cannot express: {run}", dt, n))
            continue
        if isinstance(run, EngineError):
            rows.append(_row(variant, scenario, t, "broken",
                             f"broken: the original runs, the transformed scenario fails: {run}", dt, n))
            continue
        j = judge_invariance(original.y, t.map_back(run.y), scales=scales, amplification=amplification,
                             n_steps=n, precision=precision,
                             rounding_factor=getattr(traits, "rounding_factor", 1.0),
                             offset_m=t.position_offset_m(), dt_s=dt,
                             differenced=getattr(traits, "velocity_from_positions", False))
        rows.append(_row(variant, scenario, t, j.verdict, j.assessment, dt, n, j))
        judged.append((len(rows) - 1, t, j))
        if j.verdict == "broken" and all(math.isfinite(v) for v in j.deviation.values()):
            refine.append((len(rows) - 1, t, tsc, j))
    if refine:
        def allowance_at(t, n_steps, dt_s) -> dict:
            base, off = invariance_allowance(scales, amplification, n_steps, precision=precision,
                                             rounding_factor=getattr(traits, "rounding_factor", 1.0),
                                             offset_m=t.position_offset_m(), dt_s=dt_s,
                                             differenced=getattr(traits, "velocity_from_positions", False))
            return {q: base[q] + off[q] for q in base}
        _refine(rows, refine, scenario, variant, allowance_at)
    _declared(rows, judged, variant)
    return rows


def _declared(rows, judged, variant) -> None:
    """The variant's declared findings (engines.base.InvarianceFinding, read through
    analysis.expectations.invariance_finding) applied to its judged rows ``judged`` ((row index, transform,
    judgement)): a check that is still ``broken`` (after the refinement) in the declared quantities only
    becomes ``known finding``, its sentence the declaration's reason and the measured numbers; one broken
    beyond them stays broken, saying so; one that does not break is marked "not broken here" (a declaration
    broken nowhere is "no longer broken": :func:`declared_summary`). Every entry point (the sweep,
    assert_engine, the fuzz) goes through here: one judge."""
    from cross_checks.analysis.expectations import invariance_finding
    from cross_checks.core.quantities import QUANTITIES
    for i, t, j in judged:
        finding = invariance_finding(variant, t)
        if finding is None:
            continue
        row = rows[i]
        declared = (f"{variant} declares this finding (under {t.kind} at {finding.range_text()}, in "
                    f"{', '.join(q.replace('_', ' ') for q in finding.quantities)}): {finding.reason}")
        if row["verdict"] != "broken":
            row["declared"] = "not broken here"
            continue
        beyond = [q for q in QUANTITIES if not j.deviation[q] <= j.allowance[q]]
        outside = [q for q in beyond if q not in finding.quantities or not math.isfinite(j.deviation[q])]
        if outside:
            row["declared"] = "beyond the declaration"
            row["assessment"] += (f"; beyond its declared finding, which names "
                                  f"{', '.join(finding.quantities)} only, in {', '.join(outside)} "
                                  f"({declared})")
            continue
        row["verdict"] = row["declared"] = "known finding"
        measured = row["assessment"].removeprefix("broken: ")
        row["assessment"] = f"known finding (declared, not a failure): {declared}; measured here: {measured}"


def _refine(rows, refine, scenario, variant, allowance_at) -> None:
    """The broken rows ``refine`` ((row index, transform, transformed scenario, judgement)) run again at
    Δt/r for r in INVARIANCE_REFINEMENTS: where the deviation of the worst quantity shrinks at least at order
    INVARIANCE_STEP_MIN_ORDER each time Δt halves, the transformed and the original runs converge to the same
    motion and what parts them is the step's truncation error: the step is not covariant under that
    transform (a splitting along body axes under a turned body frame; a step that integrates the body
    origin, not the COM, under a COM offset). The row becomes ``step-dependent``, saying so with the
    numbers; a deviation that does not shrink stays ``broken`` (its sentence gains the numbers). A finer
    run's deviation within its own round-off allowance (``allowance_at(transform, steps, Δt)``: more steps,
    more round-off) has vanished as far as can be seen: that halving counts as converging."""
    from cross_checks.core import tolerances as tol
    from cross_checks.core.quantities import UNITS, state_errors
    from cross_checks.engines import EngineError, NotExpressible, run_requests
    from cross_checks.engines.base import RunRequest
    dt, T = scenario.dt_s, scenario.duration_s
    fine = [dt / r for r in tol.INVARIANCE_REFINEMENTS]
    reqs = []
    for h in fine:
        reqs.append(RunRequest(scenario, h, scenario.n_steps(h, T)))
        reqs += [RunRequest(tsc, h, scenario.n_steps(h, T)) for _, _, tsc, _ in refine]
    runs = run_requests(variant, reqs)
    width = 1 + len(refine)
    for k, (i, t, _, j) in enumerate(refine):
        q = j.worst
        devs, vanished = [j.deviation[q]], []
        for level in range(len(fine)):
            a, b = runs[level * width], runs[level * width + 1 + k]
            if any(isinstance(x, (EngineError, NotExpressible)) or x.meta.get("status") != "ok"
                   for x in (a, b)):
                devs = None
                break
            y0 = np.asarray(a.y, dtype=float)
            e = state_errors(t.map_back(b.y), y0)[q]
            devs.append(float(np.max(e[np.all(np.isfinite(y0), axis=-1)], initial=0.0)))
            n_fine = scenario.n_steps(fine[level], T)
            vanished.append(devs[-1] <= allowance_at(t, n_fine, fine[level])[q])
        if devs is None:
            continue
        ratios = [d0 / d1 if d1 > 0 else math.inf for d0, d1 in zip(devs, devs[1:])]
        steps = [a / b for a, b in zip([1.0] + list(tol.INVARIANCE_REFINEMENTS), tol.INVARIANCE_REFINEMENTS)]
        orders = [math.log(r) / math.log(1.0 / s) if r > 0 else -math.inf for r, s in zip(ratios, steps)]
        shown = ", ".join(f"{d:.3g}" for d in devs)
        at = ", ".join(["Δt"] + [f"Δt/{r:g}" for r in tol.INVARIANCE_REFINEMENTS])
        said = (f"largest deviation in {q.replace('_', ' ')} {shown} {UNITS[q]} at {at}: order "
                + ", ".join(f"{o:.2f}" + (" (then within round-off)" if v else "")
                            for o, v in zip(orders, vanished))
                + " as Δt shrinks")
        row = rows[i]
        need = step_order(scenario, variant, q)
        if all(v or o >= need for o, v in zip(orders, vanished)):
            row["verdict"] = "step-dependent"
            ratio = j.deviation[q] / j.allowance[q]
            row["assessment"] = (f"step-dependent (the scheme's own): {said}: the transformed run converges "
                                 "to the original's motion; the step is not covariant under this transform, "
                                 f"and what parts them is its truncation error ({ratio:.3g}× round-off at "
                                 "Δt), vanishing as Δt → 0")
        elif all(v or o >= tol.INVARIANCE_STEP_MIN_ORDER for o, v in zip(orders, vanished)):
            row["assessment"] = (f"{row['assessment']}; it vanishes as Δt shrinks ({said}), but slower than "
                                 f"the order {need + tol.SWEEP_ORDER_TOL:g} the variant's step has here: the "
                                 "transformed scenario is integrated at a lower order")
        else:
            row["assessment"] = f"{row['assessment']}; it does not vanish as Δt shrinks ({said})"


def step_order(scenario, variant, quantity) -> float:
    """The order each halving's deviation must shrink at to be the step's own truncation error: the order the
    expectations give the variant on this scenario and quantity (two runs of an order-p step differ by
    O(Δtᵖ)), read within SWEEP_ORDER_TOL; at least INVARIANCE_STEP_MIN_ORDER (a consistent scheme)."""
    from cross_checks.analysis.expectations import expectation
    from cross_checks.core import tolerances as tol
    try:
        e = expectation(scenario, variant, quantity, "free_running", measure_physics=False)
    except Exception:  # noqa: BLE001 - an engine file without expectations: a consistent scheme's order
        return tol.INVARIANCE_STEP_MIN_ORDER
    if e.verdict != "converges" or not e.order:
        return tol.INVARIANCE_STEP_MIN_ORDER
    return max(tol.INVARIANCE_STEP_MIN_ORDER, float(e.order) - tol.SWEEP_ORDER_TOL)


def _run_item(item) -> list:
    """``item`` = (scenario, variant, scales, amplification, user engines): :func:`check_invariance` in a
    worker (engine files registered there too); any error of the harness becomes rows saying so."""
    scenario, variant, scales, amplification, user_engines = item
    try:
        from cross_checks.engines import adopt_user_engines
        adopt_user_engines(user_engines)
        return check_invariance(scenario, variant, scales=scales, amplification=amplification)
    except Exception as exc:  # noqa: BLE001
        return _unjudged(scenario, variant, f"internal error while checking: {type(exc).__name__}: {exc}")


def _unjudged(scenario, variant, why: str) -> list:
    return [_row(variant, scenario, t, "not judged", f"not judged: {why}") for t in default_transforms()]


def run_invariance(runner, scenarios, variants, refs, leave_out=(), show_progress: bool = False) -> list:
    """Every invariance row of ``variants`` on ``scenarios`` (each with its reference result ``refs``: the
    scales and error amplification the sweep measured), on ``runner`` (cross_checks.sweep.execute.Runner:
    one item per (scenario, variant), longest first), except the pairs in ``leave_out``. A worker that dies
    leaves its pair's rows "not judged", saying so. Rows in scenario, then variant order."""
    from cross_checks.core.progress import Progress
    from cross_checks.engines import user_engines
    from cross_checks.sweep.plan import job_cost_s
    extra = user_engines()
    items = [(sc, v, ref.scales, (ref.measured or {}).get("amplification"), extra)
             for sc, ref in zip(scenarios, refs) for v in variants if (sc.name, v) not in leave_out]
    cost = {(it[0].name, it[1]): job_cost_s(it[0], it[1], it[0].dt_s) for it in items}
    order = {(it[0].name, it[1]): i for i, it in enumerate(items)}
    items.sort(key=lambda it: -cost[(it[0].name, it[1])])
    out: dict = {}
    with Progress("rbcheck sweep", "invariance checks", len(items), enabled=show_progress,
                  total_work=sum(cost.values())) as bar:
        def done(item, rows):
            out[(item[0].name, item[1])] = rows
            bar.update(1, f"{item[0].name} {item[1]}", work=cost[(item[0].name, item[1])])

        def crashed(item):
            return _unjudged(item[0], item[1], "the worker process died running the transforms (a crash "
                                               "inside the engine?)")

        runner.map_unordered(_run_item, items, done, on_crash=crashed, in_flight=lambda it: True)
    return [r for key in sorted(out, key=order.get) for r in out[key]]


def _clamped(traits, original, scenario, transformed) -> str:
    """"" unless the variant clamps the gyroscopic torque (Traits.gyroscopic_clamp_N_m) and the transformed
    body's exceeds the clamp where the original's does not: then the sentence saying so. The gyroscopic torque
    |ω_B × I ω_B| along the variant's own run of the original, in the transformed body's scale (every
    transform keeps ω; only a scale changes the inertia's size: by its largest moment's ratio)."""
    limit = getattr(traits, "gyroscopic_clamp_N_m", None)
    if limit is None:
        return ""
    import numpy as np

    from reference_sim.quaternion import quat_conj, rotate
    inertia = scenario.problem.body.inertia_B
    w_B = rotate(quat_conj(original.y[:, 6:10]), original.y[:, 10:13])
    torque = float(np.nanmax(np.linalg.norm(np.cross(w_B, w_B @ inertia.T), axis=-1)))
    ratio = (float(np.linalg.eigvalsh(transformed.problem.body.inertia_B)[-1])
             / float(np.linalg.eigvalsh(inertia)[-1]))
    if torque * ratio > limit >= torque:
        return (f"its step clamps the gyroscopic torque to {limit:g} N m (a declared trait); this body's "
                f"|ω × Iω| reaches {torque * ratio:.3g} N m here (the original's {torque:.3g}), beyond the "
                "clamp, so it moves otherwise by design")
    return ""


def invariance_summary(rows) -> tuple:
    """``(records, counts)``: summary.json's ``invariance`` (one record per check that does not hold,
    schema.INVARIANCE_RECORD) and ``run.invariance`` (the number of checks and of each verdict)."""
    from cross_checks.analysis.judge import INVARIANCE_VERDICTS
    keep = ("engine", "scenario", "transform", "magnitude", "verdict", "worst_quantity", "assessment")
    records = []
    for r in rows:
        if r["verdict"] != "holds":
            rec = {k: r[k] for k in keep}
            if r.get("declared"):
                rec["declared"] = r["declared"]
            ratio = r["worst_ratio"]
            rec["worst_ratio"] = float(ratio) if isinstance(ratio, float) and math.isfinite(ratio) else None
            records.append(rec)
    counts = {"checks": len(rows), **{v: sum(r["verdict"] == v for r in rows) for v in INVARIANCE_VERDICTS},
              "no longer broken": sum(d["verdict"] == "no longer broken" for d in declared_summary(rows))}
    return records, counts


def declared_summary(rows) -> list:
    """summary.json's ``invariance_declared``: per variant and transform kind it declares a finding for (the
    rows whose ``declared`` is set), the checks the declaration covers, how many are known findings and how
    many broke beyond it, and the verdict: "known finding" (it broke as declared somewhere), "broken" (only
    beyond it) or "no longer broken" (it broke on none of them: the declaration can go)."""
    groups: dict = {}
    for r in rows:
        if r.get("declared"):
            groups.setdefault((r["engine"], r["transform"]), []).append(r["declared"])
    out = []
    for (engine, kind), said in groups.items():
        known, beyond = said.count("known finding"), said.count("beyond the declaration")
        out.append({"engine": engine, "transform": kind, "checks": len(said), "known_findings": known,
                    "beyond": beyond, "verdict": ("known finding" if known else "broken" if beyond
                                                  else "no longer broken")})
    return out


def broken_lines(summary) -> list:
    """One line per broken invariance of a summary (what makes the sweep exit 1)."""
    return [f"{r['engine']} on {r['scenario']}: invariance under {r['transform']} {r['magnitude']} "
            f"{r['assessment']}"
            for r in summary.get("invariance") or [] if r["verdict"] == "broken"]


def no_longer_broken_lines(summary) -> list:
    """One line per declared finding that broke on none of the checks it covers (said, never a failure: the
    declaration in the variant's traits or engine file can go)."""
    return [f"{d['engine']}: its declared invariance finding under {d['transform']} broke on none of the "
            f"{d['checks']} check(s) it covers here: no longer broken (the declaration can go)"
            for d in summary.get("invariance_declared") or [] if d["verdict"] == "no longer broken"]
