"""The host loop (cross_checks.engines.loop) against worlds that break the contract: a world that raises,
returns the wrong shape or a non-finite state before any step fails its own runs with an EngineError naming
the engine and the runs, and every other world's runs are kept; the loop's split of a run's time into the
engine's and rbcheck's; and the loop's per-step semantics against a readable loop written here."""
import sys
from pathlib import Path

import numpy as np
import pytest

from cross_checks.engines import forces
from cross_checks.engines.base import EngineError, RunRequest
from cross_checks.scenario import load_scenario

sys.path.insert(0, str(Path(__file__).resolve().parents[3] / "examples" / "python_engine"))
from expmap_engine import ExpmapEngine, ExpmapWorld  # noqa: E402

sys.path.pop(0)


class _Faulty(ExpmapWorld):
    fault = ""

    def read(self):
        y = super().read()
        if self.fault == "shape":
            return y[:, :12]
        if self.fault == "nan_first":
            return np.full_like(y, np.nan)
        return y

    def step(self):
        if self.fault == "raise":
            raise RuntimeError("the engine's own words")
        super().step()


class _FaultyEngine(ExpmapEngine):
    name = "faulty"

    def __init__(self, fault_for):
        self.fault_for = fault_for     # scenario name -> fault

    def group_key(self, request):
        return (request.scenario.name,)   # one world per scenario: a fault stays in its world

    def build(self, requests, variant, dt_s):
        w = _Faulty(requests, dt_s)
        w.fault = self.fault_for.get(requests[0].scenario.name, "")
        return w


@pytest.mark.parametrize("fault, words", [("raise", "RuntimeError: the engine's own words"),
                                          ("shape", "has shape"),
                                          ("nan_first", "non-finite state before any step")])
def test_a_broken_world_fails_its_runs_and_keeps_every_other(fault, words):
    good, bad = load_scenario("projectile"), load_scenario("tennis_racket")
    engine = _FaultyEngine({"tennis_racket": fault})
    reqs = [RunRequest(good, good.dt_s, 20), RunRequest(bad, bad.dt_s, 20),
            RunRequest(good, good.dt_s / 2, 20)]
    runs = engine.simulate_many("euler", reqs)
    assert isinstance(runs[1], EngineError) and words in str(runs[1])
    assert "faulty:euler on tennis_racket" in str(runs[1]) or fault == "nan_first"
    clean = ExpmapEngine().simulate_many("euler", [reqs[0], reqs[2]])
    for got, want in zip((runs[0], runs[2]), clean):
        assert not isinstance(got, EngineError) and np.array_equal(got.y, want.y)


def test_the_engines_time_is_the_time_inside_its_steps():
    """A world whose step sleeps 2 ms and whose read sleeps 3 ms: the run's engine_s holds at least the step's
    sleeps and host_s at least the read's (the state's recording is rbcheck's), each a lower bound that
    sleeping guarantees, whatever the machine's load (no time is asserted from above)."""
    import time

    class Slow(ExpmapWorld):
        def step(self):
            time.sleep(0.002)
            super().step()

        def read(self):
            time.sleep(0.003)
            return super().read()

    class SlowEngine(ExpmapEngine):
        def build(self, requests, variant, dt_s):
            return Slow(requests, dt_s)

    sc = load_scenario("projectile")
    run = SlowEngine().simulate(sc, "euler", sc.dt_s, 20)
    assert run.engine_s >= 20 * 0.002 and run.host_s >= 20 * 0.003


def _readable_loop(sc, dt, n):
    """The loop's semantics written out for one body of the example engine: forces from the start of each
    step (the requested state at step 1), the weight taken off, the pre-step decay, one step, read."""
    w = ExpmapWorld([RunRequest(sc, dt, n)], dt)
    y0 = sc.problem.initial_packed()
    w.set_state(y0[None])
    ys, y = [w.read()[0]], y0
    g_v, g_w = forces.decay_factors(sc, dt)
    for k in range(n):
        f, tau = forces.harness_force_torque(sc, y if k else y0, dt)
        if sc.problem.forces.has_decay:
            yd = w.read()[0].copy()
            yd[3:6] *= g_v
            yd[10:13] *= g_w
            w.set_state(yd[None])
        w.apply((f - forces.weight_W(sc))[None], tau[None])
        w.step()
        y = w.read()[0]
        ys.append(y)
    return np.array(ys)


