"""`rbcheck bench`: repeated measurements (median, spread), one N per table, the sweep's floor counted from
the scenarios themselves (no timing is asserted: speed lives in the benchmark's output), and Drake's
single-trajectory cost beside MuJoCo's through the same adapter interface (None when Drake is absent)."""
import math

import numpy as np
import pytest

from cross_checks import bench, engines
from cross_checks.engines import get_adapter
from cross_checks.engines.base import EngineAdapter, Variant


def test_stats_are_the_median_and_the_range():
    assert bench.stats([3.0, 1.0, 2.0, 10.0, 2.5]) == {"median": 2.5, "min": 1.0, "max": 10.0, "repeats": 5}


def test_every_repeat_is_timed_after_a_warm_up():
    calls = []
    times = bench._times(lambda: calls.append(1), 4)
    assert len(calls) == 5 and len(times) == 4 and all(t >= 0 for t in times)


def test_the_sweep_floor_counts_every_engine_step_of_the_sweep(monkeypatch):
    """engine steps = Σ over variants and Δt of the scenario's steps (from its file, not from rbcheck's
    rows); floor = steps × bare step ÷ cores; the report stage is timed apart from the run stage."""
    from cross_checks.core.files import usable_cores
    from cross_checks.engines import all_variants
    from cross_checks.scenario import load_scenario
    monkeypatch.setattr(bench, "QUICK_SCENARIOS", ("projectile",))
    rendered = []
    sw = bench.sweep_floor(quick=True, repeats=2, render=lambda d: rendered.append(d), bare_step_us=2.0)
    sc = load_scenario("projectile")
    dts = set(sc.dt_ladder_s) | {sc.dt_s}
    variants = [v.name for v in all_variants() if v.available and v.engine in bench.SWEEP_ENGINES]
    steps = len(variants) * sum(round(sc.duration_s / dt) for dt in dts)
    assert sw["variants"] == variants and sw["scenarios"] == ["projectile"]
    assert sw["engine_steps"] == steps
    assert sw["floor_s"] == pytest.approx(steps * 2e-6 / usable_cores())
    assert len(rendered) == 2 and sw["report_s"]["repeats"] == 2 and sw["report_included"]
    for k in ("run_s", "report_s", "total_s"):
        assert 0 <= sw[k]["min"] <= sw[k]["median"] <= sw[k]["max"]
    assert sw["total_s"]["min"] >= sw["run_s"]["min"] + sw["report_s"]["min"] - 1e-9


def _table_input():
    m = {k: {"median": 2.0, "min": 1.0, "max": 3.0, "repeats": 3} for k in (
        "reference_course_body_steps_per_s", "reference_expmap_gyro_body_steps_per_s",
        "mujoco_multibody_body_steps_per_s", "mujoco_rollout_body_steps_per_s", "pybullet_body_steps_per_s",
        "reference_single_us_per_step", "mujoco_single_us_per_step", "mujoco_bare_step_us")}
    sw = {"scenarios": ["projectile"], "variants": ["reference:course"], "cores": 2, "engine_steps": 1000,
          "runs": 5, "bare_mj_step_us": 1.0, "floor_s": 5e-4, "report_included": True,
          **{k: {"median": 0.004, "min": 0.003, "max": 0.005, "repeats": 3}
             for k in ("run_s", "report_s", "total_s", "s_in_simulate")}}
    r = {"measurements": m, "n_bodies": 200, "repeats": 3, "cpu_count": 2, "load_average": [0.5, 0, 0],
         **{k: v["median"] for k, v in m.items()}, "sweep": sw, "targets": {},
         "mujoco_best_body_steps_per_s": 2.0, "ratio_reference_single_vs_mj_step": 1.0,
         "sweep_floor_ratio": 0.004 / 5e-4, "sweep_run_floor_ratio": 8.0,
         "mujoco_adapter_single_us_per_step": 2.0, "drake_single_us_per_step": 4.0,
         "drake_constant_force_us_per_step": 3.0}
    return r


def test_the_table_says_one_n_for_every_row_and_prints_the_ratio():
    r = _table_input()
    text = bench.format_table(r)
    assert "every row: N = 200 bodies; median of 3 repeats" in text
    assert "floor = steps x bare mj_step / cores = 1,000 x 1.000 us / 2 = 0.00 s" in text
    assert "sweep / floor = 8.0x" in text and math.isclose(r["sweep_floor_ratio"], 8.0)


