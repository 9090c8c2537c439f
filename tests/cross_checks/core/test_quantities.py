"""Error metrics of the four quantities (cross_checks.core.quantities) on hand-made cases."""
import math

import numpy as np
import pytest

from cross_checks.core.quantities import error_summary, state_errors
from reference_sim.quaternion import quat_from_axis_angle
from tests.helpers.scenarios import state

# --- errors --------------------------------------------------------------------------------------

@pytest.mark.parametrize("angle", [1e-6, 0.3, 2.5, math.pi - 1e-3])
def test_orientation_error_is_the_rotation_angle_between_the_pair(angle):
    q_ref = quat_from_axis_angle(np.array([0.3, -0.5, 0.8]), 0.7)
    dq = quat_from_axis_angle(np.array([1.0, 2.0, -1.0]), angle)
    from reference_sim.quaternion import quat_mul
    q = quat_mul(q_ref, dq)
    e = state_errors(state(q=q)[None], state(q=q_ref)[None])["orientation"][0]
    assert e == pytest.approx(angle, rel=1e-12, abs=1e-15)


def test_orientation_error_is_sign_invariant():
    q = quat_from_axis_angle(np.array([0.0, 0.0, 1.0]), 0.4)
    q_ref = quat_from_axis_angle(np.array([1.0, 0.0, 0.0]), -1.1)
    e_pos = state_errors(state(q=q)[None], state(q=q_ref)[None])["orientation"][0]
    e_neg = state_errors(state(q=-q)[None], state(q=q_ref)[None])["orientation"][0]
    assert e_pos == e_neg
    assert state_errors(state(q=-q)[None], state(q=q)[None])["orientation"][0] == 0.0


def test_orientation_error_normalises_non_unit_quaternions():
    q = quat_from_axis_angle(np.array([0.0, 1.0, 0.0]), 0.5)
    e = state_errors(state(q=1.001 * q)[None], state()[None])["orientation"][0]
    assert e == pytest.approx(0.5, rel=1e-12)


def test_vector_errors_are_euclidean_norms():
    a = state(x=(1, 2, 3), v=(0, 0, 1), w=(0.5, 0, 0))
    b = state(x=(1, 2, 0), v=(3, 4, 1), w=(0, 0, 0))
    e = state_errors(a[None], b[None])
    assert e["position"][0] == 3.0 and e["velocity"][0] == 5.0 and e["angular_velocity"][0] == 0.5


def test_error_summary_final_and_max():
    s = error_summary({"position": np.array([0.0, 3.0, 1.0])})
    assert s["position"] == {"final": 1.0, "max": 3.0}
