"""Metrics of a trajectory beyond its errors (those are cross_checks.core.quantities): conservation
drifts, their classification, and the round-off floors verdicts are measured against.

Packed states ``y (..., 13)`` are ``[x_W (m), v_W (m/s), q_WB (w, x, y, z), w_W (rad/s, WORLD)]``.

Conservation (no reference needed), each only where the physics conserves it::

    energy            (E(t) − E(0)) / |E(0)|,  E = ½ m|v|² + ½ ωᵀ I_W ω + U_gravity + U_springs
    angular momentum  |L(t) − L(0)| / |L(0)|,  L = I_W ω about the COM (world)
    linear momentum   |p(t) − p(0)| / |p(0)|,  p = m v (only where no force acts)

(When the initial value is exactly zero the drift is the absolute change instead.)
"""
from __future__ import annotations

import math

import numpy as np

from cross_checks.core import tolerances as tol
from cross_checks.core.quantities import QUANTITIES, unit_q
from reference_sim.quaternion import matrix_from_quat
from reference_sim.state import Q, V, W, X

__all__ = ["energy_J", "angular_momentum_W", "linear_momentum_W", "conserved", "relative_drift",
           "drift_kind", "roundoff_floor", "differencing_floor", "lever_arms", "lever_roundoff",
           "lever_floor", "run_floor", "drift_floor", "same_scheme_allowance", "same_scheme_difference",
           "diverged_together"]


# --- conserved quantities --------------------------------------------------------------------------

def energy_J(problem, y, *, with_scale: bool = False):
    """Total energy (J) of states ``y (..., 13)``: ½ m|v|² + ½ ωᵀ I_W ω + gravity + spring potential.

    With ``with_scale`` also returns ``kinetic + |potential|`` (J), the size of the terms whose
    difference E is: the magnitude its round-off is relative to (a falling body's E is a small
    difference of large kinetic and potential energies).
    """
    y = np.asarray(y, dtype=float)
    body, fm = problem.body, problem.forces
    q = unit_q(y[..., Q])
    w = y[..., W]
    L = angular_momentum_W(problem, y)
    kinetic = 0.5 * body.mass_kg * np.sum(y[..., V] ** 2, axis=-1) + 0.5 * np.sum(w * L, axis=-1)
    potential = fm.potential_energy_J(body, y[..., X], q)
    if with_scale:
        return kinetic + potential, kinetic + np.abs(potential)
    return kinetic + potential


def angular_momentum_W(problem, y):
    """World angular momentum about the COM, ``I_W ω`` (kg m²/s), shape (..., 3)."""
    y = np.asarray(y, dtype=float)
    R = matrix_from_quat(unit_q(y[..., Q]))
    return np.einsum("...ij,...j->...i", problem.body.world_inertia(R), y[..., W])


def linear_momentum_W(problem, y):
    """Linear momentum ``m v`` (kg m/s), shape (..., 3)."""
    return problem.body.mass_kg * np.asarray(y, dtype=float)[..., V]


def conserved(forces) -> dict:
    """Which quantities the physics conserves: ``{name: (bool, reason when not)}`` for
    "energy", "angular_momentum", "linear_momentum"."""
    fm = forces
    gravity, drag = bool(np.any(np.asarray(fm.gravity_W) != 0)), bool(fm.linear_drag_N_s_per_m)
    causes = {
        "energy": [(drag, "linear drag"), (fm.has_decay, "velocity decay"),
                   (bool(fm.point_forces), "applied point forces"), (bool(fm.torques), "applied torques")],
        "angular_momentum": [(not fm.torque_free, "torques act about the COM"),
                             (fm.angular_velocity_decay != 1.0, "angular velocity decay")],
        "linear_momentum": [(gravity, "gravity"), (bool(fm.springs), "springs"), (drag, "linear drag"),
                            (bool(fm.point_forces), "applied forces"),
                            (fm.velocity_decay != 1.0, "velocity decay")],
    }
    out = {}
    for name, found in causes.items():
        why = [text for present, text in found if present]
        out[name] = (not why, "not conserved: " + ", ".join(why) if why else "")
    return out


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


def roundoff_floor(scale: float, n_steps: int, reference_label: str = "analytic", *, reference_error=None,
                   amplification: float = 1.0, quantity: str = "position",
                   eps: float = tol.ROUNDOFF_PER_STEP_REL) -> float:
    """Smallest error that still says something about the scheme (same unit as ``scale``).

    With ``reference_error`` (the reference's MEASURED error in this quantity, see
    references.reference_error): ``reference_error + ε·scale·(b·N + √N·A)`` — the run's own round-off:
    roundings of the same sign add up linearly (b = 1 for position and velocity, and for every quantity in
    float32), the rest like a random walk, each grown by the measured error amplification A
    (docs/verdicts.md §1).
    Without a measurement (a caller that has none): ``max(N ε, REFERENCE_ACCURACY_REL[kind])·scale``.
    ``eps``: the machine epsilon of the run's precision (tolerances.MACHINE_EPSILON; float64 by default) —
    the reference's error is measured in float64 whatever the run's precision.
    """
    n = max(n_steps, 1)
    if reference_error is None:
        kind = "ground_truth" if reference_label.startswith("ground_truth") else "analytic"
        return max(n * eps, tol.REFERENCE_ACCURACY_REL[kind]) * scale
    biased = n if quantity in ("position", "velocity") or eps > tol.ROUNDOFF_PER_STEP_REL else 0
    return float(reference_error) + eps * scale * (biased + math.sqrt(n) * max(1.0, float(amplification)))


