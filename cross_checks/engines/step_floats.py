"""Plain-float pieces of the engine adapters' per-step loops: the same numbers, bit for bit, as the NumPy
functions they stand for, without building tiny arrays every step.

Each takes and returns Python floats and says which function it reproduces and in which order it does the
arithmetic (IEEE 754 results depend on it); tests/cross_checks/engines/test_step_floats.py compares them
with that function bit for bit.
"""
from __future__ import annotations

from cross_checks.engines import forces
from reference_sim.simulate import BLOWUP_LIMIT

__all__ = ["harness_fn", "quat_mul_floats", "bad_floats"]


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


def quat_mul_floats(a, b) -> list:
    """``reference_sim.quaternion.quat_mul(a, b)`` for two quaternions (w, x, y, z) of 4 floats each, with
    NumPy's order of operations: the dot product summed left to right (``np.sum`` of 3 terms), then
    ``s1 v2 + s2 v1`` plus the cross product ``v1 × v2`` (reference_sim.vec.cross3)."""
    s1, x1, y1, z1 = a
    s2, x2, y2, z2 = b
    return [s1 * s2 - (x1 * x2 + y1 * y2 + z1 * z2),
            s1 * x2 + s2 * x1 + (y1 * z2 - z1 * y2),
            s1 * y2 + s2 * y1 + (z1 * x2 - x1 * z2),
            s1 * z2 + s2 * z1 + (x1 * y2 - y1 * x2)]


def bad_floats(row) -> bool:
    """``reference_sim.simulate.bad_rows`` of one state given as floats: whether it is non-finite or has a
    component beyond BLOWUP_LIMIT."""
    total = sum(row)
    return total != total or max(row) > BLOWUP_LIMIT or min(row) < -BLOWUP_LIMIT
