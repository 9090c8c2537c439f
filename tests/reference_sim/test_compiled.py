"""The compiled single-body path is the Python float path, bit for bit, and steps aside for a planted bug.

Every comparison is exact (``np.array_equal``): the compiled kernels transcribe ScalarStepper's arithmetic
operation for operation with fastmath off, so there is no round-off to allow for.
"""
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import reference_sim.simulate as S
from cross_checks.scenario import catalog_names, load_scenario
from reference_sim import compiled
from reference_sim.body import RigidBody
from reference_sim.forces import ForceModel, PointForce, Spring, Torque
from reference_sim.integrators import VARIANTS
from reference_sim.quaternion import matrix_from_quat, quat_normalize
from reference_sim.scalar import ScalarStepper
from reference_sim.state import Problem, State

from .test_integrators import coupled_problem

pytestmark = pytest.mark.skipif(compiled._kernel() is None, reason="numba is not importable here")


def _python_run(monkeypatch, problem, variant, dt, n):
    with monkeypatch.context() as m:
        m.setattr(compiled, "usable", lambda stepper: False)
        return S.simulate(problem, variant, dt, n)


def _assert_same_run(a, b):
    assert a.message == b.message and a.diverged_at_s == b.diverged_at_s
    assert a.y.shape == b.y.shape and np.array_equal(a.y, b.y)
    assert np.array_equal(a.t_s, b.t_s)


def _used_compiled(monkeypatch, problem, variant, dt, n):
    """The run, asserting that it went through the compiled loop."""
    calls = []
    real = compiled.run_until_exceptional

    def counting(*args, **kw):
        calls.append(args[2])
        return real(*args, **kw)

    with monkeypatch.context() as m:
        m.setattr(compiled, "run_until_exceptional", counting)
        run = S.simulate(problem, variant, dt, n)
    assert calls, "the run did not step compiled"
    return run, calls


@pytest.mark.parametrize("variant", list(VARIANTS))
@pytest.mark.parametrize("decay", [(1.0, 1.0), (0.99, 0.995)])
def test_compiled_run_is_bit_identical_to_the_python_run_with_every_force_kind(monkeypatch, variant, decay):
    problem = coupled_problem(decay)
    fast, _ = _used_compiled(monkeypatch, problem, variant, 1.5e-3, 400)
    _assert_same_run(fast, _python_run(monkeypatch, problem, variant, 1.5e-3, 400))


@pytest.mark.parametrize("name", catalog_names())
def test_compiled_runs_of_the_catalog_are_bit_identical_at_its_coarsest_step(monkeypatch, name):
    sc = load_scenario(name)
    dt = max(sc.dt_ladder_s)
    n = min(sc.n_steps(dt), 300)
    for variant in VARIANTS:
        fast, _ = _used_compiled(monkeypatch, sc.problem, variant, dt, n)
        _assert_same_run(fast, _python_run(monkeypatch, sc.problem, variant, dt, n))


@pytest.mark.slow
@pytest.mark.parametrize("name", catalog_names())
def test_compiled_runs_of_the_whole_sweep_are_bit_identical(monkeypatch, name):
    from cross_checks.sweep.jobs import job_dts
    sc = load_scenario(name)
    for variant in VARIANTS:
        for dt in job_dts(sc):
            fast, _ = _used_compiled(monkeypatch, sc.problem, variant, dt, sc.n_steps(dt))
            _assert_same_run(fast, _python_run(monkeypatch, sc.problem, variant, dt, sc.n_steps(dt)))


_vec = st.lists(st.floats(-2.0, 2.0), min_size=3, max_size=3).map(np.array)


