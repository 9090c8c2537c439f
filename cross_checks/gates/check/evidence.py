"""``rbcheck check``, step 3: the evidence rows of a verdict, each measured against a derived allowance
(docs/check.md, "The evidence"): the one-step defect against the exact flow (full-state files,
:mod:`cross_checks.analysis.flow`), the acceleration consistency of the poses (pose-only files), the
conserved quantities, and the free-running error against the reference, its allowance capped
(tolerances.CHECK_FREE_RUN_CAP_FRACTION) and not decisive beyond the cap.

An :class:`Evidence` row is decisive over a time window; it fails when its value exceeds the
allowance at any decisive time — and a NaN never passes.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from cross_checks.analysis import metrics as M
from cross_checks.analysis.flow import (
    conservation_sensitivities,
    error_growth,
    flow_rhs,
    majorant,
    motion_rate,
)
from cross_checks.core import tolerances as tol
from cross_checks.core.quantities import BLOCKS, QUANTITIES, UNITS, quantity_scales, state_errors
from reference_sim.quaternion import matrix_from_quat, quat_conj, quat_log, quat_mul
from reference_sim.state import Q, V, W, X

__all__ = ["Evidence", "evidence_row", "reconstruct_states", "pose_consistency", "conserved_evidence",
           "free_running_evidence", "ratio"]

UNITS = dict(UNITS, energy="J", angular_momentum="kg m²/s", quaternion_norm="")


@dataclass
class Evidence:
    """One row of the verdict table.

    kind : "one-step defect", "acceleration", "conserved", "free-running".
    quantity, unit : what is measured.
    max_value : largest measured value over the decisive window (NaN when any is NaN).  max_ratio :
    largest value / allowance there.  t_worst_s : time of that ratio; value_at_worst and allowance: the
    value and the allowance then.  first_over_s : first decisive time the allowance was exceeded (None:
    never).  source : where the allowance comes from.  decisive_until_s : end of the decisive window (None:
    the whole run; ``-inf``: not decisive at all).  note : extra words.
    """

    kind: str
    quantity: str
    unit: str
    max_value: float
    max_ratio: float
    t_worst_s: float
    first_over_s: float | None
    allowance: float
    source: str
    decisive_until_s: float | None = None
    note: str = ""
    series: dict = field(default_factory=dict, repr=False)
    value_at_worst: float = math.nan

    @property
    def decisive(self) -> bool:
        return self.decisive_until_s is None or self.decisive_until_s > -math.inf

    @property
    def passed(self) -> bool:
        return not self.decisive or bool(self.max_ratio <= 1.0)

    def as_dict(self) -> dict:
        d = {k: getattr(self, k) for k in ("kind", "quantity", "unit", "max_value", "max_ratio", "t_worst_s",
                                            "value_at_worst", "allowance", "first_over_s", "source", "note")}
        d["decisive"] = self.decisive
        d["decisive_until_s"] = (None if self.decisive_until_s is None
                                 else (self.decisive_until_s
                                       if math.isfinite(self.decisive_until_s) else None))
        d["passed"] = self.passed
        return d


def ratio(value, allowance):
    """value / allowance elementwise; 0/0 = 0, x/0 = inf, NaN stays NaN."""
    v = np.asarray(value, dtype=float)
    a = np.asarray(allowance, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = v / a
    return np.where((a == 0.0) & (v == 0.0), 0.0, np.where((a == 0.0) & (v > 0.0), np.inf, r))


def evidence_row(kind, quantity, t_s, value, allowance, source, *, decisive=None, note="") -> Evidence:
    """Build a row from per-time ``value`` and ``allowance`` (T,); ``decisive`` (T,) bool masks the
    times where it counts (default all)."""
    t = np.asarray(t_s, dtype=float)
    v = np.asarray(value, dtype=float)
    a = np.asarray(allowance, dtype=float)
    r = ratio(v, a)
    mask = np.ones(len(t), dtype=bool) if decisive is None else np.asarray(decisive, dtype=bool)
    unit = ({"position": "m/s²", "orientation": "rad/s²"}[quantity]
            if kind == "acceleration" else UNITS.get(quantity, ""))
    if len(t) == 0:
        return Evidence(kind, quantity, unit, math.nan, math.nan, math.nan, None, math.nan, source,
                        -math.inf, note)
    nan_any = bool(np.any(np.isnan(v[mask]))) if mask.any() else False
    vm = v[mask] if mask.any() else v
    max_value = math.nan if np.any(np.isnan(vm)) else float(np.max(vm))
    if mask.any():
        rm = np.where(mask, r, -np.inf)
        k = int(np.argmax(np.where(np.isnan(rm), np.inf, rm)))
        max_ratio = math.nan if nan_any else float(rm[k])
        over = np.flatnonzero(mask & ~(r <= 1.0))
        first = float(t[over[0]]) if over.size else None
    else:
        k = int(np.argmax(np.nan_to_num(r, nan=np.inf)))
        max_ratio, first = float(r[k]), None
    if decisive is None or mask.all():
        until = None
    elif not mask.any():
        until = -math.inf
    else:
        until = float(t[np.flatnonzero(mask)[-1]])
    return Evidence(kind, quantity, unit, max_value, max_ratio, float(t[k]), first, float(a[k]),
                    source, until, note, series={"t_s": t, "value": v, "allowance": a},
                    value_at_worst=float(v[k]))


# --- pose-only files: acceleration consistency ----------------------------------------------------

def _rotvec_rate(q0, q1, span):
    """World angular velocity (rad/s) taking q0 to q1 in ``span`` s: log(q1 q0⁻¹) / span."""
    d = quat_mul(q1, quat_conj(q0))
    return quat_log(d) / span[..., None]


def reconstruct_states(inp, y_ref):
    """Full states for a file without velocities (K, 13): the recorded poses, velocities from central
    differences of the poses (one-sided at the ends), and the reference for absent quantities."""
    y = np.array(y_ref, dtype=float)
    yy = inp.y
    span = inp.span_s
    K = len(yy)
    lo = np.concatenate([[0], np.arange(K - 1)])        # row before (the row itself at the start)
    hi = np.concatenate([np.arange(1, K), [K - 1]])      # row after (the row itself at the end)
    dt = np.concatenate([[0.0], span]) + np.concatenate([span, [0.0]])
    if "position" in inp.present:
        y[:, X] = yy[:, X]
        y[:, V] = (yy[hi, X] - yy[lo, X]) / dt[:, None]
    if "orientation" in inp.present:
        qn = yy[:, Q] / np.linalg.norm(yy[:, Q], axis=1, keepdims=True)
        y[:, Q] = qn
        y[:, W] = _rotvec_rate(qn[lo], qn[hi], dt)
    return y


def pose_consistency(inp, scenario, y_hat) -> list:
    """Acceleration-consistency rows for a file without velocities: second differences of the poses
    against the equations of motion at the reconstructed states ``y_hat`` (:func:`reconstruct_states`).

    A consistent scheme of order ≥ 1 with step h leaves a residual ≤ C (3h + Δ²L/12) M2 in the
    acceleration (h c_v, the shift of the evaluation point and the velocity reconstruction, h M2 each
    at most, plus the central difference's own truncation); the rows' rounding adds 4 × print / Δ².
    """
    span = inp.span_s
    ok = np.flatnonzero(np.abs(span[1:] - span[:-1]) <= 1e-9 * span[1:]) + 1   # interior rows, equal spans
    rows = []
    if ok.size == 0:
        return rows
    D = span[ok]
    h = D / inp.span_steps[ok]
    yy = inp.y
    y = y_hat[ok]
    F = flow_rhs(scenario)
    f = F(y)
    L = motion_rate(scenario, y)
    M2 = majorant(F, y, L)
    coef = tol.CHECK_LOCAL_C * (3.0 * h + D ** 2 * L / 12.0)
    u = inp.unit_roundoff
    t = inp.t_s[ok]
    if "position" in inp.present:
        a_hat = (yy[ok + 1, X] - 2.0 * yy[ok, X] + yy[ok - 1, X]) / D[:, None] ** 2
        res = np.linalg.norm(a_hat - f[:, V], axis=1)
        pf = inp.print_floor["position"]
        mag = np.linalg.norm(yy[ok, X], axis=1)
        allow = coef * M2["velocity"] + (4.0 * pf[ok] + 4.0 * inp.span_steps[ok]
                                         * tol.CHECK_ROUNDINGS_PER_STEP * u * mag) / D ** 2
        rows.append(evidence_row("acceleration", "position", t, res, allow,
                                 "second difference of the positions vs f/m: C "
                                 "(3h + Δ²L/12) |a'| + 4 × written precision / Δ²"))
    if "orientation" in inp.present:
        qn = yy[:, Q] / np.linalg.norm(yy[:, Q], axis=1, keepdims=True)
        alpha_hat = (_rotvec_rate(qn[ok], qn[ok + 1], D) - _rotvec_rate(qn[ok - 1], qn[ok], D)) / D[:, None]
        res = np.linalg.norm(alpha_hat - f[:, W], axis=1)
        pf = inp.print_floor["orientation"]
        allow = coef * M2["angular_velocity"] + (4.0 * pf[ok] + 8.0 * inp.span_steps[ok]
                                                 * tol.CHECK_ROUNDINGS_PER_STEP * u) / D ** 2
        rows.append(evidence_row("acceleration", "orientation", t, res, allow,
                                 "second difference of the orientations vs Euler's equations: "
                                 "C (3h + Δ²L/12) |α'| + 4 × written precision / Δ²"))
    return rows


# --- conserved quantities --------------------------------------------------------------------------

def _cumulative(a):
    """Allowance accumulated before each row: [0, a0, a0 + a1, ...] (K,) from per-interval (K−1,)."""
    return np.concatenate([[0.0], np.cumsum(a)])


def conserved_evidence(inp, scenario, allow) -> list:
    """|q| = 1 (orientation present), and energy / world angular momentum where the physics conserves
    them (full-state files): their drift may not exceed the local allowances summed along the run,
    each weighted by the quantity's sensitivity (|∂E/∂x| = |f|, m|v|, |τ| + |ω × L|, |L|;
    |∂L/∂ω| ≤ I_max, |∂L/∂θ| ≤ |L| + I_max |ω|), plus the written precision of the two rows compared."""
    rows = []
    t, y = inp.t_s, inp.y
    if "orientation" in inp.present:
        qn = np.linalg.norm(y[:, Q], axis=1)
        pf = inp.print_floor["orientation"] / 2.0
        acc = _cumulative(inp.span_steps * tol.CHECK_ROUNDINGS_PER_STEP * inp.unit_roundoff)
        rows.append(evidence_row("conserved", "quaternion_norm", t, np.abs(qn - 1.0),
                                 pf + acc + 4.0 * inp.unit_roundoff,
                                 "written precision of q + the roundings of each step "
                                 "(a normalised quaternion)"))
    if not inp.full_state or allow is None:
        return rows
    p = scenario.problem
    cons = M.conserved(p.forces)
    per = {q: allow.physics[q] + allow.arith[q] for q in QUANTITIES}
    sens = conservation_sensitivities(scenario, y)
    if cons["energy"][0]:
        grad = sens["energy"]
        E, E_terms = M.energy_J(p, y, with_scale=True)
        drift = np.abs(E - E[0])
        bound = _cumulative(sum(grad[q][:-1] * per[q] for q in QUANTITIES))
        bound += sum(grad[q] * inp.print_floor[q] + grad[q][0] * inp.print_floor[q][0] for q in QUANTITIES)
        bound += 4.0 * inp.unit_roundoff * (E_terms + E_terms[0])
        rows.append(evidence_row("conserved", "energy", t, drift, bound,
                                 "the local allowances summed along the run, weighted by |∂E/∂y| "
                                 "(a consistent scheme's drift), + written precision"))
    if cons["angular_momentum"][0]:
        R = matrix_from_quat(y[:, Q] / np.linalg.norm(y[:, Q], axis=1, keepdims=True))
        L = np.einsum("kij,kj->ki", p.body.world_inertia(R), y[:, W])
        Lmag = np.linalg.norm(L, axis=1)
        drift = np.linalg.norm(L - L[0], axis=1)
        grad = sens["angular_momentum"]
        bound = _cumulative(sum(grad[q][:-1] * per[q] for q in ("angular_velocity", "orientation")))
        bound += sum(grad[q] * inp.print_floor[q] + grad[q][0] * inp.print_floor[q][0]
                     for q in ("angular_velocity", "orientation"))
        bound += 4.0 * inp.unit_roundoff * (Lmag + Lmag[0])
        rows.append(evidence_row("conserved", "angular_momentum", t, drift, bound,
                                 "the local allowances summed along the run, weighted "
                                 "by |∂L/∂y| (world L = I_W ω), + written precision"))
    return rows


# --- free-running error ----------------------------------------------------------------------------

def _extent(y_ref, q):
    if q == "orientation":
        return math.pi
    sl = BLOCKS[q]
    d = np.linalg.norm(y_ref[:, sl] - y_ref[0, sl], axis=1)
    if q == "angular_velocity":
        return float(max(np.max(d), np.max(np.linalg.norm(y_ref[:, sl], axis=1))))
    return float(np.max(d))


def free_running_evidence(inp, scenario, y_ref, ref_label, allow_per_row) -> tuple:
    """Free-running error rows, the growth used and the errors. ``allow_per_row``: quantity -> (K−1,)
    local allowances (physics + arithmetic) per row interval.

    The allowance at t: Σ_p G_{p→q}(t) · (allowances of p summed before t) + the written precision +
    the reference's accuracy; the comparison is decisive while that stays below the cap
    ``CHECK_FREE_RUN_CAP_FRACTION × extent_q`` (extent: how far q moves along the reference; π for
    the orientation).
    """
    t = inp.t_s
    errs = state_errors(inp.y, y_ref)
    scales = quantity_scales(y_ref)
    growth_scales = {"position": scales["position"], "velocity": scales["velocity"], "orientation": 1.0,
                     "angular_velocity": scales["angular_velocity"]}
    rows = []
    growth = error_growth(scenario, t, growth_scales)
    acc = {p: _cumulative(allow_per_row[p]) for p in QUANTITIES}
    for q in QUANTITIES:
        if q not in inp.present:
            continue
        cap = tol.CHECK_FREE_RUN_CAP_FRACTION * _extent(y_ref, q)
        ref_floor = M.roundoff_floor(scales[q], len(t) - 1, ref_label)
        allowance = sum(growth[(p, q)] * acc[p] for p in QUANTITIES) + inp.print_floor[q] + ref_floor
        decisive = np.maximum.accumulate(allowance) < cap
        note = ""
        if not decisive.all():
            t_cap = float(t[np.argmin(decisive)])
            note = (f"the allowance reaches the cap ({cap:.3g} {UNITS[q]}) at t = {t_cap:.4g} s: from there "
                    "the free-running comparison is reported, not decisive (the local evidence decides)")
        rows.append(evidence_row("free-running", q, t, errs[q], np.minimum(allowance, cap),
                                 "local allowances carried to t by the scenario's measured error "
                                 f"growth, capped at {tol.CHECK_FREE_RUN_CAP_FRACTION:g} × how "
                                 "far the quantity moves",
                                 decisive=decisive, note=note))
    return rows, growth, errs
