"""Convergence fitting on synthetic ladders and the comparison with an expectation
(cross_checks.analysis.convergence)."""
import math

import pytest

from cross_checks.analysis.convergence import (
    compare_with_expectation,
    fit_convergence,
    measured_pre_asymptotic,
    order_within_floors,
    pairwise_orders,
)
from cross_checks.analysis.expectations import Expectation, expectation
from cross_checks.core import tolerances as tol
from cross_checks.engines import resolve
from cross_checks.scenario import load_scenario

LADDER = [0.02 / 2 ** k for k in range(5)]


# --- convergence fitting ---------------------------------------------------------------------------

@pytest.mark.parametrize("p", [1, 2, 4])
def test_fit_recovers_the_order_of_a_clean_ladder(p):
    e = [3.0 * h ** p for h in LADDER]
    fit = fit_convergence(LADDER, e)
    assert fit.verdict == "converges"
    assert fit.order == pytest.approx(p, abs=1e-12)
    assert fit.pairwise_orders == pytest.approx([p] * 4, abs=1e-12)
    assert all(fit.fitted)


def test_pairwise_orders_are_log2_ratios_for_halving():
    assert pairwise_orders([0.2, 0.1], [8.0, 2.0]) == [pytest.approx(2.0)]
    assert pairwise_orders([0.2, 0.1], [8.0, 0.0]) == [None]


def test_fit_sorts_the_ladder():
    e = [3.0 * h ** 2 for h in LADDER]
    fit = fit_convergence(LADDER[::-1], e[::-1])
    assert fit.dt_s == LADDER and fit.order == pytest.approx(2.0)


def test_points_at_the_roundoff_floor_are_dropped():
    floor = 1e-11
    e = [max(h ** 4, 5e-12) for h in LADDER]   # 1.6e-7 … 6.3e-10, then 3.9e-11 (4× floor) and round-off
    fit = fit_convergence(LADDER, e, floors=[floor] * 5)
    assert fit.verdict == "converges"
    assert fit.fitted == [True, True, True, False, False]
    assert fit.order == pytest.approx(4.0, abs=1e-9)
    assert "round-off" in fit.note


def test_all_points_at_the_floor_is_at_roundoff():
    fit = fit_convergence(LADDER, [1e-15, 3e-16, 0.0, 2e-15, 1e-15], floors=[1e-13] * 5)
    assert fit.verdict == "at_roundoff" and fit.order is None


def test_a_plateau_does_not_converge():
    e = [3.0 + 1e-3 * h for h in LADDER]
    fit = fit_convergence(LADDER, e)
    assert fit.verdict == "does_not_converge"
    assert abs(fit.order) < 0.01


def test_error_growing_again_below_the_best_step_does_not_converge():
    # frame-rate dependent physics: smallest error at one Δt, larger on both sides
    e = [0.3, 0.01, 0.2, 0.3, 0.35]
    assert fit_convergence(LADDER, e).verdict == "does_not_converge"


def test_pre_asymptotic_coarsest_point_is_dropped():
    e = [3.0 * h ** 2 for h in LADDER]
    e[0] *= 40.0  # the coarsest point is far off the asymptotic line
    fit = fit_convergence(LADDER, e)
    assert fit.fitted[0] is False
    assert fit.order == pytest.approx(2.0, abs=1e-12)


def test_diverged_points_are_left_out_and_all_diverged_is_diverged():
    e = [math.nan] + [h for h in LADDER[1:]]
    fit = fit_convergence(LADDER, e, statuses=["diverged", "ok", "ok", "ok", "ok"])
    assert fit.verdict == "converges" and fit.order == pytest.approx(1.0)
    assert "diverged" in fit.note
    fit = fit_convergence(LADDER, [math.nan] * 4 + [1e-3], statuses=["diverged"] * 4 + ["ok"])
    assert fit.verdict == "diverged"
    fit = fit_convergence(LADDER, [math.nan] * 5, statuses=["failed"] * 5)
    assert fit.verdict == "failed"


def test_a_point_less_than_ten_times_above_its_floor_is_not_fitted():
    # mujoco:rk4 on tumbling_box (ω error, rad/s): 3.2e-10 is half round-off at 1.7× its floor; fitted,
    # it bent the order to 3.4
    e = [5.6e-7, 3.4e-8, 2.4e-9, 3.2e-10, 9.8e-11]
    floors = [7.8e-11, 1.0e-10, 1.4e-10, 1.9e-10, 2.6e-10]
    fit = fit_convergence([0.008, 0.004, 0.002, 0.001, 0.0005], e, floors)
    assert fit.fitted == [True, True, True, False, False] and fit.order == pytest.approx(3.93, abs=0.01)


