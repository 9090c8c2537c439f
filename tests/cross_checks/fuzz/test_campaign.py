"""rbcheck fuzz end to end: planted bugs are found, shrunk and reproduced by rbcheck sweep; correct engines
pass; bad input is one line and exit 2; a campaign is deterministic per seed."""
import json
import os
from pathlib import Path

import pytest

from cross_checks.cli import main
from cross_checks.engines import get_adapter, resolve
from cross_checks.engines.base import EngineAdapter, Variant
from cross_checks.fuzz import campaign
from cross_checks.fuzz.generate import to_toml
from cross_checks.scenario import load_scenario
from tests.helpers.byo import build_cbody
from tests.mutants import MUTANTS

MUT = {m.name: m for m in MUTANTS}


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("RBCHECK_CACHE_DIR", str(tmp_path / "cache"))
    return tmp_path / "cache"


def _sweep(path, variants, out, extra=()):
    return main(["sweep", str(path), "--engines", *variants,
                 "--jobs", "1", "--no-cache", "--out", str(out), *extra])


def _found(mutant, tmp_path, monkeypatch, budget_s, shrink_s):
    monkeypatch.setattr(campaign, "SHRINK_S", shrink_s)
    mutant.apply(monkeypatch)
    s = campaign.run_campaign([mutant.swept], tmp_path / "fz", budget_s=budget_s, seed=0, jobs=1,
                              use_cache=False, log=lambda _: None)
    # found within the search's own budget (``budget_s`` bounds the search: no time is asserted here, the
    # machine's load decides how many cases fit in it)
    assert s["counterexamples"], f"{mutant.name} not found in {s['cases']['judged']} cases"
    return s


def _reproduces(s, mutant, tmp_path, monkeypatch):
    """The first counterexample is a scenario file on which rbcheck sweep exits 1 with the bug, 0 without."""
    cx = s["counterexamples"][0]
    assert cx["confirmed_by_sweep"] and cx["sweep_gated"]
    path = tmp_path / "fz" / cx["file"]
    text = path.read_text()
    assert cx["property"] in text and "reproduce (exit 1): rbcheck sweep" in text
    load_scenario(str(path))   # a valid scenario file as it stands
    assert _sweep(path, [mutant.swept], tmp_path / "sweep_bug") == 1
    monkeypatch.undo()
    monkeypatch.setenv("RBCHECK_CACHE_DIR", str(tmp_path / "cache2"))
    from cross_checks.fuzz.shrink import confirm  # the same sweep's gates, without drawing its report
    assert confirm(load_toml_spec(path), [resolve(v) for v in [resolve(mutant.variant)]]) == []


def load_toml_spec(path):
    import tomllib
    return tomllib.loads(Path(path).read_text())


def test_a_wrong_rk4_stage_weight_is_found_shrunk_and_reproduced(tmp_path, monkeypatch, cache):
    monkeypatch.setattr(campaign, "BATCH", 4)   # a small batch: the default run's time budget
    s = _found(MUT["rk4_wrong_stage_weight"], tmp_path, monkeypatch, budget_s=1.0, shrink_s=4.0)
    cx = s["counterexamples"][0]
    assert cx["shrink_steps"], "the case was not made any smaller"
    assert "expected 4" in cx["sentence"]
    _reproduces(s, MUT["rk4_wrong_stage_weight"], tmp_path, monkeypatch)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["gyroscopic_sign_flipped", "body_torque_in_world_axes",
                                  "rk4_third_stage_from_k1",
                                  "midpoint_stage_at_full_step", "mujoco_world_omega_as_body",
                                  "course_decay_twice", "lever_arms_not_rotated"])
def test_planted_bugs_are_found_within_two_minutes_and_reproduced(name, tmp_path, monkeypatch, cache):
    s = _found(MUT[name], tmp_path, monkeypatch, budget_s=30.0, shrink_s=40.0)
    _reproduces(s, MUT[name], tmp_path, monkeypatch)


@pytest.fixture
def clean_registry():
    """Engine files registered by a test are forgotten after it (the registry is per process)."""
    from cross_checks import engines
    engines.reset_registry()
    yield
    engines.reset_registry()