def test_drake_is_measured_beside_mujoco_through_the_adapters():
    pytest.importorskip("pydrake")
    through_adapter, constant_force = bench.drake_single_us(200, 1)
    from cross_checks.engines import mujoco_engine
    assert through_adapter["median"] > 0 and constant_force["median"] > 0
    assert bench.adapter_single_us(mujoco_engine, "euler", 200, 1)["median"] > 0


def test_without_drake_the_keys_are_none_and_the_table_says_why(monkeypatch):
    from cross_checks.engines import drake_engine
    monkeypatch.setattr(drake_engine, "pydrake", None)
    assert bench.drake_single_us(10, 1) == (None, None)
    r = _table_input()
    r.update(drake_single_us_per_step=None, drake_constant_force_us_per_step=None)
    assert "Drake not installed (pip install 'rbcheck[drake]')" in bench.format_table(r)


class _Counting(EngineAdapter):
    """A batching engine for the bench: the reference's expmap_gyro, counting its simulate_many calls."""
    name = "countsim"
    variants = {"expmap_gyro": Variant(1, "reference expmap_gyro, batched")}
    calls: list = []

    def version(self):
        return "test"

    def simulate(self, scenario, variant, dt_s, n_steps):
        return get_adapter("reference").simulate(scenario, variant, dt_s, n_steps)

    def simulate_many(self, variant, requests):
        self.calls.append(len(requests))
        return get_adapter("reference").simulate_many(variant, requests)


def test_engines_that_batch_are_measured_through_simulate_many_at_the_tables_n(monkeypatch):
    """Every installed engine whose adapter overrides simulate_many is a row (the table's engines excepted), N
    different bodies in ONE call, after an untimed warm-up call that takes any compilation."""
    monkeypatch.setattr(engines, "_user", dict(engines._user))
    engines.register_adapter(_Counting(), "test_bench.py")
    assert "countsim:expmap_gyro" in bench.batching_variants()
    assert bench.batching_variants(["mujoco"]) == []            # MuJoCo has its own rows
    _Counting.calls.clear()
    st = bench.adapter_batched("countsim:expmap_gyro", 7, 5, 2)
    assert _Counting.calls == [7, 7, 7] and st["repeats"] == 2 and st["median"] > 0


def test_the_table_has_a_row_per_batching_adapter():
    r = _table_input()
    r["batched_adapters"] = {"mujoco:euler": 2.0}
    r["measurements"]["adapter_batched[mujoco:euler]"] = {"median": 2.0, "min": 1.0, "max": 3.0, "repeats": 3}
    assert "through the adapter, simulate_many: mujoco:euler" in bench.format_table(r)


def test_the_sweep_is_measured_before_any_engine_adapter_runs_in_the_process(monkeypatch):
    """The sweep forks its workers: a JAX or Warp engine started before it in the bench's process would be
    inherited by them (JAX warns of a deadlock at every fork), so the adapters' rows come after it."""
    order = []
    stat = {"median": 1.0, "min": 1.0, "max": 1.0, "repeats": 1}
    for name in ("reference_batched", "mujoco_multibody", "mujoco_rollout", "pybullet_bodies",
                 "reference_single_us", "mujoco_single_us", "mujoco_bare_step_us"):
        monkeypatch.setattr(bench, name, lambda *a, **k: stat)
    monkeypatch.setattr(bench, "adapter_single_us", lambda *a, **k: order.append("adapter") or stat)
    monkeypatch.setattr(bench, "drake_single_us", lambda *a, **k: order.append("adapter") or (None, None))
    monkeypatch.setattr(bench, "adapter_batched", lambda *a, **k: order.append("adapter") or stat)
    monkeypatch.setattr(bench, "overhead_rows", lambda *a, **k: order.append("adapter") or [])
    rows_of = []
    monkeypatch.setattr(bench, "batched_rows",
                        lambda vs, *a, **k: order.append("own") or rows_of.append(vs) or ([], {}, {}))
    monkeypatch.setattr(bench, "batching_variants",
                        lambda *a, **k: ["jaxsim:semi_implicit_euler", "rapier:symplectic_euler"])
    sweep = {"total_s": stat, "run_s": stat, "floor_s": 1.0}
    monkeypatch.setattr(bench, "sweep_floor", lambda *a, **k: order.append("sweep") or sweep)
    r = bench.run_bench(quick=True, repeats=1)
    assert order[0] == "sweep" and order.count("sweep") == 1 and "adapter" in order and "own" in order
    # the CPU engines' batched rows before any JAX or Warp one
    assert rows_of == [["mujoco:euler", "pybullet:multibody", "rapier:symplectic_euler",
                        "jaxsim:semi_implicit_euler"]]
    assert r["sweep"] is sweep and r["targets"]["sweep (run + report) <= 8x its floor"]


