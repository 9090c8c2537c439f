"""The same simulators through every entry point — `rbcheck check` on a CSV it wrote, the sweep, and
`assert_engine` — get the same, true outcome (issue: one judge).

The simulators are a user's engine known to rbcheck only by its declared order
(tests/helpers/wrong_engines.py): a correct build, and builds with the spring's rest length ignored and
with I and I⁻¹ swapped. On spring_pendulum and symmetric_top the wrong builds' errors stay flat over the
Δt ladder; a first-order engine of unknown traits makes no order claim there (pre-asymptotic), so before
the sweep judged each run on its own recorded states the sweep and assert_engine passed them while
`check` failed them from one file."""
import pytest

from cross_checks import engines
from cross_checks.engines import resolve
from cross_checks.scenario import load_scenario
from tests.helpers.sweeps import gated_variants, private_cache
from tests.helpers.wrong_engines import UserEngine

BUILDS = {"correct": True, "no_rest_length": False, "inverse_inertia": False}


@pytest.fixture
def user_engine():
    engines.reset_registry()
    engines.register_adapter(UserEngine(), "tests/helpers/wrong_engines.py")
    yield
    engines.reset_registry()


#: (scenario, build): each build where its bug acts (symmetric_top has no spring for the rest-length bug)
CASES = [("spring_pendulum", b) for b in BUILDS] + [("symmetric_top", "correct"),
                                                    ("symmetric_top", "inverse_inertia")]


@pytest.fixture(scope="module")
def cases_cache(tmp_path_factory):
    """One private rbcheck cache for the cases below (not the user's: nothing from an earlier test run is
    read). A scenario's references (DOP853 and Drake's second reference: most of a spring_pendulum case's
    time) are computed by its first case and read by the others; runs are keyed by variant, and no two
    cases sweep the same build on the same scenario, so each case's sweep runs its build itself (and its
    assert_engine reads those runs back, as it read them from the user's cache before)."""
    with private_cache(tmp_path_factory.mktemp("cases_cache")) as path:
        yield path


@pytest.mark.parametrize("scenario, build", CASES)
def test_check_sweep_and_assert_engine_agree(user_engine, cases_cache, tmp_path, capsys, scenario, build):
    from cross_checks.cli import main
    from cross_checks.cli.sweep import _gate_failures
    from cross_checks.sweep import run_sweep
    from cross_checks.testing import assert_engine
    variant = f"userengine:{build}"
    sc = load_scenario(scenario)
    correct = BUILDS[build]
    # 1. the sweep
    summary = run_sweep([sc], [variant], tmp_path / "sweep", jobs=1, progress=False)
    assert summary["run"]["cached_runs"] == 0   # the build's own runs, stepped here
    failures = _gate_failures(summary)
    assert (not failures) == correct, failures
    if not correct:
        assert any("no pre-asymptotic excuse" in f and "its own steps are not the scenario's equations" in f
                   for f in failures), failures
    # 2. assert_engine (the same sweep, through the public API)
    if correct:
        assert_engine(variant, [scenario])
    else:
        with pytest.raises(AssertionError, match="its own steps are not the scenario's equations"):
            assert_engine(variant, [scenario])
    # 3. rbcheck check on the engine's own trajectory at the scenario's Δt
    from cross_checks.engines import run_variant
    csv = tmp_path / "run.csv"
    run_variant(sc, variant, sc.dt_s).write(csv)
    capsys.readouterr()
    rc = main(["check", str(csv), "--scenario", scenario])
    out = capsys.readouterr().out
    assert rc == (0 if correct else 1), out[:600]