@pytest.mark.slow
def test_the_broken_c_engine_is_found_through_its_engine_file(tmp_path, cache, capsys, clean_registry):
    eng = build_cbody(tmp_path / "eng")
    out = tmp_path / "fz"
    rc = main(["fuzz", "--engine-file", str(eng["broken"]), "--engines", "cbody_broken:euler",
               "--budget", "60", "--jobs", "2", "--out", str(out)])
    assert rc == 1
    s = json.loads((out / "fuzz.json").read_text())
    cx = s["counterexamples"][0]
    assert cx["confirmed_by_sweep"] and cx["property"] in ("free_running_order", "agreement")
    path = out / cx["file"]
    assert _sweep(path, ["cbody_broken:euler"], tmp_path / "s1", ["--engine-file", str(eng["broken"])]) == 1
    assert _sweep(path, ["cbody:euler"], tmp_path / "s2", ["--engine-file", str(eng["good"])]) == 0


@pytest.mark.slow
def test_the_shipped_engines_raise_no_false_alarm_in_a_short_campaign(tmp_path, cache, clean_registry):
    rc = main(["fuzz", "--budget", "120", "--seed", "3", "--jobs", "2", "--out", str(tmp_path / "fz")])
    s = json.loads((tmp_path / "fz" / "fuzz.json").read_text())
    unexplained = [c for c in s["counterexamples"] if not c["explanation"]]
    assert not unexplained and not s["not_shrunk"], [c["sentence"] for c in unexplained]
    assert rc == (1 if s["counterexamples"] else 0)


def test_the_same_seed_gives_the_same_verdicts_and_the_cache_returns_them(tmp_path, cache, monkeypatch):
    monkeypatch.setattr(campaign, "BATCH", 4)
    item = (5, 1, [resolve("reference:course")], {}, str(cache), True, None)
    first, second = campaign.run_batch(item), campaign.run_batch(item)
    assert not first["cached"] and second["cached"]
    assert first["cases"] == second["cases"]
    again = campaign.run_batch((5, 1, [resolve("reference:course")], {}, None, False, None))   # anew
    assert again["cases"] == first["cases"]


def _maximal_violation(prop="free_running_order"):
    return {"property": prop, "variants": ["pybullet:maximal"], "quantity": "orientation",
            "verdict": "does_not_converge", "sentence": "…"}


def _spec_with_moments(index, moments_kg_m2):
    from cross_checks.fuzz import generate
    spec = generate.draw(4, index).spec(0.01, 8)
    spec["body"] = {"mass": 1.0, "inertia": [[moments_kg_m2[i] if i == j else 0.0 for j in range(3)]
                                              for i in range(3)]}
    return spec


def test_an_unexplained_failure_is_never_listed_under_an_explained_one_of_the_same_variant():
    # I1 I2 I3 = 1e-18 kg³m⁶ is below Bullet's solve33 threshold (2.2e-16: explained), 0.06 is not
    tiny, usual = _spec_with_moments(1, [1e-6, 1e-6, 1e-6]), _spec_with_moments(2, [0.3, 0.4, 0.5])
    results = [{"seed": 4, "cases": [
        {"index": 1, "spec": tiny,
         "violations": [_maximal_violation(), _maximal_violation("one_step_order")]},
        {"index": 2, "spec": usual, "violations": [_maximal_violation()]},
        {"index": 3, "spec": tiny, "violations": [_maximal_violation()]},
        {"index": 4, "spec": usual, "violations": []}]}]
    failures = campaign._failures(results)
    assert set(failures) == {(("pybullet:maximal",), True), (("pybullet:maximal",), False)}
    explained, unexplained = failures[(("pybullet:maximal",), True)], failures[(("pybullet:maximal",), False)]
    assert [h[1] for h in explained["hits"]] == [1, 3] and explained["cases"] == 2
    assert explained["also"] == {"one_step_order": 1}
    assert [h[1] for h in unexplained["hits"]] == [2] and unexplained["cases"] == 1


def test_the_shrinker_keeps_a_failure_explained_or_not_as_it_was_found():
    from types import SimpleNamespace

    from cross_checks.fuzz.shrink import signature
    v = _maximal_violation()
    sig = signature(v)
    outcome = SimpleNamespace(violations=[v])
    tiny, usual = _spec_with_moments(1, [1e-6, 1e-6, 1e-6]), _spec_with_moments(2, [0.3, 0.4, 0.5])
    unexplained_keep, explained_keep = campaign._same_finding(sig, False), campaign._same_finding(sig, True)
    assert unexplained_keep(usual, outcome) and not unexplained_keep(tiny, outcome)
    assert explained_keep(tiny, outcome) and not explained_keep(usual, outcome)
    assert not unexplained_keep(usual, SimpleNamespace(violations=[_maximal_violation("conservation")]))


