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


def test_every_rung_within_its_floor_is_no_agreement_where_the_steps_are_wrong_in_that_quantity():
    """Errors all within their floors (here a flat 0.05 under amplified float32 floors of 0.1) agree with
    "converges" — unless the runs' own one-step defect says their equations are wrong in that quantity;
    another quantity's defect (the course's missing term in ω) leaves an exact position exact."""
    from cross_checks.analysis.judge import LocalEvidence
    dts, errs, floors = [0.01, 0.005, 0.0025], [0.05, 0.05, 0.05], [0.1, 0.1, 0.1]
    exp = Expectation("converges", 1.0, "an order-1 scheme", "float32")
    fit = fit_convergence(dts, errs, floors)
    assert fit.verdict == "at_roundoff"
    assert judge_fit(fit, exp).matches is True
    wrong = LocalEvidence(40.0, "angular_velocity", 0.01, 1.0)
    refused = judge_fit(fit, exp, wrong, "angular_velocity")
    assert refused.matches is False and "no round-off excuse" in refused.assessment and refused.claimed
    assert judge_fit(fit, exp, wrong, "position").matches is True
    assert judge_fit(fit, exp, LocalEvidence(0.5, "angular_velocity", 0.01, 1.0),
                     "angular_velocity").matches is True
    # a float32 verdict names its precision and the rungs it judged
    assert ("float32" in judge_fit(fit, exp).assessment
            and "no two rungs resolved of 3" in judge_fit(fit, exp).assessment)
    # ... and the unit of its floors: ε, or ε times the rounding factor its variant declares
    assert "floors from ε = 1.2e-07 per step" in judge_fit(fit, exp).assessment
    deeper = Expectation("converges", 1.0, "an order-1 scheme", "float32", 2.0)
    assert ("floors from 2 × ε = 2.4e-07 per step, its declared rounding factor)"
            in judge_fit(fit, deeper).assessment)


def test_the_expectation_carries_the_variants_precision_and_rounding_factor(monkeypatch):
    import dataclasses

    from cross_checks.analysis import expectations as ex
    from cross_checks.scenario import load_scenario
    sc = load_scenario("constant_spin")
    e = ex.expectation(sc, "reference:rk4", "angular_velocity", measure_physics=False)
    assert (e.precision, e.rounding_factor) == ("float64", 1.0)
    declared = dataclasses.replace(ex.traits("reference:rk4"), precision="float32", rounding_factor=3.0)
    monkeypatch.setattr(ex, "traits", lambda variant: declared)
    e = ex.expectation(sc, "reference:rk4", "angular_velocity", measure_physics=False)
    assert (e.precision, e.rounding_factor) == ("float32", 3.0)
