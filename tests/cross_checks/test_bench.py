"""`rbcheck bench`: repeated measurements (median, spread), one N per table, the sweep's floor counted from
the scenarios themselves (no timing is asserted: speed lives in the benchmark's output), and Drake's
single-trajectory cost beside MuJoCo's through the same adapter interface (None when Drake is absent)."""
import math

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
    monkeypatch.setattr(bench, "own_batched", lambda *a, **k: order.append("own") or ({}, {}))
    monkeypatch.setattr(bench, "batching_variants", lambda *a, **k: ["jaxsim:semi_implicit_euler"])
    sweep = {"total_s": stat, "run_s": stat, "floor_s": 1.0}
    monkeypatch.setattr(bench, "sweep_floor", lambda *a, **k: order.append("sweep") or sweep)
    r = bench.run_bench(quick=True, repeats=1)
    assert order[0] == "sweep" and order.count("sweep") == 1 and "adapter" in order and "own" in order
    assert r["sweep"] is sweep and r["targets"]["sweep (run + report) <= 8x its floor"]


def test_the_engines_own_time_is_measured_apart_from_rbchecks_and_both_are_printed():
    """One trajectory through rbcheck: the engine's own time per step (inside its step) and the whole cost
    per step through rbcheck, engine included; the first never exceeds the second, and the table prints
    both and their ratio."""
    rows = bench.overhead_rows(300, 1, variants={"mujoco:euler", "pybullet:multibody"})
    assert {r["variant"] for r in rows} == {"mujoco:euler", "pybullet:multibody"}
    for r in rows:
        assert 0 < r["engine_us_per_step"] <= r["rbcheck_us_per_step"]
    t = _table_input()
    t["overhead"] = rows
    t["batched"] = [{"variant": "mujoco:euler", "engine_body_steps_per_s": 4e6,
                     "rbcheck_body_steps_per_s": 1e6}]
    text = bench.format_table(t)
    assert "mujoco:euler" in text and "through rbcheck" in text
    assert "4.000e+06        1.000e+06    0.25  N bodies in one model" in text


def test_every_cpu_engine_has_its_own_minimal_loop_beside_the_engine_and_rbcheck():
    """Each CPU engine's overhead row has its own minimal loop (apply + step + read in its own API) beside
    its step alone and the cost through rbcheck, every installed one measured (a loop that fails to run
    fails here); the table prints the three and both ratios."""
    from cross_checks.engines import all_variants
    assert set(bench.OWN_LOOP) == set(bench.CPU_ENGINES)
    installed = {v.name for v in all_variants() if v.available and v.engine in bench.CPU_ENGINES}
    defaults = {}
    for v in all_variants():
        if v.name in installed:
            defaults.setdefault(v.engine, v.name)
    rows = bench.overhead_rows(200, 1, variants=set(defaults.values()))
    assert {r["variant"] for r in rows} == set(defaults.values())
    for r in rows:
        assert r["own_loop_us_per_step"] > 0 and 0 < r["engine_us_per_step"] <= r["rbcheck_us_per_step"]
    t = _table_input()
    t["overhead"] = [{"variant": "pybullet:multibody", "engine_us_per_step": 1.0, "own_loop_us_per_step": 2.5,
                      "rbcheck_us_per_step": 4.0}]
    text = bench.format_table(t)
    assert "own loop" in text and "vs own loop" in text
    assert "pybullet:multibody                               1.00      2.50             4.00   4.00x" in text
    assert text.split("pybullet:multibody", 1)[1].split("\n")[0].endswith("1.60x")


