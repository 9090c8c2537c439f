"""The ranking (reports/ranking.py) reads each variant's measured work-precision curve the way the page
says: log-log interpolation between measured points, bounds outside them, never an extrapolation; the
common cost and accuracy are where the most variants were measured; a variant whose verdicts contradict
its expectations is never named the most accurate without that said. Also: the plain-words glossary,
the sign-continuous quaternions and the accuracy colours told apart in greyscale."""
import csv
import json
import math
import re
import shutil
from pathlib import Path

import pytest

from reports import plots
from reports.data import load_results
from reports.ranking import (
    Curve,
    Point,
    at_cost,
    best_sentences,
    common_level,
    cost_at,
    engine_answer,
    is_engine,
    ranking,
)
from reports.words import GLOSSARY, explain
from tests.helpers.sweeps import built_once
from tests.reports.test_browser import _browser_sweep


def _power_law(p=2.0, c0=1e-3, e0=1e-2, n=5):
    """Error ∝ cost^-p over n halvings of Δt (cost doubles, error falls 2^p)."""
    pts = [Point(0.01 / 2 ** k, c0 * 2 ** k, e0 / 2 ** (p * k)) for k in range(n)]
    return Curve("x:y", "s", 1e-6, pts)


def test_interpolation_is_exact_on_a_power_law_and_extrapolates_only_along_the_measured_slope():
    c = _power_law()
    for cost in (1.3e-3, 3.7e-3, 1.1e-2):                 # inside: a power law is a line in log-log
        v = at_cost(c, cost)
        assert v.bound == "" and v.value == pytest.approx(1e-2 * (cost / 1e-3) ** -2.0, rel=1e-12)
        back = cost_at(c, v.value)
        assert back.bound == "" and back.value == pytest.approx(cost, rel=1e-12)
    above = at_cost(c, 1.0)                                # costlier than its costliest run: a bound
    assert above.bound == "≤" and above.value == c.points[-1].error
    # cheaper than its cheapest run: along the measured slope (exact on a power law), said as such
    below = at_cost(c, 1e-4)
    assert below.bound == "≈" and below.value == pytest.approx(1e-2 * (1e-4 / 1e-3) ** -2.0, rel=1e-12)
    assert "extrapolated along its measured slope" in below.why
    assert cost_at(c, 1.0).bound == "≤" and cost_at(c, 1.0).value == c.points[0].cost
    beyond = cost_at(c, 1e-12)                             # finer than its finest run: the same, reversed
    # (a round-off floor: no slope to follow, the nearest measured value as a bound)
    assert beyond.bound == "≈" and beyond.value == pytest.approx(1e-3 * (1e-12 / 1e-2) ** -0.5, rel=1e-9)
    # an exact scheme's error of 0 (drawn at 1e-300) on its finer run: no slope is read from it (a bound)
    exact = Curve("x:y", "s", 1e-6, [Point(0.01, 1e-3, 1e-12), Point(0.005, 2e-3, 1e-300)])
    assert at_cost(exact, 1e-6).bound == "≥" and at_cost(exact, 1e-6).value == 1e-12
    assert 0 < cost_at(Curve("x:y", "s", 1e-6, [Point(0.01, 1e-3, 1.0), Point(0.005, 2e-3, 0.999)]),
                       1e-290).value < float("inf")
    flat = Curve("x:y", "s", 1e-6, [Point(0.01, 1e-3, 1e-9), Point(0.005, 2e-3, 1e-9)])
    assert cost_at(flat, 1e-12).bound == "≥" and cost_at(flat, 1e-12).value == 2e-3
    assert at_cost(flat, 1e-4).bound == "≥" and at_cost(flat, 1e-4).value == 1e-9


def test_the_common_level_is_inside_the_most_measured_ranges():
    ranges = [(1e-3, 1e-2), (2e-3, 5e-2), (4e-3, 1e-1), (1.0, 10.0)]
    lvl = common_level(ranges)
    assert sum(lo <= lvl <= hi for lo, hi in ranges) == 3
    assert common_level([]) is None


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    return built_once(tmp_path_factory, "browser_report", _browser_sweep) / "res"


