"""The report at forty variants (issue #32): every figure keeps its legends and titles inside the figure,
apart from each other and from the panels (measured on the figure's artists, not by eye); each variant
keeps one colour, dash pattern and marker in every figure; the pages fit 1024 px; the ranking table sorts
and the first screen names the most accurate and the cheapest variants.

The forty variants are synthetic: the browser tests' real sweep (four variants on three scenarios), each
variant copied under engine names of twelve families with its wall times scaled (so that the costs
differ). The layout needs forty names, not forty engines.
"""
import csv
import json
import math
import shutil

import numpy as np
import pytest
from matplotlib.transforms import Bbox

import reports
from reports import canvas, plots
from reports.data import load_results
from tests.helpers.sweeps import built_once
from tests.reports.test_browser import _browser_sweep, _click, _column, _url, browser  # noqa: F401

#: Twelve families, forty variants (the default sweep's engines and those coming), long names included.
FAMILIES = {"reference": 8, "mujoco": 5, "pybullet": 2, "drake": 4, "dart": 1, "jaxsim": 3, "brax": 3,
            "mjx": 3, "rapier": 3, "physx": 2, "mujoco_warp": 3, "newton": 3}
SOURCES = ["reference:course", "reference:rk4", "reference:explicit_euler", "mujoco:euler"]


def forty_names():
    names = []
    for fam, n in FAMILIES.items():
        names += [f"{fam}:{'semi_implicit_euler_with_gyroscopic' if i == 0 else 'variant'}_{i}"
                  for i in range(n)]
    assert len(names) == 40
    return names


def _synthesize(src, dst):
    """``dst``: ``src`` with every variant replaced by forty, each a copy of a source variant with its
    wall and engine times multiplied by a factor of its own (the ranking then has forty distinct costs)."""
    shutil.copytree(src, dst)
    names = forty_names()
    of = {n: SOURCES[i % len(SOURCES)] for i, n in enumerate(names)}
    factor = {n: 1.3 ** i for i, n in enumerate(names)}
    with (src / "results.csv").open(newline="") as fh:
        reader = csv.DictReader(fh)
        fields, rows = reader.fieldnames, list(reader)
    out = []
    for n in names:
        for r in rows:
            if r["engine"] == of[n]:
                out.append({**r, "engine": n, "wall_s": repr(float(r["wall_s"]) * factor[n]),
                            "engine_s": repr(float(r["engine_s"] or "nan") * factor[n])})
    with (dst / "results.csv").open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=fields)
        w.writeheader()
        w.writerows(out)
    s = json.loads((src / "summary.json").read_text())
    by_name = {v["name"]: v for v in s["variants"]}
    s["variants"] = [{**by_name[of[n]], "name": n} for n in names]
    for key in ("convergence", "local_convergence"):
        s[key] = [{**r, "engine": n} for n in names for r in s[key] if r["engine"] == of[n]]
    s["agreement"] = []
    (dst / "summary.json").write_text(json.dumps(s))
    for p in (dst / "series").glob("*.npz"):
        with np.load(p) as z:
            data = {k: z[k] for k in z.files}
        new = {k: v for k, v in data.items() if k.startswith("reference::")}
        for n in names:
            new.update({f"{n}::{k.split('::', 1)[1]}": v for k, v in data.items()
                        if k.startswith(of[n] + "::")})
        np.savez(p, **new)
    for p in (dst / "plots").glob("*.png"):
        p.unlink()
    reports.render(dst, jobs=2, progress=False)


@pytest.fixture(scope="module")
def forty(tmp_path_factory):
    base = built_once(tmp_path_factory, "browser_report", _browser_sweep) / "res"
    return built_once(tmp_path_factory, "forty_report", lambda d: _synthesize(base, d / "res")) / "res"


def _drawn(res, sc, kind, folder, monkeypatch):
    kept = {}
    save = canvas.save_png

    def keep(fig, path):
        save(fig, path)
        kept["fig"] = fig
    monkeypatch.setattr(canvas, "save_png", keep)
    folder.mkdir(exist_ok=True)
    name = plots.draw(res, sc, kind, folder)[1]
    monkeypatch.setattr(canvas, "save_png", save)
    return name, kept.get("fig")


def _inside(box):
    """Whether an extent lies inside ``box``, to 1 px (extents are rounded to pixels when drawn)."""
    return lambda e: e.x0 >= box.x0 - 1 and e.y0 >= box.y0 - 1 and e.x1 <= box.x1 + 1 and e.y1 <= box.y1 + 1


def _overlap(a, b, tol=1.0) -> bool:
    return a.x0 < b.x1 - tol and b.x0 < a.x1 - tol and a.y0 < b.y1 - tol and b.y0 < a.y1 - tol