def differencing_floor(position_scale: float, n_steps: int, dt_s: float,
                       eps: float = tol.ROUNDOFF_PER_STEP_REL, amplification: float = 1.0) -> float:
    """Round-off of a velocity recomputed as the change of position over Δt (engines.base.Traits.
    velocity_from_positions), m/s: the positions' round-off after ``n_steps`` steps (``ε·|x|·(N + √N·A)``, as
    :func:`roundoff_floor`'s run round-off of the position) divided by Δt — one step's ``ε|x|/Δt`` for N = 1.
    It grows as Δt shrinks (as Δt⁻² over a run of fixed duration)."""
    n = max(n_steps, 1)
    return eps * position_scale * (n + math.sqrt(n) * max(1.0, float(amplification))) / dt_s


def lever_arms(problem, y) -> dict:
    """What the round-off of lever arms measured from the world origin grows with, measured along the
    reference states ``y`` (T, 13) of ``problem``: ``{"position_max_m": max |x_W|, "velocity_max_m_s": max
    |v_W|, "angular_velocity_max_rad_s": max |ω_W|, "force_max_N": |m g| + max |f_W| (the force at the COM,
    weight included, reference_sim.forces), "mass_kg": m, "inertia_min_kg_m2": the smallest principal
    moment}`` (JSON-ready floats). Measured once per scenario (the sweep: with its reference; the fuzz: per
    case) and given to :func:`run_floor`."""
    p = problem
    y = np.asarray(y, dtype=float)
    q = y[:, 6:10] / np.linalg.norm(y[:, 6:10], axis=1, keepdims=True)
    f, _ = p.forces.force_torque(p.body, y[:, 0:3], y[:, 3:6], q, matrix_from_quat(q))
    weight = p.body.mass_kg * float(np.linalg.norm(p.forces.gravity_W))
    return {"position_max_m": float(np.max(np.linalg.norm(y[:, 0:3], axis=1))),
            "velocity_max_m_s": float(np.max(np.linalg.norm(y[:, 3:6], axis=1))),
            "angular_velocity_max_rad_s": float(np.max(np.linalg.norm(y[:, 10:13], axis=1))),
            "force_max_N": weight + float(np.max(np.linalg.norm(f, axis=1))),
            "mass_kg": float(p.body.mass_kg),
            "inertia_min_kg_m2": float(np.linalg.eigvalsh(p.body.inertia_B)[0])}


def lever_roundoff(lever: dict, eps: float) -> dict:
    """An engine's round-off from lever arms measured from the world origin (MuJoCo's and Featherstone's
    spatial algebra: the COM of a subtree recomputed as Σ m x / Σ m, torques as r × F with r known to
    ε |x| only, momenta about the origin), for the measurements ``lever`` (:func:`lever_arms`) in a
    precision of machine epsilon ``eps``: ``{"acc_rad_s2": a, "velocity_m_s": u, "omega_rad_s": w}`` with
    a = K ε |x|max (|m g| + |F|max) / I_min the angular acceleration it may add, u = K ε |x|max |ω|max the
    velocity error of a spatial transform v − ω × x, and w = K ε m |x|max |v|max / I_min the angular
    velocity error of recovering ω from a momentum about the origin that holds m x × v
    (K = tolerances.LEVER_ROUNDINGS; measured on MuJoCo: docs/fuzz.md §5)."""
    x, F = lever["position_max_m"], lever["force_max_N"]
    w, v = lever["angular_velocity_max_rad_s"], lever["velocity_max_m_s"]
    I_min = lever["inertia_min_kg_m2"]
    k = tol.LEVER_ROUNDINGS * eps
    return {"acc_rad_s2": k * x * F / I_min, "velocity_m_s": k * x * w,
            "omega_rad_s": k * lever["mass_kg"] * x * v / I_min}


