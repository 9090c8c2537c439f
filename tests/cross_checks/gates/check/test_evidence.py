"""cross_checks.gates.check.evidence: how a row of evidence is judged — a NaN never passes, only the decisive
window counts, and the numbers reported are those at the worst time."""
import math

import numpy as np

from cross_checks.gates.check.evidence import evidence_row, ratio


def test_ratio_of_zero_by_zero_is_zero_and_anything_else_by_zero_is_infinite():
    r = ratio([0.0, 1.0, math.nan, 2.0], [0.0, 0.0, 1.0, 4.0])
    assert r[0] == 0.0 and r[1] == math.inf and math.isnan(r[2]) and r[3] == 0.5


def test_a_nan_never_vanishes_in_the_maximum():
    t = np.arange(5.0)
    e = evidence_row("one-step defect", "position", t, [0.1, math.nan, 0.1, 0.1, 0.1], np.ones(5), "x")
    assert math.isnan(e.max_ratio) and math.isnan(e.max_value) and not e.passed
    assert e.first_over_s == 1.0


def test_the_worst_time_carries_its_own_value_and_allowance():
    t = np.arange(4.0)
    e = evidence_row("free-running", "orientation", t, [0.1, 5.0, 0.3, 0.2], [1.0, 10.0, 0.1, 1.0], "x")
    assert e.max_ratio == 0.3 / 0.1 and e.t_worst_s == 2.0 and e.value_at_worst == 0.3 and e.allowance == 0.1
    assert e.max_value == 5.0 and e.first_over_s == 2.0 and not e.passed


def test_only_the_decisive_window_decides():
    t = np.arange(6.0)
    value = [0.1, 0.1, 0.1, 9.0, 9.0, math.nan]
    decisive = np.array([True, True, True, False, False, False])
    e = evidence_row("free-running", "position", t, value, np.ones(6), "x", decisive=decisive)
    assert e.passed and e.decisive and e.decisive_until_s == 2.0 and e.max_value == 0.1
    e = evidence_row("free-running", "position", t, value, np.ones(6), "x", decisive=np.zeros(6, bool))
    assert e.passed and not e.decisive and e.as_dict()["decisive"] is False