def test_the_runs_own_defect_separates_every_correct_variant_from_the_wrong_builds(user_engine):
    """Measured on the runs themselves (what the sweep records as step_defect_ratio): every correct variant
    within its allowance at the coarsest and finest Δt of the ladder, the wrong builds far above it, and
    growing as 1/Δt (a wrong equation's O(Δt) defect over an allowance O(Δt²))."""
    from cross_checks.analysis.expectations import traits
    from cross_checks.analysis.flow import run_local_defect
    from cross_checks.engines import available_variants, run_variant
    sc = load_scenario("spring_pendulum")
    coarse, fine = max(sc.dt_ladder_s), min(sc.dt_ladder_s)
    for v in [*gated_variants(), *(v for v in available_variants() if v.startswith("userengine:"))]:
        # the wrong builds, and every step declared without the gyroscopic term (the course, Rapier's option)
        wrong = (v in ("userengine:no_rest_length", "userengine:inverse_inertia")
                 or not traits(resolve(v)).gyroscopic_term)
        r = {dt: run_local_defect(sc, run_variant(sc, v, dt).y, dt, max_rows=64)[0] for dt in (coarse, fine)}
        if wrong:
            assert r[coarse] > 5.0 and r[fine] / r[coarse] > 0.5 * coarse / fine, (v, r)
        else:
            assert max(r.values()) <= 1.0, (v, r)


# --- the four entry points on the example engine file: correct and broken (gyroscopic sign) ---------------

@pytest.fixture(scope="module")
def cbody(tmp_path_factory):
    from tests.helpers.byo import build_cbody, write_scenarios
    folder = tmp_path_factory.mktemp("cbody")
    built = build_cbody(folder / "build")
    return built, write_scenarios(folder / "scen")["byo_tumble"]


@pytest.mark.first   # among the longest tests (tests/conftest.py)
@pytest.mark.parametrize("which", ["good", "broken"])
def test_check_sweep_assert_engine_and_fuzz_agree_on_an_engine_file(cbody, tmp_path, capsys, which,
                                                                    monkeypatch):
    """The same engine file through `rbcheck check` (a CSV of its run), `rbcheck sweep`, `assert_engine` and
    `rbcheck fuzz`: the correct build passes all four, the broken one fails all four."""
    from cross_checks.cli import main
    from cross_checks.fuzz import campaign
    from cross_checks.testing import assert_engine
    # the fuzz's one batch of 16 cases, not 64, and one failure shrunk for at most 1 s, not up to 6 for 60 s
    # each (each case a ladder of the engine file's runs, a process each: most of this test's time): the sign
    # flip of the broken build shows in every case that tumbles, a failure found is exit 1 however far it was
    # shrunk, and what the fuzz's search finds and how it shrinks it is tests/cross_checks/fuzz's to test
    # (test_campaign.py sets these too)
    monkeypatch.setattr(campaign, "BATCH", 16)
    monkeypatch.setattr(campaign, "MAX_SHRUNK", 1)
    monkeypatch.setattr(campaign, "SHRINK_S", 1.0)
    built, scen = cbody
    name = "cbody" if which == "good" else "cbody_broken"
    ef, variant, correct = str(built[which]), f"{name}:euler", which == "good"
    outcomes = {}
    # check: the engine's own run at the scenario's Δt
    assert main(["run", str(scen), "--engine", variant,
                 "--engine-file", ef, "--out", str(tmp_path / "r.csv")]) == 0
    outcomes["check"] = main(["check", str(tmp_path / "r.csv"), "--scenario", str(scen)])
    outcomes["sweep"] = main(["sweep", str(scen), "--engines", variant, "--engine-file", ef, "--jobs", "1",
                              "--no-cache", "--out", str(tmp_path / "sweep")])
    try:
        with private_cache(tmp_path / "cache"):   # not the user's rbcheck cache: nothing read or left
            assert_engine(variant, [scen], engine_file=ef)
        outcomes["assert_engine"] = 0
    except AssertionError:
        outcomes["assert_engine"] = 1
    outcomes["fuzz"] = main(["fuzz", "--engines", variant, "--engine-file", ef, "--budget", "3",
                             "--seed", "0", "--jobs", "1", "--no-cache", "--out", str(tmp_path / "fuzz")])
    engines.reset_registry()   # the engine files main() registered stay out of the next test
    said = capsys.readouterr()
    assert outcomes == {k: (0 if correct else 1) for k in outcomes}, (outcomes, said.out[-4000:])