def test_one_resolved_point_and_one_above_the_floor_give_a_lower_bound():
    # mujoco:rk4 on particle_body (ω): only the coarsest error is 10× above its floor, the next 9×
    e = [7.0e-11, 4.4e-12, 2.8e-13, 2.0e-14, 4.5e-14]
    floors = [3.8e-13, 4.9e-13, 6.4e-13, 8.6e-13, 1.2e-12]
    fit = fit_convergence(LADDER, e, floors)
    assert fit.verdict == "converges" and fit.order_is_lower_bound
    assert fit.fitted == [True, True, False, False, False] and fit.order == pytest.approx(3.99, abs=0.01)
    rk4 = Expectation("converges", 4.0, "")
    assert compare_with_expectation("converges", 3.99, rk4, True)[0] is True
    assert compare_with_expectation("converges", 2.0, rk4, True)[0] is None      # inconclusive, not wrong
    assert compare_with_expectation("converges", 2.0, rk4, False)[0] is False
    # with no resolved point at all the errors are round-off, whatever they do
    assert fit_convergence(LADDER, [3e-13, 1e-12, 5e-13, 2e-12, 9e-13], [2e-13] * 5).verdict == "at_roundoff"


def test_a_low_order_whose_finest_pair_reaches_the_expected_one_is_measured_pre_asymptotic():
    # expmap_gyro on a particle body on a spring: 0.76, 0.49, 0.75, 0.88 … and 0.94, 0.97 on finer steps
    e = [0.7556, 0.4523, 0.3184, 0.1896, 0.1033]
    fit = fit_convergence(LADDER, e)
    assert fit.verdict == "converges" and fit.order < 1.0 - tol.SWEEP_ORDER_TOL
    assert "finest pair" in measured_pre_asymptotic(fit, 1.0)
    # a scheme of the wrong order shows it on its finest pair too: not excused
    wrong = fit_convergence(LADDER, [h ** 2 for h in LADDER])
    assert measured_pre_asymptotic(wrong, 4.0) == ""
    stuck = fit_convergence(LADDER, [0.76, 0.5, 0.36, 0.26, 0.19])  # pairwise orders ~0.5, not reaching 1
    assert measured_pre_asymptotic(stuck, 1.0) == ""


# --- comparison with an expectation (the expectations themselves: test_expectations.py) ----------

def test_comparison_with_expectation():
    conv = expectation(load_scenario("projectile"), resolve("reference:midpoint"), "position")
    assert compare_with_expectation("converges", 2.05, conv)[0] is True
    assert compare_with_expectation("converges", 1.0, conv)[0] is False
    assert compare_with_expectation("converges", 3.0, conv) == (True, "order 3.00, above the nominal 2")
    assert compare_with_expectation("at_roundoff", None, conv)[0] is True
    assert compare_with_expectation("does_not_converge", 0.0, conv)[0] is False
    assert compare_with_expectation("diverged", None, conv)[0] is False
    nc = expectation(load_scenario("tennis_racket"), resolve("reference:course"), "orientation")
    assert compare_with_expectation("does_not_converge", 0.0, nc)[0] is True
    assert compare_with_expectation("converges", 1.0, nc)[0] is False


def test_one_exact_point_inside_a_non_convergent_ladder_is_not_roundoff():
    # a frame-rate dependent decay (the course's γ applied per step at every Δt): at the scenario's own
    # Δt the course matches the reference exactly, nowhere else
    e = [0.26, 6e-17, 0.13, 0.149, 0.1498]
    fit = fit_convergence(LADDER, e, floors=[1e-13] * 5)
    assert fit.verdict == "does_not_converge"


def test_error_growing_again_at_round_off_level_is_amplified_roundoff():
    # MuJoCo RK4 on tumbling_box (orientation, rad): order 4 until ~1e-10, then round-off grows
    e = [2.0e-8, 1.3e-9, 1.4e-10, 3.26e-11, 1.49e-10]
    fit = fit_convergence(LADDER[1:] + [LADDER[-1] / 2], e, floors=[1e-12] * 5)
    assert fit.verdict == "converges"
    assert fit.fitted == [True, True, False, False, False]
    assert fit.order == pytest.approx(3.94, abs=0.01)
    assert "amplified" in fit.note


def test_rising_pairwise_orders_are_called_pre_asymptotic():
    e = [2.35e-1, 1.91e-1, 1.32e-1, 8.0e-2, 4.43e-2]
    fit = fit_convergence(LADDER, e)
    assert "pre-asymptotic" in fit.note


def test_the_median_of_the_pre_asymptotic_rule_is_numpys():
    """convergence._median (a few pairwise orders) equals np.median exactly, odd and even counts."""
    import numpy as np

    from cross_checks.analysis.convergence import _median
    rng = np.random.default_rng(11)
    for n in range(1, 9):
        for _ in range(500):
            v = (rng.standard_normal(n) * 10.0 ** rng.uniform(-3, 3, n)).tolist()
            assert _median(v) == float(np.median(v))


