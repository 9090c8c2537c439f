"""Physics measured on a scenario's reference: rates, separatrix proximity, amplification, reference errors —
each against a hand computation or an independent solution."""
import math

import numpy as np
import pytest

from cross_checks.analysis import physics as P
from cross_checks.core.quantities import quantity_scales, state_errors
from cross_checks.scenario import load_scenario
from cross_checks.scenario.references import error_amplification, reference_error, reference_solution
from reference_sim.ground_truth import GROUND_TRUTH_RTOL, ground_truth


def test_rates_of_an_oscillator_a_symmetric_top_and_a_pure_spin_by_hand():
    osc = P.scenario_physics(load_scenario("spring_oscillator")).rates
    # √(k/m), to 1 %: 5 s hold 5.03 periods, not a whole number, so the mean and rms are slightly off
    assert osc.translation == pytest.approx(math.sqrt(40.0 / 1.0), rel=1e-2)
    assert osc.body_rotation == 0.0 and osc.world_rotation == 0.0
    top = P.scenario_physics(load_scenario("symmetric_top")).rates
    # I = (1, 1, 2), ω_B = (1, 0.5, 4): ω_B precesses about the axis at (I3 − I1)/I1 ω3 = 4 rad/s; ω_W cones
    # about L at |L|/I1 = |(1, 0.5, 8)| rad/s (to 1 %: 6.4 and 12.9 periods in the 10 s sampled)
    assert top.body_rotation == pytest.approx(4.0, rel=1e-2)
    assert top.world_rotation == pytest.approx(math.sqrt(1 + 0.25 + 64), rel=1e-2)
    spin = P.scenario_physics(load_scenario("constant_spin")).rates
    assert spin.body_rotation == 0.0 and spin.world_rotation == 0.0   # ω stays put: nothing to drift


def test_decay_and_drag_rates_come_from_the_force_model():
    r = P.scenario_physics(load_scenario("velocity_decay")).rates
    assert (r.decay_v == pytest.approx(-math.log(0.99) / 0.01)
            and r.decay_w == pytest.approx(-math.log(0.995) / 0.01))
    assert P.scenario_physics(load_scenario("linear_drag")).rates.drag == pytest.approx(0.8 / 2.0)


def test_separatrix_proximity_by_hand():
    # tennis_racket: I = (1, 2, 3), ω = (0.01, 2, 0.01):
    # 2E = 8.0004, |L|² = 16.001 -> δ = (2·8.0004 − 16.001)/16.001
    assert (P.separatrix_proximity(load_scenario("tennis_racket").problem)
            == pytest.approx(-0.0002 / 16.001, rel=1e-9))
    assert P.separatrix_proximity(load_scenario("symmetric_top").problem) is None   # two equal moments
    assert P.separatrix_proximity(load_scenario("applied_torque").problem) is None  # torques act


def test_amplitude_model_order_is_the_slope_of_the_amplitude_error():
    dts = [0.008, 0.004, 0.002, 0.001, 0.0005]
    chis = [P.amplitude_parameter(40.0, dt, 5.0) for dt in dts]   # spring_oscillator: χ = 0.8 … 0.05
    assert chis[0] == pytest.approx(0.8)
    slope = lambda e: np.polyfit(np.log(dts), np.log(e), 1)[0]  # noqa: E731
    assert P.amplitude_model_order(dts, chis, (1,)) == pytest.approx(slope([math.expm1(c) for c in chis]))
    assert P.amplitude_model_order(dts, chis, (-1,)) == pytest.approx(slope([-math.expm1(-c) for c in chis]))
    assert P.amplitude_model_order(dts, chis) == P.amplitude_model_order(dts, chis, (1,))  # the worse of ±
    sat = P.amplitude_model_order(dts, chis, (1,), amplification=100.0, saturate=True)
    assert sat < 0.2  # a perturbation grown 100× saturates at the quantity's scale: no order left


def test_amplitude_model_predicts_explicit_euler_on_an_oscillator():
    # An independent run: explicit Euler on the spring oscillator's ladder fits the order the model predicts.
    from reference_sim.simulate import simulate
    sc = load_scenario("spring_oscillator")
    yT, _ = reference_solution(sc, np.array([0.0, sc.duration_s]))
    dts = sc.dt_ladder_s
    errs = [np.linalg.norm(simulate(sc.problem, "explicit_euler", dt, sc.n_steps(dt)).y[-1, 0:3]
                           - yT[-1, 0:3])
            for dt in dts]
    fitted = np.polyfit(np.log(dts), np.log(errs), 1)[0]
    chis = [P.amplitude_parameter(40.0, dt, sc.duration_s) for dt in dts]
    assert fitted == pytest.approx(P.amplitude_model_order(dts, chis, (1,)), abs=0.02)


def test_amplification_of_a_projectile_by_hand():
    # A velocity error ε·scale_v becomes a position error ε·scale_v·T: A_x = scale_v T / scale_x.
    sc = load_scenario("projectile")
    y, _ = reference_solution(sc, np.linspace(0.0, sc.duration_s, 201))
    s = quantity_scales(y)
    A = error_amplification(sc, s)
    assert A["position"] == pytest.approx(s["velocity"] * sc.duration_s / s["position"], rel=1e-4)
    assert A["velocity"] == pytest.approx(1.0) and A["orientation"] == pytest.approx(1.0)


def test_amplification_near_the_separatrix_is_large_and_far_from_it_small():
    assert error_amplification(load_scenario("tumbling_box"))["orientation"] > 100.0
    assert error_amplification(load_scenario("applied_torque"))["orientation"] < 3.0


def test_closed_form_and_dop853_differ_by_no_more_than_their_measured_errors():
    # Two independent references of tennis_racket; each error measured its own way (closed form: perturbed
    # evaluation; DOP853: against a 10× looser solution). Their difference must be explained by the two.
    sc = load_scenario("tennis_racket")
    t = np.array([0.0, sc.duration_s])
    y_cf, _ = reference_solution(sc, t)
    y_gt = ground_truth(sc.problem, t)
    e_cf = reference_error(sc, y_cf[-1], "analytic")
    e_gt = reference_error(sc, y_gt[-1], f"ground_truth (DOP853, rtol {GROUND_TRUTH_RTOL:g})")
    d = state_errors(y_cf[-1:], y_gt[-1:])
    for q in ("orientation", "angular_velocity"):
        assert d[q][0] <= e_cf[q] + e_gt[q], (q, d[q][0], e_cf[q], e_gt[q])
    # and both are far below the old blanket 1e-12 (closed form) / 1e-10 (DOP853) relative allowances
    assert e_cf["orientation"] < 1e-12 * math.pi and e_gt["orientation"] < 1e-10 * math.pi


@pytest.mark.slow
@pytest.mark.parametrize("name", ["tumbling_box", "particle_body", "symmetric_top"])
def test_closed_form_and_dop853_errors_explain_their_difference_on_every_tumbling_body(name):
    sc = load_scenario(name)
    t = np.array([0.0, sc.duration_s])
    y_cf, _ = reference_solution(sc, t)
    y_gt = ground_truth(sc.problem, t)
    e_cf = reference_error(sc, y_cf[-1], "analytic")
    e_gt = reference_error(sc, y_gt[-1], "ground_truth")
    d = state_errors(y_cf[-1:], y_gt[-1:])
    for q in d:
        assert d[q][0] <= e_cf[q] + e_gt[q], (q, d[q][0], e_cf[q], e_gt[q])
