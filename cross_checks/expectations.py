"""What each engine variant is expected to do on each scenario: the ONE place for expected orders.

A sweep fits a convergence order per (scenario, variant, quantity) and compares it with
:func:`expectation`: the nominal order of the variant, unless a rule of this module says the variant
cannot converge on that scenario (and why). The reason strings end up, verbatim, in summary.json and
in the report's findings, so they are written as sentences for users.

Orders are global orders of the error at a fixed final time, ``e(Δt) ≈ C Δt^p``. In the one-step mode
(each step restarted from the reference state) the local error of an order-p scheme is O(Δt^{p+1}).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from reference_sim.integrators import EXPECTED_ORDER as _REFERENCE_ORDER

__all__ = ["energy_drift_bound", "NON_SYMPLECTIC_EULER", "characteristic_rate_sq", "euler_amplitude_parameter", "QUANTITIES", "NOMINAL_ORDER", "NO_GYROSCOPIC_TERM", "EQUIVALENT_PAIRS", "Expectation",
           "expectation", "expected_order", "nominal_order", "gyroscopic_term_matters", "rotation_drives_translation"]

#: The quantities a convergence verdict is given for (DESIGN.md).
QUANTITIES = ("position", "orientation", "velocity", "angular_velocity")

#: Nominal global order per ENGINE:VARIANT, the same for every quantity.
NOMINAL_ORDER = {
    # reference:* — reference_sim.integrators.EXPECTED_ORDER is the single source for the NumPy
    # schemes (its own tests prove them): course / course_gyro / expmap_gyro are symplectic Euler
    # (one force evaluation, O(Δt²) local error -> 1); explicit and implicit Euler: 1; mid-point and
    # leapfrog (Störmer–Verlet): 2; classical RK4: 4.
    **{f"reference:{v}": float(p) for v, p in _REFERENCE_ORDER.items()},
    # MuJoCo Euler is semi-implicit Euler + exp-map quaternion = reference:expmap_gyro (ENGINE_FACTS): 1.
    "mujoco:euler": 1.0,
    # MuJoCo RK4: classical RK4 on (qpos, qvel); forces re-evaluated at every stage by the adapter: 4.
    "mujoco:rk4": 4.0,
    # MuJoCo implicit(fast): velocity-implicit Euler, one linearised solve per step -> 1.
    "mujoco:implicit": 1.0,
    "mujoco:implicitfast": 1.0,
    # PyBullet: semi-implicit Euler in both modes (multibody explicit gyro, maximal implicit gyro): 1.
    "pybullet:multibody": 1.0,
    "pybullet:maximal": 1.0,
}

#: Variants whose rotation update has no gyroscopic torque −ω × (I ω) (the course's own step).
NO_GYROSCOPIC_TERM = frozenset({"reference:course"})

#: Whole-state explicit and implicit Euler are not symplectic: on an oscillation or a spin of angular
#: frequency ω they grow (explicit) or damp (implicit) the amplitude by (1 + (ωΔt)²)^{±1/2} per step,
#: i.e. by e^{±χ} over the run with χ = ω² Δt T / 2. The final error ~ e^{χ} − 1 has log-log slope
#: χ e^χ / (e^χ − 1) ≈ 1 + χ/2, so a fitted order is within SWEEP_ORDER_TOL of 1 only where
#: χ ≤ 2 SWEEP_ORDER_TOL at the coarsest Δt of the ladder. Beyond that the ladder is pre-asymptotic
#: for these schemes and the sweep makes no claim (their order 1 is proven on short runs by
#: tests/reference_sim/test_integrators.py).
NON_SYMPLECTIC_EULER = frozenset({"reference:explicit_euler", "reference:implicit_euler"})

#: Measured non-convergence that no nominal order predicts, per (variant, scenario), for the
#: rotational quantities. tumbling_box spins at 5 rad/s near its intermediate axis and flips ~8 times
#: in 10 s; the flip period depends on the distance from the separatrix, which the non-symplectic
#: Euler schemes' energy error (relative ~2χ = 6 % even at Δt = 2.5e-4 s) shifts, so the phase of
#: the flips is off by O(1) at every Δt of the ladder. Measured orientation errors at t = 10 s for
#: explicit Euler: 2.7, 1.4, 0.9, 1.7 rad at Δt = 2.5e-4 … 3.1e-5 s (beyond the ladder).
MEASURED_ROTATION_NON_CONVERGENCE = {
    (v, "tumbling_box"): (
        "its energy error (~2χ = 6 % even at the finest Δt) moves the body across the flip phase of a "
        "tumble near the intermediate axis (~8 flips in 10 s): orientation errors stay ~1–3 rad at every Δt "
        "down to 3e-5 s (measured)")
    for v in ("reference:explicit_euler", "reference:implicit_euler")
}

#: Pairs that implement the same arithmetic and must agree to round-off (tolerances.SAME_SCHEME_REL).
EQUIVALENT_PAIRS = (
    ("reference:expmap_gyro", "mujoco:euler",
     "MuJoCo's Euler is semi-implicit Euler with an explicit gyroscopic term and the exp-map "
     "quaternion update, which is what reference:expmap_gyro implements (ENGINE_FACTS.md)"),
    ("mujoco:implicit", "mujoco:implicitfast",
     "for a single free body without joints or contacts the two implicit integrators solve the same "
     "linear system (ENGINE_FACTS.md: 1e-13 apart)"),
    ("mujoco:euler", "pybullet:multibody",
     "PyBullet's multibody mode with damping off integrates a free body exactly like MuJoCo Euler "
     "(ENGINE_FACTS.md: 2.3e-14 rad apart)"),
)

_TRANSLATION = ("position", "velocity")
_ROTATION = ("orientation", "angular_velocity")


@dataclass(frozen=True)
class Expectation:
    """What a (scenario, variant, quantity) should show.

    verdict : "converges", "does_not_converge", or None (no expectation; one-step mode only).
    order : expected order (float) when it converges, else None.
    reason : one sentence saying why (for a non-convergence: the physics the variant misses).
    """

    verdict: str | None
    order: float | None
    reason: str

    def as_dict(self) -> dict:
        return {"expected_verdict": self.verdict, "expected_order": self.order, "reason": self.reason}


def nominal_order(variant: str) -> float | None:
    """The nominal global order of ``ENGINE:VARIANT`` (None for a name this module does not know)."""
    return NOMINAL_ORDER.get(variant)


def _isotropic(inertia_B) -> bool:
    m = np.linalg.eigvalsh(np.asarray(inertia_B, float))
    return bool(m[-1] - m[0] <= 1e-12 * m[-1])


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


def characteristic_rate_sq(scenario) -> float:
    """ω_c² (1/s²): the largest squared angular frequency of the motion — spring k/m (and k|r|²/I_min
    for a spring attached off the COM), the initial spin |ω0|², drag or decay rates squared."""
    p = scenario.problem
    m, I_min = p.body.mass_kg, float(np.linalg.eigvalsh(p.body.inertia_B)[0])
    rates = [float(np.dot(p.initial.w_W, p.initial.w_W)), (p.forces.linear_drag_N_s_per_m / m) ** 2]
    for sp in p.forces.springs:
        rates.append(sp.stiffness_N_per_m / m)
        rates.append(sp.stiffness_N_per_m * float(np.dot(sp.attach_B, sp.attach_B)) / I_min)
    return max(rates)


def euler_amplitude_parameter(scenario, dt_s: float) -> float:
    """χ = ω_c² Δt T / 2 (dimensionless): the exponent of the non-symplectic Euler amplitude error."""
    return 0.5 * characteristic_rate_sq(scenario) * dt_s * scenario.duration_s


def expectation(scenario, variant: str, quantity: str, mode: str = "free_running") -> Expectation:
    """The expected verdict and order of ``variant`` on ``scenario`` for ``quantity``.

    ``mode`` "free_running" gives the global order p; "one_step" gives the local order p + 1, and no
    expectation (verdict None) where the free run is expected not to converge: a missing term shows
    up as an O(Δt) local error in some quantities and O(Δt²) in others.
    """
    if mode not in ("free_running", "one_step"):
        raise ValueError(f"unknown mode {mode!r}; modes: free_running, one_step")
    free = _free_running(scenario, variant, quantity)
    if mode == "free_running":
        return free
    if free.verdict != "converges" or free.order is None:
        return Expectation(None, None, free.reason)
    return Expectation("converges", free.order + 1.0,
                       f"one step of an order-{free.order:g} scheme has an O(Δt^{free.order + 1:g}) local error")


def _free_running(scenario, variant: str, quantity: str) -> Expectation:
    if quantity not in QUANTITIES:
        raise ValueError(f"unknown quantity {quantity!r}; quantities: {', '.join(QUANTITIES)}")
    fm = scenario.problem.forces

    if variant in NO_GYROSCOPIC_TERM and gyroscopic_term_matters(scenario):
        if quantity in _ROTATION or rotation_drives_translation(scenario):
            coupled = ("" if quantity in _ROTATION else
                       "; the spring or body-frame force carries that rotation error into the translation")
            return Expectation(
                "does_not_converge", None,
                "the course update has no gyroscopic term −ω × (I ω), which is not zero on this body "
                f"(anisotropic inertia, ω off the principal axes){coupled}")

    why = MEASURED_ROTATION_NON_CONVERGENCE.get((variant, scenario.name))
    if why and (quantity in _ROTATION or rotation_drives_translation(scenario)):
        return Expectation("does_not_converge", None, f"{variant} is not symplectic: {why}")

    if variant in NON_SYMPLECTIC_EULER:
        from .tolerances import SWEEP_ORDER_TOL
        chi = euler_amplitude_parameter(scenario, max(scenario.dt_ladder_s))
        if chi > 2.0 * SWEEP_ORDER_TOL:
            chi_fine = euler_amplitude_parameter(scenario, min(scenario.dt_ladder_s))
            return Expectation(
                None, None,
                f"pre-asymptotic on this ladder: {variant} is not symplectic, its amplitude error grows like "
                f"e^χ − 1 with χ = ω²ΔtT/2 = {chi:.2g} at the coarsest Δt ({chi_fine:.2g} at the finest), and it "
                f"is first order only once χ ≤ {2.0 * SWEEP_ORDER_TOL:g}; no order is claimed here")

    p = nominal_order(variant)
    if p is None:
        return Expectation("converges", None, f"no nominal order is recorded for {variant}")
    return Expectation("converges", p, f"{variant} is an order-{p:g} scheme")


def expected_order(variant: str, quantity: str, scenario=None) -> float | None:
    """The expected global order of ``variant`` for ``quantity`` (None where it is expected not to
    converge). ``scenario``: a Scenario, a catalog name, or None (then the nominal order)."""
    if scenario is None:
        return nominal_order(variant)
    if isinstance(scenario, str):
        from .scenario import load_scenario
        scenario = load_scenario(scenario)
    return expectation(scenario, variant, quantity).order


def energy_drift_bound(scenario, variant: str, dt_s: float) -> float | None:
    """Upper bound on the maximum relative energy drift of ``variant`` on a conservative scenario.

    An order-p scheme's global error over T at step Δt on a motion of angular frequency ω is
    ~ C (ωΔt)^p ωT; energy errors are of the same relative size. C ≤ 2 covers every scheme here
    (explicit Euler's energy grows as e^{2χ} − 1 ≈ ω²ΔtT = (ωΔt)ωT, i.e. C = 1; ENGINE_FACTS: MuJoCo
    Euler on the tennis racket drifts 4.6e-3 over 20 s at Δt = 1e-3, C = 0.29). Returns None where no
    bound applies: a non-conservative scenario, a variant without a nominal order, or the course
    update on a body whose gyroscopic term matters (it does not model the conserved motion at all).
    """
    if not scenario.problem.forces.conservative:
        return None
    if variant in NO_GYROSCOPIC_TERM and gyroscopic_term_matters(scenario):
        return None
    p = nominal_order(variant)
    if p is None:
        return None
    w2 = characteristic_rate_sq(scenario)
    g = float(np.linalg.norm(scenario.problem.forces.gravity_W))
    if g > 0.0:
        # Under gravity the energy error of symplectic Euler is m|g|·½|g|tΔt over E = ½m|v0|²: the rate
        # |g|/|v0| gives exactly C = 1 (|v0| = 0 leaves no finite bound: E(0) has no kinetic scale).
        v0 = float(np.linalg.norm(scenario.problem.initial.v_W))
        w2 = max(w2, (g / v0) ** 2 if v0 > 0.0 else math.inf)
    w = math.sqrt(w2)
    n_steps = max(1, round(scenario.duration_s / dt_s))
    # + round-off: N steps of ε each, ×10 for the terms of E (measured 7 N ε on particle_body's RK4).
    return 2.0 * (w * dt_s) ** p * w * scenario.duration_s + 10.0 * n_steps * 2.2e-16
