"""The reference solution of a scenario: a closed form where one exists, else the DOP853 ground truth.

Translation and rotation decouple when no force produces a torque (forces at the COM only); then
each part gets its own closed form:

* translation: gravity (+ constant world forces at the COM) -> projectile; + linear drag or the
  course's velocity decay -> exponential drag; one spring at the COM -> harmonic oscillator;
* rotation (torque-free): reference_sim.analytic.torque_free (constant spin, axisymmetric top, or the
  Jacobi elliptic solution); with angular velocity decay, only a spin about a principal axis.

The course's per-step decay factor γ (given at the scenario's dt) is, physically, exponential
damping at the rate ``k = −ln γ / dt``: ``v̇ = f/m − k v`` (and the same for ω). The reference is that
continuously damped motion; every engine variant applies ``e^{−kΔt}`` per step or ``−k v`` in its
right-hand side, so every variant converges to it (at Δt = dt the course variants apply exactly γ).
"""
from __future__ import annotations

import math

import numpy as np

from reference_sim import analytic
from reference_sim.ground_truth import GROUND_TRUTH_RTOL, ground_truth
from reference_sim.quaternion import quat_exp, quat_mul
from reference_sim.state import Q, V, W, X

__all__ = ["reference_solution", "analytic_available", "decay_rates_per_s"]


def decay_rates_per_s(scenario):
    """Continuous rates (k_v, k_ω), 1/s, equal to the per-step decay factors at the scenario's dt."""
    return scenario.problem.forces.decay_rates_per_s()


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
        c = fm.linear_drag_N_s_per_m + m * decay_rates_per_s(scenario)[0]
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
    k = decay_rates_per_s(scenario)[1]
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


#: Relative size of the initial-ω perturbation used to measure error amplification: large enough
#: that the closed form resolves the response (1e-7 ≫ its 1e-12 accuracy), small enough to stay
#: linear over the catalog's durations.
AMPLIFICATION_EPS = 1e-7


def error_amplification(scenario) -> dict:
    """How much the dynamics amplify an error in the initial angular velocity by the final time.

    For each quantity: ``max_k |Δq(T)| / scale_q / ε`` over perturbations ``ω0 → ω0 + ε|ω0| e_k``,
    computed with the closed form (cheap). Near an unstable rotation (tumbling_box flips ~8 times)
    this is ~1e2–1e3: round-off and reference errors grow by as much, so the round-off floor of a
    convergence fit must too. Scenarios without a closed form return 1 (their DOP853 floor, 1e-10
    relative, already dominates). Values are ≥ 1.
    """
    import dataclasses

    from reference_sim.state import Problem, State
    from .expectations import QUANTITIES
    ones = {q: 1.0 for q in QUANTITIES}
    if scenario.reference == "ground_truth" or not analytic_available(scenario)[0]:
        return ones
    p = scenario.problem
    w0 = np.asarray(p.initial.w_W, float)
    size = AMPLIFICATION_EPS * max(float(np.linalg.norm(w0)), 1e-3)
    t = np.array([0.0, scenario.duration_s])
    y0, _ = reference_solution(scenario, t)
    from reference_sim.quaternion import geodesic_angle
    scales = {"position": max(1.0, float(np.linalg.norm(y0[-1, X]))), "velocity": max(1.0, float(np.linalg.norm(y0[-1, V]))),
              "orientation": math.pi, "angular_velocity": max(1.0, float(np.linalg.norm(w0)))}
    amp = dict(ones)
    for k in range(3):
        w = w0.copy()
        w[k] += size
        sc = dataclasses.replace(scenario, problem=Problem(p.body, p.forces, State(p.initial.x_W, p.initial.v_W,
                                                                                   p.initial.q_WB, w)))
        y1, _ = reference_solution(sc, t)
        rel = size / scales["angular_velocity"]
        d = {"position": np.linalg.norm(y1[-1, X] - y0[-1, X]), "velocity": np.linalg.norm(y1[-1, V] - y0[-1, V]),
             "orientation": float(geodesic_angle(y0[-1, Q], y1[-1, Q])),
             "angular_velocity": np.linalg.norm(y1[-1, W] - y0[-1, W])}
        for q in QUANTITIES:
            amp[q] = max(amp[q], float(d[q]) / scales[q] / rel)
    return amp
