"""``rbcheck check``, step 4: which scheme a trajectory is, and which mistake explains it (docs/check.md,
"Which scheme it is" and "Likely cause").

From the user's own recorded states every candidate advances one row interval and is compared with the
next row: every reference variant (through the reference adapter's ``one_step``; IS a variant when every
step reproduces it within the rounding of the data, and each variant is checked against the exact flow),
every catalogued mistake (:mod:`cross_checks.gates.check.mistakes`: named when it explains every step
within the local allowance and CHECK_MISTAKE_MARGIN times better than any correct scheme), a Δt
mismatch (the scale s of the step that best fits), and the usual slips of the initial state.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from cross_checks.analysis.flow import distances, exact_flow, quantity_distance
from cross_checks.core.quantities import BLOCKS, QUANTITIES
from cross_checks.gates.check.evidence import ratio
from cross_checks.gates.check.mistakes import applicable_mistakes, course_step
from reference_sim.integrators import VARIANTS
from reference_sim.quaternion import quat_conj, quat_log, quat_mul, rotate
from reference_sim.state import Q, V, W, X

__all__ = ["CandidateScore", "step_rows", "score_candidate", "score_variants", "diagnose_mistakes",
           "fit_step_scale", "initial_state_slips", "written_slips", "OMEGA_IN_BODY_AXES"]


@dataclass
class CandidateScore:
    """How well one candidate step explains the rows.

    name : e.g. "reference:rk4".  max_ratio / p99_ratio : max and 99th percentile over rows and
    quantities of |next row − candidate step| / local allowance.  same : every step reproduced within
    the data's rounding.  own_defect : the candidate's own max defect ratio against the exact flow
    (≤ 1: a correct scheme here), NaN when not evaluated.  worst_quantity : where max_ratio occurs.
    """

    name: str
    max_ratio: float
    p99_ratio: float
    same: bool
    own_defect: float = math.nan
    worst_quantity: str = ""
    max_rel_diff: float = math.nan

    @property
    def correct(self) -> bool:
        return bool(self.own_defect <= 1.0)

    def as_dict(self) -> dict:
        return {"name": self.name, "max_ratio": self.max_ratio, "p99_ratio": self.p99_ratio,
                "same": self.same, "own_defect_ratio": self.own_defect, "correct_here": self.correct,
                "worst_quantity": self.worst_quantity}


def step_rows(step, y0, inp):
    """Advance each row of ``y0`` (N, 13) by its interval's ``span_steps`` steps of ``step(y, h)``."""
    h_rows = inp.span_s / inp.span_steps
    uniform = bool(np.all(h_rows == h_rows[0]))
    out = np.empty_like(y0)
    for m in np.unique(inp.span_steps):
        idx = inp.span_steps == m
        z = y0[idx]
        hh = float(h_rows[0]) if uniform else h_rows[idx]
        with np.errstate(all="ignore"):
            for _ in range(int(m)):
                z = step(z, hh)
        out[idx] = z
    return out


def score_candidate(name, y_next, y_cand, allow, quantities, flow_end=None, solve_tol=None) -> CandidateScore:
    """Compare a candidate's steps ``y_cand`` with the recorded next rows ``y_next`` (N, 13).

    ``solve_tol`` (quantity -> (N,)): how far an implicit candidate's own solve may stop from its root,
    added to the rounding of the data when deciding whether the file IS the candidate."""
    d = distances(y_next, y_cand, quantities)
    r = {q: ratio(d[q], allow.total[q]) for q in quantities}
    stack = np.stack([r[q] for q in quantities])
    if np.any(np.isnan(stack)):
        mx = p99 = math.nan
        worst = ""
    else:
        mx = float(np.max(stack))
        p99 = float(np.max(np.percentile(stack, 99, axis=1)))
        worst = quantities[int(np.argmax(np.max(stack, axis=1)))]
    tol_same = {q: allow.arith[q] + allow.print_[q] + (0.0 if solve_tol is None else solve_tol[q])
                for q in quantities}
    same = bool(not math.isnan(mx) and all(np.all(d[q] <= tol_same[q]) for q in quantities))
    own = math.nan
    if flow_end is not None:
        dd = distances(y_cand, flow_end, quantities)
        own_stack = np.stack([ratio(dd[q], allow.total[q]) for q in quantities])
        own = math.nan if np.any(np.isnan(own_stack)) else float(np.max(own_stack))
    return CandidateScore(name, mx, p99, same, own, worst)


