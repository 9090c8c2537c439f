"""Long runs of a torque-free body: over thousands of periods, does a scheme keep the energy, |L| and L's
direction — and does its energy drift towards ``L²/2I₂``, turning a stable spin about the major or the minor
axis into an intermediate-axis tumble? A qualitative failure no short convergence ladder shows
(docs/gyro_integrators.md, "Long runs").

The separatrix distance ``δ = (2E I₂ − |L|²)/|L|²`` is ``I₂/I₃ − 1 < 0`` for a pure spin about the major axis,
``I₂/I₁ − 1 > 0`` about the minor axis, and 0 on the separatrix (the intermediate-axis tumble). A scheme that
keeps E and |L| keeps δ; one whose E and |L|² drift together (a body-frame Euler step: a time rescaling) keeps
it too; one whose energy moves towards ``L²/2I₂`` at fixed |L| drives |δ| to 0.

Each run is one member of :func:`reference_sim.simulate.run_members` (or any step function of the
definition's signature); the metrics read only the recorded states.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from reference_sim.body import RigidBody
from reference_sim.forces import ForceModel
from reference_sim.quaternion import matrix_from_quat
from reference_sim.state import Problem, State

__all__ = ["LongRun", "long_runs", "DriftMetrics", "drift_metrics", "finding", "SECULAR_MIN_CHANGE",
           "SECULAR_MIN_TREND_TO_SCATTER"]

#: A secular drift of |δ| is named only when |δ| has changed by the end (the mean of the last 5 % of the run)
#: by at least this share of |δ(0)|:
#: a scheme that keeps δ (to round-off, or with a bounded O(Δt²) oscillation) changes it by far less
#: (measured on the long runs below: ≤ 1e-9 for the midpoint rule, ≤ 2e-4 for DLM's bounded oscillation).
SECULAR_MIN_CHANGE = 0.02
#: ... and at least this many times the scatter of |δ| (its standard deviations over the first and over the
#: last 5 % of the run, added): a bounded oscillation changes its mean by less than its scatter; a drift, far
#: more.
SECULAR_MIN_TREND_TO_SCATTER = 3.0

#: The long runs' body: principal moments 1, 2, 3 kg m² (the catalog's tennis racket).
_MOMENTS = (1.0, 2.0, 3.0)


@dataclass(frozen=True)
class LongRun:
    """A torque-free long run: ``problem``, ``n_steps`` steps of ``dt_s``, and what it is."""

    name: str
    problem: Problem
    dt_s: float
    n_steps: int
    description: str


def long_runs(periods: float = 2000.0, dt_s: float = 0.01, spin_rad_s: float = 2.0,
              perturbation: float = 0.01) -> list:
    """The three long runs: a spin about the major axis and one about the minor axis, each perturbed by
    ``perturbation`` × ``spin_rad_s`` about the other two axes, and the tennis racket (a spin about the
    intermediate axis, the same perturbation); each ``periods`` spin periods ``2π/spin`` long."""
    T = periods * 2.0 * math.pi / spin_rad_s
    n = int(round(T / dt_s))
    body = RigidBody(1.0, np.diag(np.asarray(_MOMENTS, dtype=float)))
    out = []
    for name, axis, what in (("major_axis_spin", 2, "a stable spin about the major axis (I₃ = 3)"),
                             ("minor_axis_spin", 0, "a stable spin about the minor axis (I₁ = 1)"),
                             ("tennis_racket_long", 1, "the tennis racket: a spin about the middle axis")):
        w = np.full(3, perturbation * spin_rad_s)
        w[axis] = spin_rad_s
        init = State(np.zeros(3), np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0]), w)
        out.append(LongRun(name, Problem(body, ForceModel(), init), dt_s, n,
                           f"{what}, perturbed by {perturbation:g} of the spin, over {periods:g} periods"))
    return out


@dataclass(frozen=True)
class DriftMetrics:
    """What a long run did to the conserved quantities of the free rigid body.

    energy_rate_per_s : the secular rate of the relative energy, ``d/dt (E − E₀)/E₀`` (least squares), 1/s.
    energy_drift_max : ``max |E/E₀ − 1|``.
    momentum_rate_per_s : the same for |L|; momentum_drift_max : ``max ||L|/|L₀| − 1|``.
    direction_drift_max_rad : the largest angle between L(t) and L(0), rad (L is fixed in the world).
    separatrix_start, separatrix_end : δ at the start and at the end (the mean of the last 5 % of the run).
    separatrix_rate_per_s : the mean rate of |δ| over the run, (|δ|(end) − |δ|(0))/T, 1/s: negative towards
        the separatrix (a drift that reaches the separatrix stops there: a least-squares slope would hide it).
    toward_intermediate : |δ| has fallen by the end (SECULAR_MIN_CHANGE, SECULAR_MIN_TREND_TO_SCATTER).
    away_from_intermediate : |δ| grows secularly by the same measures (a damped tumble settling into a spin).
    duration_s : the run's length.
    """

    energy_rate_per_s: float
    energy_drift_max: float
    momentum_rate_per_s: float
    momentum_drift_max: float
    direction_drift_max_rad: float
    separatrix_start: float
    separatrix_end: float
    separatrix_rate_per_s: float
    toward_intermediate: bool
    away_from_intermediate: bool
    duration_s: float


def _slope(t, a):
    """Least-squares slope of a(t) and the RMS of the residuals."""
    A = np.column_stack([t, np.ones_like(t)])
    coef, *_ = np.linalg.lstsq(A, a, rcond=None)
    return float(coef[0]), float(np.sqrt(np.mean((a - A @ coef) ** 2)))


def drift_metrics(problem: Problem, t_s, y) -> DriftMetrics:
    """:class:`DriftMetrics` of the recorded states ``y`` (n, 13) at times ``t_s`` (n,) of a torque-free
    run."""
    t = np.asarray(t_s, dtype=float)
    y = np.asarray(y, dtype=float)
    R = matrix_from_quat(y[:, 6:10] / np.linalg.norm(y[:, 6:10], axis=-1, keepdims=True))
    w = y[:, 10:13]
    L = np.einsum("nij,nj->ni", R @ problem.body.inertia_B @ np.swapaxes(R, -1, -2), w)
    E = 0.5 * np.sum(w * L, axis=-1)
    Lm = np.linalg.norm(L, axis=-1)
    I2 = float(np.linalg.eigvalsh(problem.body.inertia_B)[1])
    delta = (2.0 * E * I2 - Lm ** 2) / Lm ** 2
    e_rel, l_rel = E / E[0] - 1.0, Lm / Lm[0] - 1.0
    cos = np.clip(L @ L[0] / (Lm * Lm[0]), -1.0, 1.0)
    T = float(t[-1] - t[0])
    k = max(1, len(delta) // 20)
    a = np.abs(delta)
    end = float(np.mean(delta[-k:]))
    change = float(a[0] - np.mean(a[-k:]))          # how much |δ| fell over the run (start vs the last 5 %)
    scatter = float(np.std(a[:k]) + np.std(a[-k:]))  # a bounded oscillation's size at either end

    def secular(c):
        return bool(c >= SECULAR_MIN_CHANGE * abs(delta[0]) and c >= SECULAR_MIN_TREND_TO_SCATTER * scatter)

    return DriftMetrics(_slope(t, e_rel)[0], float(np.max(np.abs(e_rel))), _slope(t, l_rel)[0],
                        float(np.max(np.abs(l_rel))), float(np.max(np.arccos(cos))), float(delta[0]), end,
                        -change / T, secular(change), secular(-change), T)


def finding(variant: str, run_name: str, m: DriftMetrics) -> str:
    """The finding of a long run: "" when |δ| drifts neither way."""
    if m.toward_intermediate:
        what = "drifts toward the intermediate axis (energy → L²/2I₂)"
    elif m.away_from_intermediate:
        what = "drifts away from the intermediate axis (a tumble settles into a spin)"
    else:
        return ""
    return (f"{variant} on {run_name}: {what} at rate {abs(m.separatrix_rate_per_s):.3g}/s of the "
            f"separatrix distance δ = (2E I₂ − |L|²)/|L|² (δ from {m.separatrix_start:.3g} to "
            f"{m.separatrix_end:.3g} over {m.duration_s:.4g} s; energy {m.energy_rate_per_s:+.3g}/s, "
            f"|L| {m.momentum_rate_per_s:+.3g}/s)")
