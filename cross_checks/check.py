"""``rbcheck check TRAJ.csv --scenario SCENARIO``: score a trajectory from any simulator.

The trajectory (DESIGN.md CSV, e.g. a student's own implementation of the course exported row by
row) is compared with

1. the scenario's reference (analytic or DOP853): errors of position, velocity, orientation and
   angular velocity, final and max over time;
2. the course-type reference variants run at the trajectory's own Δt (inferred from its times):
   ``reference:course`` (the course's step), ``reference:course_gyro`` (plus the gyroscopic term) and
   ``reference:expmap_gyro`` (= MuJoCo Euler) — the largest difference over time of each.

Verdict (exit code 0 for the first three, 1 otherwise):

* ``is reference:course`` — it reproduces the course's step to CHECK_SAME_SCHEME_REL (relative to
  max(1, |state|)): it IS the course scheme. (When the course scheme itself cannot converge on the
  scenario — no gyroscopic term — a note says so; that is the course's property, not the student's.)
* ``is reference:course_gyro`` / ``is reference:expmap_gyro`` — likewise for those schemes.
* ``agrees with the reference`` — every quantity's max error is within CHECK_BUDGET_FACTOR times that
  of reference:expmap_gyro at the same Δt (a correct first-order scheme): a correct simulator of this
  physics at this step size.
* ``disagrees`` — none of the above; the largest violations are named, with the nearest variant.
* ``does not start at the initial state`` / ``diverged`` — the first row is not the scenario's
  initial state, or the trajectory contains non-finite values.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import metrics as M
from . import tolerances as tol
from .expectations import QUANTITIES, expectation

__all__ = ["CheckError", "CheckResult", "check_trajectory", "COMPARED_VARIANTS", "format_report"]

#: Reference variants a trajectory is compared with, step for step.
COMPARED_VARIANTS = ("reference:course", "reference:course_gyro", "reference:expmap_gyro")
#: The correct first-order scheme whose error sets the "agrees" budget.
BUDGET_VARIANT = "reference:expmap_gyro"


class CheckError(ValueError):
    """A trajectory that cannot be checked against the scenario (message: file, field, reason)."""


@dataclass
class CheckResult:
    scenario: str
    reference_label: str
    n_rows: int
    t_end_s: float
    dt_s: float | None
    uniform: bool
    errors: dict                       # quantity -> {"final", "max"} against the reference
    budget: dict                       # quantity -> allowed max error ("agrees" verdict)
    variant_diffs: dict                # variant -> {"max_rel": float, quantity: max abs diff}
    verdict: str
    passed: bool
    notes: list = field(default_factory=list)


def _rel_diff(y, y_other, scales):
    d = M.state_errors(y, y_other)
    out = {q: float(np.max(d[q])) for q in QUANTITIES}
    out["max_rel"] = max(out[q] / scales[q] for q in QUANTITIES)
    return out


def _snap_dt(dt, scenario):
    for cand in (scenario.dt_s, *scenario.dt_ladder_s):
        if abs(dt - cand) <= 1e-6 * cand:
            return cand
    return dt


def check_trajectory(traj, scenario, source: str = "TRAJ.csv") -> CheckResult:
    """Score ``traj`` (a Trajectory) against ``scenario``'s reference and the course-type variants."""
    from .engines import run_variant
    from .references import reference_solution

    t = np.asarray(traj.t_s, dtype=float)
    y = np.asarray(traj.y, dtype=float)
    notes = []
    if len(t) < 2:
        raise CheckError(f"{source}: rows: need at least 2 rows (t = 0 and one step), got {len(t)}")
    steps = np.diff(t)
    dt = float(np.median(steps))
    if abs(t[0]) > tol.CHECK_UNIFORM_DT_REL * dt:
        raise CheckError(f"{source}: t: must start at 0 (the scenario's initial state), starts at {t[0]:g} s")
    uniform = bool(np.max(np.abs(steps - dt)) <= tol.CHECK_UNIFORM_DT_REL * dt)
    if t[-1] > scenario.duration_s * (1 + 1e-9) + dt:
        notes.append(f"the trajectory ({t[-1]:g} s) is longer than the scenario ({scenario.duration_s:g} s); "
                     "it is compared over its whole length")

    finite = np.all(np.isfinite(y), axis=1)
    diverged_at = None
    if not finite.all():
        k = int(np.argmin(finite))
        diverged_at = float(t[k])
        t, y = t[:k], y[:k]
        if len(t) < 2:
            raise CheckError(f"{source}: row 2: non-finite state values from the first step on")
    qn = np.linalg.norm(y[:, 6:10], axis=1)
    if np.max(np.abs(qn - 1.0)) > 1e-6:
        notes.append(f"quaternions are not unit length (|q| up to {np.max(np.abs(qn - 1.0)):.1e} away from 1); "
                     "normalised before comparing")

    y_ref, label = reference_solution(scenario, t)
    scales = M.quantity_scales(y_ref)
    errs = M.error_summary(M.state_errors(y, y_ref))

    y0 = scenario.problem.initial_packed()
    d0 = M.state_errors(y[:1], y0[None, :])
    bad0 = [q for q in QUANTITIES if d0[q][0] > tol.CHECK_INITIAL_STATE_REL * scales[q]]

    variant_diffs, budget = {}, {}
    if uniform:
        dt_run = _snap_dt(dt, scenario)
        n = int(round(t[-1] / dt_run))
        if n >= 1 and np.allclose(t, dt_run * np.arange(n + 1), rtol=0, atol=tol.CHECK_UNIFORM_DT_REL * dt_run):
            for v in COMPARED_VARIANTS:
                run = run_variant(scenario, v, dt_run, n * dt_run)
                m = min(len(run.t_s), len(t))
                variant_diffs[v] = _rel_diff(y[:m], run.y[:m], scales)
                if v == BUDGET_VARIANT:
                    e_v = M.state_errors(run.y[:m], y_ref[:m])
                    budget = {q: tol.CHECK_BUDGET_FACTOR * max(float(np.max(e_v[q])),
                                                               M.roundoff_floor(scales[q], n, label))
                              for q in QUANTITIES}
            dt = dt_run
        else:
            notes.append("the times are not multiples of one step from t = 0; scheme comparisons skipped")
    else:
        notes.append(f"the time steps are not uniform (within {tol.CHECK_UNIFORM_DT_REL:g} of the median "
                     f"{dt:g} s); scheme comparisons skipped")

    # verdict
    same = [v for v in COMPARED_VARIANTS if v in variant_diffs
            and variant_diffs[v]["max_rel"] <= tol.CHECK_SAME_SCHEME_REL]
    if diverged_at is not None:
        verdict, passed = f"diverged: non-finite values from t = {diverged_at:g} s", False
    elif bad0:
        verdict = ("does not start at the scenario's initial state ("
                   + ", ".join(f"{q} off by {d0[q][0]:.3g} {M.UNITS[q]}" for q in bad0) + "); wrong scenario?")
        passed = False
    elif same:
        v = same[0]
        verdict = (f"is {v}: reproduces it step for step to {variant_diffs[v]['max_rel']:.1e} "
                   f"(relative; tolerance {tol.CHECK_SAME_SCHEME_REL:g})")
        passed = True
        if v == "reference:course":
            exp = expectation(scenario, v, "orientation")
            if exp.verdict == "does_not_converge":
                notes.append(f"the course scheme itself does not converge on {scenario.name}: {exp.reason} "
                             f"(orientation error {errs['orientation']['max']:.3g} rad at most)")
    elif budget and all(errs[q]["max"] <= budget[q] for q in QUANTITIES):
        verdict = (f"agrees with the reference: every error is within {tol.CHECK_BUDGET_FACTOR:g}× that of "
                   f"{BUDGET_VARIANT} (a correct first-order scheme) at Δt = {dt:g} s")
        passed = True
    else:
        if budget:
            over = sorted((errs[q]["max"] / budget[q], q) for q in QUANTITIES if errs[q]["max"] > budget[q])
            what = "; ".join(f"{q} error up to {errs[q]['max']:.3g} {M.UNITS[q]} > allowed {budget[q]:.3g}"
                             for _, q in reversed(over))
        else:
            what = "no scheme comparison was possible"
        nearest = ""
        if variant_diffs:
            v = min(variant_diffs, key=lambda k: variant_diffs[k]["max_rel"])
            nearest = f"; nearest reference variant: {v} (differs by up to {variant_diffs[v]['max_rel']:.3g}, relative)"
        verdict, passed = f"disagrees with the reference: {what}{nearest}", False
    return CheckResult(scenario.name, label, len(traj.t_s), float(traj.t_s[-1]), dt if uniform else None, uniform,
                       errs, budget, variant_diffs, verdict, passed, notes)