@pytest.mark.parametrize("name", ["spring_pendulum", "velocity_decay", "linear_drag", "tennis_racket"])
def test_the_loop_is_the_readable_loop_bit_for_bit(name):
    sc = load_scenario(name)
    run = ExpmapEngine().simulate(sc, "euler", sc.dt_s, 50)
    assert np.array_equal(run.y, _readable_loop(sc, sc.dt_s, 50))


class _RolloutWorld(ExpmapWorld):
    """The example's bodies, each at its own step, with a rollout that takes every kind of force itself
    (``rollout_forces``), as a compiled engine's loop does: the loop's harness called back every step."""

    rollout_forces = True

    def __init__(self, requests):
        super().__init__(requests, np.array([[float(r.dt_s)] for r in requests]))

    def rollout(self, n_steps, harness):
        out = []
        for _ in range(n_steps):
            if harness.state_dependent:   # forces from the start-of-step state, then the decay
                self.apply(*harness.wrench(self.y, np.arange(len(self.y))))
            self.y[:, 3:6] *= harness.g_v[:, None]
            self.y[:, 10:13] *= harness.g_w[:, None]
            self.step()
            out.append(self.read())
        return np.array(out)


class _Rolling(ExpmapWorld):
    """A world whose rollout takes every force (a compiled engine's loop, written out): per step the
    harness's wrench from the current state, the pre-step decay, one step; the loop must never step it."""

    rollout_takes_all_forces = True

    def __init__(self, requests, dt_s, calls):
        super().__init__(requests, dt_s)
        self.calls = calls

    def step(self):
        raise AssertionError("the loop stepped a world whose rollout takes every force")

    def rollout(self, n_steps, harness):
        self.calls.append(n_steps)
        out = []
        for _ in range(n_steps):
            y = self.read()
            f, tau = harness.wrench(y)
            y[:, 3:6] *= harness.g_v[:, None]
            y[:, 10:13] *= harness.g_w[:, None]
            self.set_state(y)
            self.apply(f, tau)
            ExpmapWorld.step(self)
            out.append(self.read())
        return np.array(out)


def test_a_world_of_several_steps_whose_rollout_takes_every_force_runs_each_body_as_alone():
    """One world (world_key) for two scenarios at two steps each, state-dependent forces and decay among
    them: every run is the per-step loop's run of its request alone, bit for bit, on its own time axis."""
    built = []

    class RolloutEngine(ExpmapEngine):
        def world_key(self, request, variant):
            return ("one world",)

        def build(self, requests, variant, dt_s):
            built.append(len(requests))
            return _RolloutWorld(requests)

    scs = [load_scenario("spring_pendulum"), load_scenario("velocity_decay")]
    reqs = [RunRequest(sc, h, n) for sc in scs for h, n in ((sc.dt_s, 30), (sc.dt_s / 2, 45))]
    runs = RolloutEngine().simulate_many("euler", reqs)
    assert built == [4]
    for r, run in zip(reqs, runs):
        alone = ExpmapEngine().simulate(r.scenario, "euler", r.dt_s, r.n_steps)
        assert np.array_equal(run.y, alone.y) and np.array_equal(run.t_s, alone.t_s)
        assert run.engine_s > 0.0 and run.host_s >= 0.0


class _RollingEngine(ExpmapEngine):
    def __init__(self):
        self.calls = []

    def build(self, requests, variant, dt_s):
        return _Rolling(requests, dt_s, self.calls)


