"""The compiled path is the definition, bit for bit: every run through reference_sim.compiled equals the run
stepped by reference_sim.integrators alone (its divergence time, message and states included).

Every comparison is exact (``np.array_equal``): the compiled kernels transcribe the definition's arithmetic
operation for operation, in its order, with fastmath off, so there is no round-off to allow for.
"""
import dataclasses
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

import reference_sim.simulate as S
from cross_checks.engines.base import RunRequest
from cross_checks.engines.reference import ReferenceAdapter
from cross_checks.scenario import catalog_names, load_scenario
from reference_sim import compiled
from reference_sim.body import RigidBody
from reference_sim.forces import ForceModel, Members, PointForce, Spring, Torque
from reference_sim.integrators import VARIANTS
from reference_sim.quaternion import matrix_from_quat, quat_normalize
from reference_sim.state import Problem, State

from .test_integrators import coupled_problem

pytestmark = pytest.mark.skipif(compiled.kernel() is None, reason="numba is not importable here")


def _python_run(monkeypatch, problem, variant, dt, n):
    """The run stepped by the definition only (what a machine without numba runs)."""
    with monkeypatch.context() as m:
        m.setattr(compiled, "kernel", lambda: None)
        return S.simulate(problem, variant, dt, n)


def _assert_same_run(a, b):
    assert a.message == b.message and a.diverged_at_s == b.diverged_at_s
    assert a.y.shape == b.y.shape and np.array_equal(a.y, b.y)
    assert np.array_equal(a.t_s, b.t_s)


def _used_compiled(monkeypatch, problem, variant, dt, n):
    """The run, asserting that it went through the compiled loop; and the step each call started from."""
    calls = []
    real = compiled.advance

    def counting(variant, rows, offsets, pos, *args):
        calls.append(int(pos[0]))
        return real(variant, rows, offsets, pos, *args)

    with monkeypatch.context() as m:
        m.setattr(compiled, "advance", counting)
        run = S.simulate(problem, variant, dt, n)
    assert calls, "the run did not step compiled"
    return run, calls


#: The variants with a kernel; a variant without one steps by its definition
#: (test_a_variant_without_a_kernel_runs_its_definition).
COMPILED = list(compiled.VARIANT_CODES)


@pytest.mark.parametrize("variant", COMPILED)
@pytest.mark.parametrize("decay", [(1.0, 1.0), (0.99, 0.995)])
def test_compiled_run_is_bit_identical_to_the_definition_with_every_force_kind(monkeypatch, variant, decay):
    problem = coupled_problem(decay)
    fast, _ = _used_compiled(monkeypatch, problem, variant, 1.5e-3, 400)
    _assert_same_run(fast, _python_run(monkeypatch, problem, variant, 1.5e-3, 400))
    # and each step is the definition's step from the run's previous state, one body or a batch of four
    step = VARIANTS[variant].step
    assert np.array_equal(step(problem, fast.y[:-1], 1.5e-3), fast.y[1:])


@pytest.mark.parametrize("variant", COMPILED)
@pytest.mark.parametrize("decay", [(1.0, 1.0), (0.99, 0.995)])
def test_compiled_batch_with_every_constant_force_kind_is_bit_identical(monkeypatch, variant, decay):
    # the forces of the course-type steps taken in lanes (compiled.lane_members): gravity, a world and a body
    # torque (every component), on coupled_problem's body (products of inertia); members from their own
    # initial ω and v, every fourth from rest (where the first step's ω is Δt ω̇, every bit of the torque
    # showing), at their own steps, for their own numbers of steps
    p = coupled_problem(decay)
    fm = dataclasses.replace(p.forces, springs=(), point_forces=(), linear_drag_N_s_per_m=0.0,
                             torques=(Torque(np.array([0.3, -0.2, 0.7]), "body"),
                                      Torque(np.array([0.1, 0.2, -0.3]), "world")))
    p = Problem(p.body, fm, p.initial)
    members = p.members.take(np.zeros(_BATCH, dtype=int))
    dts = 1.5e-3 * np.array([1.0, 0.5, 2.0])[np.arange(_BATCH) % 3]
    y0 = np.tile(p.initial_packed(), (_BATCH, 1))
    y0[:, 3:6] *= np.linspace(0.5, 2.0, _BATCH)[:, None]
    y0[:, 10:13] *= np.where(np.arange(_BATCH) % 4 == 0, 0.0, np.linspace(2.0, 0.5, _BATCH))[:, None]
    _batch_runs(monkeypatch, members, variant, dts, 200 + 10 * np.arange(_BATCH), y0)
    lanes = compiled.lane_members(variant, compiled.parameters(members, dts))
    assert lanes.all() if variant in ("course", "course_gyro", "expmap_gyro") else not lanes.any()


