"""One judge: the sweep (and assert_engine, which runs it), the fuzz and `rbcheck check`'s ladder mode decide
every convergence verdict with cross_checks.analysis.judge and report exactly what it decided.

Each entry point runs for real while the judge is spied on: every verdict the entry point reports must be
the judge's verdict for that ladder (same verdict, match, sentence), and every ladder it reports must have
been judged. A hypothesis test draws ladders of errors and floors and asserts that the fuzz's property
(a violation exactly where the judge says "does not match") and the judge agree on all of them."""
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import cross_checks.analysis.judge as J
from cross_checks.analysis.expectations import Expectation
from cross_checks.scenario import load_scenario


@pytest.fixture
def spy(monkeypatch):
    """Every judgement made, as (dts, errors, floors, expectation verdict, order) -> Judgement."""
    seen = []
    real = J.judge_ladder

    def judge_ladder(dts, errors, floors, statuses, exp, local=None, quantity=None):
        j = real(dts, errors, floors, statuses, exp, local, quantity)
        seen.append(j)
        return j
    for module in ("cross_checks.sweep.assemble", "cross_checks.fuzz.properties",
                   "cross_checks.gates.check.ladder"):
        monkeypatch.setattr(f"{module}.judge_ladder", judge_ladder)
    return seen


def _key(values) -> tuple:
    return tuple("nan" if v is None or (isinstance(v, float) and math.isnan(v)) else float(v) for v in values)


def test_the_sweep_reports_the_judges_verdicts(spy, tmp_path):
    from cross_checks.sweep import run_sweep
    s = run_sweep([load_scenario("tennis_racket")],
                  ["reference:course", "reference:explicit_euler", "mujoco:rk4"],
                  tmp_path / "r", jobs=1, use_cache=False, progress=False, second_reference=False)
    recs = s["convergence"] + s["local_convergence"]
    assert len(recs) == 24 and len(spy) >= len(recs)
    for r in recs:
        judged = [j for j in spy
                  if _key(j.fit.errors) == _key(r["errors"]) and _key(j.fit.dt_s) == _key(r["dt_s"])]
        assert judged, f"not judged by the judge: {r['engine']} {r['quantity']}"
        assert any((j.verdict, j.matches, j.assessment)
                   == (r["verdict"], r["matches_expectation"], r["assessment"])
                   for j in judged), r
    verdicts = {(r["engine"], r["quantity"]): r["verdict"] for r in s["convergence"]}
    assert verdicts[("reference:course", "orientation")] == "does_not_converge"        # judged, as expected
    assert verdicts[("reference:explicit_euler", "angular_velocity")] == "pre_asymptotic"


def test_assert_engine_fails_exactly_on_the_judges_mismatches(spy):
    from cross_checks.testing import assert_engine
    summary = assert_engine("reference:rk4", ["projectile", "constant_spin"])
    assert spy and all(j.matches is not False for j in spy)
    assert all(r["matches_expectation"] is not False for r in summary["convergence"])


def test_check_ladder_reports_the_judges_verdicts(spy, tmp_path):
    from cross_checks.core.trajectory import Trajectory
    from cross_checks.engines import run_variant
    from cross_checks.gates.check import check_trajectory
    from cross_checks.gates.check.ladder import check_ladder
    sc = load_scenario("projectile")
    results = [check_trajectory(run_variant(sc, "reference:course_gyro", dt), sc, f"f{dt}.csv")
               for dt in (0.02, 0.01)]
    lad = check_ladder(results, sc)
    assert lad["convergence"] and len(spy) == len(lad["convergence"])
    for r, j in zip(lad["convergence"], spy):
        assert ((r["verdict"], r["matches_expectation"], r["assessment"])
                == (j.verdict, j.matches, j.assessment))
    assert isinstance(results[0], object) and Trajectory   # (the files are the engine's own runs)


ORDER = st.sampled_from([1.0, 2.0, 4.0])


@st.composite
def ladders(draw):
    """Three halving rungs (the fuzz's) or five (the sweep's): errors of any order from -1 to 6 with noise,
    floors from none to far above the errors."""
    k = draw(st.sampled_from([3, 5]))
    h0 = draw(st.floats(1e-4, 0.05))
    dts = [h0 / 2 ** i for i in range(k)]
    q = draw(st.floats(-1.0, 6.0))
    c = draw(st.floats(1e-12, 10.0))
    noise = draw(st.lists(st.floats(0.5, 2.0), min_size=k, max_size=k))
    errors = [c * (h / h0) ** q * n for h, n in zip(dts, noise)]
    floor = draw(st.floats(0.0, 1e-6))
    return dts, errors, [floor * (1 + i) for i in range(k)]


@settings(max_examples=300, deadline=None)
@given(ladder=ladders(), order=ORDER,
       kind=st.sampled_from(["converges", "pre_asymptotic", "does_not_converge"]))
def test_the_fuzz_and_the_judge_agree_on_any_ladder(ladder, order, kind):
    from cross_checks.fuzz.properties import _fit_record
    dts, errors, floors = ladder
    exp = Expectation(kind, order if kind == "converges" else None, "drawn")
    j = J.judge_ladder(dts, errors, floors, None, exp)
    rec, claimed = _fit_record(None, "any:variant", "orientation", dts, errors, floors, None, exp,
                               "free_running_order")
    if kind != "converges":   # the fuzz tests order claims only; the judge makes none that can fail here
        assert rec is None and not claimed and j.matches is not False or kind == "does_not_converge"
        return
    assert (rec is not None) == (j.matches is False)
    assert claimed == j.claimed
    if rec is not None:
        assert rec["verdict"] == j.fit.verdict and rec["order"] == j.fit.order
