"""Metric definitions on hand-made cases, convergence fitting on synthetic ladders, expectations."""
import math

import numpy as np
import pytest

from cross_checks import metrics as M
from cross_checks import tolerances as tol
from cross_checks.expectations import NOMINAL_ORDER, QUANTITIES, expectation
from cross_checks.engines import STATIC_VARIANTS
from cross_checks.scenario import catalog_names, load_scenario, parse_scenario
from reference_sim.quaternion import quat_from_axis_angle

LADDER = [0.02 / 2 ** k for k in range(5)]


def state(x=(0, 0, 0), v=(0, 0, 0), q=(1, 0, 0, 0), w=(0, 0, 0)):
    return np.concatenate([x, v, q, w]).astype(float)


# --- errors --------------------------------------------------------------------------------------

@pytest.mark.parametrize("angle", [1e-6, 0.3, 2.5, math.pi - 1e-3])
def test_orientation_error_is_the_rotation_angle_between_the_pair(angle):
    q_ref = quat_from_axis_angle(np.array([0.3, -0.5, 0.8]), 0.7)
    dq = quat_from_axis_angle(np.array([1.0, 2.0, -1.0]), angle)
    from reference_sim.quaternion import quat_mul
    q = quat_mul(q_ref, dq)
    e = M.state_errors(state(q=q)[None], state(q=q_ref)[None])["orientation"][0]
    assert e == pytest.approx(angle, rel=1e-12, abs=1e-15)


def test_orientation_error_is_sign_invariant():
    q = quat_from_axis_angle(np.array([0.0, 0.0, 1.0]), 0.4)
    q_ref = quat_from_axis_angle(np.array([1.0, 0.0, 0.0]), -1.1)
    e_pos = M.state_errors(state(q=q)[None], state(q=q_ref)[None])["orientation"][0]
    e_neg = M.state_errors(state(q=-q)[None], state(q=q_ref)[None])["orientation"][0]
    assert e_pos == e_neg
    assert M.state_errors(state(q=-q)[None], state(q=q)[None])["orientation"][0] == 0.0


def test_orientation_error_normalises_non_unit_quaternions():
    q = quat_from_axis_angle(np.array([0.0, 1.0, 0.0]), 0.5)
    e = M.state_errors(state(q=1.001 * q)[None], state()[None])["orientation"][0]
    assert e == pytest.approx(0.5, rel=1e-12)


def test_vector_errors_are_euclidean_norms():
    a = state(x=(1, 2, 3), v=(0, 0, 1), w=(0.5, 0, 0))
    b = state(x=(1, 2, 0), v=(3, 4, 1), w=(0, 0, 0))
    e = M.state_errors(a[None], b[None])
    assert e["position"][0] == 3.0 and e["velocity"][0] == 5.0 and e["angular_velocity"][0] == 0.5


def test_error_summary_final_and_max():
    s = M.error_summary({"position": np.array([0.0, 3.0, 1.0])})
    assert s["position"] == {"final": 1.0, "max": 3.0}


# --- conservation ------------------------------------------------------------------------------------

def _scenario(forces="", inertia="[1.0, 2.0, 3.0]", mass=2.0):
    return parse_scenario(f"""
name = "hand"
duration = 1.0
dt = 0.01
[body]
mass = {mass}
inertia = {inertia}
[initial]
[forces]
{forces}
""")


def test_energy_sums_translation_rotation_gravity_and_spring():
    sc = _scenario('gravity = [0.0, 0.0, -10.0]\n[[forces.spring]]\nanchor = [0.0, 0.0, 1.0]\n'
                   'stiffness = 4.0\nrest_length = 0.5')
    y = state(x=(0, 0, 3), v=(1, 2, 2), w=(0, 0, 2))  # identity orientation: I_W = diag(1, 2, 3)
    kinetic = 0.5 * 2.0 * 9.0 + 0.5 * 3.0 * 4.0        # 9 + 6
    gravity = 2.0 * 10.0 * 3.0                          # m g z
    spring = 0.5 * 4.0 * (2.0 - 0.5) ** 2               # ½ k (L − L0)², L = 2
    assert M.energy_J(sc.problem, y) == pytest.approx(kinetic + gravity + spring, rel=1e-15)