@pytest.mark.slow
@pytest.mark.parametrize("name", catalog_names())
def test_compiled_runs_of_the_whole_sweep_are_bit_identical(monkeypatch, name):
    from cross_checks.sweep.jobs import job_dts
    sc = load_scenario(name)
    for variant in COMPILED:
        for dt in job_dts(sc):
            fast, _ = _used_compiled(monkeypatch, sc.problem, variant, dt, sc.n_steps(dt))
            _assert_same_run(fast, _python_run(monkeypatch, sc.problem, variant, dt, sc.n_steps(dt)))


_vec = st.lists(st.floats(-2.0, 2.0), min_size=3, max_size=3).map(np.array)


@st.composite
def _problems(draw, constant_forces=False):
    """A random problem; ``constant_forces``: without springs or point forces (the forces of the course-type
    steps the compiled loop takes in lanes, compiled.lane_members), with or without drag."""
    mass = draw(st.floats(0.2, 5.0))
    a, b, c = draw(st.lists(st.floats(0.1, 1.0), min_size=3, max_size=3))  # a box's sides, m: a physical body
    R = matrix_from_quat(quat_normalize(np.array([1.0, *draw(_vec)])))  # its axes turned: products of inertia
    inertia = R @ np.diag([b * b + c * c, a * a + c * c, a * a + b * b]) * (mass / 12.0) @ R.T
    springs = tuple(Spring(draw(_vec), 0.2 * draw(_vec),
                           draw(st.floats(0.0, 60.0)), draw(st.floats(0.0, 1.0)))
                    for _ in range(draw(st.integers(0, 0 if constant_forces else 2))))
    points = tuple(PointForce(draw(_vec), 0.2 * draw(_vec), draw(st.sampled_from(["world", "body"])))
                   for _ in range(draw(st.integers(0, 0 if constant_forces else 2))))
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
@given(problem=_problems(), variant=st.sampled_from(COMPILED), dt=st.sampled_from([1e-3, 1e-2, 0.05]))
def test_compiled_equals_the_definition_on_random_problems(monkeypatch, problem, variant, dt):
    fast = S.simulate(problem, variant, dt, 120)
    _assert_same_run(fast, _python_run(monkeypatch, problem, variant, dt, 120))


def _batch_runs(monkeypatch, members, variant, dts, ns, y0):
    """run_members compiled and by the definition alone (every member at once), asserted equal run by run;
    the compiled runs."""
    fast = S.run_members(members, variant, dts, ns, y0)
    with monkeypatch.context() as m:
        m.setattr(compiled, "kernel", lambda: None)
        slow = S.run_members(members, variant, dts, ns, y0)
    for a, b in zip(fast, slow):
        _assert_same_run(a, b)
    return fast


#: More than twice as many members as lanes (_compiled_kernels.LANES, 16): every lane in use, lanes taking the
#: next member as runs of different lengths end
_BATCH = 35


@pytest.mark.parametrize("name", catalog_names())
def test_compiled_batches_of_the_catalog_are_bit_identical(monkeypatch, name):
    # the scenario's problem as many members, each at a step of its ladder, for its own number of steps, from
    # its own initial ω and v: the course-type steps of a scenario without springs, point forces or drag go
    # through the lanes (vectorised across members), the others one member at a time. Member 0 is the
    # scenario's own run at its coarsest step, from its initial state, for up to 300 steps (the longest
    # member: the definition's side steps all members at once, so it costs no more than the batch; a
    # member's run is its run alone: test_gyro_integrators.py::test_members_advance_on_their_own)
    assert _BATCH > 2 * compiled._kernels().LANES
    sc = load_scenario(name)
    members = sc.problem.members.take(np.zeros(_BATCH, dtype=int))
    dts = np.array([sc.dt_ladder_s[j % len(sc.dt_ladder_s)] for j in range(_BATCH)])
    dts[0] = max(sc.dt_ladder_s)
    ns = np.array([min(sc.n_steps(dt), 300 if j == 0 else 40 + 7 * j) for j, dt in enumerate(dts)])
    y0 = np.tile(sc.problem.initial_packed(), (_BATCH, 1))
    y0[:, 3:6] *= 1.0 + 0.01 * np.arange(_BATCH)[:, None]
    y0[:, 10:13] *= 1.0 - 0.01 * np.arange(_BATCH)[:, None]
    fm = sc.problem.forces
    calls, real = [], compiled.advance
    monkeypatch.setattr(compiled, "advance", lambda *a: calls.append(a[0]) or real(*a))
    for variant in COMPILED:
        _batch_runs(monkeypatch, members, variant, dts, ns, y0)
        assert variant in calls, f"{variant} did not step compiled"
        lanes = compiled.lane_members(variant, compiled.parameters(members, dts))
        constant = not fm.springs and not fm.point_forces and fm.linear_drag_N_s_per_m == 0.0
        course_type = variant in ("course", "course_gyro", "expmap_gyro")
        assert lanes.all() if constant and course_type else not lanes.any()


