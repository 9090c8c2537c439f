"""Recorded runs: every step kept, divergence stops the run with its time, never NaN rows."""
import numpy as np

from reference_sim.body import RigidBody
from reference_sim.forces import ForceModel, Spring
from reference_sim.simulate import BLOWUP_LIMIT, bad_rows, none_bad, recorded_run, simulate
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
    p = Problem(RigidBody(1.0, [1.0, 1.0, 1.0]),
                ForceModel(springs=(Spring(np.zeros(3), np.zeros(3), 1e6, 0.0),)),
                State(np.array([0.1, 0, 0]), np.zeros(3), np.array([1.0, 0, 0, 0]), np.zeros(3)))
    assert simulate(p, "explicit_euler", 0.01, 200).diverged_at_s is not None
    run = simulate(p, "implicit_euler", 0.01, 200)
    assert run.diverged_at_s is None and np.abs(run.y[-1, 0]) < 0.1


def test_a_nan_in_any_component_is_a_divergence_at_its_step(monkeypatch):
    # a NaN that is not the first component, after larger finite ones, with and without the compiled path
    from reference_sim import compiled, integrators

    def nan_at_step_3(problem, y, dt):
        out = y + 1e-3
        if np.any(y[..., 0] >= 2e-3 - 1e-12):
            out[..., 11] = np.nan   # ω_y only
        return out
    monkeypatch.setitem(integrators.VARIANTS, "rk4", integrators.Scheme(nan_at_step_3, 4, "a NaN at step 3"))
    monkeypatch.setattr(compiled, "kernel", lambda: None)
    run = simulate(_problem([0.1, 1.0, 0.1]), "rk4", 0.01, 10)
    assert run.diverged_at_s == 0.03 and "non-finite state" in run.message
    assert len(run.y) == 3 and np.all(np.isfinite(run.y))


def test_an_exception_in_a_step_is_a_divergence_with_its_words(monkeypatch):
    from reference_sim import compiled, integrators

    def raise_at_step_5(problem, y, dt):
        if np.any(y[..., 0] >= 4e-3 - 1e-12):
            raise ValueError("math domain error")
        return y + 1e-3
    monkeypatch.setitem(integrators.VARIANTS, "rk4",
                        integrators.Scheme(raise_at_step_5, 4, "raises at step 5"))
    monkeypatch.setattr(compiled, "kernel", lambda: None)
    run = simulate(_problem([0.1, 1.0, 0.1]), "rk4", 0.01, 100)
    assert (run.diverged_at_s == 0.05
            and run.message == "diverged at t = 0.05 s: ValueError: math domain error")
    assert len(run.y) == 5


def test_recorded_run_stops_at_the_first_bad_state_and_keeps_the_ones_before():
    y = np.zeros((6, 13))
    y[:, 6] = 1.0
    whole = recorded_run(y, 0.1)
    assert whole.diverged_at_s is None and np.array_equal(whole.t_s, 0.1 * np.arange(6))
    y[3, 0], y[4, 1] = np.inf, np.nan
    cut = recorded_run(y, 0.1)
    assert len(cut.y) == 3 and cut.diverged_at_s == 0.1 * 3
    assert cut.message == "diverged at t = 0.3 s (non-finite state)"
    y[3, 0] = 2 * BLOWUP_LIMIT
    assert recorded_run(y, 0.1).message.endswith(f"(state beyond {BLOWUP_LIMIT:g})")


def test_none_bad_is_true_exactly_when_bad_rows_flags_nothing():
    """The loop's fast divergence check of a chunk: every single bad component (non-finite, beyond the
    limit either side) in an otherwise fine array turns it false; values at the limit, -0.0 and an empty
    array do not."""
    rng = np.random.default_rng(3)
    fine = rng.standard_normal((5, 4, 13))
    fine[0, 0, 0], fine[1, 1, 1], fine[2, 2, 2] = BLOWUP_LIMIT, -BLOWUP_LIMIT, -0.0
    assert none_bad(fine) and not bad_rows(fine).any() and none_bad(np.empty((0, 3, 13)))
    for value in (np.nan, np.inf, -np.inf, np.nextafter(BLOWUP_LIMIT, np.inf), -2.0 * BLOWUP_LIMIT):
        for idx in ((0, 0, 0), (4, 3, 12), (2, 1, 7)):
            y = fine.copy()
            y[idx] = value
            assert not none_bad(y) and bad_rows(y).any(), (value, idx)
