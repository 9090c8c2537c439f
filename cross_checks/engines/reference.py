"""The NumPy reference of the course equations as an engine adapter (``reference:VARIANT``)."""
from __future__ import annotations

import dataclasses
import time

import numpy as np

import reference_sim
from cross_checks.engines import base as B
from cross_checks.engines.base import ModuleAdapter, Variant
from reference_sim.forces import Members
from reference_sim.integrators import BULLET_MAX_GYROSCOPIC_TORQUE, ImplicitSolveError, get_step
from reference_sim.integrators import VARIANTS as SCHEMES
from reference_sim.simulate import Run, run_members
from reference_sim.simulate import simulate as _simulate

ENGINE = "reference"
#: What each scheme's step does besides its order (cross_checks.engines.base.Traits;
#: tests/cross_checks/analysis/test_expectations.py pins each sign on the schemes themselves): the course's
#: update has no gyroscopic term; the course-type schemes with it are body-frame symplectic Euler steps;
#: explicit and implicit Euler step the whole state in world axes.
TRAITS = {
    "course": B.Traits(gyroscopic_term=False),
    "course_gyro": B.SYMPLECTIC_EULER_EXPLICIT_GYRO, "expmap_gyro": B.SYMPLECTIC_EULER_EXPLICIT_GYRO,
    "explicit_euler": B.WHOLE_STATE_EXPLICIT_EULER, "implicit_euler": B.WHOLE_STATE_IMPLICIT_EULER,
    "midpoint": B.HIGHER_ORDER, "leapfrog": B.HIGHER_ORDER, "rk4": B.HIGHER_ORDER,
    # Bullet's implicit gyroscopic steps (body and world axes: the same step, see their docstrings): a
    # body-frame implicit Euler step of Euler's equations, linearised; energy and |L|² decay together
    "implicit_gyro_body": B.SYMPLECTIC_EULER_IMPLICIT_GYRO,
    "implicit_gyro_world": B.SYMPLECTIC_EULER_IMPLICIT_GYRO,
    # Bullet's explicit one: expmap_gyro wherever its clamp does not act; where it acts (a fast spin of a
    # large body) it solves another equation
    "explicit_gyro_clamped": dataclasses.replace(B.SYMPLECTIC_EULER_EXPLICIT_GYRO,
                                                 gyroscopic_clamp_N_m=BULLET_MAX_GYROSCOPIC_TORQUE),
    # Jolt's: |L| kept exactly, the energy drifts by O(Δt²) per step towards L²/2I₂ (up from a spin about the
    # major axis, down from one about the minor axis): its own kind, either sign
    "jolt_gyro": B.Traits(rotation_drift="momentum", rotation_sign=None),
    # second order, symmetric (Buss's map is not, but is second order): no amplitude rule applies. What each
    # keeps by construction on a torque-free body (docs/gyro_integrators.md): Buss and DLM hold L over the
    # step (ω₁ = I_W(R₁)⁻¹ L), DLM is symplectic (bounded energy error); the midpoint rule and Moser–Veselov
    # keep every quadratic invariant: the energy, |Π| and L (Π₁ = FᵀΠ, R₁ = R F)
    "buss_augmented": B.Traits(keeps=("angular_momentum",)),
    "dlm_splitting": B.Traits(keeps=("angular_momentum", "energy_bounded")),
    "lp_midpoint": B.Traits(keeps=("energy", "angular_momentum")),
    "moser_veselov": B.Traits(keeps=("energy", "angular_momentum")),
}
#: ... and none holds a lever arm from the world origin: torques are r × F with r = R r_B from the COM, and ω
#: is stepped itself, never recovered from a momentum about the origin (reference_sim/integrators.py).
TRAITS = {v: dataclasses.replace(t, lever_arms=False) for v, t in TRAITS.items()}
#: Declared variants: reference_sim.integrators.VARIANTS, the one registry (orders proven by its own tests).
VARIANTS = {v: Variant(float(s.order), s.description, traits=TRAITS[v]) for v, s in SCHEMES.items()}


def version() -> str:
    return reference_sim.__version__


def simulate(scenario, variant: str, dt_s: float, n_steps: int) -> Run:
    return _simulate(scenario.problem, variant, dt_s, n_steps)


def simulate_many(variant: str, requests) -> list:
    """The runs of ``requests`` (base.RunRequest) with ``variant``, all advanced together as the members of
    one compiled run (reference_sim.simulate.run_members): each equal to :func:`simulate` of that request,
    each stopping at its own ``n_steps`` or at its own divergence."""
    requests = list(requests)
    if not requests:
        return []
    problems = [r.scenario.problem for r in requests]
    t0 = time.perf_counter()
    runs = run_members(Members.stack(problems), variant, [r.dt_s for r in requests],
                       [r.n_steps for r in requests], np.array([p.initial_packed() for p in problems]))
    engine_s, steps = time.perf_counter() - t0, max(1, sum(r.n_steps for r in requests))
    for r, run in zip(requests, runs):   # the reference is its own engine: its time is the compiled run's
        run.engine_s, run.host_s = engine_s * r.n_steps / steps, 0.0
    return runs


def one_step(scenario, variant: str, dt_s: float, y_start) -> np.ndarray:
    """One step from each row of ``y_start`` (T, 13) — batched: all rows advance in one call."""
    step = get_step(variant)
    with np.errstate(all="ignore"):
        try:
            return step(scenario.problem, np.asarray(y_start, dtype=float), dt_s)
        except ImplicitSolveError:
            return np.full(np.shape(y_start), np.nan)


class ReferenceAdapter(ModuleAdapter):
    """``reference:VARIANT`` — registered under the entry-point group ``rbcheck.engines``."""

    harness = ()
