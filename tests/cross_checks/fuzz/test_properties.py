"""The fuzz's verdict rules, each against numbers rbcheck did not compute (hand-derived or an engine's)."""
import numpy as np
import pytest

from cross_checks.fuzz.properties import two_term_consistent

H = np.array([0.0377, 0.01885, 0.009425])


def test_an_order_p_error_with_a_large_next_term_is_two_term_consistent():
    # measured by the fuzz on reference:course (a weakly decayed spring from rest, 8 steps): e/h is affine
    assert two_term_consistent(H, [1.26e-4, 1.52e-4, 9.79e-5], [1e-13] * 3, 1.0)
    # hand-built: a h + b h² with b h = −0.74 a at the coarsest rung
    a, b = 0.0128, -0.25
    assert two_term_consistent(H, a * H + b * H ** 2, [0.0] * 3, 1.0)
    assert two_term_consistent(H, 3.0 * H ** 4 - 50.0 * H ** 5, [0.0] * 3, 4.0)


@pytest.mark.parametrize("order, errors", [
    (1.0, 0.3 + 0 * H),          # a plateau (decay twice, a frame mix-up)
    (1.0, 0.3 * H ** 0.5),       # half an order short
    (4.0, 2.0 * H ** 2),         # RK4 with a wrong stage weight: order 2
    (2.0, 5.0 * H),              # mid-point stage at the full step: order 1
])
def test_a_wrong_order_is_not_two_term_consistent(order, errors):
    assert not two_term_consistent(H, errors, [0.0] * 3, order)


def test_errors_near_their_floor_are_never_excused():
    a, b = 0.0128, -0.25
    e = a * H + b * H ** 2
    assert not two_term_consistent(H, e, e / 50.0, 1.0)


def test_the_lever_arm_floor_covers_mujocos_measured_round_off():
    """A tensor body at rest falling far from the origin: the true ω stays exactly 0, MuJoCo's picks up
    round-off from lever arms measured from the world origin — above the plain ε floor, below the
    lever-arm term of fuzz.properties.lever_roundoff."""
    from cross_checks.engines import get_adapter
    from cross_checks.fuzz.pipeline import scenario_of
    from cross_checks.fuzz.properties import lever_roundoff
    I = np.diag([0.00113, 0.0128, 0.0131])
    R = np.linalg.qr(np.array([[1.0, 0.3, 0.2], [0.1, 1.0, 0.4], [0.3, 0.2, 1.0]]))[0]
    spec = {"name": "lever", "duration": 0.4, "dt": 0.01, "body": {"mass": 9.25, "inertia": (R @ I @ R.T).tolist()},
            "initial": {"position": [0.4, -0.3, 0.5], "velocity": [0.28, 0.0, 0.0]},
            "forces": {"gravity": [0.0, 0.0, -11.65]}}
    sc = scenario_of(spec)
    run = get_adapter("mujoco").simulate(sc, "euler", 0.01, 40)
    w_err = float(np.max(np.linalg.norm(np.asarray(run.y)[:, 10:13], axis=1)))
    y_ref = np.asarray(get_adapter("reference").simulate(sc, "rk4", 0.01, 40).y)
    lv = lever_roundoff(sc, y_ref)
    assert w_err > 10 * 2.0 ** -52           # above any ε |ω| (|ω| = 0 here): it is the lever arms
    assert w_err <= lv["acc_rad_s2"] * sc.duration_s


def test_a_too_low_order_that_the_measured_round_off_leaves_room_for_is_no_claim():
    # the fuzz (seed 3, case 190) called drake:runge_kutta3 order 2.66: its lever-arm floor dropped the finest
    # rung, leaving the coarsest pair, bent by the next term; within the floors the order can be 2.89
    from cross_checks.analysis.expectations import Expectation
    from cross_checks.fuzz.properties import _fit_record
    exp = Expectation("converges", 3.0, "an order-3 scheme")
    dts = [0.024343227673126657, 0.012171613836563329, 0.006085806918281664]
    e = [8.619677552088268e-11, 1.3597802417763613e-11, 1.8910664527449406e-12]
    fl = [1.762448012359544e-13, 2.307381268013016e-13, 3.078033268746281e-13]
    assert _fit_record(None, "drake:runge_kutta3", "orientation", dts, e, fl, None, exp,
                       "free_running_order") == (None, False)
    # the same ladder with an order-2 scheme's finest error (resolved 11x above its floor): still a violation
    e_wrong = e[:2] + [e[1] / 4.0]
    rec, claimed = _fit_record(None, "drake:runge_kutta3", "orientation", dts, e_wrong, fl, None, exp,
                               "free_running_order")
    assert claimed and rec is not None and rec["order"] < 2.7