def test_a_contradicted_variant_is_not_named_most_accurate_without_saying_so(base, tmp_path):
    # the costs measured in the base sweep are wall times (load-dependent) and its 2-rung stiff spring has
    # contradictions of its own: the copy gets fixed costs (every variant 1 µs a step) and every verdict as
    # expected but one of whichever variant then ranks first
    d = tmp_path / "res"
    shutil.copytree(base, d)
    with (d / "results.csv").open(encoding="utf-8", newline="") as fh:
        rows = list(csv.DictReader(fh))
    for r in rows:
        r["wall_s"] = r["engine_s"] = repr(int(r["steps"]) * 1e-6)
    with (d / "results.csv").open("w", encoding="utf-8", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    s = json.loads((d / "summary.json").read_text())
    for r in s["convergence"]:
        r.update(matches_expectation=True, assessment="as expected")
    (d / "summary.json").write_text(json.dumps(s))
    first, clean = ranking(load_results(d)).best("overall", "acc")
    assert first is clean and len(ranking(load_results(d)).groups["overall"]["standings"]) > 1
    planted_on = next(r["scenario"] for r in s["convergence"] if r["engine"] == first.variant)
    for r in s["convergence"]:      # every verdict as expected but one of the first's
        planted = r["engine"] == first.variant and r["scenario"] == planted_on
        r.update(matches_expectation=not planted, assessment="planted")
    (d / "summary.json").write_text(json.dumps(s))
    rk = ranking(load_results(d))
    now_first, clean = rk.best("overall", "acc")
    assert now_first.variant == first.variant and clean is not None and clean.variant != first.variant
    line = {label: text for label, text, _ in best_sentences(rk, "overall")}["Most accurate at a common cost"]
    assert f"{first.variant} (×1) — but its verdicts contradict the expectations on {planted_on}" in line
    assert f"the first with every verdict as expected: {clean.variant}" in line


def test_every_symbol_is_explained_where_it_first_appears_and_only_there():
    texts = ["a first-order step damps it by e^(−χ) over the run, χ = ω_c²ΔtT/2; near the separatrix "
             "(δ = -1.2e-05)", "again χ and δ and ω_c"]
    out = explain(texts)
    for sym, meaning in GLOSSARY.items():
        joined = " ".join(out)
        if sym not in " ".join(texts):
            continue
        i = joined.index(sym)
        assert meaning in joined[i:i + 60 + len(meaning) + 40], sym      # right after its first use
        assert joined.count(meaning + ")") == 1, sym                     # and only there
    assert out[1] == texts[1]
    assert "e^(−χ) (χ: " in out[0] and "(δ (how close" in out[0]


def test_the_pages_explain_their_symbols(base):
    """The report's own pages: every glossary symbol that a page shows is explained at its first use."""
    for page in Path(base).glob("*.html"):
        text = re.sub(r"<[^>]+>", "", page.read_text(encoding="utf-8"))
        text = text.replace("&#39;", "'")
        for sym in ("χ", "δ", "ω_c", "ω_W"):
            if sym in text:
                assert GLOSSARY[sym] in text, (page.name, sym)


def _lstar(hex_color):
    rgb = [int(hex_color[i:i + 2], 16) / 255 for i in (0, 2, 4)]
    lin = [c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4 for c in rgb]
    y = 0.2126 * lin[0] + 0.7152 * lin[1] + 0.0722 * lin[2]
    return 116 * y ** (1 / 3) - 16 if y > 0.008856 else 903.3 * y


def test_the_three_accuracy_greens_are_told_apart_in_greyscale():
    """CIE L* (lightness, what is left in greyscale) of the three accuracy tiers at least 8 apart: a
    difference of about 2.3 is just noticeable side by side, 8 is seen at a glance across a table."""
    css = (Path(plots.__file__).parent / "templates" / "style.css").read_text()
    l_star = {k: _lstar(re.search(rf"\.{k} {{ background: #([0-9a-f]{{6}})", css)[1])
              for k in ("acc1", "acc2", "acc3")}
    assert l_star["acc1"] + 8 <= l_star["acc2"] and l_star["acc2"] + 8 <= l_star["acc3"], l_star
    assert not math.isnan(sum(l_star.values()))


def test_the_sentences_number_places_in_english():
    from reports.ranking import ordinal as _ordinal
    from reports.ranking import ratio_text
    assert [_ordinal(n) for n in (1, 2, 3, 4, 11, 12, 13, 21, 22, 23, 111)] == \
        ["1st", "2nd", "3rd", "4th", "11th", "12th", "13th", "21st", "22nd", "23rd", "111th"]
    assert [ratio_text(x) for x in (1.0, 1.34, 12.3, 160.0, 1234.0, 5.2e8)] == \
        ["×1", "×1.3", "×12", "×160", "×1200", "×5.2e8"]


def test_which_engine_is_answered_among_engines_and_every_engine_variant_is_ranked(base):
    """The ranking page's first answer names engines only (the reference's schemes are rbcheck's), and every
    engine variant whose verdicts are as expected on half its scenarios gets an accuracy rank, even where its
    curve does not reach the common cost (its measured slope, or its nearest measured value, stands in)."""
    res = load_results(base)
    answer = engine_answer(res)
    engines_swept = [v for v in res.variants if is_engine(v)]
    assert engines_swept and answer["overall"]
    named = " ".join(text for _, text in answer["overall"])
    assert any(v in named for v in engines_swept) and "reference:" not in named
    for s in answer["ranking"].groups["overall"]["standings"]:
        if s.n_scenarios - len(s.contradicts_on) >= 0.5 * s.n_scenarios:
            assert s.acc_rank is not None, s.variant
    page = (base / "ranking.html").read_text(encoding="utf-8")
    assert page.index("Which engine?") < page.index("Which variant, the reference's schemes included?")