def test_a_counterexample_file_is_exact_toml(tmp_path):
    from cross_checks.fuzz import generate
    spec = generate.draw(4, 2).spec(0.0123456789, 8)
    path = tmp_path / "c.toml"
    path.write_text(to_toml(spec, header="a header\nsecond line"))
    sc = load_scenario(str(path))
    assert sc.dt_s == 0.0123456789 and sc.name == spec["name"]


@pytest.mark.slow
def test_a_batch_is_the_same_to_the_last_bit_whatever_the_blas_thread_count(tmp_path):
    # A batch runs with one BLAS thread (campaign.compute_batch), so the process's own OpenBLAS setting, which
    # moved the last bits of the stacked DOP853 solves before, changes nothing: the cache key may ignore it.
    import os
    import subprocess
    import sys
    code = ("import json, sys; from cross_checks.fuzz.campaign import compute_batch; "
            "from cross_checks.engines import resolve; "
            "r = compute_batch(2026, 2, [resolve(v) for v in ('reference:rk4', 'reference:course', "
            "'mujoco:euler')]); "
            "r.pop('seconds'); json.dump(r, sys.stdout, sort_keys=True)")
    outs = []
    for threads in ("1", "2"):
        env = {**os.environ, "OPENBLAS_NUM_THREADS": threads, "MPLBACKEND": "Agg"}
        outs.append(subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                                   check=True, cwd=Path(__file__).resolve().parents[3]).stdout)
    assert outs[0] == outs[1] and len(outs[0]) > 1000


class _CrashingEngine(EngineAdapter):
    """A test engine: the reference's course step, except that the process dies (as in a segfault inside an
    engine) on the cases of batch 1."""

    name = "crashing"
    variants = {"course": Variant(1, "the reference's course step; the process dies on batch 1")}

    def version(self):
        return "1"

    def simulate(self, scenario, variant, dt_s, n_steps):
        index = int(scenario.name.rsplit("_", 1)[1])
        if index // campaign.BATCH == 1:
            os._exit(3)
        return get_adapter("reference").simulate(scenario, "course", dt_s, n_steps)


def test_a_batch_whose_worker_dies_is_reported_as_such_and_the_others_are_judged(tmp_path, cache, monkeypatch,
                                                                                  clean_registry):
    from cross_checks import engines
    from reference_sim import compiled
    monkeypatch.setattr(campaign, "BATCH", 2)   # set before the pool forks: the workers inherit it
    engines.register_adapter(_CrashingEngine(), "tests/cross_checks/fuzz/test_campaign.py")
    # the budget counts from before search loads the reference's kernels (a minute where numba compiles
    # them): loaded here first, 0.5 s is ample for the window's two batches to start, and the search stops
    # soon after instead of keeping both workers busy with batches 2, 3, … for 2 s
    compiled.warm()
    results = campaign.search(0, [resolve("crashing:course")], budget_s=0.5, jobs=2,
                              cache_root=str(cache), use_cache=False)
    assert [r["batch"] for r in results][:2] == [0, 1]   # both started at once (a window of 2 workers)
    for r in results:
        if r["batch"] == 1:
            assert r["cases"] == [] and "worker process died running this batch" in r["error"]
        else:
            assert "error" not in r and len(r["cases"]) == 2


def test_batches_run_on_a_given_executor_give_the_verdicts_of_a_local_run(tmp_path, cache, monkeypatch):
    from concurrent.futures import ThreadPoolExecutor
    monkeypatch.setattr(campaign, "BATCH", 3)
    two = [resolve("reference:course"), resolve("mujoco:euler")]
    local = campaign.search(4, two, budget_s=0.0, jobs=1, use_cache=False)
    with ThreadPoolExecutor(max_workers=1) as pool:   # as a Dask client's get_executor() is used
        remote = campaign.search(4, two, budget_s=0.0, jobs=2, executor=pool,
                                 use_cache=False)
    assert [r["batch"] for r in remote] == [0] and remote[0]["cases"] == local[0]["cases"]