def test_a_flat_fit_s_tiny_negative_order_is_written_as_zero():
    from cross_checks.analysis.convergence import fmt_order
    assert fmt_order(-0.0004) == "0.00" and fmt_order(-0.006) == "-0.01" and fmt_order(0.987) == "0.99"
    fit = fit_convergence([0.06, 0.03, 0.015],
                          [9.16e-4, 9.16e-4 * (1 + 1e-6), 9.16e-4 * (1 + 2e-6)], [2.5e-13] * 3)
    assert fit.order < 0 and "(fitted order 0.00)" in compare_with_expectation(
        fit.verdict, fit.order, Expectation("converges", 1.0, "an order-1 scheme"))[1]


# Drake runge_kutta3 in the fuzz (seed 3, case 190): the finest error within 10x a generous lever-arm floor
DRAKE_DT = [0.024343227673126657, 0.012171613836563329, 0.006085806918281664]
DRAKE_E = [8.619677552088268e-11, 1.3597802417763613e-11, 1.8910664527449406e-12]
DRAKE_FL = [1.762448012359544e-13, 2.307381268013016e-13, 3.078033268746281e-13]


def test_order_within_floors_raises_the_coarse_errors_and_lowers_the_fine_ones_by_their_floors():
    fit = fit_convergence(DRAKE_DT, DRAKE_E, DRAKE_FL)
    assert fit.fitted == [True, True, False] and fit.order == pytest.approx(2.664, abs=1e-3)
    # three halvings: the middle point sits at the mean log Δt, so the slope is that of the two ends
    by_hand = math.log2((DRAKE_E[0] + DRAKE_FL[0]) / (DRAKE_E[2] - DRAKE_FL[2])) / 2.0
    assert (order_within_floors(fit) == pytest.approx(by_hand, rel=1e-12)
            and by_hand == pytest.approx(2.885, abs=1e-3))


def test_order_within_floors_leaves_a_resolved_wrong_order_wrong():
    # order 2 where 3 is claimed, errors 100x and more above their floors: no room for order 3
    dts = [0.02, 0.01, 0.005]
    e = [4e-9 * (h / 0.02) ** 2 for h in dts]
    fit = fit_convergence(dts, e, [x / 100.0 for x in e])
    assert fit.order == pytest.approx(2.0, abs=1e-9)
    assert order_within_floors(fit) < 3.0 - tol.SWEEP_ORDER_TOL
    assert order_within_floors(fit) == pytest.approx(math.log2(1.01 / 0.99) / 2.0 + 2.0, rel=1e-12)


def test_order_within_floors_ignores_points_at_or_below_their_floor():
    fit = fit_convergence([0.02, 0.01, 0.005], [1e-9, 2.5e-10, 1e-13], [1e-14, 1e-14, 1e-13])
    assert fit.fitted == [True, True, False]
    assert order_within_floors(fit) == pytest.approx(math.log2((1e-9 + 1e-14) / (2.5e-10 - 1e-14)), rel=1e-12)


# MuJoCo rk4's one-step angular velocity defects (fuzz seed 2026, case 5622): two rungs flat at 3.4e-15 rad/s,
# above floor estimates of 1.3-1.8e-15 — round-off, measured
MJ_DT = [0.00215, 0.001075, 0.0005375, 0.00026875]
MJ_FL = [1.37e-15, 9.81e-16, 1.76e-15, 1.32e-15]


def test_a_flat_round_off_tail_is_the_floor_of_every_rung():
    e = [2.44e-13, 1.04e-14, 3.37e-15, 3.38e-15]
    fit = fit_convergence(MJ_DT, e, MJ_FL)
    assert fit.fitted == [True, True, False, False] and fit.order == pytest.approx(4.55, abs=0.01)
    by_hand = math.log2((2.44e-13 + 3.38e-15) / (1.04e-14 - 3.38e-15))
    assert (order_within_floors(fit) == pytest.approx(by_hand, rel=1e-12)
            and by_hand > 5.0 - tol.SWEEP_ORDER_TOL)


def test_a_flat_tail_leaves_room_for_round_off_not_for_a_wrong_order():
    e = [2.44e-13, 2.44e-13 / 16.0, 3.4e-15, 3.4e-15]   # order 4 where one step of RK4 has 5
    fit = fit_convergence(MJ_DT, e, MJ_FL)
    assert order_within_floors(fit) < 5.0 - tol.SWEEP_ORDER_TOL
    # a tail that still shrinks (two rungs more than 2x apart) is not taken for round-off: the fitted pair
    # with its own floors (the tail point above its floor only lowers the three-point slope)
    fit = fit_convergence(MJ_DT, [2.44e-13, 1.04e-14, 3.37e-15, 1.2e-15], MJ_FL)
    assert order_within_floors(fit) == pytest.approx(math.log2((2.44e-13 + 1.37e-15) / (1.04e-14 - 9.81e-16)),
                                                     rel=1e-12)