def test_relative_energy_drift_of_a_known_change():
    sc = _scenario()
    y = np.array([state(v=(3, 0, 0)), state(v=(math.sqrt(9.9), 0, 0))])  # E: 9 J -> 9.9 J
    d = M.relative_drift(M.energy_J(sc.problem, y))
    assert d[0] == 0.0
    assert d[1] == pytest.approx(0.1, rel=1e-12)


def test_angular_momentum_drift_is_relative_vector_change():
    sc = _scenario()
    y = np.array([state(w=(1, 0, 0)), state(w=(0, 0.5, 0))])  # L: (1,0,0) -> (0,1,0): |ΔL| = √2
    d = M.relative_drift(M.angular_momentum_W(sc.problem, y))
    assert d[1] == pytest.approx(math.sqrt(2.0), rel=1e-15)


def test_drift_from_an_exactly_zero_initial_value_is_absolute():
    assert M.relative_drift(np.array([0.0, 1e-3]))[1] == 1e-3


def test_drift_kind_separates_secular_bounded_and_roundoff():
    t = np.linspace(0.0, 10.0, 2001)
    assert M.drift_kind(t, 1e-4 * t, 1e-12) == "secular"
    assert M.drift_kind(t, 1e-4 * np.sin(5.0 * t), 1e-12) == "bounded"
    assert M.drift_kind(t, 1e-4 * (1.0 - np.cos(3.0 * t)), 1e-12) == "bounded"
    assert M.drift_kind(t, 1e-4 * np.sin(5.0 * t) + 1e-3 * t, 1e-12) == "secular"
    assert M.drift_kind(t, 1e-16 * np.sin(5.0 * t), 1e-12) == "roundoff"


def test_conserved_quantities_follow_the_forces():
    c = M.conserved(load_scenario("tennis_racket").problem.forces)
    assert c["energy"][0] and c["angular_momentum"][0] and c["linear_momentum"][0]
    c = M.conserved(load_scenario("projectile").problem.forces)
    assert c["energy"][0] and c["angular_momentum"][0] and not c["linear_momentum"][0]
    c = M.conserved(load_scenario("velocity_decay").problem.forces)
    assert not any(v[0] for v in c.values())
    assert "velocity decay" in c["energy"][1]


# --- convergence fitting ---------------------------------------------------------------------------

@pytest.mark.parametrize("p", [1, 2, 4])
def test_fit_recovers_the_order_of_a_clean_ladder(p):
    e = [3.0 * h ** p for h in LADDER]
    fit = M.fit_convergence(LADDER, e)
    assert fit.verdict == "converges"
    assert fit.order == pytest.approx(p, abs=1e-12)
    assert fit.pairwise_orders == pytest.approx([p] * 4, abs=1e-12)
    assert all(fit.fitted)


def test_pairwise_orders_are_log2_ratios_for_halving():
    assert M.pairwise_orders([0.2, 0.1], [8.0, 2.0]) == [pytest.approx(2.0)]
    assert M.pairwise_orders([0.2, 0.1], [8.0, 0.0]) == [None]


def test_fit_sorts_the_ladder():
    e = [3.0 * h ** 2 for h in LADDER]
    fit = M.fit_convergence(LADDER[::-1], e[::-1])
    assert fit.dt_s == LADDER and fit.order == pytest.approx(2.0)


def test_points_at_the_roundoff_floor_are_dropped():
    floor = 1e-10
    e = [max(h ** 4, 5e-11) for h in LADDER]   # 1.6e-7 … 6.3e-10, then two points at round-off
    fit = M.fit_convergence(LADDER, e, floors=[floor] * 5)
    assert fit.verdict == "converges"
    assert fit.fitted == [True, True, True, False, False]
    assert fit.order == pytest.approx(4.0, abs=1e-9)
    assert "round-off" in fit.note


