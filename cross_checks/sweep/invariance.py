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

from cross_checks.analysis.judge import judge_invariance
from cross_checks.core.quantities import COLUMN_STEM, QUANTITIES, quantity_scales
from cross_checks.scenario.transforms import TransformRefused, apply, default_transforms

__all__ = ["INVARIANCE_COLUMNS", "check_invariance", "invariance_summary", "broken_lines"]

INVARIANCE_COLUMNS = (["engine", "scenario", "transform", "magnitude", "dt", "steps", "verdict",
                       "worst_quantity", "worst_ratio"]
                      + [f"{COLUMN_STEM[q]}_dev" for q in QUANTITIES]
                      + [f"{COLUMN_STEM[q]}_allowance" for q in QUANTITIES]
                      + ["assessment"])


def _row(variant, scenario, transform, verdict, assessment, dt="", steps="", judgement=None) -> dict:
    row = {"engine": variant, "scenario": scenario.name, "transform": transform.kind,
           "magnitude": transform.magnitude, "dt": dt, "steps": steps, "verdict": verdict,
           "worst_quantity": "", "worst_ratio": math.nan,
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


def check_invariance(scenario, variant: str, transforms=None, *, scales: dict | None = None,
                     amplification: dict | None = None) -> list:
    """The invariance rows of ``variant`` on ``scenario`` for ``transforms`` (default:
    :func:`~cross_checks.scenario.transforms.default_transforms`). ``scales`` and ``amplification`` (per
    quantity, as the sweep measures them for its floors); measured here when not given (the scales from the
    variant's own run of the original, the amplification by references.error_amplification)."""
    from cross_checks.engines import EngineError, NotExpressible, declared_traits, run_requests
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
    traits = declared_traits(variant)
    precision = getattr(traits, "precision", "float64")
    if scales is None:
        scales = quantity_scales(original.y)
    if amplification is None:
        from cross_checks.scenario.references import error_amplification
        amplification = error_amplification(scenario, scales)
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
    return rows


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
            ratio = r["worst_ratio"]
            rec["worst_ratio"] = float(ratio) if isinstance(ratio, float) and math.isfinite(ratio) else None
            records.append(rec)
    counts = {"checks": len(rows), **{v: sum(r["verdict"] == v for r in rows) for v in INVARIANCE_VERDICTS}}
    return records, counts


def broken_lines(summary) -> list:
    """One line per broken invariance of a summary (what makes the sweep exit 1)."""
    return [f"{r['engine']} on {r['scenario']}: invariance under {r['transform']} {r['magnitude']} "
            f"{r['assessment']}"
            for r in summary.get("invariance") or [] if r["verdict"] == "broken"]
