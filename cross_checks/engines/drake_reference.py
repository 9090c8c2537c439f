"""Drake's error-controlled integration of a scenario: the second, independent high-accuracy reference.

The model is the adapter's (:class:`cross_checks.engines.drake_engine.DrakeModel`: Drake's own
multibody dynamics of the free body, its gravity, the scenario's forces and decay as the right-hand
side at every stage), integrated by Drake's error-controlled ``runge_kutta5`` (Dormand–Prince 5(4))
at a target accuracy — nothing of rbcheck's closed forms, DOP853 ground truth or quaternion code is
used on the way, except the scenario's force formulas (the same ones the engines are given).
"""
from __future__ import annotations

import numpy as np

from cross_checks.engines.drake_engine import DrakeModel, version

__all__ = ["INTEGRATOR", "drake_solution", "drake_label", "version"]

#: Drake's error-controlled integrator of the second reference (Dormand–Prince 5(4)).
INTEGRATOR = "runge_kutta5"


def drake_label(target_accuracy: float) -> str:
    return f"drake {version()} {INTEGRATOR}, error-controlled, target accuracy {target_accuracy:g}"


def drake_solution(scenario, t_s, target_accuracy: float):
    """``(y, steps)``: states (T, 13) packed ``[x_W, v_W, q_WB, ω_W]`` at the increasing times ``t_s`` (from
    0), from the scenario's initial state, and the number of steps Drake took. Raises ImportError when Drake
    is not installed and RuntimeError when Drake cannot reach a time (its message)."""
    t_s = np.asarray(t_s, dtype=float)
    model = DrakeModel(scenario, INTEGRATOR)
    integ = model.integrator
    integ.set_fixed_step_mode(False)
    integ.set_target_accuracy(float(target_accuracy))
    integ.set_maximum_step_size(max(float(t_s[-1]), 1e-9))
    integ.request_initial_step_size_target(1e-4 * max(float(t_s[-1]), 1e-9))
    model.set_state(scenario.problem.initial_packed())
    out = np.empty((t_s.size, 13))
    for k, t in enumerate(t_s):
        if t > 0.0:
            model.simulator.AdvanceTo(float(t))
        out[k] = model.state()
    return out, int(integ.get_num_steps_taken())