def test_all_points_at_the_floor_is_at_roundoff():
    fit = M.fit_convergence(LADDER, [1e-15, 3e-16, 0.0, 2e-15, 1e-15], floors=[1e-13] * 5)
    assert fit.verdict == "at_roundoff" and fit.order is None


def test_a_plateau_does_not_converge():
    e = [3.0 + 1e-3 * h for h in LADDER]
    fit = M.fit_convergence(LADDER, e)
    assert fit.verdict == "does_not_converge"
    assert abs(fit.order) < 0.01


def test_error_growing_again_below_the_best_step_does_not_converge():
    # frame-rate dependent physics: smallest error at one Δt, larger on both sides
    e = [0.3, 0.01, 0.2, 0.3, 0.35]
    assert M.fit_convergence(LADDER, e).verdict == "does_not_converge"


def test_pre_asymptotic_coarsest_point_is_dropped():
    e = [3.0 * h ** 2 for h in LADDER]
    e[0] *= 40.0  # the coarsest point is far off the asymptotic line
    fit = M.fit_convergence(LADDER, e)
    assert fit.fitted[0] is False
    assert fit.order == pytest.approx(2.0, abs=1e-12)


def test_diverged_points_are_left_out_and_all_diverged_is_diverged():
    e = [math.nan] + [h for h in LADDER[1:]]
    fit = M.fit_convergence(LADDER, e, statuses=["diverged", "ok", "ok", "ok", "ok"])
    assert fit.verdict == "converges" and fit.order == pytest.approx(1.0)
    assert "diverged" in fit.note
    fit = M.fit_convergence(LADDER, [math.nan] * 4 + [1e-3], statuses=["diverged"] * 4 + ["ok"])
    assert fit.verdict == "diverged"
    fit = M.fit_convergence(LADDER, [math.nan] * 5, statuses=["failed"] * 5)
    assert fit.verdict == "failed"


def test_roundoff_floor_grows_with_the_steps_and_the_reference():
    a = M.roundoff_floor(1.0, 100, "analytic")
    b = M.roundoff_floor(1.0, 1_000_000, "analytic")
    assert a == tol.REFERENCE_ACCURACY_REL["analytic"]
    assert b == pytest.approx(tol.ROUNDOFF_PER_STEP_REL * 1e6)
    assert M.roundoff_floor(1.0, 100, "ground_truth (DOP853, rtol 1e-12)") == tol.REFERENCE_ACCURACY_REL["ground_truth"]


# --- expectations ------------------------------------------------------------------------------------

def test_every_known_variant_has_a_nominal_order():
    for eng, vs in STATIC_VARIANTS.items():
        for v in vs:
            assert NOMINAL_ORDER[f"{eng}:{v}"] in (1.0, 2.0, 4.0)


@pytest.mark.parametrize("name", ["tennis_racket", "tumbling_box", "particle_body", "symmetric_top"])
def test_course_is_expected_not_to_converge_in_rotation_on_gyroscopic_bodies(name):
    sc = load_scenario(name)
    for q in ("orientation", "angular_velocity"):
        e = expectation(sc, "reference:course", q)
        assert e.verdict == "does_not_converge" and "gyroscopic" in e.reason
    assert expectation(sc, "reference:course", "position").order == 1.0   # translation is decoupled
    assert expectation(sc, "reference:course_gyro", "orientation").order == 1.0


def test_course_converges_where_the_gyroscopic_term_vanishes():
    for name in ("constant_spin", "projectile", "linear_drag", "spring_oscillator"):
        sc = load_scenario(name)
        assert all(expectation(sc, "reference:course", q).verdict == "converges" for q in QUANTITIES)


def test_course_position_fails_when_rotation_drives_translation():
    assert expectation(load_scenario("spring_pendulum"), "reference:course", "position").verdict == "does_not_converge"
    assert expectation(load_scenario("applied_torque"), "reference:course", "position").verdict == "converges"


def test_every_variant_is_expected_to_converge_under_velocity_decay():
    # Decay is the rate k = −ln γ / dt in every variant (e^{−kΔt} per step or −k v in the right-hand
    # side): each converges at its own order to the continuously damped motion.
    sc = load_scenario("velocity_decay")
    for v in ("reference:rk4", "mujoco:euler", "reference:course", "pybullet:maximal"):
        for q in QUANTITIES:
            e = expectation(sc, v, q)
            assert e.verdict == "converges" and e.order == NOMINAL_ORDER[v], (v, q, e)


