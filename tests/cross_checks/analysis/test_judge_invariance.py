"""The invariance rule of the one judge (cross_checks.analysis.judge.judge_invariance, docs/invariance.md):
its allowance against numbers derived by hand, and each verdict on states built to land on it."""
import math

import numpy as np
import pytest

from cross_checks.analysis.judge import INVARIANCE_VERDICTS, invariance_allowance, judge_invariance
from cross_checks.core import tolerances as tol

ONES = {"position": 1.0, "velocity": 1.0, "orientation": math.pi, "angular_velocity": 1.0}
AMP = {"position": 1.0, "velocity": 1.0, "orientation": 1.0, "angular_velocity": 1.0}


def test_the_allowance_by_hand():
    # two runs × the noise factor 10 × 16 unit roundoffs (2⁻⁵³) of each step's scale; N = 100, √N = 10, A = 1
    base, off = invariance_allowance(ONES, AMP, 100, offset_m=1000.0)
    k = 20 * 16 * 2.0 ** -53
    assert base["position"] == pytest.approx(k * 110, rel=1e-12)           # N + √N A: biased (a sum)
    assert base["orientation"] == pytest.approx(k * math.pi * 110, rel=1e-12)  # biased in every quantity
    assert off["position"] == pytest.approx(k * 1000 * 110, rel=1e-12)     # ε |d| (N + √N A)
    assert off["angular_velocity"] == pytest.approx(k * 1000 * 10, rel=1e-12)
    b32, _ = invariance_allowance(ONES, AMP, 100, precision="float32", rounding_factor=3.0)
    # float32: every quantity biased
    assert b32["orientation"] == pytest.approx(20 * 16 * 3 * 2 ** -24 * math.pi * 110, rel=1e-12)
    bamp, _ = invariance_allowance(ONES, {**AMP, "orientation": 1e4}, 100)
    assert bamp["orientation"] == pytest.approx(k * math.pi * (100 + 10 * 1e4), rel=1e-12)
    bdiff, _ = invariance_allowance(ONES, AMP, 100, dt_s=1e-3, differenced=True)
    assert bdiff["velocity"] == pytest.approx(k * 110 + k * 110 / 1e-3, rel=1e-12)


def _states(n=101):
    t = np.linspace(0.0, 1.0, n)
    y = np.zeros((n, 13))
    y[:, 0] = t
    y[:, 3] = 1.0
    y[:, 6] = np.cos(0.5 * t)
    y[:, 9] = np.sin(0.5 * t)
    y[:, 12] = 1.0
    return y


def _judge(y0, y1, **kw):
    return judge_invariance(y0, y1, scales=ONES, amplification=AMP, n_steps=100, **kw)


def test_identical_runs_hold():
    j = _judge(_states(), _states())
    assert j.verdict == "holds" and all(v == 0.0 for v in j.deviation.values())


def test_a_loss_within_the_offset_allowance_is_precision_loss_with_its_number():
    y1 = _states()
    y1[-1, 0] += 1e-10          # above the base 3.9e-12 m, below the 3.9e-9 m of |d| = 1 km
    j = _judge(_states(), y1, offset_m=1000.0)
    assert j.verdict == "precision loss" and j.worst == "position"
    assert j.deviation["position"] == pytest.approx(1e-10, rel=1e-3)
    assert "1e-10 m in position" in j.assessment and "|d| = 1000 m" in j.assessment
    assert "cannot tell" not in j.assessment
    assert _judge(_states(), y1).verdict == "broken"          # the same loss without a translation


def test_an_allowance_beyond_the_motion_s_scale_says_the_check_is_blind_there():
    y1 = _states()
    y1[-1, 0] += 0.5            # float32 at 10 km over 100 steps allows ~2.6e3 m: more than the 1 m scale
    j = _judge(_states(), y1, offset_m=1e4, precision="float32")
    assert j.verdict == "precision loss" and "cannot tell an error from round-off here" in j.assessment


def test_a_deviation_beyond_the_allowance_is_broken():
    y1 = _states()
    y1[50, 6:10] = [np.cos(0.3), 0.0, 0.0, np.sin(0.3)]       # an orientation off by ~0.1 rad mid-run
    j = _judge(_states(), y1, offset_m=1e4)
    assert j.verdict == "broken" and j.worst == "orientation" and "orientation" in j.assessment


def test_a_run_that_leaves_the_finite_numbers_is_broken():
    y1 = _states()
    y1[70:, :] = np.nan
    j = _judge(_states(), y1)
    assert j.verdict == "broken" and "finite" in j.assessment


def test_runs_of_different_lengths_are_broken():
    assert _judge(_states(), _states(50)).verdict == "broken"


def test_the_verdicts():
    assert INVARIANCE_VERDICTS[:6] == ("holds", "precision loss", "step-dependent", "broken",
                                       "known finding", "cannot express")
    assert tol.INVARIANCE_RUNS_COMPARED == 2