def test_the_engines_own_time_is_measured_apart_from_rbchecks_and_both_are_printed():
    """One trajectory through rbcheck: the time inside the engine's step and the whole cost per step through
    rbcheck, engine included; the first never exceeds the second, and the table prints both and their
    ratio. The engine's own cost per step is its own minimal loop (a CPU engine's)."""
    rows = bench.overhead_rows(300, 1, variants={"mujoco:euler", "pybullet:multibody"})
    assert {r["variant"] for r in rows} == {"mujoco:euler", "pybullet:multibody"}
    for r in rows:
        assert 0 < r["engine_step_us_per_step"] <= r["rbcheck_us_per_step"]
        assert r["engine_us_per_step"] == r["own_loop_us_per_step"]
    t = _table_input()
    t["overhead"] = rows
    t["batched"] = [{"variant": "mujoco:euler", "engine_body_steps_per_s": 4e6,
                     "rbcheck_body_steps_per_s": 1e6}]
    text = bench.format_table(t)
    assert "mujoco:euler" in text and "through rbcheck" in text
    assert "4.000e+06        1.000e+06    0.25  N bodies in one model" in text


def _cpu_defaults() -> dict:
    """The installed CPU engines' default variants {engine: "engine:variant"}."""
    from cross_checks.engines import all_variants
    defaults: dict = {}
    for v in all_variants():
        if v.available and v.engine in bench.CPU_ENGINES:
            defaults.setdefault(v.engine, v.name)
    return defaults


def test_every_cpu_engine_has_its_own_minimal_loop_beside_the_engine_and_rbcheck():
    """Each CPU engine's overhead row has its own minimal loop (apply + step + read in its own API) beside
    its step alone and the cost through rbcheck, every installed one measured (a loop that fails to run
    fails here); the table prints the three, the ratio and rbcheck's own time."""
    assert set(bench.OWN_LOOP) == set(bench.CPU_ENGINES)
    defaults = _cpu_defaults()
    rows = bench.overhead_rows(200, 1, variants=set(defaults.values()))
    assert {r["variant"] for r in rows} == set(defaults.values())
    for r in rows:
        assert r["own_loop_us_per_step"] > 0 and 0 < r["engine_step_us_per_step"] <= r["rbcheck_us_per_step"]
        assert r["engine_us_per_step"] == r["own_loop_us_per_step"]
        assert r["rbcheck_own_us_per_step"] == r["rbcheck_us_per_step"] - r["own_loop_us_per_step"]
    t = _table_input()
    t["overhead"] = [{"variant": "pybullet:multibody", "engine_us_per_step": 2.5,
                      "engine_step_us_per_step": 1.0, "own_loop_us_per_step": 2.5,
                      "rbcheck_us_per_step": 4.0}]
    text = bench.format_table(t)
    assert "own loop" in text and "rbcheck own" in text
    assert "pybullet:multibody                      1.00      2.50             4.00   1.60x   4.00x" in text
    assert text.split("pybullet:multibody", 1)[1].split("\n")[0].endswith("+1.50")


@pytest.mark.parametrize("engine", bench.CPU_ENGINES)
def test_an_engines_own_loop_reaches_rbchecks_final_state_bit_for_bit(engine):
    """rbcheck's own time is measured as the cost through rbcheck less the engine's own minimal loop: that
    is only rbcheck's if the loop does all the work a run needs (the torque applied and turned as the
    adapter does, every step taken and read). Held here against rbcheck's run of the same 300 steps: the
    same final state to the last bit (measured: all six engines, 2026-11-29)."""
    variant = _cpu_defaults().get(engine)
    if variant is None:
        pytest.skip(f"{engine} not installed")
    from cross_checks.engines import get_adapter
    name = variant.split(":", 1)[1]
    loop = bench.OWN_LOOP[engine](name, 300)
    try:
        loop.run()
        y_own = loop.final()
    finally:
        loop.close()
    run = get_adapter(engine).simulate(bench._bench_scenario(), name, bench.H, 300)
    assert np.array_equal(y_own, run.y[-1])
    assert not np.array_equal(run.y[-1], run.y[-2])   # the body moved: a loop that never stepped would differ


