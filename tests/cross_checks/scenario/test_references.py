"""Each catalog scenario's closed-form reference agrees with the DOP853 ground truth of the same ODE."""
import numpy as np
import pytest

from cross_checks.scenario import catalog_names, load_scenario
from cross_checks.scenario.references import analytic_available, reference_solution
from reference_sim.ground_truth import ground_truth
from reference_sim.quaternion import geodesic_angle
from tests.helpers.tolerances import CLOSED_FORM_VS_GROUND_TRUTH, CLOSED_FORM_VS_GROUND_TRUTH_TUMBLING_BOX

ANALYTIC = [n for n in catalog_names() if analytic_available(load_scenario(n))[0]]


def test_most_of_the_catalog_has_a_closed_form():
    assert {"projectile", "linear_drag", "velocity_decay", "spring_oscillator", "constant_spin",
            "symmetric_top", "tennis_racket", "tumbling_box", "particle_body"} <= set(ANALYTIC)
    assert not analytic_available(load_scenario("spring_pendulum"))[0]
    assert not analytic_available(load_scenario("applied_torque"))[0]


@pytest.mark.parametrize("name", ANALYTIC)
def test_closed_form_matches_ground_truth(name):
    sc = load_scenario(name)
    t = np.linspace(0.0, sc.duration_s, 41)
    y_cf, label = reference_solution(sc, t)
    assert label == "analytic"
    y_gt = ground_truth(sc.problem, t)  # the decay, if any, is in the right-hand side as −k v, −k ω
    scale = 1.0 + np.max(np.abs(y_gt), axis=0)
    err_xv = np.max(np.abs(y_cf[:, 0:6] - y_gt[:, 0:6]) / scale[0:6])
    err_q = np.max(geodesic_angle(y_gt[:, 6:10], y_cf[:, 6:10]))
    err_w = np.max(np.abs(y_cf[:, 10:13] - y_gt[:, 10:13]))
    tol = CLOSED_FORM_VS_GROUND_TRUTH_TUMBLING_BOX if name == "tumbling_box" else CLOSED_FORM_VS_GROUND_TRUTH
    assert max(err_xv, err_q, err_w) < tol, (err_xv, err_q, err_w)


def test_ground_truth_requested_explicitly_is_used():
    sc = load_scenario("applied_torque")
    y, label = reference_solution(sc, np.array([0.0, 0.5]))
    assert label.startswith("ground_truth") and y.shape == (2, 13)


def test_the_sweep_and_the_fuzz_estimate_the_amplification_alike():
    from cross_checks.core.quantities import QUANTITIES, quantity_scales
    from cross_checks.fuzz.exact import amplification
    from cross_checks.scenario.references import error_amplification
    from tests.helpers.tolerances import AMPLIFICATION_TWO_SOLVES_REL
    sc = load_scenario("spring_pendulum")   # DOP853 in both; its amplification is largest at the end
    y, _ = reference_solution(sc, np.linspace(0.0, sc.duration_s, 201))
    scales = quantity_scales(y)
    sweep = error_amplification(sc, scales)
    fuzz = amplification([sc], [scales], n_samples=2)   # at t = 0 (relative change 1) and at the end
    for q in QUANTITIES:
        assert fuzz[q][0] == pytest.approx(sweep[q], rel=AMPLIFICATION_TWO_SOLVES_REL), q


def test_a_perturbed_solution_that_blows_up_is_an_infinite_amplification():
    from cross_checks.scenario.references import amplification_of
    scales = {"position": 1.0, "velocity": 1.0, "orientation": np.pi, "angular_velocity": 1.0}
    y = np.tile(np.array([0.0] * 6 + [1.0, 0.0, 0.0, 0.0] + [0.0] * 3), (1, 2, 13, 1))
    y[0, :, 1, 0] += 3e-6     # a 1e-6 perturbation of x grown 3 times, in both scenarios ...
    y[0, 1, 4, 3] = np.nan    # ... and the second's v-perturbed solution blew up
    a = amplification_of(y, [scales, scales])
    assert a["position"][0] == pytest.approx(3.0) and a["velocity"][0] == 1.0   # at least 1
    assert a["velocity"][1] == np.inf
