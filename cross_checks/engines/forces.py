"""The harness's forces: what every engine gets applied, whoever steps it (docs/semantics.md, "Forces are
evaluated where each scheme's equations say" and "Velocity decay").

* Forces and torques are evaluated from the state at the start of each step and held over the step
  (zero-order hold), unless the engine evaluates them at every stage (:func:`stage_force_torque`).
* Velocity decay (the per-step factor γ at the scenario's dt) is damping at the rate ``k = −ln γ / dt``: a
  step Δt gets ``e^{−kΔt}`` (:func:`decay_factors`). A single-stage engine gets it BEFORE the step,
  ``v ← e^{−k_vΔt} v``, ``ω ← e^{−k_ωΔt} ω``, with that step's force and torque scaled alike: for a
  semi-implicit step exactly the course's ``v ← e^{−kΔt} (v + Δt f/m)``, and its rotation exactly where the
  gyroscopic torque vanishes (else a difference of order (1 − e^{−kΔt}) Δt: still first order). A multi-stage
  engine gets the damping in its right-hand side: a force ``−m k_v v`` at the COM, a torque ``−k_ω I_W ω``.
* An engine that applies gravity itself gets the harness force minus the weight ``m g`` (:func:`weight_W`).

The host loop (:mod:`cross_checks.engines.loop`) applies them to every world; the plain-float twins of its
per-step pieces are in :mod:`cross_checks.engines.step_floats`.
"""
from __future__ import annotations

import functools

import numpy as np

__all__ = ["float_forces", "decay_factors", "harness_force_torque", "harness_force_torque_floats",
           "stage_force_torque", "stage_force_torque_floats", "weight_W",
           "minus_weight"]


@functools.lru_cache(maxsize=64)
def float_forces(scenario):
    """The single-state force evaluator of this scenario (or of a Problem: the loop's, when the engine takes
    some forces itself) (reference_sim.compiled.ForceEvaluator: the definition's force model, compiled):
    ``.force_torque(y)`` -> 6 floats."""
    from reference_sim.compiled import ForceEvaluator
    return ForceEvaluator(getattr(scenario, "problem", scenario))


def decay_factors(scenario, dt_s: float):
    """``(γ_v, γ_ω)``: the per-step decay factors ``e^{−kΔt}`` at step ``dt_s`` (exactly the scenario's
    own factors at its dt); what an engine that applies decay per step must use at that Δt."""
    return scenario.problem.forces.decay_factors(float(dt_s))


def harness_force_torque(scenario, y, dt_s: float):
    """World force (N, at the COM) and world torque (N m) to apply for the step of ``dt_s`` starting at
    ``y`` (13,), scaled by the pre-step decay factors (see the module docstring); evaluated by
    :func:`float_forces`."""
    fx, fy, fz, tx, ty, tz = harness_force_torque_floats(scenario, y, dt_s)
    return np.array([fx, fy, fz]), np.array([tx, ty, tz])


def harness_force_torque_floats(scenario, y, dt_s: float) -> tuple:
    """:func:`harness_force_torque` as 6 plain floats (fx, fy, fz, tx, ty, tz): the same numbers, for an
    adapter's per-step loop, where building two small arrays per step costs more than the engine's step."""
    fx, fy, fz, tx, ty, tz = float_forces(scenario).force_torque(y)
    gv, gw = decay_factors(scenario, dt_s)
    return gv * fx, gv * fy, gv * fz, gw * tx, gw * ty, gw * tz


def stage_force_torque(scenario, y):
    """World force and torque of the right-hand side at state ``y`` (13,), decay included as the
    damping force ``−m k_v v`` at the COM and the torque ``−k_ω I_W ω`` (so that ``ω̇`` gets ``−k_ω ω``):
    what a multi-stage engine must see at every stage."""
    fx, fy, fz, tx, ty, tz = stage_force_torque_floats(scenario, y)
    return np.array([fx, fy, fz]), np.array([tx, ty, tz])


def stage_force_torque_floats(scenario, y) -> tuple:
    """:func:`stage_force_torque` as 6 plain floats (for the per-stage callback)."""
    return float_forces(scenario).force_torque(y, stage=True)


def weight_W(scenario) -> np.ndarray:
    """The body's weight ``m g`` (N, world axes): what an engine that applies gravity itself must not get
    again in its applied force."""
    return scenario.problem.body.mass_kg * np.asarray(scenario.problem.forces.gravity_W, dtype=float)


def minus_weight(harness, weight_W):
    """``y -> (fx, fy, fz, tx, ty, tz)``: the plain-float ``harness(y)`` (step_floats.harness_fn) with the
    weight ``weight_W`` (N, world axes) taken off its force: what an engine that applies gravity gets."""
    w0, w1, w2 = (float(w) for w in weight_W)

    def wrench(y):
        fx, fy, fz, tx, ty, tz = harness(y)
        return fx - w0, fy - w1, fz - w2, tx, ty, tz
    return wrench
