"""Metrics of a trajectory (DESIGN.md definitions): errors against a reference, conservation drifts,
local (one-step) errors, and convergence orders over a Δt ladder.

Packed states ``y (..., 13)`` are ``[x_W (m), v_W (m/s), q_WB (w, x, y, z), w_W (rad/s, WORLD)]``.

Errors (per time sample)::

    position          |x − x_ref|                                          m
    velocity          |v − v_ref|                                          m/s
    orientation       2 atan2(|vec(q_ref⁻¹ q)|, |scalar(q_ref⁻¹ q)|)       rad, sign-invariant
    angular_velocity  |ω − ω_ref|  (world axes)                            rad/s

Conservation (no reference needed), each only where the physics conserves it::

    energy            (E(t) − E(0)) / |E(0)|,  E = ½ m|v|² + ½ ωᵀ I_W ω + U_gravity + U_springs
    angular momentum  |L(t) − L(0)| / |L(0)|,  L = I_W ω about the COM (world)
    linear momentum   |p(t) − p(0)| / |p(0)|,  p = m v (only where no force acts)

(When the initial value is exactly zero the drift is the absolute change instead.)

Convergence: the least-squares slope of log(final error) against log(Δt) over the asymptotic part
of the ladder (points at the round-off floor dropped, and a pre-asymptotic coarsest point), plus the
pairwise orders ``log(e_i / e_{i+1}) / log(Δt_i / Δt_{i+1})``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from reference_sim.quaternion import geodesic_angle, matrix_from_quat
from reference_sim.state import Q, V, W, X

from . import tolerances as tol
from .expectations import QUANTITIES

__all__ = ["QUANTITIES", "UNITS", "state_errors", "error_summary", "energy_J", "angular_momentum_W",
           "linear_momentum_W", "conserved", "relative_drift", "drift_kind", "quantity_scales",
           "roundoff_floor", "drift_floor", "pairwise_orders", "ConvergenceFit", "fit_convergence", "decimation_indices",
           "compare_with_expectation", "measured_pre_asymptotic"]

UNITS = {"position": "m", "velocity": "m/s", "orientation": "rad", "angular_velocity": "rad/s"}


# --- errors against a reference ------------------------------------------------------------------

def _unit_q(q):
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def state_errors(y, y_ref) -> dict:
    """Per-sample errors ``{quantity: (T,)}`` of states ``y`` against ``y_ref`` (both (T, 13)).

    The orientation error is the geodesic angle (rad, in [0, π]) and so identical for q and −q;
    quaternions are normalised first (a CSV from another simulator may carry rounding).
    """
    y = np.asarray(y, dtype=float)
    y_ref = np.asarray(y_ref, dtype=float)
    with np.errstate(invalid="ignore"):
        return {
            "position": np.linalg.norm(y[..., X] - y_ref[..., X], axis=-1),
            "velocity": np.linalg.norm(y[..., V] - y_ref[..., V], axis=-1),
            "orientation": geodesic_angle(_unit_q(y_ref[..., Q]), _unit_q(y[..., Q])),
            "angular_velocity": np.linalg.norm(y[..., W] - y_ref[..., W], axis=-1),
        }


def error_summary(errors: dict) -> dict:
    """``{quantity: {"final": e[-1], "max": max e}}``; NaN where a series is empty or non-finite."""
    out = {}
    for k, e in errors.items():
        e = np.asarray(e, dtype=float)
        if e.size == 0 or not np.all(np.isfinite(e)):
            out[k] = {"final": math.nan, "max": math.nan if e.size == 0 or not np.any(np.isfinite(e))
                      else float(np.nanmax(e))}
        else:
            out[k] = {"final": float(e[-1]), "max": float(e.max())}
    return out


# --- conserved quantities --------------------------------------------------------------------------

def energy_J(problem, y, *, with_scale: bool = False):
    """Total energy (J) of states ``y (..., 13)``: ½ m|v|² + ½ ωᵀ I_W ω + gravity + spring potential.

    With ``with_scale`` also returns ``kinetic + |potential|`` (J), the size of the terms whose
    difference E is: the magnitude its round-off is relative to (a falling body's E is a small
    difference of large kinetic and potential energies).
    """
    y = np.asarray(y, dtype=float)
    body, fm = problem.body, problem.forces
    q = _unit_q(y[..., Q])
    R = matrix_from_quat(q)
    w = y[..., W]
    L = np.einsum("...ij,...j->...i", body.world_inertia(R), w)
    kinetic = 0.5 * body.mass_kg * np.sum(y[..., V] ** 2, axis=-1) + 0.5 * np.sum(w * L, axis=-1)
    potential = fm.potential_energy_J(body, y[..., X], q)
    if with_scale:
        return kinetic + potential, kinetic + np.abs(potential)
    return kinetic + potential


def angular_momentum_W(problem, y):
    """World angular momentum about the COM, ``I_W ω`` (kg m²/s), shape (..., 3)."""
    y = np.asarray(y, dtype=float)
    R = matrix_from_quat(_unit_q(y[..., Q]))
    return np.einsum("...ij,...j->...i", problem.body.world_inertia(R), y[..., W])


def linear_momentum_W(problem, y):
    """Linear momentum ``m v`` (kg m/s), shape (..., 3)."""
    return problem.body.mass_kg * np.asarray(y, dtype=float)[..., V]


def conserved(forces) -> dict:
    """Which quantities the physics conserves: ``{name: (bool, reason when not)}`` for
    "energy", "angular_momentum", "linear_momentum"."""
    fm = forces
    why_e = []
    if fm.linear_drag_N_s_per_m:
        why_e.append("linear drag")
    if fm.has_decay:
        why_e.append("velocity decay")
    if fm.point_forces:
        why_e.append("applied point forces")
    if fm.torques:
        why_e.append("applied torques")
    why_l = []
    if not fm.torque_free:
        why_l.append("torques act about the COM")
    if fm.angular_velocity_decay != 1.0:
        why_l.append("angular velocity decay")
    why_p = []
    if np.any(np.asarray(fm.gravity_W) != 0):
        why_p.append("gravity")
    if fm.springs:
        why_p.append("springs")
    if fm.linear_drag_N_s_per_m:
        why_p.append("linear drag")
    if fm.point_forces:
        why_p.append("applied forces")
    if fm.velocity_decay != 1.0:
        why_p.append("velocity decay")
    return {
        "energy": (not why_e, "not conserved: " + ", ".join(why_e) if why_e else ""),
        "angular_momentum": (not why_l, "not conserved: " + ", ".join(why_l) if why_l else ""),
        "linear_momentum": (not why_p, "not conserved: " + ", ".join(why_p) if why_p else ""),
    }


def relative_drift(values):
    """Drift of a conserved quantity relative to its initial value.

    values : (T,) scalar series -> ``(v(t) − v(0)) / |v(0)|`` (signed);
             (T, 3) vector series -> ``|v(t) − v(0)| / |v(0)|``.
    An exactly zero initial value gives the absolute change (the relative one is undefined).
    """
    v = np.asarray(values, dtype=float)
    if v.ndim == 1:
        d = v - v[0]
        s = abs(float(v[0]))
    else:
        d = np.linalg.norm(v - v[0], axis=-1)
        s = float(np.linalg.norm(v[0]))
    return d / s if s > 0.0 else d


def drift_kind(t_s, drift, floor: float) -> str:
    """Classify a drift series: "roundoff" (max |drift| ≤ floor), "secular" (a least-squares trend
    over the run larger than ``SECULAR_TREND_VS_RESIDUAL`` residual standard deviations and the
    floor), else "bounded" (an oscillation). "n/a" for an empty or non-finite series."""
    t = np.asarray(t_s, dtype=float)
    d = np.asarray(drift, dtype=float)
    if d.size < 3 or not np.all(np.isfinite(d)):
        return "n/a"
    if float(np.max(np.abs(d))) <= floor:
        return "roundoff"
    A = np.column_stack([np.ones_like(t), t - t[0]])
    coef, *_ = np.linalg.lstsq(A, d, rcond=None)
    trend = float(coef[1] * (t[-1] - t[0]))
    resid = float(np.std(d - A @ coef))
    if abs(trend) > tol.SECULAR_TREND_VS_RESIDUAL * resid and abs(trend) > floor:
        return "secular"
    return "bounded"


# --- round-off floors ------------------------------------------------------------------------------

def quantity_scales(y_ref) -> dict:
    """Scale of each quantity along a reference trajectory (at least 1 in its SI unit): the
    magnitude round-off is relative to. Orientation errors are angles in [0, π]: scale π."""
    y_ref = np.asarray(y_ref, dtype=float)
    return {
        "position": max(1.0, float(np.max(np.linalg.norm(y_ref[:, X], axis=-1)))),
        "velocity": max(1.0, float(np.max(np.linalg.norm(y_ref[:, V], axis=-1)))),
        "orientation": math.pi,
        "angular_velocity": max(1.0, float(np.max(np.linalg.norm(y_ref[:, W], axis=-1)))),
    }


def roundoff_floor(scale: float, n_steps: int, reference_label: str = "analytic", *, reference_error=None,
                   amplification: float = 1.0, quantity: str = "position") -> float:
    """Smallest error that still says something about the scheme (same unit as ``scale``).

    With ``reference_error`` (the reference's MEASURED error in this quantity, see
    references.reference_error): ``reference_error + ε·scale·(b·N + √N·A)`` — the run's own round-off:
    roundings of the same sign add up linearly (b = 1 for position and velocity: a falling body's
    increments keep their sign, measured 0.34 N ε |x| on tumbling_box), the rest like a random walk,
    each grown by the measured error amplification A (measured: RK4 orientation flattens at 1.0 √N ε π
    on tennis_racket, at 0.8 √N ε π A on tumbling_box).
    Without a measurement (a caller that has none): ``max(N ε, REFERENCE_ACCURACY_REL[kind])·scale``.
    """
    n = max(n_steps, 1)
    eps = tol.ROUNDOFF_PER_STEP_REL
    if reference_error is None:
        kind = "ground_truth" if reference_label.startswith("ground_truth") else "analytic"
        return max(n * eps, tol.REFERENCE_ACCURACY_REL[kind]) * scale
    biased = n if quantity in ("position", "velocity") else 0
    return float(reference_error) + eps * scale * (biased + math.sqrt(n) * max(1.0, float(amplification)))


def drift_floor(n_steps: int, amplification: float = 1.0) -> float:
    """Round-off level of a relative drift after ``n_steps`` steps:
    ``n_steps · ROUNDOFF_PER_STEP_REL · amplification``, where ``amplification`` (≥ 1) is the size of
    the terms summed into the quantity relative to its initial value (see :func:`energy_J`)."""
    return max(n_steps, 1) * tol.ROUNDOFF_PER_STEP_REL * max(1.0, float(amplification))


# --- convergence -----------------------------------------------------------------------------------

def pairwise_orders(dt_s, errors) -> list:
    """``log(e_i / e_{i+1}) / log(Δt_i / Δt_{i+1})`` for consecutive ladder points (dt descending);
    ``log2(e(h) / e(h/2))`` for a halving ladder. None where an error is zero or not finite."""
    out = []
    for i in range(len(dt_s) - 1):
        e0, e1 = errors[i], errors[i + 1]
        if e0 is None or e1 is None or not (np.isfinite(e0) and np.isfinite(e1)) or e0 <= 0 or e1 <= 0:
            out.append(None)
        else:
            out.append(float(math.log(e0 / e1) / math.log(dt_s[i] / dt_s[i + 1])))
    return out


@dataclass
class ConvergenceFit:
    """Result of :func:`fit_convergence` (ladder sorted by Δt descending).

    order : least-squares slope over the fitted points, or None.
    pairwise_orders : between consecutive points (None where undefined).
    fitted : which points the slope used.
    verdict : "converges", "does_not_converge", "at_roundoff", "diverged", "failed" or "insufficient".
    note : why points were dropped, in words ("" when none were).
    order_is_lower_bound : the order came from points fewer than RESOLVED_ABOVE_FLOOR times above their
        floors (fewer than two were): round-off can only add to the finer errors, so the true order is
        at least this.
    """

    dt_s: list
    errors: list
    order: float | None
    pairwise_orders: list
    fitted: list
    verdict: str
    note: str = ""
    floors: list = field(default_factory=list)
    order_is_lower_bound: bool = False


def _lsq_slope(x, y):
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    xm = x - x.mean()
    return float(np.sum(xm * (y - y.mean())) / np.sum(xm * xm))


def fit_convergence(dt_s, errors, floors=None, statuses=None) -> ConvergenceFit:
    """Fit the convergence order of final errors over a Δt ladder and give a verdict.

    Parameters
    ----------
    dt_s : (K,) steps, s (any order; sorted descending here).
    errors : (K,) final errors (NaN for runs that produced none).
    floors : (K,) round-off floor of each point (see :func:`roundoff_floor`); 0 when omitted.
    statuses : (K,) run status per point ("ok", "diverged", "failed"); "ok" when omitted.

    Verdicts: fewer than two finished runs -> "diverged" (when any diverged) or "failed"/"insufficient";
    fewer than two points resolved above their floor -> "at_roundoff" (the scheme is exact here); else the
    least-squares order over the asymptotic points: "converges" when it is ≥ CONVERGES_MIN_ORDER and
    the error shrinks at every halving, otherwise "does_not_converge".
    """
    dt = np.asarray(dt_s, dtype=float)
    e = np.asarray(errors, dtype=float)
    fl = np.zeros_like(e) if floors is None else np.asarray(floors, dtype=float)
    st = np.array(["ok"] * len(dt) if statuses is None else list(statuses), dtype=object)
    order_idx = np.argsort(-dt, kind="stable")
    dt, e, fl, st = dt[order_idx], e[order_idx], fl[order_idx], st[order_idx]
    K = len(dt)
    pw = pairwise_orders(dt.tolist(), e.tolist())
    fitted = [False] * K
    res = dict(dt_s=dt.tolist(), errors=[float(v) for v in e], pairwise_orders=pw, floors=fl.tolist())

    ok = np.array([s == "ok" for s in st]) & np.isfinite(e)
    notes = []
    bad = [f"Δt = {dt[i]:g} s {st[i]}" for i in range(K) if not ok[i]]
    if bad:
        notes.append("; ".join(bad))
    if ok.sum() < 2:
        verdict = "diverged" if any(s == "diverged" for s in st) else ("failed" if any(s == "failed" for s in st)
                                                                       else "insufficient")
        return ConvergenceFit(order=None, fitted=fitted, verdict=verdict, note="; ".join(notes), **res)

    idx_ok = [int(i) for i in np.flatnonzero(ok)]
    # (a) Round-off at the fine end: the first point not resolved above its floor (≤ RESOLVED_ABOVE_FLOOR
    #     × floor: round-off may be a tenth of it) and every finer one, provided none of the finer ones is
    #     resolved (else the low point is an accident of the ladder — e.g. the one Δt where frame-rate
    #     dependent physics happens to match).
    above = list(idx_ok)
    for k, i in enumerate(idx_ok):
        if all(e[j] <= tol.RESOLVED_ABOVE_FLOOR * fl[j] for j in idx_ok[k:]):
            above = idx_ok[:k]
            notes.append(f"{len(idx_ok) - k} point(s) within {tol.RESOLVED_ABOVE_FLOOR:g}× the round-off floor "
                         f"dropped (Δt ≤ {dt[i]:g} s)")
            break
    # (b) Round-off amplified by the dynamics: the error grows again at the fine end while still tiny
    #     (≤ AMPLIFIED_ROUNDOFF_FACTOR × floor); drop the fine points within ROUNDOFF_NOISE_FACTOR of
    #     the smallest error.
    if len(above) >= 3 and e[above[-1]] > e[above[-2]]:
        m = min(e[i] for i in above)
        i_min = min(above, key=lambda i: e[i])
        finer = [i for i in above if i > i_min]
        if m <= tol.AMPLIFIED_ROUNDOFF_FACTOR * fl[i_min] and all(e[i] <= tol.ROUNDOFF_NOISE_FACTOR * m for i in finer):
            keep = list(above)
            while keep and e[keep[-1]] <= tol.ROUNDOFF_NOISE_FACTOR * m:
                keep.pop()
            notes.append(f"errors stop falling at {m:.2g} (Δt = {dt[i_min]:g} s) and grow again: round-off amplified "
                         f"by the dynamics; {len(above) - len(keep)} fine point(s) dropped")
            above = keep
    lower_bound = False
    if len(above) < 2:
        # Fewer than two resolved points: if the coarsest is resolved, fit it with the finer ones above the
        # floor itself; the order is then a lower bound (what round-off adds to a finer point can only
        # lower it). With no resolved point at all, the errors are round-off whatever they do.
        cand = list(idx_ok)
        while cand and e[cand[-1]] <= fl[cand[-1]]:
            cand.pop()
        if len(above) == 0 or len(cand) < 2 or len(cand) <= len(above):
            return ConvergenceFit(order=None, fitted=fitted, verdict="at_roundoff", note="; ".join(notes), **res)
        above, lower_bound = cand, True
        notes.append(f"fewer than two errors {tol.RESOLVED_ABOVE_FLOOR:g}× above their floors: fitted on the "
                     f"{len(cand)} above it, the order is a lower bound")

    use = list(above)
    # A pre-asymptotic coarsest point: its pairwise order is far from that of the finer pairs.
    if len(use) >= 4:
        pw_use = pairwise_orders(dt[use].tolist(), e[use].tolist())
        rest = [p for p in pw_use[1:] if p is not None]
        if pw_use[0] is not None and rest and all(p > 0 for p in rest) \
                and abs(pw_use[0] - float(np.median(rest))) > tol.PRE_ASYMPTOTIC_ORDER_DEV:
            notes.append(f"coarsest Δt = {dt[use[0]]:g} s pre-asymptotic (pairwise order {pw_use[0]:.2f}), dropped")
            use = use[1:]
    order = _lsq_slope(np.log(dt[use]), np.log(e[use]))
    for i in use:
        fitted[i] = True
    pw_use = pairwise_orders(dt[use].tolist(), e[use].tolist())
    shrinking = all(p is not None and p > 0 for p in pw_use)
    verdict = "converges" if order >= tol.CONVERGES_MIN_ORDER and shrinking else "does_not_converge"
    if (len(pw_use) >= 2 and all(p is not None for p in pw_use) and pw_use[-1] - pw_use[0] >= 0.2
            and all(b > a - 0.05 for a, b in zip(pw_use, pw_use[1:]))):
        notes.append(f"pairwise orders still rising towards the finest Δt ({pw_use[0]:.2f} → {pw_use[-1]:.2f}): "
                     "pre-asymptotic on this ladder")
    return ConvergenceFit(order=order, fitted=fitted, verdict=verdict, note="; ".join(notes),
                          order_is_lower_bound=lower_bound, **res)


def measured_pre_asymptotic(fit: ConvergenceFit, expected_order) -> str:
    """Why a converging fit whose order is too LOW is pre-asymptotic on its ladder, from the errors
    themselves ("" when it is not): the errors shrink at every halving, the finest fitted pair already
    shows the expected order (within SWEEP_ORDER_TOL) and the coarser pairs approach it. A scheme of
    the wrong order shows that order on its finest pair too, so it is not excused."""
    if fit.verdict != "converges" or fit.order_is_lower_bound or expected_order is None or fit.order is None:
        return ""
    if fit.order >= expected_order - tol.SWEEP_ORDER_TOL:
        return ""
    idx = [i for i, f in enumerate(fit.fitted) if f]
    pw = pairwise_orders([fit.dt_s[i] for i in idx], [fit.errors[i] for i in idx])
    if len(pw) < 2 or any(p is None for p in pw):
        return ""
    first, last = abs(pw[0] - expected_order), abs(pw[-1] - expected_order)
    if last <= tol.SWEEP_ORDER_TOL and last < first:
        return (f"pre-asymptotic (measured): fitted order {fit.order:.2f} over the ladder, but the finest pair "
                f"already shows {pw[-1]:.2f} (expected {expected_order:g}) and the coarser pairs approach it "
                f"({', '.join(f'{p:.2f}' for p in pw)}); no claim on this ladder")
    return ""


def compare_with_expectation(verdict: str, order, expected, order_is_lower_bound: bool = False) -> tuple:
    """``(matches, phrase)``: whether an observed verdict/order agrees with an
    :class:`~cross_checks.expectations.Expectation`; ``matches`` is None when nothing is expected (or
    the expectation makes no claim on this ladder, or the order is only a lower bound below it).

    A scheme that is exact to round-off, or converges faster than its nominal order, agrees with
    "converges"; a lower order (beyond SWEEP_ORDER_TOL), a plateau, a divergence or a failure do not.
    """
    ev, eo = expected.verdict, expected.order
    if ev is None:
        return None, "no expectation"
    if ev == "pre_asymptotic":
        seen = f"{verdict.replace('_', ' ')}" + (f", fitted order {order:.2f}" if order is not None else "")
        return None, f"no claim on this ladder (pre-asymptotic; {seen})"
    if verdict == "at_roundoff":
        return (ev == "converges"), ("exact to round-off" if ev == "converges"
                                     else "exact to round-off although non-convergence was expected")
    if verdict == "converges":
        if ev != "converges":
            return False, f"converges (order {order:.2f}) although non-convergence was expected"
        if eo is None:
            return True, f"converges (order {order:.2f})"
        if order < eo - tol.SWEEP_ORDER_TOL:
            if order_is_lower_bound:
                return None, (f"order ≥ {order:.2f} only (the finer errors are near the round-off floor), "
                              f"expected {eo:g}: inconclusive")
            return False, f"order {order:.2f}, expected {eo:g}"
        if order > eo + tol.SWEEP_ORDER_TOL:
            return True, f"order {order:.2f}, above the nominal {eo:g}"
        return True, f"order {order:.2f} as expected ({eo:g})"
    if verdict == "does_not_converge":
        if ev == "does_not_converge":
            return True, "does not converge, as expected"
        if order_is_lower_bound:
            return None, "the finer errors are near the round-off floor: inconclusive"
        return False, ("does not converge" + (f" (fitted order {order:.2f})" if order is not None else "")
                       + (f", expected order {eo:g}" if eo is not None else ""))
    return False, verdict.replace("_", " ")


# --- series helpers ---------------------------------------------------------------------------------

def decimation_indices(n: int, max_points: int) -> np.ndarray:
    """At most ``max_points`` indices evenly spread over ``range(n)``, always the first and the last."""
    if n <= max_points:
        return np.arange(n)
    return np.unique(np.round(np.linspace(0, n - 1, max_points)).astype(int))
