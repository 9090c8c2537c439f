"""What a scenario's motion is like, measured on its reference solution: the physics the expectations
of :mod:`cross_checks.analysis.expectations` are decided from (never the scenario's name).

* **Characteristic rates** (rad/s or 1/s) of the parts of the motion a scheme may integrate without
  preserving amplitudes: for a signal ``s(t)`` of the true motion, ``rms|ṡ| / rms|s − s̄|`` — exactly
  the angular frequency of a sinusoid, ``k``-like for a decay, 0 for a constant — of

  - the COM velocity ``v_W`` (translation: a spring's ``√(k/m)``),
  - the body-frame angular velocity ``ω_B`` (the polhode: the wobble of a torque-free body, 0 for a
    spin about a principal axis),
  - the world-frame angular velocity ``ω_W`` (how fast ``I_W ω`` turns with the body: the space-cone
    rate ``|L|/I_1`` of a symmetric top; 0 for a pure spin, where ω stays put),

  plus the dissipative rates of the force model (drag ``c/m``, decay ``k_v``, ``k_ω``). Derivatives come
  from the equations of motion (``reference_sim.integrators.rhs``) along the reference, not from
  differences.
* **Separatrix proximity** of a torque-free body with three distinct moments
  ``δ = (2E I₂ − |L|²) / |L|²`` (dimensionless, from the initial state's energy and momentum; 0 on the
  separatrix through the intermediate axis I₂). Reported with the measured amplification
  (``references.error_amplification``), which is what decides: a perturbation that moves the body
  to a neighbouring motion grows by that factor.
* **χ = ½ ω_c² Δt T**: the amplitude drift ``e^{±χ}`` over the run of a first-order scheme that does not
  preserve the amplitude of a mode of rate ``ω_c``; :func:`amplitude_model_order` is the order a fit over
  the ladder would find from that drift alone (docs/verdicts.md §3, rule 2).
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

__all__ = ["MotionRates", "ScenarioPhysics", "motion_rates", "separatrix_proximity", "scenario_physics",
           "amplitude_parameter", "amplitude_model_order", "physics_from_dict"]

#: Points of the reference grid the rates are measured on (uniform in time): ≥ 20 per period of the
#: fastest catalog motion (spring_pendulum's ω_W ≈ 22 rad/s over 5 s needs ≥ 350).
RATE_SAMPLES = 2001


@dataclass(frozen=True)
class MotionRates:
    """Characteristic rates of the true motion (see the module docstring), rad/s or 1/s."""

    translation: float        # of v_W
    body_rotation: float      # of ω_B (the polhode)
    world_rotation: float     # of ω_W
    drag: float               # c/m
    decay_v: float            # k_v
    decay_w: float            # k_ω
    world_rotation_amplitude: float = 0.0  # rms|ω_W − ω̄_W| / max(1, max|ω_W|): the share of ω that turns
    gyroscopic_torque_max: float = 0.0     # max |ω × (I_W ω)| over the samples, N m (Traits' clamp)


@dataclass(frozen=True)
class ScenarioPhysics:
    """Everything :mod:`cross_checks.analysis.expectations` decides from, for one scenario.

    rates : MotionRates.
    separatrix_proximity : δ (None unless torque-free with three distinct moments and ω ≠ 0).
    amplification : {quantity: A ≥ 1}: relative final error per relative initial error (measured).
    duration_s : T.
    decided : what the expectations decided from these physics (expectations._decided), kept with them:
        not a measurement (left out of equality, ``repr`` and :meth:`as_dict`).
    """

    rates: MotionRates
    separatrix_proximity: float | None
    amplification: dict
    duration_s: float
    decided: dict = field(default_factory=dict, compare=False, repr=False)

    def as_dict(self) -> dict:
        return {"rates": asdict(self.rates), "separatrix_proximity": self.separatrix_proximity,
                "amplification": dict(self.amplification), "duration_s": self.duration_s}


def physics_from_dict(d: dict) -> ScenarioPhysics:
    return ScenarioPhysics(MotionRates(**d["rates"]), d["separatrix_proximity"], dict(d["amplification"]),
                           float(d["duration_s"]))


def _rate(s, ds) -> float:
    """``rms|ṡ| / rms|s − s̄|`` of a sampled vector signal (T, 3); 0 when s does not move (relative 1e-9)."""
    dev = s - s.mean(axis=0)
    den = math.sqrt(float(np.mean(np.sum(dev * dev, axis=-1))))
    size = math.sqrt(float(np.mean(np.sum(s * s, axis=-1))))
    if den <= 1e-9 * max(size, 1e-300) or den == 0.0:
        return 0.0
    return math.sqrt(float(np.mean(np.sum(ds * ds, axis=-1)))) / den


def motion_rates(problem, y) -> MotionRates:
    """Rates of the motion sampled uniformly in time, ``y`` (T, 13) on the reference."""
    from reference_sim.integrators import rhs
    from reference_sim.quaternion import quat_conj, rotate
    y = np.asarray(y, dtype=float)
    d = rhs(problem, y)
    q_BW = quat_conj(y[:, 6:10])
    w_B = rotate(q_BW, y[:, 10:13])
    dw_B = rotate(q_BW, d[:, 10:13])  # ω_B = Rᵀω_W: dω_B/dt = Rᵀ(ω̇_W − ω × ω_W) = Rᵀ ω̇_W
    fm = problem.forces
    k_v, k_w = fm.decay_rates_per_s()
    w_W = y[:, 10:13]
    dev = w_W - w_W.mean(axis=0)
    scale_w = max(1.0, float(np.max(np.linalg.norm(w_W, axis=-1))))
    Iw_B = w_B @ problem.body.inertia_B     # I_B symmetric: (I_B ω_B) per row; |ω × I_W ω| = |ω_B × I_B ω_B|
    gyro = float(np.max(np.linalg.norm(np.cross(w_B, Iw_B), axis=-1)))
    return MotionRates(translation=_rate(y[:, 3:6], d[:, 3:6]), body_rotation=_rate(w_B, dw_B),
                       world_rotation=_rate(w_W, d[:, 10:13]),
                       drag=fm.linear_drag_N_s_per_m / problem.body.mass_kg, decay_v=k_v, decay_w=k_w,
                       world_rotation_amplitude=(math.sqrt(float(np.mean(np.sum(dev * dev, axis=-1))))
                                                 / scale_w), gyroscopic_torque_max=gyro)


def separatrix_proximity(problem) -> float | None:
    """δ = (2E I₂ − |L|²)/|L|² of the initial rotation (principal moments I₁ < I₂ < I₃), or None where
    there is no separatrix: torques act, two moments are equal (within 1e-9), or ω = 0."""
    from reference_sim.quaternion import quat_conj, rotate
    if not problem.forces.torque_free:
        return None
    moments, R_BP = problem.body.principal_axes()
    if min(np.diff(moments)) <= 1e-9 * moments[-1]:
        return None
    w_P = R_BP.T @ rotate(quat_conj(problem.initial.q_WB), problem.initial.w_W)
    L2 = float(np.sum((moments * w_P) ** 2))
    if L2 == 0.0:
        return None
    two_E = float(np.sum(moments * w_P ** 2))
    return (two_E * moments[1] - L2) / L2


_CACHE: dict = {}


def scenario_physics(scenario, amplification=None, y_ref=None) -> ScenarioPhysics:
    """The physics of ``scenario``: rates measured on its reference (``y_ref`` (T, 13) uniform in time
    from 0 to the duration, computed here when omitted), separatrix proximity, and the measured
    amplification (``references.error_amplification`` when omitted). Cached per scenario content."""
    key = (scenario.content_hash, scenario.duration_s, scenario.source)
    if amplification is None and y_ref is None and key in _CACHE:
        return _CACHE[key]
    from cross_checks.scenario.references import error_amplification, reference_solution
    if y_ref is None:
        y_ref, _ = reference_solution(scenario, np.linspace(0.0, scenario.duration_s, RATE_SAMPLES))
    if amplification is None:
        amplification = error_amplification(scenario)
    phys = ScenarioPhysics(motion_rates(scenario.problem, y_ref), separatrix_proximity(scenario.problem),
                           dict(amplification), float(scenario.duration_s))
    _CACHE[key] = phys
    return phys


def amplitude_parameter(rate_sq: float, dt_s: float, duration_s: float) -> float:
    """χ = ½ ω_c² Δt T (dimensionless) for a mode of squared rate ``rate_sq`` (1/s²)."""
    return 0.5 * rate_sq * dt_s * duration_s


def _log_model_errors(chis, sign: int, amplification: float, saturate: bool):
    """ln of the model errors (in logs, so that any χ is fine): ln|e^{sχ} − 1| + ln A, saturated as
    ln(u / (1 + u))."""
    out = []
    if amplification <= 0.0:   # no share of the motion carries this drift (e.g. ω_W does not turn): no model
        return None
    for chi in chis:
        if chi <= 0.0:
            return None
        if sign > 0:
            lg = chi + math.log(-math.expm1(-chi)) if chi > 1.0 else math.log(math.expm1(chi))
        else:
            lg = math.log(-math.expm1(-chi))
        lu = lg + math.log(amplification)
        out.append(lu - np.logaddexp(0.0, lu) if saturate else lu)
    return out


def amplitude_model_order(dts, chis, signs=(1, -1), amplification: float = 1.0,
                          saturate: bool = False) -> float:
    """The order a least-squares fit over the ladder ``dts`` would find if the errors were the amplitude
    drift alone: ``|e^{sχ} − 1|`` — or, for a drift that moves the body to a neighbouring motion,
    ``u = amplification·|e^{sχ} − 1|`` (the relative perturbation, grown as the motion grows any
    perturbation), saturating at O(1) like the error of any bounded quantity: ``u / (1 + u)``.
    Returns the one furthest from 1 over ``signs``."""
    x = np.log(np.asarray(dts, dtype=float))
    worst = 1.0
    for s in signs:
        y = _log_model_errors(chis, s, amplification, saturate)
        if y is None or len(x) < 2:
            continue
        y = np.asarray(y)
        xm = x - x.mean()
        slope = float(np.sum(xm * (y - y.mean())) / np.sum(xm * xm))
        if abs(slope - 1.0) > abs(worst - 1.0):
            worst = slope
    return worst
