"""Recorded runs: every step kept, divergence stops the run with its time, never NaN rows."""
import numpy as np

from reference_sim.body import RigidBody
from reference_sim.forces import ForceModel, Spring
from reference_sim.simulate import BLOWUP_LIMIT, simulate
from reference_sim.state import Problem, State


def _problem(w, springs=()):
    return Problem(RigidBody(1.0, [1.0, 2.0, 3.0]), ForceModel(springs=springs),
                   State(np.zeros(3), np.zeros(3), np.array([1.0, 0, 0, 0]), np.asarray(w, float)))


def test_records_every_step_including_t0():
    run = simulate(_problem([0.1, 1.0, 0.1]), "rk4", 0.01, 100)
    assert run.y.shape == (101, 13) and run.t_s[0] == 0.0 and run.diverged_at_s is None
    np.testing.assert_allclose(run.t_s, 0.01 * np.arange(101))


def test_blowup_is_reported_with_its_time_and_no_bad_rows():
    run = simulate(_problem([0.1, 20.0, 0.1]), "expmap_gyro", 0.01, 2000)
    assert run.diverged_at_s is not None and 8.0 < run.diverged_at_s < 9.0
    assert "diverged at t = " in run.message
    assert np.all(np.isfinite(run.y)) and np.max(np.abs(run.y)) <= BLOWUP_LIMIT
    assert len(run.t_s) == len(run.y) == round(run.diverged_at_s / 0.01)


def test_stiff_spring_explicit_euler_diverges_implicit_does_not():
    # ω Δt = sqrt(1e6) * 0.01 = 10 >> 2: explicit Euler is unstable; implicit Euler is unconditionally stable.
    p = Problem(RigidBody(1.0, [1.0, 1.0, 1.0]), ForceModel(springs=(Spring(np.zeros(3), np.zeros(3), 1e6, 0.0),)),
                State(np.array([0.1, 0, 0]), np.zeros(3), np.array([1.0, 0, 0, 0]), np.zeros(3)))
    assert simulate(p, "explicit_euler", 0.01, 200).diverged_at_s is not None
    run = simulate(p, "implicit_euler", 0.01, 200)
    assert run.diverged_at_s is None and np.abs(run.y[-1, 0]) < 0.1


def test_a_nan_in_any_component_of_the_fast_path_is_a_divergence_at_its_step(monkeypatch):
    # max() over plain floats skips a NaN that is not the first element: the single-body path must not
    import reference_sim.scalar as scalar

    class NanAtStep3:
        def __init__(self, problem, variant, dt_s):
            self.n = 0

        def step(self, y):
            self.n += 1
            out = [v + 1e-3 for v in y]
            if self.n == 3:
                out[11] = float("nan")   # ω_y only, after larger finite components
            return out

    monkeypatch.setattr(scalar, "ScalarStepper", NanAtStep3)
    run = simulate(_problem([0.1, 1.0, 0.1]), "rk4", 0.01, 10)
    assert run.diverged_at_s == 0.03 and "non-finite state" in run.message
    assert len(run.y) == 3 and np.all(np.isfinite(run.y))


def test_block_divergence_test_cuts_the_run_where_a_per_step_test_would(monkeypatch):
    # The Python float path tests states in blocks of CHECK_EVERY: its run must equal the one that tests
    # every step (CHECK_EVERY = 1), for blow-ups landing at different places inside a block. (The compiled
    # path tests every step; tests/reference_sim/test_compiled.py compares it with this one.)
    import reference_sim.simulate as S
    from reference_sim import compiled
    monkeypatch.setattr(compiled, "usable", lambda stepper: False)
    cases = [([0.1, 20.0, 0.1], "expmap_gyro"), ([0.1, 25.0, 0.1], "expmap_gyro"), ([0.1, 25.0, 0.1], "course_gyro"),
             ([0.1, 40.0, 0.1], "course_gyro")]
    blocked = [simulate(_problem(w), v, 0.01, 3000) for w, v in cases]
    monkeypatch.setattr(S, "CHECK_EVERY", 1)
    for (w, v), one in zip(cases, blocked):
        each = simulate(_problem(w), v, 0.01, 3000)
        assert one.diverged_at_s is not None and one.diverged_at_s == each.diverged_at_s, v
        assert one.message == each.message
        np.testing.assert_array_equal(one.y, each.y)
    assert len({round(r.diverged_at_s / 0.01) % 64 for r in blocked}) > 1  # not all at one place in a block


def test_an_exception_after_an_unnoticed_bad_state_reports_the_bad_state(monkeypatch):
    import reference_sim.scalar as scalar

    class InfThenRaise:
        def __init__(self, problem, variant, dt_s):
            self.n = 0

        def step(self, y):
            self.n += 1
            if self.n == 6:
                raise ValueError("math domain error")
            out = [v + 1e-3 for v in y]
            if self.n == 4:
                out[0] = float("inf")
            return out

    monkeypatch.setattr(scalar, "ScalarStepper", InfThenRaise)
    run = simulate(_problem([0.1, 1.0, 0.1]), "rk4", 0.01, 100)
    assert run.diverged_at_s == 0.04 and "non-finite state" in run.message and len(run.y) == 4