@pytest.mark.parametrize("variant", COMPILED)
@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(problems=st.lists(_problems(constant_forces=True), min_size=1, max_size=40),
       dt=st.sampled_from([1e-3, 1e-2, 0.05]), data=st.data())
def test_compiled_batches_equal_the_definition_on_random_problems(monkeypatch, variant, problems, dt, data):
    # random members without springs or point forces, some with drag (stepped one by one, the others in lanes
    # for a course-type variant), each with its own step and number of steps
    members = Members.stack(problems)
    dts = dt * np.array(data.draw(st.lists(st.sampled_from([1.0, 0.5, 0.25]), min_size=len(problems),
                                           max_size=len(problems))))
    ns = np.array(data.draw(st.lists(st.integers(0, 120), min_size=len(problems), max_size=len(problems))))
    _batch_runs(monkeypatch, members, variant, dts, ns, np.array([p.initial_packed() for p in problems]))


@pytest.mark.parametrize("variant", ["course_gyro", "expmap_gyro"])
def test_spins_that_blow_up_in_lanes_are_cut_where_the_definition_cuts_them(monkeypatch, variant):
    # a fast spin about the intermediate axis blows up (test_a_spin_that_blows_up_is_cut_where_the_definition_
    # cuts_it): faster spins blow up sooner, the slowest not within the run; every lane meets its own end
    p = Problem(RigidBody(1.0, [1.0, 2.0, 3.0]), ForceModel(),
                State(np.zeros(3), np.zeros(3), np.array([1.0, 0, 0, 0]), np.array([0.1, 20.0, 0.1])))
    n = _BATCH
    members = p.members.take(np.zeros(n, dtype=int))
    y0 = np.tile(p.initial_packed(), (n, 1))
    y0[:, 10:13] *= np.linspace(0.2, 1.5, n)[:, None]
    assert compiled.lane_members(variant, compiled.parameters(members, np.full(n, 0.01))).all()
    runs = _batch_runs(monkeypatch, members, variant, 0.01, 2000, y0)
    cut = [r.diverged_at_s for r in runs if r.diverged_at_s is not None]
    assert 1 < len(cut) < n and len(set(cut)) > 1


def _stiff(k=1e6):
    return Problem(RigidBody(1.0, [1.0, 1.0, 1.0]),
                   ForceModel(springs=(Spring(np.zeros(3), np.zeros(3), k, 0.0),)),
                   State(np.array([0.1, 0, 0]), np.zeros(3), np.array([1.0, 0, 0, 0]), np.zeros(3)))


@pytest.mark.parametrize("variant", ["explicit_euler", "course", "midpoint", "rk4", "implicit_gyro_body",
                                     "implicit_gyro_world", "explicit_gyro_clamped", "jolt_gyro",
                                     "buss_augmented", "dlm_splitting", "lp_midpoint", "moser_veselov"])
def test_a_blow_up_is_the_definitions_divergence_time_message_and_states(monkeypatch, variant):
    fast, _ = _used_compiled(monkeypatch, _stiff(), variant, 0.01, 400)
    assert fast.diverged_at_s is not None
    _assert_same_run(fast, _python_run(monkeypatch, _stiff(), variant, 0.01, 400))