def lever_floor(lever: dict, quantity: str, dt_s: float, n_steps: int, amplification: float = 1.0,
                eps: float = 2.0 ** -52) -> float:
    """The lever-arm round-off (:func:`lever_roundoff`) in ``quantity`` after ``n_steps`` steps of ``dt_s``
    (t = n Δt), grown by ``amplification``: the angular acceleration a integrates to a t in ω and ½ a t² in
    the orientation; the ω representation error w is made anew every step, adding like a random walk
    (1 + √n), and moves the orientation by w t (1 + √n); the velocity error u of a transform adds up every
    step (n u), and the position by n u Δt."""
    lv = lever_roundoff(lever, eps)
    a, u, w = lv["acc_rad_s2"], lv["velocity_m_s"], lv["omega_rad_s"]
    n, t = n_steps, dt_s * n_steps
    walk = 1.0 + math.sqrt(n)
    if quantity == "angular_velocity":
        return (a * t + w * walk) * amplification
    if quantity == "orientation":
        return (0.5 * a * t * t + w * t * walk) * amplification
    if quantity == "velocity":
        return u * n * amplification
    return u * n * dt_s * amplification


def run_floor(variant, quantity: str, n_steps: int, dt_s: float, scales: dict, reference_error=None, *,
              amplification: float = 1.0, lever: dict | None = None,
              reference_label: str = "analytic") -> float:
    """THE round-off floor of a run (the sweep's convergence records, its refinement and the fuzz's order
    properties all take theirs from here): ``n_steps`` steps of ``dt_s`` of ``variant`` (a Resolved
    ENGINE:VARIANT, cross_checks.engines.resolve) in ``quantity``, in the unit of ``scales[quantity]``:

    * :func:`roundoff_floor`: the reference's measured ``reference_error`` plus the run's own round-off in
      the variant's rounding unit (ε of its precision × its rounding factor), grown by ``amplification``;
    * for the velocity of a variant that recomputes it from positions (Traits.velocity_from_positions),
      :func:`differencing_floor`;
    * for a variant whose arithmetic may hold lever arms from the world origin (Traits.lever_arms: every
      engine but rbcheck's own schemes), :func:`lever_floor` of the measurements ``lever``
      (:func:`lever_arms` along the reference; None: not measured, no lever term), in its precision's ε.

    A one-step run is ``n_steps = 1`` with the reference's one-step error and ``amplification`` 1."""
    eps = variant.rounding_unit
    f = roundoff_floor(scales[quantity], n_steps, reference_label, reference_error=reference_error,
                       amplification=amplification, quantity=quantity, eps=eps)
    if quantity == "velocity" and variant.traits.velocity_from_positions:
        f += differencing_floor(scales["position"], n_steps, dt_s, eps, amplification)
    if lever and variant.traits.lever_arms:
        lever_eps = float(np.finfo(variant.precision).eps) * float(variant.traits.rounding_factor)
        f += lever_floor(lever, quantity, dt_s, n_steps, amplification, lever_eps)
    return f


def drift_floor(n_steps: int, amplification: float = 1.0, eps: float = tol.ROUNDOFF_PER_STEP_REL) -> float:
    """Round-off level of a relative drift after ``n_steps`` steps:
    ``n_steps · ROUNDOFF_PER_STEP_REL · amplification``, where ``amplification`` (≥ 1) is the size of
    the terms summed into the quantity relative to its initial value (see :func:`energy_J`)."""
    return max(n_steps, 1) * eps * max(1.0, float(amplification))


# --- the same arithmetic twice ---------------------------------------------------------------------


def same_scheme_allowance(n_steps: int, eps: float, amplification: float = 1.0) -> float:
    """THE allowance of two variants that compute the same arithmetic (expectations.EQUIVALENT_PAIRS), the
    sweep's agreement records and the fuzz's agreement property alike: the largest difference relative to
    each quantity's scale (:func:`same_scheme_difference`) after ``n_steps`` steps —
    ``max(SAME_SCHEME_REL, SAME_SCHEME_ROUNDINGS_PER_STEP · N ε A)``: the two round differently at each of
    the step's roundings, in the coarser of their rounding units ``eps``, and the dynamics grow what they
    left by the measured ``amplification`` A (the largest over the quantities)."""
    return max(tol.SAME_SCHEME_REL, tol.SAME_SCHEME_ROUNDINGS_PER_STEP * n_steps * eps * amplification)


def same_scheme_difference(differences: dict, scales: dict) -> tuple:
    """``(largest relative difference, its quantity)`` of two runs' ``differences`` {quantity: largest
    difference, its unit} (core.quantities.state_errors): positions, velocities and angular velocities
    relative to ``scales`` (core.quantities.quantity_scales: at least 1), the orientation in rad."""
    rel = {q: float(differences[q]) / (1.0 if q == "orientation" else scales[q]) for q in QUANTITIES}
    worst = max(rel, key=lambda q: rel[q])
    return rel[worst], worst


def diverged_together(t_a_s: float, t_b_s: float, dt_s: float) -> bool:
    """Two runs of the same arithmetic that both diverged did so together: detection may differ by a step
    (MuJoCo flags its instability warning during the step that starts the blow-up), so within 2 Δt."""
    return abs(float(t_a_s) - float(t_b_s)) <= 2.0 * dt_s + 1e-12
