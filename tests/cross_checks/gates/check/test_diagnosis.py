"""cross_checks.gates.check.diagnosis: the slips named for a wrong first row, and the Δt scale fitted to rows
that advance too far (hand-built states)."""
import numpy as np

from cross_checks.gates.check.diagnosis import initial_state_slips
from cross_checks.scenario import load_scenario
from reference_sim.quaternion import quat_conj, rotate

SC = load_scenario("velocity_decay")     # q0 = 45° about y, ω0 = R (0, 0, 2)
Y0 = SC.problem.initial_packed()
TOL = {q: 1e-12 for q in ("position", "velocity", "orientation", "angular_velocity")}
PRESENT = tuple(TOL)


def test_the_scenarios_own_first_row_has_no_slip():
    assert initial_state_slips(Y0, Y0, TOL, PRESENT) == []


def test_angular_velocity_in_body_axes_is_named():
    row = Y0.copy()
    row[10:13] = rotate(quat_conj(Y0[6:10]), Y0[10:13])
    assert initial_state_slips(row, Y0, TOL, PRESENT) == [
        "the angular velocity is written in body axes (the file's columns wx,wy,wz are world axes)"]


def test_a_quaternion_written_x_y_z_w_is_named():
    row = Y0.copy()
    row[6:10] = Y0[[7, 8, 9, 6]]
    assert "the quaternion is written in (x, y, z, w) order under the names qw,qx,qy,qz" in \
        initial_state_slips(row, Y0, TOL, PRESENT)


def test_degrees_per_second_are_named():
    row = Y0.copy()
    row[10:13] = np.rad2deg(Y0[10:13])
    assert initial_state_slips(row, Y0, TOL, PRESENT) == ["the angular velocity is in degrees "
                                                          "per second (radians expected)"]