def score_variants(inp, scenario, y0, y_next, flow_end, allow, refs):
    """Scores of every reference variant (``refs``: variant -> its Resolved name), each stepped by the
    reference adapter's ``one_step``.

    An iterative variant's step is its root only to IMPLICIT_TOL (1 + |y|) per component and step (two
    evaluations of the same step may stop at different iterates): that is added to its identity test."""
    from cross_checks.engines import get_adapter
    from reference_sim.integrators import IMPLICIT_TOL
    adapter = get_adapter("reference")
    solve = {q: inp.span_steps * IMPLICIT_TOL * math.sqrt(BLOCKS[q].stop - BLOCKS[q].start)
             * (1.0 + np.linalg.norm(np.nan_to_num(y_next[:, BLOCKS[q]]), axis=1))
             * (2.0 if q == "orientation" else 1.0)
             for q in QUANTITIES}
    out = []
    for v, scheme in VARIANTS.items():
        y_c = step_rows(lambda z, hh, v=v: adapter.one_step(scenario, v, hh, z), y0, inp)
        out.append(score_candidate(refs[v], y_next, y_c, allow, QUANTITIES, flow_end,
                                   solve if scheme.iterative else None))
    return out


def diagnose_mistakes(inp, scenario, y0, y_next, allow) -> list:
    """Scores of every applicable catalogued mistake that is VISIBLE on these rows, best first.

    Each mistake is made on each correct base (mistakes.BASES); it is visible when its steps differ
    from its base's by more than the local allowance somewhere (``effect`` > 1) — otherwise the base
    alone explains the rows as well and the mistake cannot be told from it here."""
    from cross_checks.gates.check.mistakes import BASES
    out = []
    h = inp.span_s / inp.span_steps
    base_steps = {}
    for mistake in applicable_mistakes(scenario, h):
        for label, knobs in mistake.variants():
            y_c = step_rows(lambda z, hh, k=knobs: course_step(scenario, z, hh, k), y0, inp)
            s = score_candidate(label, y_next, y_c, allow, QUANTITIES)
            base = next((b for b in BASES if label.endswith(f"({b})")), None)
            if base is not None:
                if base not in base_steps:
                    base_steps[base] = step_rows(lambda z, hh, k=BASES[base]: course_step(scenario, z, hh, k),
                                                 y0, inp)
                d = distances(y_c, base_steps[base], QUANTITIES)
                s.effect = max(float(np.nanmax(ratio(d[q], allow.total[q]))) for q in QUANTITIES)
            else:
                s.effect = math.inf
            if not s.effect > 1.0:
                continue
            s.sentence = mistake.sentence
            s.mistake = mistake.name
            out.append(s)
    return sorted(out, key=lambda s: (math.isnan(s.max_ratio), s.max_ratio))


def _increments(y0, y1):
    """Per-row increments (N, 12): Δx, Δv, rotation vector of q1 q0⁻¹, Δω."""
    dq = quat_log(quat_mul(y1[:, Q], quat_conj(y0[:, Q])))
    return np.concatenate([y1[:, X] - y0[:, X], y1[:, V] - y0[:, V], dq, y1[:, W] - y0[:, W]], axis=1)


def fit_step_scale(inp, scenario, y0, y_next, flow_end, allow):
    """The scale s that best makes ``y_next ≈ flow(y0, s Δ)`` (least squares on the increments, each
    quantity weighted by 1 / its allowance), and the score of the flow over s Δ. Returns (s, score);
    ``(nan, None)`` where a state or the exact flow is not finite (a run blowing up: no scale to fit)."""
    if not (np.all(np.isfinite(flow_end)) and np.all(np.isfinite(y_next)) and np.all(np.isfinite(y0))):
        return math.nan, None
    du = _increments(y0, y_next)
    df = _increments(y0, flow_end)
    wts = np.concatenate([np.repeat(1.0 / np.maximum(allow.total[q], 1e-300)[:, None], 3, axis=1)
                          for q in ("position", "velocity", "orientation", "angular_velocity")], axis=1)
    a, b = du * wts, df * wts
    den = float(np.sum(b * b))
    if not (den > 0.0) or not np.all(np.isfinite(a)):
        return math.nan, None
    s = float(np.sum(a * b) / den)
    if not (0.05 < s < 20.0) or abs(s - 1.0) < 1e-9:
        return s, None
    fl = exact_flow(scenario, y0, inp.span_s * s)
    return s, score_candidate(f"exact motion over {s:.4g} × Δt", y_next, fl.y_end, allow, QUANTITIES)