def test_the_overhead_targets_are_read_from_the_rows_as_the_issue_words_them():
    """Hand-made rows: a CPU engine at 1.9x / 2.1x its own time, a compiled engine (no single-run target), a
    batched row at 0.49x / 0.5x, and MuJoCo's own step against 3x a Python loop of mj_step."""
    overhead = [{"variant": "mujoco:euler", "engine_us_per_step": 1.0, "rbcheck_us_per_step": 1.9},
                {"variant": "pybullet:multibody", "engine_us_per_step": 4.0, "rbcheck_us_per_step": 8.4},
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
        "mujoco:euler: through rbcheck <= 2x the engine's own per step": True,
        "mujoco:euler: engine_s per step <= 3x a Python loop of mj_step": True,
        "pybullet:multibody: through rbcheck <= 2x the engine's own per step": False,
        "mujoco:euler: simulate_many >= 0.5x the engine's own batched throughput": True,
        "pybullet:multibody: simulate_many >= 0.5x the engine's own batched throughput": False}
    assert not bench.overhead_targets(overhead[:1], [], mj_step_loop_us=0.33)[
        "mujoco:euler: engine_s per step <= 3x a Python loop of mj_step"]


def test_every_engine_with_an_own_batched_run_gets_a_batched_row(monkeypatch):
    """The engines' own batched throughputs (hand-made, as own_batched returns them) become one ``batched``
    row each beside simulate_many's at the same N, and the targets read every row (no time asserted: the
    adapter's rate is stubbed)."""
    stat = {"median": 3e5, "min": 2e5, "max": 4e5, "repeats": 1}
    seen = []
    monkeypatch.setattr(bench, "adapter_batched", lambda v, n, s, r: seen.append((v, n, s)) or stat)
    own = {"mujoco:euler": 4e6, "physx:tgs": 1e6, "rapier:symplectic_euler": 5e5, "mjx:euler": 4e5,
           "brax:generalized": 2e5, "jaxsim:semi_implicit_euler": 1e5, "mujoco_warp:euler": 7e5}
    rows = bench.batched_rows(50, 10, 1, own)
    assert [r["variant"] for r in rows] == list(own) and all(n == 50 and s == 10 for _, n, s in seen)
    assert all(set(r) == {"variant", "engine_body_steps_per_s", "rbcheck_body_steps_per_s"} for r in rows)
    t = bench.overhead_targets([], rows, mj_step_loop_us=1.0)
    goal = ": simulate_many >= 0.5x the engine's own batched throughput"
    assert t == {v + goal: 3e5 >= 0.5 * e for v, e in own.items()}
    assert [v for v in own if t[v + goal]] == ["rapier:symplectic_euler", "mjx:euler", "brax:generalized",
                                               "jaxsim:semi_implicit_euler"]


def test_an_engine_that_cannot_run_its_own_batch_is_skipped_and_says_why(monkeypatch):
    """Not installed (EngineNotInstalled), its model refused (EngineError) or no own run here (Drake, DART):
    no row, a reason each; the others are measured."""
    from cross_checks.engines.base import EngineError
    from cross_checks.engines.install import EngineNotInstalled

    def absent(*a):
        raise EngineNotInstalled("jaxsim is not installed (pip install 'rbcheck[jaxsim]')")

    def refused(*a):
        raise EngineError("MJX refused the model")
    stat = {"median": 1.0, "min": 1.0, "max": 1.0, "repeats": 1, "compile_s": None}
    calls = []
    monkeypatch.setattr(bench, "OWN_BATCHED", {"jaxsim": absent, "mjx": refused,
                                               "physx": lambda *a: calls.append(a) or stat})
    measured, why = bench.own_batched(["jaxsim:semi_implicit_euler", "mjx:euler", "physx:pgs",
                                       "drake:semi_explicit_euler"], 7, 3, 2)
    assert measured == {"physx:pgs": stat} and calls == [(7, 3, 2, "pgs")]
    assert "not installed" in why["jaxsim:semi_implicit_euler"] and "refused" in why["mjx:euler"]
    assert "no batched run of drake by itself" in why["drake:semi_explicit_euler"]


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
    JAX and Warp ones, which compile or load kernels for tens of seconds, are slow) and returns the
    documented shape: rates over the repeats and the compile time apart (None for an engine that does not
    compile)."""
    if not _installed(engine):
        pytest.skip(f"{engine} is not installed")
    st = bench.OWN_BATCHED[engine](3, 4, 2)
    assert set(st) == {"median", "min", "max", "repeats", "compile_s"} and st["repeats"] == 2
    assert 0 < st["min"] <= st["median"] <= st["max"]
    assert (st["compile_s"] is None) == (engine in ("physx", "rapier"))
