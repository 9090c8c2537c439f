"""The reference solution of a scenario: a closed form where one exists, else the DOP853 ground truth.

Translation and rotation decouple when no force produces a torque (forces at the COM only); then
each part gets its own closed form:

* translation: gravity (+ constant world forces at the COM) -> projectile; + linear drag or the
  course's velocity decay -> exponential drag; one spring at the COM -> harmonic oscillator;
* rotation (torque-free): reference_sim.analytic.torque_free (constant spin, axisymmetric top, or the
  Jacobi elliptic solution); with angular velocity decay, only a spin about a principal axis.

The course's velocity decay is the continuously damped motion ``v̇ = f/m − k v``, ``k = −ln γ / dt``
(docs/semantics.md, "Velocity decay").
"""
from __future__ import annotations

import math

import numpy as np

from reference_sim import analytic
from reference_sim.ground_truth import GROUND_TRUTH_RTOL, ground_truth
from reference_sim.quaternion import quat_exp, quat_mul
from reference_sim.state import Q, V, W, X

__all__ = ["reference_solution", "analytic_available", "error_amplification", "amplification_of",
           "reference_error",
           "final_states", "perturbed_initial_states"]


def _translation_kind(scenario):
    fm = scenario.problem.forces
    if not fm.torque_free:
        return None, "a force acts off the COM or a torque acts (translation and rotation coupled)"
    if any(p.frame == "body" for p in fm.point_forces):
        return None, "a body-frame force at the COM turns with the body"
    if fm.springs:
        if len(fm.springs) > 1:
            return None, "more than one spring"
        if fm.linear_drag_N_s_per_m != 0.0 or fm.velocity_decay != 1.0:
            return None, "a spring with drag or velocity decay"
        return "harmonic", ""
    if fm.linear_drag_N_s_per_m != 0.0 or fm.velocity_decay != 1.0:
        return "drag", ""
    return "projectile", ""


def _rotation_kind(scenario):
    fm = scenario.problem.forces
    p = scenario.problem
    if not fm.torque_free:
        return None, "torques act on the body"
    if fm.angular_velocity_decay != 1.0:
        if p.body.gyroscopic_torque_vanishes(p.initial.q_WB, p.initial.w_W):
            return "decaying_spin", ""
        return None, "angular velocity decay on a body not spinning about a principal axis"
    return "torque_free", ""


def analytic_available(scenario):
    """``(True, "")`` when a closed form covers the scenario, else ``(False, why)``."""
    t, why_t = _translation_kind(scenario)
    if t is None:
        return False, why_t
    r, why_r = _rotation_kind(scenario)
    if r is None:
        return False, why_r
    if t == "harmonic":
        s = scenario.problem.forces.springs[0]
        if s.rest_length_m != 0.0:
            try:
                _translation(scenario, np.array([0.0]))
            except ValueError as exc:
                return False, str(exc)
    return True, ""


def _translation(scenario, t_s):
    p = scenario.problem
    fm = p.forces
    m = p.body.mass_kg
    g_eff = np.asarray(fm.gravity_W, float) + sum((pf.force for pf in fm.point_forces), np.zeros(3)) / m
    kind, _ = _translation_kind(scenario)
    if kind == "projectile":
        return analytic.projectile(p.initial.x_W, p.initial.v_W, g_eff, t_s)
    if kind == "drag":
        c = fm.linear_drag_N_s_per_m + m * fm.decay_rates_per_s()[0]
        return analytic.linear_drag(m, c, p.initial.x_W, p.initial.v_W, g_eff, t_s)
    s = fm.springs[0]
    return analytic.harmonic_oscillator(m, s.stiffness_N_per_m, s.rest_length_m, s.anchor_W,
                                        p.initial.x_W, p.initial.v_W, g_eff, t_s)