def initial_state_slips(y_row0, y_init, tol_q, present):
    """Names of the usual slips that turn the scenario's initial state ``y_init`` into the first row."""
    slips = []
    q0 = y_init[Q]
    cands = {
        OMEGA_IN_BODY_AXES: lambda y: _with(y, W, rotate(quat_conj(q0), y[W])),
        "the angular velocity is in degrees per second (radians expected)":
            lambda y: _with(y, W, np.rad2deg(y[W])),
        "the quaternion is written in (x, y, z, w) order under the names qw,qx,qy,qz":
            lambda y: _with(y, Q, y[Q][[1, 2, 3, 0]]),
        "the quaternion is the inverse (world-to-body) orientation":
            lambda y: _with(y, Q, quat_conj(y[Q])),
        "y and z are swapped (a y-up / z-up mix-up)":
            lambda y: _swap_yz(y),
    }
    for words, f in cands.items():
        alt = f(np.array(y_init, dtype=float))
        if all(quantity_distance(y_row0, alt, q) <= tol_q[q] for q in present) and \
                not all(quantity_distance(y_row0, y_init, q) <= tol_q[q] for q in present):
            slips.append(words)
    return slips


#: The words of the slip "ω written in body axes" (the first row's, and every row's, diagnosis).
OMEGA_IN_BODY_AXES = ("the angular velocity is written in body axes "
                      "(the file's columns wx,wy,wz are world axes)")

#: Slips in WRITING the state, made on every row: each maps the file's rows (N, 13) to what the simulator
#: must have held if it made that slip (ω_W = R(q) ω_B for ω written in body axes).
_WRITTEN = {
    OMEGA_IN_BODY_AXES: lambda y: _with_rows(y, W, rotate(y[:, Q], y[:, W])),
    "the angular velocity is in degrees per second (radians expected)":
        lambda y: _with_rows(y, W, np.deg2rad(y[:, W])),
}


def written_slips(inp, scenario, one_step) -> list:
    """``[(words, worst ratio)]``: each slip in writing the state (ω in body axes, ω in degrees), with the
    largest one-step defect over its allowance of the file's rows read back as that slip says.

    Visible on every row, not only the first: at the identity orientation (the tennis racket's start) ω in
    body and world axes agree on the first row and part from the second on. ``one_step(inp)`` gives
    ``(flow, allowances, distances)`` of a CheckInput's rows (verdict._one_step)."""
    import dataclasses
    out = []
    for words, f in _WRITTEN.items():
        y = f(np.array(inp.y, dtype=float))
        if np.allclose(y, inp.y, rtol=0.0, atol=0.0, equal_nan=True):
            continue   # nothing to read differently (ω = 0 on every row)
        alt = dataclasses.replace(inp, y=y)
        with np.errstate(all="ignore"):
            _, allow, d = one_step(alt)
            r = [ratio(d[q], allow.total[q]) for q in QUANTITIES]
        worst = float(np.max(np.stack(r))) if not np.any(np.isnan(np.stack(r))) else math.nan
        if not math.isnan(worst):
            out.append((words, worst))
    return out


def _with_rows(y, sl, value):
    y = y.copy()
    y[:, sl] = value
    return y


def _with(y, sl, value):
    y = y.copy()
    y[sl] = value
    return y


def _swap_yz(y):
    """The state mirrored by S = swap(y, z): positions and velocities S a; axial vectors (ω, the
    quaternion's vector part) −S a, since det S = −1."""
    y = y.copy()
    for sl in (X, V):
        y[sl] = y[sl][[0, 2, 1]]
    y[W] = -y[W][[0, 2, 1]]
    q = y[Q]
    y[Q] = np.array([q[0], -q[1], -q[3], -q[2]])
    return y