def format_report(res: CheckResult, source: str) -> str:
    """Human-readable report of a check (what `rbcheck check` prints)."""
    lines = [f"{source}: {res.n_rows} rows, t = 0 … {res.t_end_s:g} s"
             + (f", Δt = {res.dt_s:g} s" if res.dt_s is not None else ", non-uniform steps"),
             f"scenario {res.scenario}, reference: {res.reference_label}", "",
             f"  {'quantity':<26}{'final error':>14}{'max error':>14}{'allowed max':>14}"]
    for q in QUANTITIES:
        e = res.errors[q]
        allowed = f"{res.budget[q]:.3g}" if q in res.budget else "–"
        lines.append(f"  {q + ' (' + M.UNITS[q] + ')':<26}{e['final']:>14.3g}{e['max']:>14.3g}{allowed:>14}")
    if res.variant_diffs:
        short = {"position": "pos. (m)", "orientation": "orient. (rad)", "velocity": "vel. (m/s)",
                 "angular_velocity": "ang.v. (rad/s)"}
        lines += ["", f"  {'max difference from':<24}{'relative':>10}" + "".join(f"{short[q]:>15}" for q in QUANTITIES)]
        for v, d in res.variant_diffs.items():
            lines.append(f"  {v:<24}{d['max_rel']:>10.2g}" + "".join(f"{d[q]:>15.3g}" for q in QUANTITIES))
    for n in res.notes:
        lines.append(f"note: {n}")
    lines += ["", ("PASS: " if res.passed else "FAIL: ") + res.verdict]
    return "\n".join(lines)

