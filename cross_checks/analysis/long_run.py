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

from cross_checks.core.tolerances import (
    LONG_RUN_END_FRACTION,
    SECULAR_MIN_CHANGE,
    SECULAR_MIN_TREND_TO_SCATTER,
)
from reference_sim.body import RigidBody
from reference_sim.forces import ForceModel
from reference_sim.quaternion import matrix_from_quat
from reference_sim.state import Problem, State

__all__ = ["LongRun", "long_runs", "DriftMetrics", "drift_metrics", "drift_series", "finding", "drift_kind",
           "SECULAR_MIN_CHANGE", "SECULAR_MIN_TREND_TO_SCATTER", "DRIFT_KINDS"]

#: What a long run's separatrix distance did (DriftMetrics.kind): crossed the separatrix, drifted toward it,
#: away from it, or neither.
DRIFT_KINDS = ("crosses_separatrix", "toward_intermediate", "away_from_intermediate", "none")

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
    crossed_separatrix : δ changed sign by the end, from a start clearly off the separatrix, and ends as far
        past it as a drift must move (SECULAR_MIN_CHANGE of |δ(0)|, SECULAR_MIN_TREND_TO_SCATTER × the
        scatter): the energy went to L²/2I₂ and past it (a spin about the major axis became one about the
        minor axis, or the reverse).
    energy_secular : the relative energy's mean over the last LONG_RUN_END_FRACTION of the run differs from
        its value at the start by more than SECULAR_MIN_TREND_TO_SCATTER times its scatter there (a bounded
        oscillation does not; a drift does), and by more than ``energy_floor`` given to :func:`drift_metrics`.
    steps : the run's recorded steps.
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
    crossed_separatrix: bool = False
    energy_secular: bool = False
    steps: int = 0

    @property
    def kind(self) -> str:
        """One of DRIFT_KINDS (a crossing first: it passed through the separatrix on its way)."""
        return drift_kind(self)


def drift_kind(m) -> str:
    """What the separatrix distance of :class:`DriftMetrics` ``m`` did: one of DRIFT_KINDS."""
    if m.crossed_separatrix:
        return "crosses_separatrix"
    if m.toward_intermediate:
        return "toward_intermediate"
    if m.away_from_intermediate:
        return "away_from_intermediate"
    return "none"


def _slope(t, a):
    """Least-squares slope of a(t) and the RMS of the residuals."""
    A = np.column_stack([t, np.ones_like(t)])
    coef, *_ = np.linalg.lstsq(A, a, rcond=None)
    return float(coef[0]), float(np.sqrt(np.mean((a - A @ coef) ** 2)))


def _invariants(problem: Problem, y):
    """Rotational energy (J), world angular momentum about the COM (N m s, (n, 3)) and the separatrix
    distance δ of the packed states ``y`` (n, 13) of a torque-free body."""
    R = matrix_from_quat(y[:, 6:10] / np.linalg.norm(y[:, 6:10], axis=-1, keepdims=True))
    w = y[:, 10:13]
    L = np.einsum("nij,nj->ni", R @ problem.body.inertia_B @ np.swapaxes(R, -1, -2), w)
    E = 0.5 * np.sum(w * L, axis=-1)
    Lm = np.linalg.norm(L, axis=-1)
    I2 = float(np.linalg.eigvalsh(problem.body.inertia_B)[1])
    return E, L, (2.0 * E * I2 - Lm ** 2) / Lm ** 2


def _angle(a, b):
    """The angle (rad) between each row of ``a`` (n, 3) and ``b`` (3,): atan2(|a × b|, a · b), accurate to
    round-off at any angle (arccos of the cosine is not: its floor is √(2ε) ≈ 2e-8 rad near 0)."""
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), a @ b)


