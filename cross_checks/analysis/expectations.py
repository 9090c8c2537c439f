"""What each engine variant is expected to do on each scenario: the ONE place for expected orders.

A sweep fits a convergence order per (scenario, variant, quantity) and compares it with
:func:`expectation`, decided from the variant's traits (:func:`traits`) and the scenario's PHYSICS
(:mod:`cross_checks.analysis.physics`), never from a scenario's name: ``does_not_converge`` where the
variant lacks a term the motion needs, ``pre_asymptotic`` (no claim) where a first-order variant's
amplitude drift alone would bend its fit beyond AMPLITUDE_MODEL_ORDER_DEV, ``converges`` at the nominal
order otherwise (docs/verdicts.md §3).

The reason strings end up, verbatim, in summary.json and in the report's findings, so they are
written as sentences for users. Orders are global orders of the error at a fixed final time,
``e(Δt) ≈ C Δt^p``; in the one-step mode the local order is p + 1.

Every ``variant`` here is a :class:`~cross_checks.engines.Resolved` (``cross_checks.engines.resolve``): the
entry points (the CLI, assert_engine, the sweep's and the fuzz's plans) resolve a name once and pass it
down; nothing here looks a name up again.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from cross_checks.core.quantities import QUANTITIES
from cross_checks.engines import Resolved
from cross_checks.engines.base import DEFAULT_TRAITS, Traits
from reference_sim.analytic import EQUAL_MOMENTS_REL_TOL

__all__ = ["energy_drift_bound", "characteristic_rate_sq", "QUANTITIES",
           "DEFAULT_TRAITS", "Traits", "traits", "EQUIVALENT_PAIRS", "pair_is_same_arithmetic", "Expectation",
           "expectation", "expected_order", "forces_change_within_step", "precision", "machine_epsilon",
           "judged_ladder_s",
           "nominal_order", "gyroscopic_term_matters", "rotation_drives_translation",
           "translation_drives_rotation", "LongRunExpectation", "long_run_expectation",
           "INVARIANT_WORDS", "gyroscopic_clamp_acts", "invariance_finding"]


def traits(variant: Resolved) -> Traits:
    """The traits ``ENGINE:VARIANT`` declares (Variant.traits), or those of the variant it declares it
    imitates (Variant.imitates); DEFAULT_TRAITS for one this module does not know (Resolved.traits)."""
    return variant.traits


#: Pairs that implement the same arithmetic and must agree to round-off (tolerances.SAME_SCHEME_REL).
EQUIVALENT_PAIRS = (
    ("reference:expmap_gyro", "mujoco:euler",
     "MuJoCo's Euler is semi-implicit Euler with an explicit gyroscopic term and the exp-map "
     "quaternion update, which is what reference:expmap_gyro implements (docs/engine_conventions.md)"),
    ("mujoco:implicit", "mujoco:implicitfast",
     "for a single free body without joints or contacts the two implicit integrators solve the same "
     "linear system (docs/engine_conventions.md: 1e-13 apart)"),
    ("mujoco:implicitfast", "mujoco:discrete",
     "without joints, constraints, damping or stiffness, MuJoCo's discrete integrator (the "
     "constraint solve and the implicit velocity update in the metric M + hD + h²K) takes "
     "implicitfast's step (docs/engine_conventions.md: bit-identical on the catalog)"),
    ("mujoco:euler", "pybullet:multibody",
     "PyBullet's multibody mode with damping off integrates a free body exactly like MuJoCo Euler "
     "(docs/engine_conventions.md: 2.3e-14 rad apart)"),
    ("mujoco:euler", "mjx:euler",
     "MJX's Euler is MuJoCo's Euler step in JAX (float64): the same arithmetic up to the order of its sums "
     "(docs/engine_conventions.md \"MJX 3.17.0\": ≤ 2.3e-14 relative, 8.6e-11 on tumbling_box)"),
    ("mjx:euler", "mjx:implicitfast",
     "MJX's implicitfast has no RNE derivative: on a lone free body without damping its matrix is M and its "
     "step Euler's (docs/engine_conventions.md \"MJX 3.17.0\")"),
)

#: Variants that apply the per-step decay AFTER their velocity update (docs/verdicts.md, "Velocity decay");
#: the engines' harness applies it BEFORE the step (cross_checks/engines/base.py).
_POST_STEP_DECAY = ("reference:course", "reference:course_gyro", "reference:expmap_gyro")


def pair_is_same_arithmetic(scenario, a: str, b: str) -> bool:
    """Whether the EQUIVALENT_PAIRS entry (a, b) computes the same numbers on ``scenario``.

    A decay after the velocity update (reference course-type schemes) and the engines' decay before the
    step (ω ← γω, torque × γ, then the step) agree exactly unless the gyroscopic term ω × Iω sees the
    angular factor γ_ω twice: with angular-velocity decay on a motion whose gyroscopic torque does not
    vanish the two differ by O((1 − γ_ω) Δt) per step — both first order, no longer the same arithmetic
    (docs/verdicts.md "Velocity decay").
    """
    if (a in _POST_STEP_DECAY) == (b in _POST_STEP_DECAY):
        return True
    k_w = scenario.problem.forces.decay_rates_per_s()[1]
    return not (k_w > 0.0 and gyroscopic_term_matters(scenario))


_TRANSLATION = ("position", "velocity")
_ROTATION = ("orientation", "angular_velocity")


@dataclass(frozen=True)
class Expectation:
    """What a (scenario, variant, quantity) should show.

    verdict : "converges", "does_not_converge", "pre_asymptotic" (no claim on this ladder), or None
        (no expectation; one-step mode only).
    order : expected order (float) when it converges, else None.
    reason : one sentence saying why (for a non-convergence: the physics the variant misses).
    precision, rounding_factor : the variant's Traits.precision and Traits.rounding_factor, which its floors
        are computed with (the judge says so in its words).
    """

    verdict: str | None
    order: float | None
    reason: str
    precision: str = "float64"
    rounding_factor: float = 1.0

    def as_dict(self) -> dict:
        return {"expected_verdict": self.verdict, "expected_order": self.order, "reason": self.reason}


def precision(variant: Resolved) -> str:
    """The floating-point format ``variant`` computes in (Traits.precision): "float64" or "float32"."""
    return variant.precision


def machine_epsilon(variant: Resolved) -> float:
    """ε of ``variant``'s precision (tolerances.MACHINE_EPSILON) times its declared Traits.rounding_factor:
    the unit of every round-off floor of its runs (and twice the unit roundoff of its one-step allowance)."""
    return variant.rounding_unit


def judged_ladder_s(scenario, variant: Resolved) -> tuple:
    """The Δt ladder (s, descending) ``variant`` is judged on: the scenario's; for a variant whose precision
    leaves its finer rungs at round-off (float32), that ladder plus coarser rungs (each of half the steps of
    the last, ⌊N/2⌋, so that T/Δt stays whole) until PRECISION_LADDER_MIN_RESOLVED rungs are expected resolved
    above their floors.

    Expected, not measured (the ladder is planned before anything runs): an order-p scheme matches the
    Taylor series of the motion up to its p-th term, so one step misses (ω_c Δt)ᵖ⁺¹/(p + 1)! and a run over T
    ~ (ω_c Δt)ᵖ ω_c T/(p + 1)! relative to the motion's scale (ω_c from :func:`characteristic_rate_sq`, at
    least 1/T); its round-off floor is ε (N + √N) with N = T/Δt (metrics.roundoff_floor without the
    amplification, which scales both alike). A rung is added only while ω_c Δt ≤ (p + 1) ×
    PRECISION_LADDER_STEP_ANGLE_PER_ORDER_RAD and the run keeps PRECISION_LADDER_MIN_STEPS steps; the finer
    rungs stay (the fit says which were at round-off)."""
    from cross_checks.core import tolerances as tol
    v = variant
    dts = sorted({float(d) for d in scenario.dt_ladder_s}, reverse=True)
    eps = v.rounding_unit
    if eps <= tol.ROUNDOFF_PER_STEP_REL or not dts:
        return tuple(dts)
    T = scenario.duration_s
    p = v.order or 1.0
    if forces_change_within_step(scenario, v.traits):
        p = min(p, 1.0)
    w = max(math.sqrt(characteristic_rate_sq(scenario)), 1.0 / T)

    def resolved(h):
        n = T / h
        return ((w * h) ** p * w * T / math.factorial(round(p) + 1)
                >= tol.RESOLVED_ABOVE_FLOOR * eps * (n + math.sqrt(n)))

    for _ in range(tol.PRECISION_LADDER_MAX_EXTRA):
        if sum(resolved(h) for h in dts) >= tol.PRECISION_LADDER_MIN_RESOLVED:
            break
        n = round(T / dts[0]) // 2
        h = T / n if n else math.inf
        if (w * h > (p + 1.0) * tol.PRECISION_LADDER_STEP_ANGLE_PER_ORDER_RAD
                or n < tol.PRECISION_LADDER_MIN_STEPS):
            break
        dts.insert(0, h)
    return tuple(dts)


def nominal_order(variant: Resolved) -> float | None:
    """The nominal global order of ``ENGINE:VARIANT``, the same for every quantity: the order its adapter
    declares (rbcheck's own adapters and a user's engine file or entry point alike; verdicts then check
    it); None for a name nobody declares."""
    return variant.order


def _isotropic(inertia_B) -> bool:
    m = np.linalg.eigvalsh(np.asarray(inertia_B, float))
    return bool(m[-1] - m[0] <= EQUAL_MOMENTS_REL_TOL * m[-1])


def _decided(physics, key, compute):
    """``compute()``, kept on the scenario's measured physics (``ScenarioPhysics.decided``) under ``key``:
    decisions that depend only on that scenario — the free-running expectation of a (variant, quantity),
    which the one-step mode asks for again, and the pre-asymptotic reason of a (traits, quantity), the same
    for every variant with those traits — are made once per scenario whose physics is passed, with no global
    state (results are those computed without it)."""
    if physics is None:
        return compute()
    memo = physics.decided
    if key not in memo:
        memo[key] = compute()
    return memo[key]


def gyroscopic_term_matters(scenario) -> bool:
    """True when ω × (I ω) is non-zero somewhere along the true motion.

    It vanishes identically only for an isotropic inertia, or for a torque-free body whose initial
    ω lies along a principal axis (then ω stays there). Any torque on an anisotropic body moves ω off
    the principal axes sooner or later.
    """
    p = scenario.problem
    if _isotropic(p.body.inertia_B):
        return False
    if not p.forces.torque_free:
        return True
    return not p.body.gyroscopic_torque_vanishes(p.initial.q_WB, p.initial.w_W)


def rotation_drives_translation(scenario) -> bool:
    """True when the force on the COM depends on the orientation (a spring attached off the COM, a
    body-frame force), so an orientation error becomes a position error."""
    fm = scenario.problem.forces
    return bool(any(np.any(s.attach_B != 0) for s in fm.springs)
                or any(pf.frame == "body" for pf in fm.point_forces))


def translation_drives_rotation(scenario) -> bool:
    """True when the torque depends on the position (a spring attached off the COM)."""
    return bool(any(np.any(s.attach_B != 0) for s in scenario.problem.forces.springs))


def characteristic_rate_sq(scenario) -> float:
    """ω_c² (1/s²): the largest squared angular frequency of the motion — spring k/m (and k|r|²/I_min
    for a spring attached off the COM), the initial spin |ω0|², drag or decay rates squared (the scale
    of the energy-drift bound, :func:`energy_drift_bound`)."""
    p = scenario.problem
    m, I_min = p.body.mass_kg, float(np.linalg.eigvalsh(p.body.inertia_B)[0])
    k_v, k_w = p.forces.decay_rates_per_s()
    rates = [float(np.dot(p.initial.w_W, p.initial.w_W)),
             (p.forces.linear_drag_N_s_per_m / m) ** 2, k_v ** 2, k_w ** 2]
    for sp in p.forces.springs:
        rates.append(sp.stiffness_N_per_m / m)
        rates.append(sp.stiffness_N_per_m * float(np.dot(sp.attach_B, sp.attach_B)) / I_min)
    return max(rates)


def expectation(scenario, variant: Resolved, quantity: str, mode: str = "free_running", physics=None, *,
                measure_physics: bool = True) -> Expectation:
    """The expected verdict and order of ``variant`` on ``scenario`` for ``quantity``.

    ``mode`` "free_running" gives the global order p; "one_step" gives the local order p + 1 — also
    where the free run is pre-asymptotic (an amplitude drift builds up over a run, not in one step) —
    and no expectation (verdict None) where the variant misses a term: a missing term shows up as an
    O(Δt) local error in some quantities and O(Δt²) in others. ``physics``: the scenario's
    :class:`~cross_checks.analysis.physics.ScenarioPhysics` (measured here when omitted, once per scenario —
    unless ``measure_physics`` is False: then no pre-asymptotic decision is made, e.g. for a scenario
    whose reference could not be computed, where every run is a failed row anyway).
    """
    e = _expectation(scenario, variant, quantity, mode, physics, measure_physics)
    prec, factor = variant.precision, float(variant.traits.rounding_factor)
    return (e if (prec, factor) == (e.precision, e.rounding_factor)
            else Expectation(e.verdict, e.order, e.reason, prec, factor))


def _expectation(scenario, variant: Resolved, quantity, mode, physics, measure_physics) -> Expectation:
    if mode not in ("free_running", "one_step"):
        raise ValueError(f"unknown mode {mode!r}; modes: free_running, one_step")
    free = _decided(physics, ("free_running", str(variant), quantity, measure_physics),
                    lambda: _free_running(scenario, variant, quantity, physics, measure_physics))
    if mode == "free_running":
        return free
    if free.verdict == "does_not_converge":
        return Expectation(None, None, free.reason)
    p = variant.order
    if p is None:
        return Expectation("converges", None, f"no nominal order is recorded for {variant}")
    if free.order is not None and free.order < p:
        return Expectation("converges", free.order + 1.0,
                           f"{free.reason}: one step has an O(Δt^{free.order + 1.0:g}) local error")
    return Expectation("converges", p + 1.0,
                       f"one step of an order-{p:g} scheme has an O(Δt^{p + 1:g}) local error")


_HELD_FORCES_REASON = ("{variant} is an order-{p:g} scheme, but its engine holds the applied force and "
                       "torque over the stages of a step; here they change within a step (they depend on the "
                       "state, or the velocities decay), and that zero-order hold makes the step first order")


def rotation_turns(scenario) -> bool:
    """Whether the body-axes angular velocity changes direction within a step: the gyroscopic term matters
    (an anisotropic body off its principal axes) or a torque or off-COM force acts."""
    fm = scenario.problem.forces
    return bool(gyroscopic_term_matters(scenario) or fm.torques or fm.springs
                or any(np.any(pf.point_B != 0) for pf in fm.point_forces))


def gyroscopic_clamp_acts(scenario, variant: Resolved, physics=None,
                         measure_physics: bool = True) -> float | None:
    """The largest gyroscopic torque |ω × (I ω)| (N m) of the scenario's motion when ``variant``'s step clamps
    it (Traits.gyroscopic_clamp_N_m) below that — the clamp acts and the step solves another equation —
    else None. Measured on the reference (physics.MotionRates.gyroscopic_torque_max; ``physics`` measured here
    when omitted, unless ``measure_physics`` is False: then None)."""
    limit = variant.traits.gyroscopic_clamp_N_m
    if limit is None or (physics is None and not measure_physics):
        return None
    if not gyroscopic_term_matters(scenario):
        return None
    from cross_checks.analysis.physics import scenario_physics
    phys = physics if physics is not None else scenario_physics(scenario)
    worst = float(phys.rates.gyroscopic_torque_max)
    return worst if worst > limit else None


def forces_change_within_step(scenario, tr: Traits) -> bool:
    """Whether a variant with traits ``tr`` holds forces that change within a step on ``scenario``
    (Traits.forces_held): its multi-stage scheme is then first order there."""
    fm = scenario.problem.forces
    return tr.forces_held and (fm.state_dependent or fm.has_decay)


def _free_running(scenario, variant: Resolved, quantity: str, physics,
                  measure_physics: bool = True) -> Expectation:
    if quantity not in QUANTITIES:
        raise ValueError(f"unknown quantity {quantity!r}; quantities: {', '.join(QUANTITIES)}")
    tr = variant.traits
    if not tr.gyroscopic_term and gyroscopic_term_matters(scenario):
        if quantity in _ROTATION or rotation_drives_translation(scenario):
            coupled = ("" if quantity in _ROTATION else
                       "; the spring or body-frame force carries that rotation error into the translation")
            return Expectation(
                "does_not_converge", None,
                "the update has no gyroscopic term −ω × (I ω), which is not zero on this body "
                f"(anisotropic inertia, ω off the principal axes){coupled}")
    clamp = gyroscopic_clamp_acts(scenario, variant, physics, measure_physics)
    if clamp is not None and (quantity in _ROTATION or rotation_drives_translation(scenario)):
        return Expectation(
            "does_not_converge", None,
            f"its step cuts the gyroscopic torque −ω × (I ω) to {tr.gyroscopic_clamp_N_m:g} N m, and here "
            f"it reaches {clamp:.3g} N m: the runs converge to the solution of that clamped equation, not to "
            "the physical motion")
    p = variant.order
    if p is None:
        return Expectation("converges", None, f"no nominal order is recorded for {variant}")
    if p > 1.0 and forces_change_within_step(scenario, tr):
        return Expectation("converges", 1.0, _HELD_FORCES_REASON.format(variant=variant, p=p))
    if (tr.rotation_order is not None and tr.rotation_order < p and rotation_turns(scenario)
            and (quantity in _ROTATION or rotation_drives_translation(scenario))):
        return Expectation("converges", tr.rotation_order,
                           f"{variant} is an order-{p:g} scheme, but its attitude update is order "
                           f"{tr.rotation_order:g} where the body-axes ω turns within a step, "
                           "as it does here")
    if p == 1.0 and (physics is not None or measure_physics):
        why = _decided(physics, ("pre_asymptotic", tr, p, quantity),
                       lambda: _pre_asymptotic_reason(scenario, variant, quantity, tr, physics))
        if why:
            return Expectation("pre_asymptotic", None, why)
    return Expectation("converges", p, f"{variant} is an order-{p:g} scheme")


def _drift_parts(scenario, tr: Traits, quantity: str, phys):
    """The amplitude drifts that reach ``quantity``: ``[(what, rate², signs, amplification, saturate)]``."""
    r = phys.rates
    both = (1, -1)
    parts = []
    translation = quantity in _TRANSLATION or translation_drives_rotation(scenario)
    rotation = quantity in _ROTATION or rotation_drives_translation(scenario)
    if translation:
        osc = r.translation ** 2 if tr.translation_drift != 0 else 0.0
        signs = (tr.translation_drift,) if tr.translation_drift not in (0, None) else both
        parts.append(("the translation", osc + r.drag ** 2 + r.decay_v ** 2, signs, 1.0, False))
    if rotation:
        kind = tr.rotation_drift
        signs = (tr.rotation_sign,) if tr.rotation_sign not in (0, None) else both
        if kind == "whole_state":
            # the drift perturbs the turning part of ω (a share a of its scale); the motion amplifies it
            amp = float(phys.amplification.get(quantity, 1.0)) * r.world_rotation_amplitude
            parts.append(("the rotation (ω_W turning with the body)", r.world_rotation ** 2 + r.decay_w ** 2,
                          signs, amp, True))
        elif kind in ("body", "momentum"):   # |L| kept, δ moved slowly at the polhode's rate (Traits)
            parts.append(("the rotation (the body-frame ω: the polhode)",
                          r.body_rotation ** 2 + r.decay_w ** 2, signs, 1.0, False))
        else:
            parts.append(("the rotation", r.decay_w ** 2, both, 1.0, False))
    return parts


def _pre_asymptotic_reason(scenario, variant: Resolved, quantity, tr: Traits, physics) -> str:
    """The reason a first-order variant makes no claim on this ladder ("" when it does claim order 1)."""
    from cross_checks.analysis.physics import amplitude_model_order, amplitude_parameter, scenario_physics
    from cross_checks.core import tolerances as tol
    phys = physics if physics is not None else scenario_physics(scenario)
    dts = list(judged_ladder_s(scenario, variant))
    if len(dts) < 2:
        return ""
    T = scenario.duration_s
    for what, rate_sq, signs, amp, saturate in _drift_parts(scenario, tr, quantity, phys):
        if rate_sq <= 0.0:
            continue
        chis = [amplitude_parameter(rate_sq, dt, T) for dt in dts]
        model = amplitude_model_order(dts, chis, signs, amp, saturate)
        if abs(model - 1.0) <= tol.AMPLITUDE_MODEL_ORDER_DEV:
            continue
        sep = phys.separatrix_proximity
        near = (f"; the body is near the intermediate-axis separatrix (δ = {sep:.2g})"
                if sep is not None and abs(sep) < 1e-2 and saturate else "")
        amp_txt = (f"; the motion amplifies that perturbation {phys.amplification.get(quantity, 1.0):.3g}× "
                   "by the final time (measured) until it saturates" if saturate else "")
        how = {1: "grows it by e^(+χ)", -1: "damps it by e^(−χ)"}.get(signs[0]) if len(signs) == 1 else None
        return ("pre-asymptotic on this ladder: a first-order step that does not keep the amplitude of "
                f"{what} {how or 'grows or damps it by e^(±χ)'} over the run, χ = ω_c²ΔtT/2 from "
                f"{chis[0]:.2g} (coarsest Δt) to {chis[-1]:.2g} (finest), ω_c = {math.sqrt(rate_sq):.3g} "
                f"rad/s measured on the reference{amp_txt}{near}; that drift alone would fit order "
                f"{model:.2f} here, beyond 1 ± {tol.AMPLITUDE_MODEL_ORDER_DEV:g}")
    return ""


def expected_order(variant: Resolved, quantity: str, scenario=None) -> float | None:
    """The expected global order of ``variant`` for ``quantity`` (None where it is expected not to
    converge). ``scenario``: a Scenario, a catalog name, or None (then the nominal order)."""
    if scenario is None:
        return nominal_order(variant)
    if isinstance(scenario, str):
        from cross_checks.scenario import load_scenario
        scenario = load_scenario(scenario)
    return expectation(scenario, variant, quantity).order


def energy_drift_bound(scenario, variant: Resolved, dt_s: float) -> float | None:
    """Upper bound on the maximum relative energy drift of ``variant`` on a conservative scenario.

    An order-p scheme's global error over T at step Δt on a motion of angular frequency ω is
    ~ C (ωΔt)^p ωT; energy errors are of the same relative size. C ≤ 2 covers every scheme here
    (explicit Euler's energy grows as e^{2χ} − 1 ≈ ω²ΔtT = (ωΔt)ωT, i.e. C = 1). Returns None where no
    bound applies: a non-conservative scenario, a variant without a nominal order, or the course
    update on a body whose gyroscopic term matters (it does not model the conserved motion at all).
    """
    if not scenario.problem.forces.conservative:
        return None
    v = variant
    tr = v.traits
    if not tr.gyroscopic_term and gyroscopic_term_matters(scenario):
        return None
    p = v.order
    if p is None:
        return None
    if forces_change_within_step(scenario, tr):
        p = min(p, 1.0)
    if tr.rotation_order is not None and rotation_turns(scenario):
        p = min(p, tr.rotation_order)
    w2 = characteristic_rate_sq(scenario)
    g = float(np.linalg.norm(scenario.problem.forces.gravity_W))
    if g > 0.0:
        # Under gravity the energy error of symplectic Euler is m|g|·½|g|tΔt over E = ½m|v0|²: the rate
        # |g|/|v0| gives exactly C = 1 (|v0| = 0 leaves no finite bound: E(0) has no kinetic scale).
        v0 = float(np.linalg.norm(scenario.problem.initial.v_W))
        w2 = max(w2, (g / v0) ** 2 if v0 > 0.0 else math.inf)
    w = math.sqrt(w2)
    n_steps = max(1, round(scenario.duration_s / dt_s))
    # + round-off: N steps of ε each, ×10 for the terms of E.
    return 2.0 * (w * dt_s) ** p * w * scenario.duration_s + 10.0 * n_steps * v.rounding_unit


#: The invariants of Traits.keeps in words (the judge's sentences).
INVARIANT_WORDS = {"energy": "the energy", "energy_bounded": "a bounded energy error (no secular drift)",
                   "angular_momentum_norm": "|L|", "angular_momentum": "L (its norm and direction)"}


@dataclass(frozen=True)
class LongRunExpectation:
    """What a variant should do on a long run of a torque-free body (docs/verdicts.md, "Long runs").

    keeps : the invariants it keeps by construction (Traits.keeps; "angular_momentum_norm" added for a
        "momentum" rotation drift and for a kept L); () claims nothing.
    separatrix : what its separatrix distance δ may do: "kept" (it keeps the energy — or its error bounded —
        and |L|, hence δ: any secular drift contradicts), "toward_intermediate" (a "momentum" step: |L| kept,
        the energy moving towards L²/2I₂ — expected, named; a drift away or a crossing contradicts), or None
        (no claim: the finding is reported, never judged).
    reason : one sentence saying why.
    precision, rounding_factor : what its round-off floors scale with (Traits).
    """

    keeps: tuple
    separatrix: str | None
    reason: str
    precision: str = "float64"
    rounding_factor: float = 1.0

    def as_dict(self) -> dict:
        return {"expected_keeps": list(self.keeps), "expected_separatrix": self.separatrix,
                "reason": self.reason}


def long_run_expectation(variant: Resolved) -> LongRunExpectation:
    """The :class:`LongRunExpectation` of ``variant`` from its declared traits (nothing else)."""
    tr = variant.traits
    keeps = list(tr.keeps)
    norm_implied = tr.rotation_drift == "momentum" or "angular_momentum" in keeps
    if norm_implied and "angular_momentum_norm" not in keeps:
        keeps.append("angular_momentum_norm")
    order = [k for k in INVARIANT_WORDS if k in keeps]
    energy = "energy" in order or "energy_bounded" in order
    if energy and "angular_momentum_norm" in order:
        sep = "kept"
        why = ("it declares that it keeps " + ", ".join(INVARIANT_WORDS[k] for k in order)
               + ": so the separatrix distance δ = (2E I₂ − |L|²)/|L|² too, and no secular drift of δ is "
               "allowed")
    elif tr.rotation_drift == "momentum":
        sep = "toward_intermediate"
        why = ("a momentum-rescaled step (rotation_drift \"momentum\"): |L| is kept to round-off while the "
               "energy drifts at O(Δt²) a step towards L²/2I₂ — a drift toward the intermediate axis is "
               "expected and named, not failed; away from it or across it would contradict the step")
    elif order:
        sep = None
        why = ("it declares that it keeps " + ", ".join(INVARIANT_WORDS[k] for k in order)
               + "; the energy is not claimed, so δ may move")
    else:
        sep = None
        why = (f"it declares no invariant it keeps by construction (rotation drift \"{tr.rotation_drift}\"): "
               "its drifts are measured and its finding named, never judged")
    return LongRunExpectation(tuple(order), sep, why, tr.precision, float(tr.rounding_factor))


def invariance_finding(variant: Resolved, transform):
    """The invariance finding ``variant`` declares for ``transform`` (a scenario.transforms.Transform): the
    first of its Traits.invariance_findings (engines.base.InvarianceFinding: the transform's kind, the range
    of its sizes and the quantities where it was measured, and the reason) that matches it; None when it
    declares none there (then a broken check is a failure). The one place every invariance entry point
    reads declarations from (cross_checks.sweep.invariance)."""
    for f in variant.traits.invariance_findings:
        if f.matches(transform):
            return f
    return None
