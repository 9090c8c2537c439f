"""What every engine adapter provides, and the harness semantics they share.

An adapter module (``cross_checks.engines.<engine>``) defines:

``ENGINE``            the engine name used in ``ENGINE:VARIANT``.
``VARIANTS``          dict variant -> one-line description.
``version()``         the engine's version string (raises ImportError when the engine is missing).
``simulate(scenario, variant, dt_s, n_steps) -> reference_sim.simulate.Run``
                      free-running run from the scenario's initial state, every step recorded
                      (``Run.y``: (n+1, 13) packed [x_W, v_W, q_WB (w x y z), w_W]); a blow-up stops the
                      run with ``diverged_at_s`` set, never an exception.
``one_step(scenario, variant, dt_s, y_start) -> y_next``
                      for each row of ``y_start`` (T, 13), one step of ``dt_s`` from exactly that
                      state (the local error mode of the metrics).

Harness semantics (identical in every adapter, DESIGN.md):

* Forces and torques are evaluated by ``scenario.problem.forces.force_torque`` from the state at the
  start of each step and held over the step (zero-order hold) unless the engine can evaluate them at
  every stage (MuJoCo RK4 through its control callback).
* The course's per-step velocity decay γ has no engine equivalent. The harness applies it BEFORE the
  step: ``v ← γ v``, ``ω ← γ_ω ω``, and scales that step's applied force by γ and torque by γ_ω. For a
  semi-implicit (Euler-type) engine this reproduces the reference's ``v ← γ (v + Δt f/m)`` exactly,
  and the rotation exactly whenever the gyroscopic torque vanishes (spin about a principal axis);
  otherwise the gyroscopic term sees γ_ω² instead of γ_ω — a difference of order (1 − γ_ω) Δt.
"""
from __future__ import annotations

import functools

import numpy as np

__all__ = ["harness_force_torque", "apply_decay_prestep", "EngineError"]


class EngineError(RuntimeError):
    """The engine rejected the model or failed during a run; the message carries the engine's own words.
    A sweep records the run as `failed` with this message and goes on."""


@functools.lru_cache(maxsize=64)
def _float_forces(scenario):
    """The plain-float force evaluator of reference_sim.scalar for this scenario (built once)."""
    from reference_sim.scalar import ScalarStepper
    return ScalarStepper(scenario.problem, "course", scenario.dt_s)


def harness_force_torque(scenario, y):
    """World force (N, at the COM) and world torque (N m) to apply for the step starting at ``y`` (13,),
    decay scaling included (see the module docstring).

    Evaluated with the plain-float kernel of reference_sim.scalar (the same formulas as
    ForceModel.force_torque, tested equal to it): it runs once per engine step, or once per RK4 stage,
    where NumPy's per-call overhead would dominate the engine's own step time.
    """
    fm = scenario.problem.forces
    fx, fy, fz, tx, ty, tz = _float_forces(scenario).force_torque(y)
    gv, gw = fm.velocity_decay, fm.angular_velocity_decay
    return np.array([gv * fx, gv * fy, gv * fz]), np.array([gw * tx, gw * ty, gw * tz])


def apply_decay_prestep(scenario, y):
    """The state(s) ``y`` (..., 13) with the pre-step decay applied (a copy)."""
    fm = scenario.problem.forces
    y = np.array(y, dtype=float)
    y[..., 3:6] *= fm.velocity_decay
    y[..., 10:13] *= fm.angular_velocity_decay
    return y