def test_the_overhead_targets_are_read_from_the_rows_as_the_issue_words_them():
    """Hand-made rows: CPU engines at 1.9x / 2.1x / 2.4x their own cost per step (the own loop), rbcheck's own
    time beside the step alone (1.4 below 4.0; 1.1 above 1.0, from the rounds' median where the row has one,
    else from the two medians), a compiled engine (no single-run target), a batched row at 0.49x / 0.5x, and
    MuJoCo's time inside its step against 3x a Python loop of mj_step."""
    overhead = [{"variant": "mujoco:euler", "engine_us_per_step": 1.0, "rbcheck_us_per_step": 1.9},
                {"variant": "pybullet:multibody", "engine_us_per_step": 7.0, "engine_step_us_per_step": 4.0,
                 "rbcheck_us_per_step": 8.4, "own_loop_us_per_step": 7.0},
                {"variant": "physx:tgs", "engine_us_per_step": 4.0, "engine_step_us_per_step": 4.0,
                 "rbcheck_us_per_step": 8.4, "own_loop_us_per_step": 4.0},
                {"variant": "dart:semi_implicit_euler", "engine_us_per_step": 1.5,
                 "engine_step_us_per_step": 1.0, "rbcheck_us_per_step": 2.4, "own_loop_us_per_step": 1.5,
                 "rbcheck_own_us_per_step": 1.1},
                {"variant": "mjx:euler", "engine_us_per_step": 100.0, "rbcheck_us_per_step": 900.0},
                {"variant": "drake:semi_explicit_euler", "engine_us_per_step": None,
                 "rbcheck_us_per_step": 9.0}]
    batched = [{"variant": "mujoco:euler", "engine_body_steps_per_s": 4e6, "rbcheck_body_steps_per_s": 2e6},
               {"variant": "pybullet:multibody", "engine_body_steps_per_s": 1e6,
                "rbcheck_body_steps_per_s": 4.9e5},
               {"variant": "rapier:symplectic_euler", "engine_body_steps_per_s": None,
                "rbcheck_body_steps_per_s": 1.0}]
    t = bench.overhead_targets(overhead, batched, mj_step_loop_us=0.34)
    assert t == {
        "mujoco:euler: through rbcheck <= 2x the engine's own cost per step": True,
        "mujoco:euler: engine_s per step <= 3x a Python loop of mj_step": True,
        "pybullet:multibody: rbcheck's own time per step <= the engine's step alone": True,
        "pybullet:multibody: through rbcheck <= 2x the engine's own cost per step": True,
        "physx:tgs: rbcheck's own time per step <= the engine's step alone": False,
        "physx:tgs: through rbcheck <= 2x the engine's own cost per step": False,
        "dart:semi_implicit_euler: rbcheck's own time per step <= the engine's step alone": False,
        "dart:semi_implicit_euler: through rbcheck <= 2x the engine's own cost per step": True,
        "mujoco:euler: simulate_many >= 0.5x the engine's own batched throughput": True,
        "pybullet:multibody: simulate_many >= 0.5x the engine's own batched throughput": False}
    assert not bench.overhead_targets(overhead[:1], [], mj_step_loop_us=0.33)[
        "mujoco:euler: engine_s per step <= 3x a Python loop of mj_step"]


class _Rate:
    """A stand-in runner whose call sets the clock: ``clock.now += seconds(call number)``."""

    def __init__(self, clock, name, seconds):
        self.clock, self.name, self.seconds, self.calls = clock, name, seconds, 0

    def __call__(self):
        self.calls += 1
        self.clock.log.append(self.name)
        self.clock.now += self.seconds(self.calls)


class _Clock:
    def __init__(self):
        self.now, self.log = 0.0, []

    def __call__(self):
        return self.now


def test_the_two_sides_of_a_row_are_timed_alternately_in_rounds(monkeypatch):
    """After one warm-up call each, every round runs each side once, the order reversed every other round;
    each side's rates are its own calls' (work / seconds)."""
    clock = _Clock()
    monkeypatch.setattr(bench.time, "perf_counter", clock)
    a = _Rate(clock, "a", lambda k: 1.0)
    b = _Rate(clock, "b", lambda k: 0.5 * k)
    rates = bench.interleaved({"a": bench.Runner(a, 10), "b": bench.Runner(b, 10)}, 4)
    assert clock.log == ["a", "b", "a", "b", "b", "a", "a", "b", "b", "a"]
    assert rates == {"a": [10.0] * 4, "b": [10 / 1.0, 10 / 1.5, 10 / 2.0, 10 / 2.5]}