def test_one_step_mode_expects_one_order_more():
    sc = load_scenario("projectile")
    assert expectation(sc, "reference:rk4", "position", "one_step").order == 5.0
    assert expectation(load_scenario("tennis_racket"), "reference:course", "orientation", "one_step").verdict is None


@pytest.mark.parametrize("name", catalog_names())
def test_every_catalog_scenario_has_an_expectation_for_every_variant(name):
    sc = load_scenario(name)
    for v in NOMINAL_ORDER:
        for q in QUANTITIES:
            e = expectation(sc, v, q)
            assert e.verdict in ("converges", "does_not_converge") or (
                e.verdict is None and e.reason.startswith("pre-asymptotic")), (v, q, e)


def test_pre_asymptotic_claim_follows_the_amplitude_parameter():
    # χ = ω²ΔtT/2 at the coarsest Δt: spring_pendulum 40·0.008·5/2 = 0.8 > 0.6 -> no claim;
    # applied_torque |ω0|² = 1.34, 1.34·0.04·2/2 = 0.054 -> order 1 claimed.
    from cross_checks.expectations import euler_amplitude_parameter
    sp, at = load_scenario("spring_pendulum"), load_scenario("applied_torque")
    assert euler_amplitude_parameter(sp, 0.008) == pytest.approx(0.8)
    assert expectation(sp, "reference:explicit_euler", "position").verdict is None
    assert expectation(at, "reference:explicit_euler", "position").order == 1.0
    assert expectation(sp, "reference:expmap_gyro", "position").order == 1.0  # symplectic: unaffected


def test_comparison_with_expectation():
    conv = expectation(load_scenario("projectile"), "reference:midpoint", "position")
    assert M.compare_with_expectation("converges", 2.05, conv)[0] is True
    assert M.compare_with_expectation("converges", 1.0, conv)[0] is False
    assert M.compare_with_expectation("converges", 3.0, conv) == (True, "order 3.00, above the nominal 2")
    assert M.compare_with_expectation("at_roundoff", None, conv)[0] is True
    assert M.compare_with_expectation("does_not_converge", 0.0, conv)[0] is False
    assert M.compare_with_expectation("diverged", None, conv)[0] is False
    nc = expectation(load_scenario("tennis_racket"), "reference:course", "orientation")
    assert M.compare_with_expectation("does_not_converge", 0.0, nc)[0] is True
    assert M.compare_with_expectation("converges", 1.0, nc)[0] is False


def test_one_exact_point_inside_a_non_convergent_ladder_is_not_roundoff():
    # a frame-rate dependent decay (the course's γ applied per step at every Δt): at the scenario's own
    # Δt the course matches the reference exactly, nowhere else
    e = [0.26, 6e-17, 0.13, 0.149, 0.1498]
    fit = M.fit_convergence(LADDER, e, floors=[1e-13] * 5)
    assert fit.verdict == "does_not_converge"


def test_error_growing_again_at_round_off_level_is_amplified_roundoff():
    # MuJoCo RK4 on tumbling_box (orientation, rad): order 4 until ~1e-10, then round-off grows
    e = [2.0e-8, 1.3e-9, 1.4e-10, 3.26e-11, 1.49e-10]
    fit = M.fit_convergence(LADDER[1:] + [LADDER[-1] / 2], e, floors=[1e-12] * 5)
    assert fit.verdict == "converges"
    assert fit.fitted == [True, True, False, False, False]
    assert fit.order == pytest.approx(3.94, abs=0.01)
    assert "amplified" in fit.note


def test_rising_pairwise_orders_are_called_pre_asymptotic():
    e = [2.35e-1, 1.91e-1, 1.32e-1, 8.0e-2, 4.43e-2]
    fit = M.fit_convergence(LADDER, e)
    assert "pre-asymptotic" in fit.note