def test_a_spin_that_blows_up_is_cut_where_the_definition_cuts_it(monkeypatch):
    p = Problem(RigidBody(1.0, [1.0, 2.0, 3.0]), ForceModel(),
                State(np.zeros(3), np.zeros(3), np.array([1.0, 0, 0, 0]), np.array([0.1, 20.0, 0.1])))
    fast, _ = _used_compiled(monkeypatch, p, "expmap_gyro", 0.01, 2000)
    assert fast.diverged_at_s is not None and 8.0 < fast.diverged_at_s < 9.0
    _assert_same_run(fast, _python_run(monkeypatch, p, "expmap_gyro", 0.01, 2000))


def test_stalled_implicit_euler_steps_are_solved_by_the_definition_and_the_loop_resumes(monkeypatch):
    # ω Δt = 10: the fixed point diverges, so the steps go to Newton (the definition's step) until the body
    # has come to rest at the anchor, where the iteration has nothing left to do
    fast, calls = _used_compiled(monkeypatch, _stiff(), "implicit_euler", 0.01, 50)
    assert fast.diverged_at_s is None and len(calls) > 20   # resumed after each step of the definition
    _assert_same_run(fast, _python_run(monkeypatch, _stiff(), "implicit_euler", 0.01, 50))


def test_a_leapfrog_half_kick_that_does_not_converge_is_the_definitions_error(monkeypatch):
    # linear drag c Δt / (2 m) = 2.5 > 1: the fixed point of the implicit half kick diverges
    p = Problem(RigidBody(1.0, [1.0, 1.0, 1.0]), ForceModel(linear_drag_N_s_per_m=50.0),
                State(np.zeros(3), np.array([1.0, 0, 0]), np.array([1.0, 0, 0, 0]), np.zeros(3)))
    fast, _ = _used_compiled(monkeypatch, p, "leapfrog", 0.1, 20)
    assert fast.diverged_at_s == pytest.approx(0.1) and "ImplicitSolveError" in fast.message
    _assert_same_run(fast, _python_run(monkeypatch, p, "leapfrog", 0.1, 20))


def test_a_moser_veselov_step_without_a_root_is_the_definitions_non_finite_state(monkeypatch):
    # on a principal-axis spin the Moser–Veselov equation Δt Π = 2/(1 + f²) I f has a root only while
    # Δt ω ≤ 1: the torque spins the body up to ω = 10 rad/s (Δt = 0.1 s) at t = 5.4 s, where Newton's iterate
    # turns non-finite; the compiled loop hands that step to the definition, which gives the non-finite state
    p = Problem(RigidBody(1.0, [1.0, 2.0, 3.0]), ForceModel(torques=(Torque(np.array([0.0, 0.0, 5.0])),)),
                State(np.zeros(3), np.zeros(3), np.array([1.0, 0, 0, 0]), np.array([0.0, 0.0, 1.0])))
    fast, calls = _used_compiled(monkeypatch, p, "moser_veselov", 0.1, 100)
    assert calls == [0] and fast.diverged_at_s == pytest.approx(5.5) and "non-finite" in fast.message
    _assert_same_run(fast, _python_run(monkeypatch, p, "moser_veselov", 0.1, 100))


def _requests():
    """Members of different scenarios and steps, with different lengths; one blows up (a fast spin)."""
    scs = [load_scenario(n)
           for n in ("tennis_racket", "spring_oscillator", "velocity_decay", "applied_torque")]
    reqs = [RunRequest(sc, dt, n) for sc, dt, n in zip(scs, (0.01, 0.004, 0.02, 0.005), (300, 120, 90, 400))]
    fast_spin = Problem(RigidBody(1.0, [1.0, 2.0, 3.0]), ForceModel(),
                        State(np.zeros(3), np.zeros(3), np.array([1.0, 0, 0, 0]), np.array([0.1, 20.0, 0.1])))
    # 10 s: course_gyro and expmap_gyro blow up at 8.65-8.68 s, the others run all of it (without numba too,
    # the definition's steps: most of this file's time)
    return reqs + [RunRequest(type("Sc", (), {"problem": fast_spin})(), 0.01, 1000)]