@pytest.mark.parametrize("kind", plots.KINDS)
def test_every_figure_keeps_its_legends_inside_apart_and_off_the_panels(forty, tmp_path, monkeypatch, kind):
    """Measured on the drawn figures: each family's legend (laid out on its own figure and placed as an
    image) lies whole — every text, the title, none over another — inside the figure it is drawn on; the
    placed legends and every text of the figure lie inside the figure (to 1 px: extents are rounded to
    pixels), no two legends overlap, no legend covers a panel shown, and every family drawn has its
    legend."""
    res = load_results(forty)
    made = []
    legend_figure = canvas.legend_figure

    def record(dpi, fam, items):
        fig, leg = legend_figure(dpi, fam, items)
        made.append((fam, [label for label, _ in items], fig, leg))
        return fig, leg
    monkeypatch.setattr(canvas, "legend_figure", record)
    plots.release()
    drawn = 0
    for s in res.scenarios:
        name, fig = _drawn(res, s["name"], kind, tmp_path / s["name"], monkeypatch)
        if name is None:
            continue
        drawn += 1
        r = fig.canvas.get_renderer()
        inside = _inside(fig.bbox)
        legends = [im for im in fig.images if im.get_label()]
        assert legends, (s["name"], kind)
        exts = [Bbox.from_extents(*np.array(im.get_extent())[[0, 2, 1, 3]]) for im in legends]
        for im, e in zip(legends, exts):
            assert inside(e), (s["name"], kind, im.get_label(), e.bounds, fig.bbox.bounds)
        for i, a in enumerate(exts):
            assert not any(_overlap(a, b) for b in exts[i + 1:]), (s["name"], kind, "legends overlap")
            for ax in fig.axes:
                if ax.get_visible():
                    assert not _overlap(a, ax.get_window_extent(r)), (s["name"], kind, "legend on a panel")
        for t in fig.texts:
            assert inside(t.get_window_extent(r)), (s["name"], kind, t.get_text()[:40])
        drawn_families = {ln.get_label() for ln in legends}
        assert len(drawn_families) == len(legends) and len(drawn_families) >= 10, drawn_families
    assert drawn or kind in ("convergence", "local", "work")
    assert made, "no legend drawn"
    names = {tuple(v.split(":", 1)) for v in res.variants}
    for fam, labels, lfig, leg in made:
        lr = lfig.canvas.get_renderer()
        inside = _inside(lfig.bbox)
        assert inside(leg.get_window_extent(lr)), (fam, "legend cut")
        for k, (text, box) in enumerate(leg.texts):
            assert inside(box), (fam, text)
            assert not any(_overlap(box, other) for _, other in leg.texts[k + 1:]), (fam, text, "overlap")
        assert {(fam, label.split("  ")[0]) for label in labels} <= names


def test_each_variant_keeps_one_style_in_every_figure_and_forty_are_told_apart():
    names = forty_names()
    st = canvas.variant_styles(names)
    keys = {(tuple(round(c, 3) for c in st[v]["color"]), st[v]["ls"], st[v]["marker"]) for v in names}
    assert len(keys) == 40                                   # no two variants drawn alike
    assert canvas.variant_styles(list(names)) == st           # the same list: the same styles, every figure
    # a family's variants share its hue; families differ in hue
    import colorsys
    hue = {v: colorsys.rgb_to_hsv(*st[v]["color"])[0] for v in names}
    for fam in FAMILIES:
        hs = [hue[v] for v in names if v.startswith(fam + ":")]
        assert max(hs) - min(hs) < 0.02 or len(hs) == 1, fam


def test_the_lines_of_a_variant_have_its_colour_in_the_work_figure(forty, tmp_path, monkeypatch):
    res = load_results(forty)
    st = canvas.variant_styles(res.variants)
    _, fig = _drawn(res, "spin_only", "work", tmp_path, monkeypatch)
    colours = {tuple(round(c, 3) for c in s["color"]) for s in st.values()}
    # a panel's variants are one artist (canvas.Curves): its parts are each variant's line and markers
    lines = [part for ax in fig.axes if ax.get_visible() for ln in ax.get_lines()
             if isinstance(ln, canvas.Curves) for part in ln.parts if part[0] == "line"]
    assert len(lines) >= 40
    assert all(tuple(round(c, 3) for c in part[3][:3]) in colours for part in lines)


@pytest.mark.parametrize("width", [1024, 1400])
def test_forty_variant_pages_fit_and_load(forty, browser, width):  # noqa: F811
    for page in ("index.html", "ranking.html", "scenario-spin_only.html", "scenario-stiff_spring.html"):
        r = browser.load(_url(forty, page), width=width)
        assert r["errors"] == [] and r["broken"] == [], (page, r)
        assert r["overflow_px"] <= 0, f"{page} is {r['overflow_px']} px wider than {width} px"


def test_first_screen_names_the_most_accurate_and_the_cheapest(forty, browser):  # noqa: F811
    browser.load(_url(forty, "index.html"), width=1024, height=768)
    top, text = browser.evaluate("(() => { const w = document.querySelector('#which');"
                                 " return [w.getBoundingClientRect().bottom, w.innerText]; })()")
    assert top <= 768, "the answer is below the first screen"
    assert "Most accurate at a common cost" in text and "Cheapest at a common accuracy" in text
    # engines first (the reference's schemes are rbcheck's own), then every variant: reference:rk4's copies
    # are the accurate ones among all
    lines = text.splitlines()
    engines_line = next(x for x in lines if x.startswith("Most accurate at a common cost (engines)"))
    every_line = next(x for x in lines if x.startswith("Most accurate at a common cost (every variant)"))
    assert "reference:" not in engines_line and "reference:variant_1" in every_line


def test_the_ranking_table_sorts_by_score_numbers_first(forty, browser):  # noqa: F811
    browser.load(_url(forty, "ranking.html"), width=1024)
    sel = "table.ranking"
    _click(browser, f"{sel} th[data-col='6']")
    col = _column(browser, sel, 6)[0]
    nums = [float(x) for x in col if x not in ("", "–")]
    assert nums == sorted(nums) and len(nums) >= 20
    assert all(x in ("", "–") for x in col[len(nums):])          # unranked last
    _click(browser, f"{sel} th[data-col='6']")
    again = [float(x) for x in _column(browser, sel, 6)[0] if x not in ("", "–")]
    assert again == sorted(nums, reverse=True)
    assert not math.isnan(sum(nums))