@st.composite
def _problems(draw):
    mass = draw(st.floats(0.2, 5.0))
    a, b, c = draw(st.lists(st.floats(0.1, 1.0), min_size=3, max_size=3))   # a box's sides, m: a physical body
    R = matrix_from_quat(quat_normalize(np.array([1.0, *draw(_vec)])))       # its axes turned: products of inertia
    inertia = R @ np.diag([b * b + c * c, a * a + c * c, a * a + b * b]) * (mass / 12.0) @ R.T
    springs = tuple(Spring(draw(_vec), 0.2 * draw(_vec), draw(st.floats(0.0, 60.0)), draw(st.floats(0.0, 1.0)))
                    for _ in range(draw(st.integers(0, 2))))
    points = tuple(PointForce(draw(_vec), 0.2 * draw(_vec), draw(st.sampled_from(["world", "body"])))
                   for _ in range(draw(st.integers(0, 2))))
    torques = tuple(Torque(draw(_vec), draw(st.sampled_from(["world", "body"])))
                    for _ in range(draw(st.integers(0, 2))))
    fm = ForceModel(gravity_W=draw(_vec) * 5.0, linear_drag_N_s_per_m=draw(st.sampled_from([0.0, 0.4])),
                    velocity_decay=draw(st.sampled_from([1.0, 0.99])),
                    angular_velocity_decay=draw(st.sampled_from([1.0, 0.98])), decay_dt_s=1e-2,
                    springs=springs, point_forces=points, torques=torques)
    q = quat_normalize(np.array([1.0, *draw(_vec)]))
    init = State(draw(_vec), draw(_vec), q, 4.0 * draw(_vec))
    return Problem(RigidBody(mass, inertia), fm, init)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(problem=_problems(), variant=st.sampled_from(list(VARIANTS)), dt=st.sampled_from([1e-3, 1e-2, 0.05]))
def test_compiled_equals_python_on_random_problems(monkeypatch, problem, variant, dt):
    fast = S.simulate(problem, variant, dt, 120)
    _assert_same_run(fast, _python_run(monkeypatch, problem, variant, dt, 120))


def _stiff(k=1e6):
    return Problem(RigidBody(1.0, [1.0, 1.0, 1.0]), ForceModel(springs=(Spring(np.zeros(3), np.zeros(3), k, 0.0),)),
                   State(np.array([0.1, 0, 0]), np.zeros(3), np.array([1.0, 0, 0, 0]), np.zeros(3)))


@pytest.mark.parametrize("variant", ["explicit_euler", "course", "midpoint", "rk4"])
def test_a_blow_up_is_the_python_paths_divergence_time_message_and_states(monkeypatch, variant):
    fast, _ = _used_compiled(monkeypatch, _stiff(), variant, 0.01, 400)
    assert fast.diverged_at_s is not None
    _assert_same_run(fast, _python_run(monkeypatch, _stiff(), variant, 0.01, 400))


def test_a_spin_that_blows_up_is_cut_where_the_python_path_cuts_it(monkeypatch):
    p = Problem(RigidBody(1.0, [1.0, 2.0, 3.0]), ForceModel(),
                State(np.zeros(3), np.zeros(3), np.array([1.0, 0, 0, 0]), np.array([0.1, 20.0, 0.1])))
    fast, _ = _used_compiled(monkeypatch, p, "expmap_gyro", 0.01, 2000)
    assert fast.diverged_at_s is not None and 8.0 < fast.diverged_at_s < 9.0
    _assert_same_run(fast, _python_run(monkeypatch, p, "expmap_gyro", 0.01, 2000))


def test_stalled_implicit_euler_steps_are_solved_in_python_and_the_loop_resumes(monkeypatch):
    # ω Δt = 10: the fixed point diverges, so the steps go to Newton (through the Python step) until the body
    # has come to rest at the anchor, where the iteration has nothing left to do
    fast, calls = _used_compiled(monkeypatch, _stiff(), "implicit_euler", 0.01, 50)
    assert fast.diverged_at_s is None and len(calls) > 20   # resumed after each Python step
    _assert_same_run(fast, _python_run(monkeypatch, _stiff(), "implicit_euler", 0.01, 50))


def test_a_leapfrog_half_kick_that_does_not_converge_is_the_python_paths_error(monkeypatch):
    # linear drag c Δt / (2 m) = 2.5 > 1: the fixed point of the implicit half kick diverges
    p = Problem(RigidBody(1.0, [1.0, 1.0, 1.0]), ForceModel(linear_drag_N_s_per_m=50.0),
                State(np.zeros(3), np.array([1.0, 0, 0]), np.array([1.0, 0, 0, 0]), np.zeros(3)))
    fast, _ = _used_compiled(monkeypatch, p, "leapfrog", 0.1, 20)
    assert fast.diverged_at_s == pytest.approx(0.1) and "ImplicitSolveError" in fast.message
    _assert_same_run(fast, _python_run(monkeypatch, p, "leapfrog", 0.1, 20))