def drift_metrics(problem: Problem, t_s, y, energy_floor: float = 0.0) -> DriftMetrics:
    """:class:`DriftMetrics` of the recorded states ``y`` (n, 13) at times ``t_s`` (n,) of a torque-free
    run (n ≥ 2). ``energy_floor``: the relative energy change below which no secular energy drift is named
    (the round-off a run of this length may accumulate: cross_checks.core.tolerances.long_run_roundoff)."""
    t = np.asarray(t_s, dtype=float)
    y = np.asarray(y, dtype=float)
    E, L, delta = _invariants(problem, y)
    Lm = np.linalg.norm(L, axis=-1)
    e_rel, l_rel = E / E[0] - 1.0, Lm / Lm[0] - 1.0
    T = float(t[-1] - t[0])
    k = max(1, int(len(delta) * LONG_RUN_END_FRACTION))
    a = np.abs(delta)
    end = float(np.mean(delta[-k:]))
    change = float(a[0] - np.mean(a[-k:]))          # how much |δ| fell over the run (start vs the last 5 %)
    # a bounded oscillation has the same size all along: measured at the end, where a drift that has stopped
    # (at the separatrix) no longer blurs it — the first 5 % would hold the whole of a drift that fast
    scatter = 2.0 * float(np.std(a[-k:]))

    def secular(c):
        return bool(c >= SECULAR_MIN_CHANGE * abs(delta[0]) and c >= SECULAR_MIN_TREND_TO_SCATTER * scatter)

    # across: δ ends clearly on the other side (by the same measures as a drift), not on the separatrix itself
    crossed = bool(np.sign(end) != np.sign(delta[0]) and secular(abs(end))
                   and abs(delta[0]) > SECULAR_MIN_TREND_TO_SCATTER * scatter)
    e_change = abs(float(np.mean(e_rel[-k:])))
    e_secular = bool(e_change > SECULAR_MIN_TREND_TO_SCATTER * 2.0 * float(np.std(e_rel[-k:]))
                     and e_change > energy_floor)
    return DriftMetrics(_slope(t, e_rel)[0], float(np.max(np.abs(e_rel))), _slope(t, l_rel)[0],
                        float(np.max(np.abs(l_rel))), float(np.max(_angle(L, L[0]))), float(delta[0]), end,
                        -change / T, secular(change) and not crossed, secular(-change) and not crossed, T,
                        crossed, e_secular, len(t) - 1)


def drift_series(problem: Problem, t_s, y, points: int) -> dict:
    """The long run's invariants at ``points`` times spread evenly over it (the first and last included),
    float32: ``t_s`` (s), ``energy_rel`` (E/E₀ − 1), ``momentum_rel`` (|L|/|L₀| − 1), ``direction_rad`` (the
    angle between L and L₀, rad), ``separatrix`` (δ) and ``L_B`` (the angular momentum in body axes, N m s,
    (points, 3): the report's polhode): what the report draws."""
    from cross_checks.core.quantities import decimation_indices
    idx = decimation_indices(len(t_s), points)
    y = np.asarray(y, dtype=float)[idx]
    E, L, delta = _invariants(problem, y)
    E0, L0 = _invariants(problem, np.asarray(y[:1]))[:2]
    Lm, L0m = np.linalg.norm(L, axis=-1), float(np.linalg.norm(L0[0]))
    return {"t_s": np.asarray(t_s, dtype=float)[idx].astype(np.float32),
            "energy_rel": (E / E0[0] - 1.0).astype(np.float32),
            "momentum_rel": (Lm / L0m - 1.0).astype(np.float32),
            "direction_rad": _angle(L, L0[0]).astype(np.float32), "separatrix": delta.astype(np.float32),
            "L_B": _body_momentum(problem, y).astype(np.float32)}


def _body_momentum(problem: Problem, y):
    """The angular momentum about the COM in body axes, I_B R^T ω_W (N m s, (n, 3)), of packed states y."""
    R = matrix_from_quat(y[:, 6:10] / np.linalg.norm(y[:, 6:10], axis=-1, keepdims=True))
    return np.einsum("ij,nkj,nk->ni", problem.body.inertia_B, R, y[:, 10:13])


def finding(variant: str, run_name: str, m: DriftMetrics) -> str:
    """The finding of a long run: "" when |δ| drifts neither way."""
    kind = drift_kind(m)
    if kind == "crosses_separatrix":
        what = "crosses the intermediate-axis separatrix (energy → L²/2I₂ and past it)"
    elif kind == "toward_intermediate":
        what = "drifts toward the intermediate axis (energy → L²/2I₂)"
    elif kind == "away_from_intermediate":
        what = "drifts away from the intermediate axis (a tumble settles into a spin)"
    else:
        return ""
    return (f"{variant} on {run_name}: {what} at rate {abs(m.separatrix_rate_per_s):.3g}/s of the "
            f"separatrix distance δ = (2E I₂ − |L|²)/|L|² (δ from {m.separatrix_start:.3g} to "
            f"{m.separatrix_end:.3g} over {m.duration_s:.4g} s; energy {m.energy_rate_per_s:+.3g}/s, "
            f"|L| {m.momentum_rate_per_s:+.3g}/s)")