def test_a_load_that_moves_between_rounds_leaves_the_paired_ratio_where_it_is(monkeypatch):
    """A machine whose load slows everything 5x after the first two rounds: timed side after side (all of one,
    then all of the other) the ratio of medians is a fifth of the truth; the median of the interleaved
    rounds' ratios keeps the true ratio 0.5 (the rbcheck side takes twice the engine's time in every
    round)."""
    clock = _Clock()
    monkeypatch.setattr(bench.time, "perf_counter", clock)
    slow = {"factor": 1.0}
    own = _Rate(clock, "own", lambda k: 1.0 * slow["factor"])
    rb = _Rate(clock, "rbcheck", lambda k: 2.0 * slow["factor"])

    def loaded(runner):
        def run():
            runner()
            if len(clock.log) >= 6:          # after the warm-ups and two rounds: the load goes up
                slow["factor"] = 5.0
        return run
    rates = bench.interleaved({"own": bench.Runner(loaded(own), 100),
                               "rbcheck": bench.Runner(loaded(rb), 100)}, 5)
    assert bench.paired_ratio(rates["rbcheck"], rates["own"]) == pytest.approx(0.5)
    # the same load change met by the old scheme (the engine's repeats first, then rbcheck's) misleads
    slow["factor"], side_by_side = 1.0, {"own": [], "rbcheck": []}
    for name, runner in (("own", own), ("rbcheck", rb)):
        for _ in range(3):
            t0 = clock()
            runner()
            side_by_side[name].append(100 / (clock() - t0))
        slow["factor"] = 5.0
    old = np.median(side_by_side["rbcheck"]) / np.median(side_by_side["own"])
    assert old == pytest.approx(0.1)


def test_every_engine_with_an_own_batched_run_gets_a_batched_row(monkeypatch):
    """Each engine's own batched run (hand-made runners: MuJoCo's two, of which a round takes the better)
    beside simulate_many's at the same N, timed alternately, is one ``batched`` row with its medians and the
    median of its rounds' ratios; an engine without an own run here, not installed or refusing its model is
    not a row and says why; the targets read the rows' ratios."""
    from cross_checks.engines.base import EngineError
    from cross_checks.engines.install import EngineNotInstalled
    seen = []

    def absent(*a):
        raise EngineNotInstalled("jaxsim is not installed (pip install 'rbcheck[jaxsim]')")

    def refused(*a):
        raise EngineError("MJX refused the model")
    own = {"mujoco": lambda n, s, v: (bench.Runner(lambda: None, n * s),
                                      bench.Runner(lambda: None, n * s, 2.0)),
           "physx": lambda n, s, v: seen.append(("own", n, s, v)) or bench.Runner(lambda: None, n * s),
           "jaxsim": absent, "mjx": refused}
    monkeypatch.setattr(bench, "OWN_BATCHED", own)
    monkeypatch.setattr(bench, "adapter_runner",
                        lambda v, n, s: seen.append((v, n, s)) or bench.Runner(lambda: None, n * s))
    # the rates of each round, as interleaved returns them: (own 0, own 1, rbcheck) per variant
    fake = {"mujoco:euler": ([4e6, 2e6, 4e6], [1e6, 5e6, 1e6], [2e6, 2e6, 1.9e6]),
            "physx:pgs": ([1e6, 1e6, 1e6], None, [4e5, 6e5, 4.9e5])}

    def rounds(runners, repeats):
        v = "mujoco:euler" if len(runners) == 3 else "physx:pgs"
        o0, o1, rb = fake[v]
        return {("own", 0): o0, "rbcheck": rb, **({("own", 1): o1} if o1 else {})}
    monkeypatch.setattr(bench, "interleaved", rounds)
    rows, m, why = bench.batched_rows(["mujoco:euler", "physx:pgs", "jaxsim:semi_implicit_euler", "mjx:euler",
                                       "drake:semi_explicit_euler"], 50, 10, 3)
    assert [r["variant"] for r in rows] == ["mujoco:euler", "physx:pgs"]
    assert ("own", 50, 10, "pgs") in seen and ("physx:pgs", 50, 10) in seen
    mj, px = rows
    assert mj["engine_body_steps_per_s"] == 4e6 and mj["rbcheck_body_steps_per_s"] == 2e6
    assert mj["ratio"] == pytest.approx(0.475)     # rounds' best 4, 5, 4; ratios 2/4, 2/5, 1.9/4
    assert m["own_batched[mujoco:euler]"]["compile_s"] == 2.0
    assert m["own_batched[physx:pgs]"]["compile_s"] is None
    assert m["adapter_batched[physx:pgs]"]["median"] == 4.9e5 and px["ratio"] == pytest.approx(0.49)
    assert set(why) == {"jaxsim:semi_implicit_euler", "mjx:euler", "drake:semi_explicit_euler"}
    assert "not installed" in why["jaxsim:semi_implicit_euler"] and "refused" in why["mjx:euler"]
    assert "no batched run of drake by itself" in why["drake:semi_explicit_euler"]
    goal = ": simulate_many >= 0.5x the engine's own batched throughput"
    assert bench.overhead_targets([], rows, mj_step_loop_us=1.0) == {"mujoco:euler" + goal: False,
                                                                    "physx:pgs" + goal: False}
    rows[1]["ratio"] = 0.5
    assert bench.overhead_targets([], rows, mj_step_loop_us=1.0)["physx:pgs" + goal]


