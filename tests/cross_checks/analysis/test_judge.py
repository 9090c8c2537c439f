"""How a convergence fit is judged against its expectation (cross_checks/analysis/judge.py, the one judge)."""
import pytest

from cross_checks.analysis.convergence import fit_convergence
from cross_checks.analysis.expectations import Expectation
from cross_checks.analysis.judge import judge_fit
from cross_checks.engines import resolve


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


def test_the_expectation_carries_the_variants_precision_and_rounding_factor():
    import dataclasses

    from cross_checks.analysis import expectations as ex
    from cross_checks.scenario import load_scenario
    sc = load_scenario("constant_spin")
    e = ex.expectation(sc, resolve("reference:rk4"), "angular_velocity", measure_physics=False)
    assert (e.precision, e.rounding_factor) == ("float64", 1.0)
    from cross_checks.engines import Resolved
    declared = dataclasses.replace(ex.traits(resolve("reference:rk4")), precision="float32",
                                   rounding_factor=3.0)
    r = resolve("reference:rk4")   # the same variant, resolved with other declared traits
    fake = Resolved(str(r), **{**r.__dict__, "traits": declared, "precision": "float32"})
    e = ex.expectation(sc, fake, "angular_velocity", measure_physics=False)
    assert (e.precision, e.rounding_factor) == ("float32", 3.0)


# --- long runs (judge_long_run) ---------------------------------------------------------------------------

def _metrics(**kw):
    from cross_checks.analysis.long_run import DriftMetrics
    base = dict(energy_rate_per_s=0.0, energy_drift_max=1e-14, momentum_rate_per_s=0.0,
                momentum_drift_max=1e-14,
                direction_drift_max_rad=1e-14, separatrix_start=-1 / 3, separatrix_end=-1 / 3,
                separatrix_rate_per_s=0.0, toward_intermediate=False, away_from_intermediate=False,
                duration_s=100.0, crossed_separatrix=False, energy_secular=False, steps=2000)
    return DriftMetrics(**{**base, **kw})


def _exp(keeps=(), separatrix=None):
    from cross_checks.analysis.expectations import LongRunExpectation
    return LongRunExpectation(tuple(keeps), separatrix, "its traits say so")


TOWARD = dict(toward_intermediate=True, separatrix_end=-0.01, separatrix_rate_per_s=-3e-3,
              energy_drift_max=0.4)


def test_a_declared_keeper_whose_separatrix_distance_drifts_is_failed_and_named():
    from cross_checks.analysis.judge import judge_long_run
    j = judge_long_run("x:y", "run", _metrics(**TOWARD), _exp(("energy", "angular_momentum_norm"), "kept"))
    assert j.matches is False and j.verdict == "toward_intermediate"
    assert "drifts toward the intermediate axis (energy → L²/2I₂) at rate 0.003/s" in j.finding
    assert "the energy drifted by 0.4" in j.assessment


def test_a_momentum_step_drifting_toward_the_intermediate_axis_is_named_not_failed():
    from cross_checks.analysis.judge import judge_long_run
    exp = _exp(("angular_momentum_norm",), "toward_intermediate")
    j = judge_long_run("x:y", "run", _metrics(**TOWARD), exp)
    assert j.matches is True and "drifts toward the intermediate axis" in j.finding
    away = judge_long_run("x:y", "run", _metrics(away_from_intermediate=True, separatrix_end=-0.5), exp)
    assert away.matches is False and "drifts away from the intermediate axis" in away.assessment
    lost = judge_long_run("x:y", "run", _metrics(**{**TOWARD, "momentum_drift_max": 1e-6}), exp)
    assert lost.matches is False and "|L| drifted by 1e-06" in lost.assessment


def test_a_variant_that_declares_nothing_is_measured_not_judged():
    from cross_checks.analysis.judge import judge_long_run
    j = judge_long_run("x:y", "run", _metrics(**TOWARD), _exp())
    assert j.matches is None and j.finding and j.assessment.startswith("no claim")
    d = judge_long_run("x:y", "run", _metrics(), _exp(), status="diverged", diverged_at_s=61.75)
    assert d.verdict == "diverged" and d.matches is None and "61.75" in d.assessment


def test_the_round_off_floor_of_a_kept_invariant_grows_with_the_steps():
    from cross_checks.analysis.judge import judge_long_run
    from cross_checks.core import tolerances as tol
    floor = tol.long_run_roundoff(2000, tol.UNIT_ROUNDOFF["float64"])
    assert floor == pytest.approx(16 * 2.0 ** -53 * 2000)
    exp = _exp(("energy", "angular_momentum"), "kept")
    assert judge_long_run("x:y", "r", _metrics(energy_drift_max=0.9 * floor), exp).matches is True
    assert judge_long_run("x:y", "r", _metrics(direction_drift_max_rad=1.1 * floor), exp).matches is False
    assert judge_long_run("x:y", "r", _metrics(), exp, status="diverged").matches is False
    bounded = _exp(("energy_bounded", "angular_momentum"), "kept")
    assert judge_long_run("x:y", "r", _metrics(energy_drift_max=1e-5), bounded).matches is True
    assert judge_long_run("x:y", "r", _metrics(energy_secular=True), bounded).matches is False
