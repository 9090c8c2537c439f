"""cross_checks.gates.check.input: rows mapped to steps, written precision, and what a file cannot be."""
import math

import numpy as np
import pytest

from cross_checks.core.trajectory import QUANTITY_GROUPS, Trajectory
from cross_checks.gates.check.input import (
    CheckError,
    prepare_input,
    printed_half_quantum,
    single_precision_time_bound,
    snap_step,
    written_digits,
)
from cross_checks.scenario import load_scenario

SC = load_scenario("projectile")        # dt = 0.01, duration 1 s


def _traj(t, y=None, present=QUANTITY_GROUPS):
    t = np.asarray(t, dtype=float)
    if y is None:
        y = np.zeros((len(t), 13))
        y[:, 3:6] = SC.problem.initial.v_W
        y[:, 6] = 1.0
    return Trajectory(t, y, {"quantities_present": list(present)})


def _float32_clock(dt, n):
    t = np.zeros(n + 1, dtype=np.float32)
    for k in range(1, n + 1):
        t[k] = t[k - 1] + np.float32(dt)
    return t.astype(float)


@pytest.mark.parametrize("dt, n", [(0.001, 10000), (0.02, 5000), (1 / 60, 20000), (0.001, 100000)])
def test_the_single_precision_bound_covers_a_float32_clock(dt, n):
    t = _float32_clock(dt, n)
    steps = np.arange(n + 1)
    drift = np.abs(t - steps * dt)
    assert np.all(drift <= single_precision_time_bound(t, steps))
    # and it is a bound, not a blanket: within 20x of the drift actually seen at the end
    assert single_precision_time_bound(t[-1], n) < 20 * max(drift[-1], 1e-6)


def test_rows_of_a_float32_clock_map_to_their_steps_although_the_times_drift_by_steps():
    t = _float32_clock(0.001, 20000)                 # 20 s: the drift exceeds one step (1.7 ms)
    assert np.max(np.abs(t - 0.001 * np.arange(len(t)))) > 0.001
    sc = load_scenario("tumbling_box")
    inp = prepare_input(_traj(t), sc, "u.csv")
    assert inp.h_s == 0.001 and np.array_equal(inp.n_steps[: 10001], np.arange(10001))
    assert inp.t_s[-1] == pytest.approx(10.0) and inp.dropped_after_s is not None


def test_a_step_estimated_from_drifting_times_snaps_to_the_round_value():
    assert snap_step(0.0010002, 1e-6, SC) == 0.001            # within the band: the scenario's dt... or 1e-3
    assert snap_step(0.0020001, 2e-6, SC) == 0.002            # not in the scenario: the shortest decimal
    assert snap_step(0.0012345678, 1e-12, SC) == 0.0012345678  # nothing round nearby: kept


@pytest.mark.parametrize("fmt, half", [("%.6f", 5e-7), ("%.3f", 5e-4), ("%.9f", 5e-10)])
def test_fixed_decimals_are_measured(fmt, half):
    vals = np.array([float(fmt % v) for v in np.random.default_rng(1).uniform(-30, 30, 200)])
    h, _ = printed_half_quantum(vals)
    assert np.allclose(h, half, rtol=1e-9)


def test_significant_digits_and_full_precision_are_measured():
    x = np.random.default_rng(2).uniform(0.1, 300, 200)
    h, digits = printed_half_quantum(np.array([float("%.6g" % v) for v in x]))
    assert digits == 6 and np.all(h >= 0.5 * 10.0 ** (np.floor(np.log10(x)) - 5) * (1 - 1e-12))
    h, digits = printed_half_quantum(x)
    assert digits == 17 and np.all(h <= 2 * np.spacing(x))


def test_a_constant_column_takes_the_writers_precision_from_the_others():
    y = np.zeros((50, 13))
    y[:, 0] = [float("%.6f" % v) for v in np.linspace(0, 3.3, 50)]
    y[:, 3] = -2.0                                  # constant: alone it would look like 1 digit
    y[:, 6] = 1.0
    inp = prepare_input(_traj(np.arange(50) * 0.01, y), SC, "c.csv")
    # 6 decimals on each component, and (≤ 9 digits: single precision) ½ ulp of |v| = 2
    assert inp.single_precision
    assert inp.print_floor["velocity"][0] == pytest.approx(math.sqrt(3) * 5e-7 + 2.0 * 2.0 ** -24)


