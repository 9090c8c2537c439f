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
from cross_checks.core.quantities import unit_q
from reference_sim.quaternion import matrix_from_quat
from reference_sim.state import Q, V, W, X

__all__ = ["energy_J", "angular_momentum_W", "linear_momentum_W", "conserved", "relative_drift",
           "drift_kind", "roundoff_floor", "drift_floor"]


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


def drift_floor(n_steps: int, amplification: float = 1.0, eps: float = tol.ROUNDOFF_PER_STEP_REL) -> float:
    """Round-off level of a relative drift after ``n_steps`` steps:
    ``n_steps · ROUNDOFF_PER_STEP_REL · amplification``, where ``amplification`` (≥ 1) is the size of
    the terms summed into the quantity relative to its initial value (see :func:`energy_J`)."""
    return max(n_steps, 1) * eps * max(1.0, float(amplification))