def _rotation(scenario, t_s):
    p = scenario.problem
    kind, _ = _rotation_kind(scenario)
    if kind == "torque_free":
        return analytic.torque_free(p.body.inertia_B, p.initial.q_WB, p.initial.w_W, t_s)
    # Spin about a fixed principal axis with ω(t) = ω0 e^{−kt}: angle ∫ω = ω0 (1 − e^{−kt}) / k.
    k = p.forces.decay_rates_per_s()[1]
    w0 = np.asarray(p.initial.w_W, float)
    frac = -np.expm1(-k * t_s) / k  # (1 − e^{−kt}) / k, s
    q = quat_mul(quat_exp(frac[:, None] * w0), p.initial.q_WB)
    w = np.exp(-k * t_s)[:, None] * w0
    return q, w


def reference_solution(scenario, t_s):
    """Reference states at times ``t_s`` (T,): ``(y (T, 13), label)``.

    ``label`` is "analytic" or "ground_truth (DOP853, rtol GROUND_TRUTH_RTOL)". A scenario that asks for
    ``reference = "ground_truth"`` gets the ground truth even where a closed form exists.
    """
    t_s = np.asarray(t_s, dtype=float)
    use_analytic = scenario.reference != "ground_truth" and analytic_available(scenario)[0]
    if use_analytic:
        y = np.empty((t_s.size, 13))
        y[:, X], y[:, V] = _translation(scenario, t_s)
        y[:, Q], y[:, W] = _rotation(scenario, t_s)
        return y, "analytic"
    return (ground_truth(scenario.problem, t_s),
            f"ground_truth (DOP853, rtol {GROUND_TRUTH_RTOL:g})")


def _with_initial(scenario, y0):
    """``scenario`` started from the packed state ``y0`` (13,) instead of its own initial state."""
    import dataclasses

    from reference_sim.state import Problem, State
    p = scenario.problem
    return dataclasses.replace(scenario, problem=Problem(p.body, p.forces, State(y0[X], y0[V], y0[Q], y0[W])))


def perturbed_initial_states(scenario, size: float, scales: dict) -> np.ndarray:
    """The initial state perturbed along each of its 12 directions: ``(13, 13)``, row 0 unperturbed, then
    x0 and v0 by ``size·scale`` along each world axis, the orientation by a rotation of ``size·π`` rad
    about each world axis, ω0 by ``size·scale`` along each world axis (``scales``: per quantity)."""
    y0 = scenario.problem.initial_packed()
    out = np.tile(y0, (13, 1))
    for k in range(3):
        out[1 + k, k] += size * scales["position"]
        out[4 + k, 3 + k] += size * scales["velocity"]
        out[7 + k, Q] = quat_mul(quat_exp(size * math.pi * np.eye(3)[k]), y0[Q])
        out[10 + k, 10 + k] += size * scales["angular_velocity"]
    return out


def final_states(scenario, y0s, rtol: float | None = None) -> np.ndarray:
    """The reference's state at the scenario's final time from each initial state of ``y0s`` (B, 13):
    the closed form where it covers the scenario, else one batched DOP853 solve (at ``rtol``)."""
    t = np.array([0.0, scenario.duration_s])
    if scenario.reference != "ground_truth" and analytic_available(scenario)[0]:
        return np.array([reference_solution(_with_initial(scenario, y0), t)[0][-1] for y0 in y0s])
    kw = {} if rtol is None else {"rtol": rtol}
    return ground_truth(scenario.problem, t, y0=np.asarray(y0s, dtype=float), **kw)[-1]


def _default_scales(scenario):
    from cross_checks.core.quantities import quantity_scales
    y, _ = reference_solution(scenario, np.linspace(0.0, scenario.duration_s, 201))
    return quantity_scales(y)