@pytest.mark.parametrize("name", ["spring_pendulum", "velocity_decay", "tennis_racket"])
def test_a_world_whose_rollout_takes_every_force_runs_every_run_and_one_step_there(name):
    """World.rollout_takes_all_forces: the loop hands every run (state-dependent forces and decay included)
    and the one-step mode to ``rollout(n, harness)``, whose results are the per-step loop's bit for bit."""
    sc = load_scenario(name)
    engine, plain = _RollingEngine(), ExpmapEngine()
    run = engine.simulate(sc, "euler", sc.dt_s, 40)
    assert engine.calls == [40] and np.array_equal(run.y, plain.simulate(sc, "euler", sc.dt_s, 40).y)
    rows = run.y[::9]
    got, want = engine.one_step(sc, "euler", sc.dt_s, rows), plain.one_step(sc, "euler", sc.dt_s, rows)
    assert np.array_equal(got, want)
    assert engine.calls == [40, 1]


class _Mixed(ExpmapWorld):
    """The example world stepping each body at its own Δt."""

    def __init__(self, requests, dt_s):
        super().__init__(requests, dt_s)
        self.dt_s = np.array([float(r.dt_s) for r in requests])[:, None]


class _MixedEngine(ExpmapEngine):
    mixed_steps = True

    def __init__(self):
        self.worlds = 0

    def group_key(self, request):
        return (request.scenario.name,)

    def build(self, requests, variant, dt_s):
        self.worlds += 1
        return _Mixed(requests, dt_s)


@pytest.mark.parametrize("name", ["spring_pendulum", "velocity_decay"])
def test_a_world_of_several_steps_gives_each_run_its_own_step_and_decay(name):
    """WorldEngine.mixed_steps: a scenario's Δt ladder in one world, each run (its decay factors, its times)
    bit for bit the run of its Δt alone."""
    sc = load_scenario(name)
    engine = _MixedEngine()
    reqs = [RunRequest(sc, sc.dt_s, 30), RunRequest(sc, sc.dt_s / 2, 50), RunRequest(sc, sc.dt_s / 4, 7)]
    runs = engine.simulate_many("euler", reqs)
    assert engine.worlds == 1
    for r, got in zip(reqs, runs):
        want = ExpmapEngine().simulate(sc, "euler", r.dt_s, r.n_steps)
        assert np.array_equal(got.y, want.y) and np.array_equal(got.t_s, want.t_s)


class _BodyTorqueWorld(ExpmapWorld):
    """The example world taking the torques fixed in body axes itself (WorldEngine.takes_body_torque), as
    MuJoCo's qfrc_applied does: τ_W = R(q) τ_B at the start of each step (``world_axes``: a planted bug
    that applies τ_B as if it were in world axes)."""
    world_axes = False

    def __init__(self, requests, dt_s):
        super().__init__(requests, dt_s)
        self.tau_B = np.zeros((len(requests), 3))

    def apply_body_torque(self, tau_B):
        self.tau_B = np.array(tau_B, dtype=float)

    def step(self):
        from scipy.spatial.transform import Rotation
        given = self.tau_W
        own = (self.tau_B if self.world_axes
               else Rotation.from_quat(self.y[:, 6:10], scalar_first=True).apply(self.tau_B))
        self.tau_W = given + own
        super().step()
        self.tau_W = given


def _body_torque_engine(world_axes: bool):
    class BodyTorqueEngine(ExpmapEngine):
        name = "bodytorque"
        takes_body_torque = True

        def build(self, requests, variant, dt_s):
            w = _BodyTorqueWorld(requests, dt_s)
            w.world_axes = world_axes
            return w
    return BodyTorqueEngine()


def _decaying_applied_torque():
    """applied_torque with both velocity decays on (the body torque then scaled by γ_ω before each step)."""
    from cross_checks.scenario import parse_scenario
    catalog = Path(__file__).resolve().parents[3] / "cross_checks" / "scenario" / "catalog"
    text = (catalog / "applied_torque.toml").read_text()
    return parse_scenario(text.replace('name = "applied_torque"', 'name = "decaying_torque"').replace(
        "[forces]\n", "[forces]\nvelocity_decay = 0.999\nangular_velocity_decay = 0.998\n"), "<test>")


