"""How a convergence fit is judged against its expectation (cross_checks/analysis/judge.py, the one judge)."""
import pytest

from cross_checks.analysis.convergence import fit_convergence
from cross_checks.analysis.expectations import Expectation
from cross_checks.analysis.judge import judge_fit


def _judged(fit, exp):
    j = judge_fit(fit, exp)
    return j.verdict, j.matches, j.assessment

DTS = [0.024343227673126657, 0.012171613836563329, 0.006085806918281664]
ERRS = [8.619677552088268e-11, 1.3597802417763613e-11, 1.8910664527449406e-12]
ORDER3 = Expectation("converges", 3.0, "an order-3 scheme")


def test_a_low_order_the_round_off_floors_leave_room_for_makes_no_claim():
    # floors that drop the finest rung (the fuzz's Drake case, seed 3 case 190): the coarsest pair alone says
    # 2.66, but within the floors the errors allow 2.89
    fit = fit_convergence(DTS, ERRS, [1.762448012359544e-13, 2.307381268013016e-13, 3.078033268746281e-13])
    verdict, matches, phrase = _judged(fit, ORDER3)
    assert (verdict, matches) == ("converges", None)
    assert "allow order 2.88 within their round-off floors" in phrase and "no claim" in phrase


def test_the_same_errors_with_epsilon_floors_match_on_all_three_rungs():
    fit = fit_convergence(DTS, ERRS, [9.6e-15, 1.1e-14, 1.4e-14])   # the sweep's own floors for this file
    assert _judged(fit, ORDER3)[1] is True and fit.order == pytest.approx(2.755, abs=1e-3)


def test_an_order_two_ladder_still_contradicts_order_three():
    e = [ERRS[0], ERRS[0] / 4.0, ERRS[0] / 16.0]
    fit = fit_convergence(DTS, e, [x / 50.0 for x in e])
    verdict, matches, _ = _judged(fit, ORDER3)
    assert verdict == "converges" and matches is False