def error_amplification(scenario, scales: dict | None = None) -> dict:
    """How much the dynamics amplify an initial error by the final time, per quantity (values ≥ 1):
    ``max_k |Δq(T)| / scale_q / ε`` over perturbations of relative size ε = AMPLIFICATION_EPS along each
    of the 12 directions of the initial state (:func:`perturbed_initial_states`; ``scales`` as in
    quantities.quantity_scales). The closed form where there is one, else a batched DOP853 solve at
    AMPLIFICATION_RTOL; the estimate is :func:`amplification_of` at the final time. Near an unstable rotation
    it is large, and round-off grows by as much.
    """
    from cross_checks.core import tolerances as tol
    scales = scales or _default_scales(scenario)
    y0s = perturbed_initial_states(scenario, tol.AMPLIFICATION_EPS, scales)
    yT = final_states(scenario, y0s, rtol=tol.AMPLIFICATION_RTOL)
    return {q: float(a[0]) for q, a in amplification_of(yT[None, None], [scales]).items()}


def amplification_of(y, scales) -> dict:
    """THE error amplification estimate (the sweep's, :func:`error_amplification`, and the fuzz's,
    fuzz.exact.amplification): ``max |Δq| / scale_q / AMPLIFICATION_EPS`` over the 12 perturbed solutions and
    the times given, at least 1 (a perturbed solution that blew up, NaN, counts as infinite).

    y : (S, M, 13, 13) states at S times of M scenarios' 13 solutions from
        :func:`perturbed_initial_states` (row 0 unperturbed, moved by AMPLIFICATION_EPS × the scales);
    scales : M dicts {quantity: scale}. Returns {quantity: (M,)}.
    """
    from cross_checks.core import tolerances as tol
    from cross_checks.core.quantities import QUANTITIES, state_errors
    eps = tol.AMPLIFICATION_EPS
    base = np.broadcast_to(y[:, :, :1, :], y.shape)
    d = state_errors(y[:, :, 1:, :], base[:, :, 1:, :])
    out = {}
    for q in QUANTITIES:
        sc_q = np.array([s[q] for s in scales])
        worst = np.max(np.nan_to_num(d[q], nan=np.inf), axis=(0, 2))
        out[q] = np.maximum(1.0, worst / sc_q / eps)
    return out


def reference_error(scenario, y_final, label: str, scales: dict | None = None) -> dict:
    """The measured error of the reference's final state ``y_final`` (13,), per quantity (its unit).

    * DOP853: the difference from a second solution at a REFERENCE_CHECK_RTOL_FACTOR times looser
      tolerance — that solution's error, an upper bound of the reference's own (DOP853's error falls
      with its tolerance: docs/verdicts.md §1).
    * Closed form: its own round-off, seen by evaluating it in a perturbed way — its inputs (each
      direction of the initial state, :func:`perturbed_initial_states`) and the final time moved by
      CLOSED_FORM_INPUT_ULPS ulps, as its internal roundings move them: the largest change.
    """
    from cross_checks.core import tolerances as tol
    from cross_checks.core.quantities import QUANTITIES, state_errors
    y_final = np.asarray(y_final, dtype=float)
    if label.startswith("ground_truth"):
        y_check = ground_truth(scenario.problem, np.array([0.0, scenario.duration_s]),
                               rtol=tol.REFERENCE_CHECK_RTOL_FACTOR * GROUND_TRUTH_RTOL)[-1]
        d = state_errors(y_check[None], y_final[None])
        return {q: float(d[q][0]) for q in QUANTITIES}
    scales = scales or _default_scales(scenario)
    size = tol.CLOSED_FORM_INPUT_ULPS * np.finfo(float).eps
    y0s = perturbed_initial_states(scenario, size, scales)
    finals = [final_states(scenario, y0s[1:])]
    T = scenario.duration_s
    for t in (T * (1.0 + size), T * (1.0 - size)):
        finals.append(reference_solution(scenario, np.array([0.0, t]))[0][-1:])
    yT = np.concatenate(finals)
    d = state_errors(yT, np.broadcast_to(y_final, yT.shape))
    return {q: float(np.max(d[q])) for q in QUANTITIES}
