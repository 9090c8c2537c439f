"""The integrators page (reports/integrators.py): every variant of the sweep is listed and ranked on work
precision and on long-run conservation; every long-run finding is a sentence on the page; the planted drift
toward the intermediate axis is named and flagged; a sweep without long runs says how to get them."""
import re

import numpy as np
import pytest

import reports
from cross_checks.scenario import parse_scenario
from cross_checks.sweep import run_sweep
from reports.data import load_results
from reports.integrators import conservation_score, integrators_view, long_standings
from tests.helpers.scenarios import TINY, TINY_LONG_RUN
from tests.helpers.sweeps import private_cache
from tests.mutants import long_run_mutants

LONG = parse_scenario(TINY_LONG_RUN)
VARIANTS = ["reference:rk4", "reference:jolt_gyro", "reference:lp_midpoint", "mujoco:euler",
            "planted_keeps:step"]


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    d = tmp_path_factory.mktemp("integrators")
    with pytest.MonkeyPatch.context() as mp, private_cache(d / "cache"):
        long_run_mutants()["planted_keeps"](mp)
        run_sweep([parse_scenario(TINY), LONG], VARIANTS, d / "res", jobs=1,
                  finish=lambda out: reports.render(out, progress=False))
    return d / "res"


def test_the_page_lists_and_ranks_every_variant(results):
    html = (results / "integrators.html").read_text(encoding="utf-8")
    text = re.sub(r"<[^>]+>|&[a-z#0-9]+;", "", html)
    for v in VARIANTS:
        assert text.count(v) >= 3, v          # work-precision table, long-run table, its sentence
    res = load_results(results)
    view = integrators_view(res)
    assert {s.variant for s in view.work} == set(VARIANTS)
    assert [s.variant for s in view.long][:1] == ["reference:lp_midpoint"]   # keeps E and L to round-off
    assert all(v in view.sentences for v in VARIANTS)
    assert 'href="integrators.html"' in (results / "index.html").read_text(encoding="utf-8")


def test_each_finding_is_a_sentence_and_the_planted_drift_is_flagged(results):
    html = (results / "integrators.html").read_text(encoding="utf-8")
    assert ("planted_keeps:step on tiny_long: drifts toward the intermediate axis (energy → L²/2I₂) at rate"
            in html)
    assert "reference:jolt_gyro on tiny_long: drifts toward the intermediate axis" in html
    assert "reference:lp_midpoint on tiny_long: drifts" not in html
    res = load_results(results)
    planted = next(s for s in long_standings(res) if s.variant == "planted_keeps:step")
    assert planted.contradicts == ["tiny_long"]
    sentence = integrators_view(res).sentences["planted_keeps:step"]
    assert "CONTRADICTS what it declares on tiny_long" in sentence


def test_the_figures_are_drawn(results):
    from matplotlib.image import imread
    for name in ("integrators-work-precision.png", "integrators-long-runs.png", "integrators-separatrix.png"):
        img = imread(results / "plots" / name)
        assert img.shape[0] > 200 and img.shape[1] > 1000, name
        assert np.std(img) > 0.05, name         # not blank


def test_the_conservation_score_ranks_a_divergence_last():
    assert conservation_score({"status": "diverged"}) == float("inf")
    assert conservation_score({"status": "ok", "energy_drift_max": 1e-3, "momentum_drift_max": 1e-9,
                               "direction_drift_max_rad": 2e-3}) == 2e-3


def test_without_long_runs_the_page_says_how_to_get_them(tmp_path):
    with private_cache(tmp_path / "cache"):
        run_sweep([parse_scenario(TINY)], ["reference:rk4"], tmp_path / "res", jobs=1,
                  finish=lambda out: reports.render(out, progress=False))
    html = (tmp_path / "res" / "integrators.html").read_text(encoding="utf-8")
    assert "This sweep ran no long run" in html and "rbcheck sweep --long" in html


def _long_rec(engine, scenario, drift, matches, verdict="none", status="ok"):
    return {"engine": engine, "scenario": scenario, "status": status, "energy_drift_max": drift,
            "momentum_drift_max": 1e-15, "direction_drift_max_rad": 1e-15, "matches_expectation": matches,
            "verdict": verdict, "diverged_at_s": None}


def test_green_means_conserves_not_only_as_declared():
    """Issue 44, point 8: buss_augmented keeps |L| as it declares and loses 63 % of its energy: its cell is
    amber (as declared, drifting), never the green of a run that conserves."""
    from reports.integrators import long_cell_class
    assert long_cell_class(_long_rec("reference:buss_augmented", "long_tennis_racket", 0.63, True,
                                     "toward_intermediate")) == "noconv"
    assert long_cell_class(_long_rec("reference:lp_midpoint", "long_tennis_racket", 3e-14, True)) == "acc1"
    assert long_cell_class(_long_rec("x:y", "long_tennis_racket", 3e-14, False)) == "bad"
    assert long_cell_class(_long_rec("x:y", "long_tennis_racket", 0.2, None)) == "noconv"
    assert long_cell_class(_long_rec("x:y", "long_tennis_racket", 0.2, None, status="diverged")) == "diverged"


def test_the_largest_drift_is_the_worst_run_not_a_mean():
    """Issue 44, point 8: a run that lost 63 % of its energy beside two that kept it read 0.015 as a geometric
    mean; the "largest drift" is the largest."""
    from types import SimpleNamespace
    names = ["long_major", "long_minor", "long_tennis_racket"]
    recs = [_long_rec("reference:buss_augmented", n, d, True) for n, d in zip(names, (1e-6, 1e-6, 0.63))]
    res = SimpleNamespace(summary={"long_runs": recs, "long_run_scenarios": [{"name": n} for n in names]},
                          variants=["reference:buss_augmented"])
    [st] = long_standings(res)
    assert st.score == 0.63 and st.worst == "long_tennis_racket"


def test_the_long_runs_polhode_shows_the_drift_toward_the_intermediate_axis(results):
    """The polhode figure's data: a scheme that keeps E and |L| (lp_midpoint) stays on its polhode (|L|²/2E
    constant along its samples); Jolt's step, whose energy drifts toward L²/2I₂, slides across the polhodes
    toward the separatrix (|L|²/2E moves toward I₂ = 2)."""
    from matplotlib.image import imread

    from reports import polhode as P
    img = imread(results / "plots" / "integrators-polhode.png")
    assert img.shape[1] > 400 and np.std(img) > 0.05
    html = (results / "integrators.html").read_text(encoding="utf-8")
    assert 'src="plots/integrators-polhode.png"' in html and "The polhode of each long run" in html
    view = integrators_view(load_results(results))
    shown = [v for v, _ in P.long_run_columns(view)]
    assert shown[0] == "reference:lp_midpoint" and "reference:jolt_gyro" in shown

    def level(v):      # |L|²/2E of each sample, in units of the moments (1, 2, 3)
        L = P.PATHS[(("long", "tiny_long"), v)]
        return np.sum(L ** 2, axis=1) / np.sum(L ** 2 / np.array([1.0, 2.0, 3.0]), axis=1)
    keeps, jolt = level("reference:lp_midpoint"), level("reference:jolt_gyro")
    assert np.ptp(keeps) < 1e-6
    assert abs(jolt[-1] - 2.0) < abs(jolt[0] - 2.0) - 0.01
