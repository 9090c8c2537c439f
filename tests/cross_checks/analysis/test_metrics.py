"""Conserved quantities, their drift and the round-off floors (cross_checks.analysis.metrics), by hand."""
import math

import numpy as np
import pytest

from cross_checks.analysis import metrics as M
from cross_checks.core import tolerances as tol
from cross_checks.scenario import load_scenario, parse_scenario
from tests.helpers.scenarios import state

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


# --- round-off floors -----------------------------------------------------------------------------

def test_measured_floor_adds_the_reference_error_and_the_amplified_roundoff_of_the_run():
    eps = tol.ROUNDOFF_PER_STEP_REL
    # position: biased roundings add up linearly, the rest as a random walk grown by the amplification
    assert M.roundoff_floor(2.0, 10_000, reference_error=3e-13, amplification=5.0, quantity="position") == \
        pytest.approx(3e-13 + eps * 2.0 * (10_000 + 100 * 5.0), rel=1e-12)
    assert M.roundoff_floor(np.pi, 10_000, reference_error=1e-13, amplification=0.5,
                            quantity="orientation") == \
        pytest.approx(1e-13 + eps * np.pi * 100, rel=1e-12)


def test_roundoff_floor_grows_with_the_steps_and_the_reference():
    a = M.roundoff_floor(1.0, 100, "analytic")
    b = M.roundoff_floor(1.0, 1_000_000, "analytic")
    assert a == tol.REFERENCE_ACCURACY_REL["analytic"]
    assert b == pytest.approx(tol.ROUNDOFF_PER_STEP_REL * 1e6)
    assert (M.roundoff_floor(1.0, 100, "ground_truth (DOP853, rtol 1e-12)")
            == tol.REFERENCE_ACCURACY_REL["ground_truth"])


# --- the one round-off floor of a run (sweep and fuzz) and the same-scheme allowance ------------------

#: Lever arms of a small body 9 m from the origin (metrics.lever_arms' fields).
FAR_LEVER = {"position_max_m": 9.0, "velocity_max_m_s": 3.0, "angular_velocity_max_rad_s": 12.0,
             "force_max_N": 5.0, "mass_kg": 0.3, "inertia_min_kg_m2": 1.2e-4}
SCALES = {"position": 9.0, "velocity": 3.0, "orientation": math.pi, "angular_velocity": 12.0}


def test_lever_arms_are_measured_along_the_states():
    sc = _scenario('gravity = [0.0, 0.0, -10.0]')
    y = np.array([state(x=[3.0, 4.0, 0.0], v=[0.0, 1.0, 0.0], w=[0.0, 0.0, 2.0]),
                  state(x=[0.0, 0.0, 1.0], v=[0.0, 0.0, -6.0], w=[0.0, 0.5, 0.0])])
    lv = M.lever_arms(sc.problem, y)
    assert lv == {"position_max_m": 5.0, "velocity_max_m_s": 6.0, "angular_velocity_max_rad_s": 2.0,
                  "force_max_N": 2.0 * 10.0 + 2.0 * 10.0, "mass_kg": 2.0, "inertia_min_kg_m2": 1.0}


@pytest.mark.parametrize("q", ["position", "velocity", "orientation", "angular_velocity"])
def test_the_run_floor_of_an_engine_adds_its_lever_arms_and_rbcheck_s_own_schemes_do_not(q):
    from cross_checks.engines import resolve
    assert resolve("mujoco:rk4").traits.lever_arms and resolve("an_engine_file:any").traits.lever_arms
    assert not any(resolve(f"reference:{v}").traits.lever_arms for v in ("rk4", "course", "jolt_gyro"))
    n, h = 400, 2.5e-3
    plain = M.run_floor(resolve("reference:rk4"), q, n, h, SCALES, 1e-13, amplification=3.0, lever=FAR_LEVER)
    assert plain == M.roundoff_floor(SCALES[q], n, reference_error=1e-13, amplification=3.0, quantity=q)
    engine = M.run_floor(resolve("mujoco:rk4"), q, n, h, SCALES, 1e-13, amplification=3.0, lever=FAR_LEVER)
    lever = M.lever_floor(FAR_LEVER, q, h, n, 3.0, 2.0 ** -52)
    assert lever > 0.0 and engine == plain + lever
    # by hand: K ε |x| F / I_min integrated over t = n h (ω), twice (orientation); the ω representation error
    # K ε m |x| |v| / I_min made each step (a random walk); K ε |x| |ω| per step in v, × h in x
    k = tol.LEVER_ROUNDINGS * 2.0 ** -52
    a, w, u, t = k * 9.0 * 5.0 / 1.2e-4, k * 0.3 * 9.0 * 3.0 / 1.2e-4, k * 9.0 * 12.0, n * h
    walk = 1.0 + math.sqrt(n)
    by_hand = {"angular_velocity": a * t + w * walk, "orientation": 0.5 * a * t * t + w * t * walk,
               "velocity": u * n, "position": u * n * h}[q]
    assert lever == pytest.approx(3.0 * by_hand, rel=1e-12)
    # unmeasured lever arms add nothing (a failed reference's floors)
    assert M.run_floor(resolve("mujoco:rk4"), q, n, h, SCALES, 1e-13, amplification=3.0) == plain


def test_a_float32_engine_s_lever_arms_round_at_float32_s_epsilon():
    from cross_checks.engines import resolve
    f32 = next((v for v in ("mujoco_warp:euler", "rapier:default", "newton:semi_implicit")
                if resolve(v).known and resolve(v).precision == "float32"), None)
    if f32 is None:
        pytest.skip("no float32 engine installed here")
    v = resolve(f32)
    plain = M.run_floor(resolve(v), "angular_velocity", 100, 1e-3, SCALES, 0.0)
    got = M.run_floor(resolve(v), "angular_velocity", 100, 1e-3, SCALES, 0.0, lever=FAR_LEVER) - plain
    eps32 = 2.0 ** -23 * v.traits.rounding_factor
    want = M.lever_floor(FAR_LEVER, "angular_velocity", 1e-3, 100, 1.0, eps32)
    assert got == pytest.approx(want, rel=1e-9)


def test_the_same_scheme_allowance_is_round_off_grown_by_the_steps_and_the_amplification():
    eps = tol.ROUNDOFF_PER_STEP_REL
    assert M.same_scheme_allowance(1000, eps) == tol.SAME_SCHEME_REL        # short runs: the fixed floor
    n, amp = 40_000, 50.0
    assert (M.same_scheme_allowance(n, eps, amp)
            == pytest.approx(tol.SAME_SCHEME_ROUNDINGS_PER_STEP * n * eps * amp))
    assert M.same_scheme_allowance(n, 2.0 ** -23) > M.same_scheme_allowance(n, eps)
    rel, worst = M.same_scheme_difference({"position": 6e-9, "velocity": 1e-9, "orientation": 1e-10,
                                           "angular_velocity": 1.2e-9}, SCALES)
    assert worst == "position" and rel == pytest.approx(6e-9 / 9.0)
    assert M.diverged_together(1.0, 1.002, 1e-3) and not M.diverged_together(1.0, 1.0021, 1e-3)
