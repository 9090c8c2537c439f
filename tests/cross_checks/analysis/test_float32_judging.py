"""Two float32 corrections of the verdict model (docs/verdicts.md §7), each on the numbers Rapier 0.36.1's
sweep measured (docs/engine_conventions.md, "Rapier 0.36.1"): a float32 step may round one way every step,
in any quantity (b = 1 in every float32 floor), and an error that grows again at the fine end is amplified
round-off only up to AMPLIFIED_ROUNDOFF_FACTOR_FLOAT32 float32 floors (1e4 of them reach the quantity's own
scale). Float64 judging is unchanged."""
import math

import pytest

from cross_checks.analysis import metrics as M
from cross_checks.analysis.expectations import Expectation
from cross_checks.analysis.judge import judge_ladder
from cross_checks.core import tolerances as tol

EPS32 = tol.MACHINE_EPSILON["float32"]


def _floors(scale, steps, quantity, eps, amp=1.0, ref=0.0):
    return [M.roundoff_floor(scale, n, reference_error=ref, amplification=amp, quantity=quantity, eps=eps)
            for n in steps]


@pytest.mark.parametrize("quantity", ["orientation", "angular_velocity"])
def test_float32_floors_count_one_signed_roundings_in_the_rotation_too(quantity):
    n = 4000
    assert M.roundoff_floor(3.0, n, reference_error=0.0, quantity=quantity, eps=EPS32) == pytest.approx(
        EPS32 * 3.0 * (n + math.sqrt(n)))
    # float64: the rotation's roundings stay a random walk (unchanged)
    assert M.roundoff_floor(3.0, n, reference_error=0.0, quantity=quantity) == pytest.approx(
        tol.ROUNDOFF_PER_STEP_REL * 3.0 * math.sqrt(n))


def test_a_float32_omega_that_gains_an_ulp_a_step_is_round_off_not_a_failure_to_converge():
    # rapier:symplectic_euler on constant_spin, ω (|ω| = 3 rad/s, exact in ω without float32): errors ∝ N
    dts, steps = [0.02, 0.01, 0.005, 0.0025, 0.00125], [250, 500, 1000, 2000, 4000]
    errors = [4.39e-06, 1.13e-04, 2.98e-04, 6.68e-04, 1.43e-03]
    exp = Expectation("converges", 1.0, "an order-1 scheme", "float32")
    j = judge_ladder(dts, errors, _floors(3.0, steps, "angular_velocity", EPS32, ref=1e-15), ["ok"] * 5, exp)
    assert (j.verdict, j.matches) == ("at_roundoff", True)


@pytest.mark.parametrize("errors, floors", [
    # rapier:symplectic_euler_no_gyro on tumbling_box, orientation (rad): the missing term's plateau
    ([2.6197, 2.6210, 2.6213, 2.62135, 2.62138], [0.0112, 0.0159, 0.0224, 0.0317, 0.0449]),
    # ... on spring_pendulum, ω (rad/s)
    ([5.76, 5.78, 5.80, 5.80, 5.804], [0.00239, 0.00338, 0.00478, 0.00677, 0.00957]),
])
def test_a_float32_plateau_that_creeps_up_is_not_round_off(errors, floors):
    dts = [0.008, 0.004, 0.002, 0.001, 0.0005]
    exp = Expectation("does_not_converge", None, "no gyroscopic term", "float32")
    j = judge_ladder(dts, errors, floors, ["ok"] * 5, exp)
    assert (j.verdict, j.matches) == ("does_not_converge", True)
    # the float64 factor, 1e4 floors, took it for amplified round-off
    j64 = judge_ladder(dts, errors, floors, ["ok"] * 5, Expectation("does_not_converge", None, "", "float64"))
    assert j64.verdict == "at_roundoff"


def test_float32_round_off_that_grows_with_the_steps_stays_round_off():
    # rapier:symplectic_euler on tennis_racket, orientation (rad), with the sweep's float32 floors (b = 1,
    # the measured amplification): the errors grow as Δt shrinks (∝ N), within 10× their floors throughout
    dts = [0.01, 0.005, 0.0025, 0.00125, 0.000625]
    errors = [0.0042397, 0.0030091, 0.0040818, 0.0080102, 0.0152109]
    floors = [0.00048493, 0.00090518, 0.0017189, 0.0033084, 0.0064338]
    j = judge_ladder(dts, errors, floors, ["ok"] * 5, Expectation("converges", 1.0, "", "float32"))
    assert (j.verdict, j.matches) == ("at_roundoff", True)
