"""Plain-float pieces of the engine adapters' per-step loops: the same numbers, bit for bit, as the NumPy
functions they stand for, without building tiny arrays every step.

Each takes and returns Python floats and says which function it reproduces and in which order it does the
arithmetic (IEEE 754 results depend on it); tests/cross_checks/engines/test_step_floats.py compares them
with that function bit for bit.
"""
from __future__ import annotations

from cross_checks.engines import forces
from reference_sim.simulate import BLOWUP_LIMIT

__all__ = ["harness_fn", "bad_floats"]


def harness_fn(scenario, dt_s: float):
    """``y -> forces.harness_force_torque_floats(scenario, y, dt_s)`` (6 floats: world force at the COM, N,
    and world torque, N m, scaled by the pre-step decay factors), with the float force evaluator and the
    factors looked up once instead of every step. ``y``: the packed state (13 floats, a list preferred)."""
    ft = forces.float_forces(scenario).force_torque
    gv, gw = (float(g) for g in forces.decay_factors(scenario, dt_s))

    def harness(y):
        fx, fy, fz, tx, ty, tz = ft(y)
        return gv * fx, gv * fy, gv * fz, gw * tx, gw * ty, gw * tz
    return harness


def bad_floats(row) -> bool:
    """``reference_sim.simulate.bad_rows`` of one state given as floats: whether it is non-finite or has a
    component beyond BLOWUP_LIMIT."""
    total = sum(row)
    return total != total or max(row) > BLOWUP_LIMIT or min(row) < -BLOWUP_LIMIT