# a variant's members' runs are their own in the definition too:
# tests/reference_sim/test_gyro_integrators.py::test_members_advance_on_their_own
@pytest.mark.parametrize("variant", COMPILED)
def test_simulate_many_is_simulate_member_by_member(monkeypatch, variant):
    reqs = _requests()
    many = ReferenceAdapter().simulate_many(variant, reqs)
    assert len(many) == len(reqs)
    for r, run in zip(reqs, many):
        _assert_same_run(run, S.simulate(r.scenario.problem, variant, r.dt_s, r.n_steps))
    if variant in ("course_gyro", "expmap_gyro"):
        assert many[-1].diverged_at_s is not None and all(run.diverged_at_s is None for run in many[:-1])
    with monkeypatch.context() as m:   # without numba: the definition steps every member at once
        m.setattr(compiled, "kernel", lambda: None)
        for a, b in zip(ReferenceAdapter().simulate_many(variant, reqs), many):
            _assert_same_run(a, b)


def test_every_kernel_is_a_variant_of_the_registry():
    assert set(compiled.VARIANT_CODES) <= set(VARIANTS)
    assert len(set(compiled.VARIANT_CODES.values())) == len(compiled.VARIANT_CODES)   # one code each


@pytest.mark.parametrize("variant", ["lp_midpoint", "implicit_euler"])
def test_a_variant_without_a_kernel_runs_its_definition(monkeypatch, variant):
    # VARIANT_CODES lists what has a kernel; any other variant steps by its definition, never compiled: here a
    # variant registered under a name without a code, with the step of one that has one
    problem = coupled_problem((0.99, 0.995))
    monkeypatch.setitem(VARIANTS, "no_kernel", VARIANTS[variant])
    calls = []
    monkeypatch.setattr(compiled, "advance", lambda *a: calls.append(a))
    run = S.simulate(problem, "no_kernel", 1.5e-3, 60)
    assert not calls and run.diverged_at_s is None and run.y.shape == (61, 13)
    y = problem.initial_packed()
    for n in range(1, 61):
        y = VARIANTS[variant].step(problem, y, 1.5e-3)
        assert np.array_equal(run.y[n], y)


def test_without_numba_every_run_steps_the_definition(monkeypatch):
    problem = coupled_problem()
    with_numba = S.simulate(problem, "leapfrog", 1e-3, 50)
    calls = []
    monkeypatch.setattr(compiled, "kernel", lambda: None)
    monkeypatch.setattr(compiled, "advance", lambda *a: calls.append(a))
    _assert_same_run(S.simulate(problem, "leapfrog", 1e-3, 50), with_numba)
    assert not calls


def _kernel_already_loaded(_):
    return compiled.kernel() is not None and compiled.ForceEvaluator(coupled_problem()).force_torque(
        coupled_problem().initial_packed()) is not None


def test_warm_loads_the_kernel_that_forked_workers_inherit():
    # the sweep and the fuzz call warm() before their process pools fork: a worker then finds the compiled
    # loop loaded, instead of loading (or compiling) it once more per worker
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
    # ceil(1000 / 64) calls, each starting where the previous stopped
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
    real = compiled.advance

    def alarm_in_the_third_chunk(variant, rows, offsets, pos, *args):
        calls.append(int(pos[0]))
        out = real(variant, rows, offsets, pos, *args)
        if len(calls) == 3:
            os.kill(os.getpid(), signal.SIGALRM)
        return out
    monkeypatch.setattr(compiled, "advance", alarm_in_the_third_chunk)
    with pytest.raises(TimeLimitExceeded, match="the run took longer than the time limit"):
        with time_limit(3600.0, "the run"):
            S.simulate(problem, "implicit_euler", 1e-4, n)
    assert len(calls) == 3 and calls[1] - calls[0] == 65_536


def test_the_compiled_loop_refuses_steps_its_rows_cannot_hold():
    p = coupled_problem()
    with pytest.raises(ValueError, match="do not fit"):
        compiled.advance("rk4", np.zeros((10, 13)), [0], np.zeros(1, dtype=np.int64), [10], 1e8,
                         compiled.parameters(p.members, [1e-3]))


def test_the_compiled_forces_are_the_definitions(monkeypatch):
    problem = coupled_problem((0.99, 0.995))
    y = S.simulate(problem, "rk4", 1e-2, 50).y
    fast = compiled.ForceEvaluator(problem)
    monkeypatch.setattr(compiled, "_KERNELS", [None])
    slow = compiled.ForceEvaluator(problem)
    for row in y:
        for stage in (False, True):
            assert fast.force_torque(row, stage) == slow.force_torque(row, stage)