def test_pybullets_row_has_a_quarter_of_the_steps_on_both_sides(monkeypatch):
    seen = []
    monkeypatch.setattr(bench, "OWN_BATCHED", {"pybullet": lambda n, s, v: seen.append(("own", s))
                                               or bench.Runner(lambda: None, n * s)})
    monkeypatch.setattr(bench, "adapter_runner",
                        lambda v, n, s: seen.append(("rbcheck", s)) or bench.Runner(lambda: None, n * s))
    rows, _, _ = bench.batched_rows(["pybullet:multibody"], 20, 100, 2)
    assert seen == [("own", 25), ("rbcheck", 25)] and rows[0]["ratio"] > 0


def test_the_table_prints_each_batched_row_with_what_the_engines_own_run_is():
    t = _table_input()
    t["measurements"]["own_batched[mjx:euler]"] = {"median": 4e5, "min": 4e5, "max": 4e5, "repeats": 1,
                                                   "compile_s": 12.5}
    t["batched"] = [{"variant": "mjx:euler", "engine_body_steps_per_s": 4e5, "rbcheck_body_steps_per_s": 1e5}]
    t["own_batched_not_measured"] = {"dart:semi_implicit_euler": "no own run"}
    text = bench.format_table(t)
    assert "N vmapped, one compiled fori_loop (compiled in 12.5 s, not counted)" in text
    assert "0.25" in text and "dart:semi_implicit_euler: the engine's own batched run not measured" in text


#: The engines whose own run compiles (JAX) or loads kernels (Warp) first: tens of seconds each.
COMPILED = ("mjx", "brax", "jaxsim", "mujoco_warp")


def _installed(engine):
    from cross_checks.engines import all_variants
    return any(v.engine == engine and v.available for v in all_variants())


@pytest.mark.parametrize("engine", [pytest.param(e, marks=pytest.mark.slow) if e in COMPILED else e
                                    for e in bench.OWN_BATCHED])
def test_each_engines_own_batched_run_steps_a_few_bodies(engine):
    """Every own-throughput function runs for a tiny N on every installed engine (skipped when absent; the
    JAX and Warp ones, which compile or load kernels for tens of seconds, are slow) and gives runners of
    the documented shape: the body-steps of a call and the compile time apart (None for an engine that
    does not compile), timed alternately with simulate_many's through batched_rows."""
    if not _installed(engine):
        pytest.skip(f"{engine} is not installed")
    from cross_checks.engines import all_variants
    variant = next(v.name for v in all_variants() if v.engine == engine and v.available)
    rows, m, why = bench.batched_rows([variant], 3, 8, 2)
    assert why == {} and [r["variant"] for r in rows] == [variant]
    steps = bench.OWN_STEPS.get(engine, lambda k: k)(8)
    st, rb = m[f"own_batched[{variant}]"], m[f"adapter_batched[{variant}]"]
    assert st["repeats"] == rb["repeats"] == 2 and 0 < st["min"] <= st["median"] <= st["max"]
    assert (st["compile_s"] is None) == (engine in ("mujoco", "pybullet", "physx", "rapier"))
    assert rows[0]["ratio"] > 0
    own = bench.OWN_BATCHED[engine](3, steps, variant.split(":", 1)[1])
    for r in own if isinstance(own, tuple) else (own,):
        assert r.work == 3 * steps
        r.close()