def test_nine_significant_digits_read_as_single_precision():
    y = np.zeros((5, 13))
    y[:, 0] = [float("%.9g" % np.float32(v)) for v in (0.1, 0.2, 0.3, 0.4, 0.5)]
    y[:, 6] = 1.0
    assert written_digits(y[:, 0])[0] <= 9
    assert prepare_input(_traj(np.arange(5) * 0.01, y), SC, "f.csv").single_precision
    y[:, 0] = [0.1, 0.2, 0.30000000000000004, 0.4, 0.5]
    assert not prepare_input(_traj(np.arange(5) * 0.01, y), SC, "d.csv").single_precision


def test_dt_maps_decimated_rows_to_several_steps():
    inp = prepare_input(_traj(np.arange(11) * 0.1), SC, "d.csv", dt_s=0.01)
    assert inp.h_s == 0.01 and np.all(inp.span_steps == 10) and inp.decimation == 10
    assert any("every row spans 10 steps" in n for n in inp.notes)


def test_dt_that_does_not_divide_the_rows_is_refused():
    with pytest.raises(CheckError,
                       match=r"d.csv: line 3: column t: with --dt 0.03 s every row interval must be a whole"):
        prepare_input(_traj(np.arange(11) * 0.1), SC, "d.csv", dt_s=0.03)


def test_a_gap_of_a_few_missing_rows_is_kept_a_jump_is_refused():
    t = np.delete(np.arange(101) * 0.01, [40, 41])
    inp = prepare_input(_traj(t), SC, "g.csv")
    assert inp.span_steps[39] == 3 and "rows missing" in " ".join(inp.notes)
    t = np.arange(101) * 0.01
    t[50:] += 1.0
    with pytest.raises(CheckError, match=r"line 52: column t: t jumps from 0.49 s to 1.5 s \(101 steps"):
        prepare_input(_traj(t), SC, "j.csv")


def test_uneven_steps_are_taken_row_by_row():
    t = np.concatenate([[0.0], np.cumsum(np.random.default_rng(3).uniform(0.008, 0.012, 100))])
    inp = prepare_input(_traj(t), SC, "v.csv")
    assert inp.h_s is None and np.allclose(inp.span_s, np.diff(t))
    assert "each row interval is taken as one step" in " ".join(inp.notes)


def test_non_finite_and_blown_up_rows_end_the_run_there():
    y = _traj(np.arange(101) * 0.01).y
    y[60:, 2] = np.inf
    inp = prepare_input(_traj(np.arange(101) * 0.01, y), SC, "n.csv")
    assert inp.diverged_at_s == pytest.approx(0.6) and inp.n_rows == 60
    y[60:, 2] = 0.0
    y[70:, 11] = 1e9                                 # beyond BLOWUP_LIMIT: a blow-up
    inp = prepare_input(_traj(np.arange(101) * 0.01, y), SC, "b.csv")
    assert inp.diverged_at_s == pytest.approx(0.7)


def test_zero_quaternions():
    y = _traj(np.arange(101) * 0.01).y
    y[:, 6] = 0.0
    with pytest.raises(CheckError, match=r"z.csv: line 2: columns qw,qx,qy,qz: the quaternion is zero"):
        prepare_input(_traj(np.arange(101) * 0.01, y), SC, "z.csv")
    y[:, 6] = 1.0
    y[20:, 6] = 0.0
    inp = prepare_input(_traj(np.arange(101) * 0.01, y), SC, "z.csv")
    assert inp.lost_orientation_at_s == pytest.approx(0.2) and inp.n_rows == 20


def test_short_and_long_files():
    inp = prepare_input(_traj(np.arange(51) * 0.01), SC, "s.csv")
    assert inp.ended_early_s == pytest.approx(0.5)
    inp = prepare_input(_traj(np.arange(151) * 0.01), SC, "l.csv")
    assert inp.ended_early_s is None and inp.n_rows == 101 and inp.dropped_after_s == pytest.approx(1.0)


@pytest.mark.parametrize("t, present, words", [
    ([0.0], QUANTITY_GROUPS, "need at least 2 rows"),
    ([0.5, 0.51, 0.52], QUANTITY_GROUPS, "must start at 0"),
    ([0.0, 0.01], ("velocity",), "needs the position"),
])
def test_files_that_cannot_be_checked(t, present, words):
    with pytest.raises(CheckError, match=words):
        prepare_input(_traj(t, present=present), SC, "x.csv")