def _torques_only(decay, world_torque, gravity):
    """A full-tensor body whose only state-dependent forces are torques fixed in body axes (two), beside a
    world torque and gravity when asked, and both decays at ``decay``."""
    fm = ForceModel(gravity_W=np.array(gravity), velocity_decay=decay, angular_velocity_decay=decay,
                    decay_dt_s=2e-3,
                    torques=(Torque(np.array([0.3, -0.1, 0.2]), "body"),
                             Torque(np.array([0.0, 0.05, 0.0]), "body"),
                             *((Torque(np.array(world_torque), "world"),) if world_torque else ())))
    body = RigidBody(1.5, [[0.05, 0.01, 0.0], [0.01, 0.06, 0.005], [0.0, 0.005, 0.08]])
    init = State(np.zeros(3), np.zeros(3), quat_normalize([1.0, 0.2, -0.1, 0.3]), np.array([0.5, -1.0, 2.0]))
    return Problem(body, fm, init)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.floats(-1e3, 1e3), min_size=13, max_size=13), st.sampled_from([1.0, 0.99]),
       st.sampled_from([None, [0.1, 0.0, -0.3]]), st.sampled_from([[0.0, 0.0, -9.81], [0.0, 0.0, 0.0]]))
@example([0.0] * 9 + [1.1e-308, 0.0, 0.0, 0.0], 1.0, None, [0.0, 0.0, -9.81])   # |q|² underflows to 0 (found)
def test_body_axes_torques_alone_are_evaluated_in_plain_floats_as_the_kernel_does(y, decay, tau_W, g):
    """Where only body-axes torques depend on the state (no spring, point force or drag), ForceEvaluator
    gives the compiled kernel's six numbers bit for bit without calling it (its 14-argument dispatch costs
    more than the arithmetic), at any state (a quaternion of any norm, lists or arrays); at a stage with
    decay, and at a quaternion whose norm is zero in floats (all zero, or its squares underflowing: 1e-308),
    it calls the kernel."""
    problem = _torques_only(decay, tau_W, g)
    ev = compiled.ForceEvaluator(problem)
    y = np.array(y)
    want = {stage: ev._at(y, stage, *ev.params) for stage in (False, True)}

    def no_kernel(*args):
        raise AssertionError("the compiled kernel (or the definition in its place) was called")
    ev._evaluate = no_kernel
    for stage in (False, True):
        if (stage and decay != 1.0) or math.sqrt(float(np.sum(y[6:10] ** 2))) == 0.0:
            continue
        assert ev.force_torque(y.tolist(), stage) == tuple(want[stage])
        assert ev.force_torque(y, stage) == tuple(want[stage])
    del ev._evaluate
    if decay != 1.0:
        assert ev.force_torque(y, True) == tuple(want[True])
    zero = np.r_[y[:6], 0.0, 0.0, 0.0, 0.0, y[10:]]
    assert np.array_equal(ev.force_torque(zero), ev._at(zero, False, *ev.params), equal_nan=True)


def test_the_forces_of_many_bodies_at_once_are_each_bodys_own_bit_for_bit():
    """compiled.ForceRows (one compiled call for N bodies of different problems: padded spring and point
    arrays) gives each body exactly ForceEvaluator's numbers at its own state."""
    from cross_checks.scenario import catalog_names, load_scenario
    from reference_sim.compiled import ForceEvaluator, ForceRows
    problems = [load_scenario(n).problem for n in catalog_names()]
    rng = np.random.default_rng(5)
    Y = np.array([p.initial_packed() for p in problems]) + 0.1 * rng.standard_normal((len(problems), 13))
    rows = ForceRows.of(problems)
    if rows is None:
        pytest.skip("numba is not available here")
    got = rows.force_torque(Y)
    want = np.array([ForceEvaluator(p)._evaluate(y, False) for p, y in zip(problems, Y)])
    assert np.array_equal(got, want)


def test_the_numba_half_angle_sinc_is_the_numpy_one_to_the_last_bit():
    import math

    from reference_sim._compiled_kernels import _half_angle_sinc
    from reference_sim.quaternion import half_angle_sinc
    from tests.reference_sim.test_quaternion import SINC_ANGLES
    rng = np.random.default_rng(7)
    angles = SINC_ANGLES + list(10.0 ** rng.uniform(-9, 2, 2000))
    got = np.array([_half_angle_sinc(t, math.sin(0.5 * t)) for t in angles])
    np.testing.assert_array_equal(got, half_angle_sinc(np.array(angles)))