def test_a_patched_step_method_turns_the_compiled_path_off_and_runs_the_patch(monkeypatch):
    problem = coupled_problem()
    assert compiled.usable(ScalarStepper(problem, "rk4", 1e-3))
    shipped = ScalarStepper._rk4
    monkeypatch.setattr(ScalarStepper, "_rk4", lambda self, y: shipped(self, y)[:6] + [1.0, 0, 0, 0] + y[10:13])
    assert not compiled.usable(ScalarStepper(problem, "rk4", 1e-3))
    run = S.simulate(problem, "rk4", 1e-3, 5)
    assert np.array_equal(run.y[-1, 6:10], [1.0, 0, 0, 0])   # the patch ran
    # a method replaced on one instance only, too
    monkeypatch.undo()
    s = ScalarStepper(problem, "rk4", 1e-3)
    s._ang_acc = lambda *a: (0.0, 0.0, 0.0)
    assert not compiled.usable(s)


def test_a_setting_planted_in_init_reaches_the_compiled_run(monkeypatch):
    # tests/mutants.py changes settings after ScalarStepper.__init__: the compiled kernel reads them too
    problem = coupled_problem((0.99, 0.995))
    clean = S.simulate(problem, "course", 1e-3, 200)
    orig = ScalarStepper.__init__

    def init(self, *a, **kw):
        orig(self, *a, **kw)
        self.gv, self.gw = self.gv * self.gv, self.gw * self.gw

    monkeypatch.setattr(ScalarStepper, "__init__", init)
    fast, _ = _used_compiled(monkeypatch, problem, "course", 1e-3, 200)
    assert not np.array_equal(fast.y, clean.y)
    _assert_same_run(fast, _python_run(monkeypatch, problem, "course", 1e-3, 200))


def test_without_numba_every_run_steps_in_python(monkeypatch):
    problem = coupled_problem()
    with_numba = S.simulate(problem, "leapfrog", 1e-3, 50)
    monkeypatch.setattr(compiled, "_KERNEL", [None])
    assert not compiled.usable(ScalarStepper(problem, "leapfrog", 1e-3))
    _assert_same_run(S.simulate(problem, "leapfrog", 1e-3, 50), with_numba)


def _kernel_already_loaded(_):
    return bool(compiled._KERNEL) and compiled._KERNEL[0] is not None


def test_warm_loads_the_kernel_that_forked_workers_inherit():
    # the sweep and the fuzz call warm() before their process pools fork: a worker then finds the compiled loop
    # loaded, instead of loading (or compiling) it once more per worker
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor
    if "fork" not in mp.get_all_start_methods():
        pytest.skip("no fork start method here")
    assert compiled.warm()
    with ProcessPoolExecutor(1, mp_context=mp.get_context("fork")) as pool:
        assert pool.submit(_kernel_already_loaded, None).result()


def test_a_run_in_chunks_is_the_run_in_one_call(monkeypatch):
    problem = coupled_problem((0.99, 0.995))
    whole = S.simulate(problem, "rk4", 1e-3, 1000)
    monkeypatch.setattr(S, "COMPILED_CHUNK", 64)
    chunked, calls = _used_compiled(monkeypatch, problem, "rk4", 1e-3, 1000)
    assert len(calls) == 16   # ceil(1000 / 64) calls, each starting where the previous one stopped
    assert calls == list(range(0, 1000, 64))
    _assert_same_run(chunked, whole)


def test_a_time_limit_stops_a_long_compiled_run_between_chunks(monkeypatch):
    # Inside compiled code a SIGALRM handler waits for the call to return: the chunks bound that wait.
    # The alarm is delivered for real, deterministically, while the third chunk runs (here: as it
    # returns); the run must stop there, not after the remaining chunks (no clock read: any CPU).
    import os
    import signal

    from cross_checks.sweep.lifecycle import TimeLimitExceeded, time_limit
    problem = coupled_problem()
    n = 4_000_000   # 62 chunks of 65,536 steps
    calls = []
    real = compiled.run_until_exceptional

    def alarm_in_the_third_chunk(*args, **kw):
        out = real(*args, **kw)
        calls.append(args[2])
        if len(calls) == 3:
            os.kill(os.getpid(), signal.SIGALRM)
        return out
    monkeypatch.setattr(compiled, "run_until_exceptional", alarm_in_the_third_chunk)
    with pytest.raises(TimeLimitExceeded, match="the run took longer than the time limit"):
        with time_limit(3600.0, "the run"):
            S.simulate(problem, "implicit_euler", 1e-4, n)
    assert len(calls) == 3 and calls[1] - calls[0] == 65_536


def test_the_compiled_loop_refuses_steps_its_rows_cannot_hold():
    stepper = ScalarStepper(coupled_problem(), "rk4", 1e-3)
    with pytest.raises(ValueError, match="do not fit"):
        compiled.run_until_exceptional(stepper, np.zeros((10, 13)), 0, 10, 1e8)