@pytest.mark.parametrize("name", ["applied_torque", "decaying_torque", "velocity_decay", "tumbling_box"])
def test_a_world_that_takes_the_body_torque_itself_moves_as_the_harness_drives_it(name):
    """An engine declaring ``takes_body_torque`` gets each body's body-axes torques (scaled by the pre-step
    γ_ω) once, and the harness's forces without them: its runs and one step equal the same world driven
    by the harness alone, to round-off (R(q)τ_B computed by the world instead of the harness), on the
    catalog's body-torque scenario, on decay and on a torque-free one; a world that takes that torque in
    world axes instead is caught (a wrong torque direction's error grows like t², far above round-off)."""
    from cross_checks.core import tolerances as tol
    sc = _decaying_applied_torque() if name == "decaying_torque" else load_scenario(name)
    assert (name != "decaying_torque") or sc.problem.forces.has_decay
    n = min(sc.n_steps(), 400)
    plain = ExpmapEngine().simulate(sc, "euler", sc.dt_s, n).y
    own = _body_torque_engine(False).simulate(sc, "euler", sc.dt_s, n).y
    scale = np.max(np.abs(plain), axis=0) + 1.0
    assert np.max(np.abs(own - plain) / scale) <= tol.SAME_SCHEME_REL
    y0 = plain[n // 2: n // 2 + 3]
    one = _body_torque_engine(False).one_step(sc, "euler", sc.dt_s, y0)
    assert np.max(np.abs(one - ExpmapEngine().one_step(sc, "euler", sc.dt_s, y0))) <= tol.SAME_SCHEME_REL
    body_torque = any(t.frame == "body" for t in sc.problem.forces.torques)
    wrong = _body_torque_engine(True).simulate(sc, "euler", sc.dt_s, n).y
    assert (np.max(np.abs(wrong - plain) / scale) > 1e3 * tol.SAME_SCHEME_REL) == body_torque


# --- the per-step path's hooks: World.applier, World.rows, World.float_rows (issue 43, point 4) ------------

class _Counting(ExpmapWorld):
    """The example's world counting its applier's making and calls, and its apply's arrays."""

    def __init__(self, requests, dt_s, log):
        super().__init__(requests, dt_s)
        self.log = log

    def applier(self, f_W, tau_W):
        self.log.append("applier")
        again = super().applier(f_W, tau_W)

        def counted():
            self.log.append("again")
            again()
        return counted

    def apply(self, f_W, tau_W):
        self.log.append(type(f_W).__name__)
        super().apply(f_W, tau_W)


def _counting_engine(log, **world_fields):
    world = type("CountingWorld", (_Counting,), world_fields)

    def build(self, reqs, variant, dt_s):
        return world(reqs, dt_s, log)
    return type("CountingEngine", (ExpmapEngine,), {"name": "counting", "build": build})()


@pytest.mark.parametrize("name", ["tennis_racket", "projectile"])
def test_constant_forces_an_engine_clears_are_reapplied_by_one_call_the_world_makes_once(name):
    """Constant forces (no state dependence, no decay) given to an engine that clears them after a step: the
    loop asks the world once for a callable (``World.applier``) and calls it before every step, nothing
    else; the run is the readable loop's bit for bit."""
    sc, log = load_scenario(name), []
    run = _counting_engine(log).simulate(sc, "euler", sc.dt_s, 50)
    assert log[0] == "ndarray" or log[0] == "applier"   # the default applier binds apply to the arrays
    assert log.count("applier") == 1 and log.count("again") == 50
    assert np.array_equal(run.y, _readable_loop(sc, sc.dt_s, 50))


class _FlatTuples(ExpmapWorld):
    """A world whose read is its own form (one flat tuple of every body's 13 numbers, columns reversed), which
    its ``rows`` turns back into raw rows (n, B, 13)."""

    def read(self):
        return tuple(self.y[:, ::-1].ravel().tolist())

    def rows(self, reads):
        return np.array(reads).reshape(len(reads), -1, 13)[..., ::-1]


@pytest.mark.parametrize("name", ["tennis_racket", "spring_pendulum", "velocity_decay"])
def test_a_worlds_reads_are_its_own_form_turned_into_rows_once_per_chunk(name):
    """The loop keeps what ``read()`` gives as it is and hands a chunk's reads to ``World.rows`` (here: flat
    tuples with the columns reversed), as do the world's defaults (the first row, the decay, the next step's
    forces) and the one-step mode: the runs and one step are the readable loop's bit for bit."""
    sc = load_scenario(name)
    engine = type("FlatEngine", (ExpmapEngine,), {"name": "flat", "chunk": 16,
                                                  "build": lambda self, reqs, v, dt: _FlatTuples(reqs, dt)})()
    run = engine.simulate(sc, "euler", sc.dt_s, 50)
    assert np.array_equal(run.y, _readable_loop(sc, sc.dt_s, 50))
    assert np.array_equal(engine.one_step(sc, "euler", sc.dt_s, run.y[:3]),
                          ExpmapEngine().one_step(sc, "euler", sc.dt_s, run.y[:3]))


@pytest.mark.parametrize("name", ["spring_pendulum", "applied_torque"])
def test_a_world_taking_float_rows_gets_the_harness_forces_as_plain_floats(name):
    """A world declaring ``float_rows`` is given the per-step forces of a few bodies as rows of plain floats
    (``Harness.wrench_rows``: no arrays built), the same numbers as the arrays: the run is the array-fed
    world's bit for bit."""
    sc, log = load_scenario(name), []
    assert sc.problem.forces.state_dependent
    rows = _counting_engine(log, float_rows=True).simulate(sc, "euler", sc.dt_s, 50).y
    assert log[0] == "ndarray" and set(log[1:]) == {"list"} and len(log) == 50   # step 1: the start forces
    assert np.array_equal(rows, ExpmapEngine().simulate(sc, "euler", sc.dt_s, 50).y)


def test_the_collector_is_off_during_the_steps_and_back_on_after_every_run():
    """The steps make no reference cycles, so the cyclic collector is off while a chunk steps (no pass over
    its reads: ~0.2 µs a step for a microsecond engine), and on again after the chunk, after the run and
    after an engine's error."""
    import gc
    seen = []

    class Watching(ExpmapWorld):
        def step(self):
            seen.append(gc.isenabled())
            if len(seen) == 30:
                raise RuntimeError("the engine's own words")
            super().step()
    engine = type("WatchEngine", (ExpmapEngine,), {"name": "watch", "chunk": 8,
                                                   "build": lambda self, reqs, v, dt: Watching(reqs, dt)})()
    sc = load_scenario("tennis_racket")
    assert gc.isenabled()
    run = engine.simulate_many("euler", [RunRequest(sc, sc.dt_s, 20)])[0]
    assert len(run.y) == 21 and not any(seen) and gc.isenabled()
    assert isinstance(engine.simulate_many("euler", [RunRequest(sc, sc.dt_s, 20)])[0], EngineError)
    assert gc.isenabled()


def test_the_forces_of_a_slice_of_many_bodies_are_each_bodys_own_bit_for_bit():
    """Harness.wrench of a slice of the bodies (one compiled call on their parameters: MuJoCo Warp's batches)
    gives the numbers of the same bodies evaluated one by one in plain floats (indices) and of all at
    once."""
    from cross_checks.engines.loop import Harness
    names = ["spring_pendulum", "applied_torque", "velocity_decay", "tennis_racket", "projectile"]
    scs = [load_scenario(n) for n in names] * 3
    h = Harness(scs, [0.01 * (1 + k % 3) for k in range(len(scs))], True)
    assert h.rows is not None
    rng = np.random.default_rng(11)
    y = rng.normal(size=(len(scs), 13))
    y[:, 6:10] /= np.linalg.norm(y[:, 6:10], axis=1, keepdims=True)
    whole = h.wrench(y)
    for part in (slice(0, 4), slice(3, 11), slice(9, len(scs))):
        f, tau = h.wrench(y[part], part)
        f1, tau1 = h.wrench(y[part], np.arange(len(scs))[part])
        assert np.array_equal(f, f1) and np.array_equal(tau, tau1)
        assert np.array_equal(f, whole[0][part]) and np.array_equal(tau, whole[1][part])
