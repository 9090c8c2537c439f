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
