"""The report in a real browser (headless Chromium through the DevTools protocol, tests/helpers/chromium.py):
every page loads with no console error, no broken image or link, fits 1024 px; tables sort and keep
their headers; the first screen says what is wrong and whether it is expected; scenario pages link the
scenario's TOML, its rows and its series; the plots leave out what carries no information.

Where no Chromium is found the browser tests are skipped with the reason (`.ci/run` installs it). They are
marked `integration`: the README's test command leaves them out, `.ci/run` and CI run them after it
(`pytest -m integration`).
"""
import csv
import io
import json
import shutil
from pathlib import Path

import pytest

import reports
from cross_checks.scenario import parse_scenario
from cross_checks.sweep import run_sweep
from tests.helpers.chromium import Browser
from tests.helpers.scenarios import TINY_LONG_RUN
from tests.helpers.sweeps import built_once, private_cache

# position never moves (only a spin): its panels must be replaced by a note
SPIN = """
name = "spin_only"
description = "Free asymmetric body spinning in place: position constant"
duration = 0.5
dt = 0.01
dt_ladder = [0.04, 0.02, 0.01]
reference = "analytic"
[body]
mass = 1.0
inertia = [1.0, 2.0, 3.0]
[initial]
angular_velocity = [0.3, 2.0, 0.2]
"""
# one Δt only: no convergence, local or work-precision plot
DROP = """
name = "drop_once"
description = "Projectile, one time step only"
duration = 0.5
dt = 0.01
reference = "analytic"
[body]
mass = 1.0
inertia = [1.0, 1.0, 1.0]
[initial]
velocity = [1.0, 0.0, 2.0]
[forces]
gravity = [0.0, 0.0, -9.81]
"""
# omega*dt = 1.5 at every step: explicit Euler grows by sqrt(1 + 1.5^2) per step and diverges (1e8) in
# ~45 of its 50 steps; the symplectic schemes and RK4 (stable below 2.78) do not
STIFF = """
name = "stiff_spring"
description = "Stiff spring (omega = 50 rad/s): explicit Euler diverges at every step of the ladder"
duration = 1.5
dt = 0.03
dt_ladder = [0.03, 0.015]
reference = "analytic"
[body]
mass = 1.0
inertia = [0.05, 0.05, 0.05]
[initial]
position = [0.1, 0.0, 0.0]
[[forces.spring]]
anchor = [0.0, 0.0, 0.0]
attach = [0.0, 0.0, 0.0]
stiffness = 2500.0
rest_length = 0.0
"""
VARIANTS = ["reference:course", "reference:rk4", "reference:explicit_euler", "mujoco:euler"]
PAGES = ["index.html", "ranking.html", "integrators.html", "scenario-spin_only.html",
         "scenario-drop_once.html", "scenario-stiff_spring.html"]


def _browser_sweep(folder):
    src = folder / "scenarios"
    src.mkdir()
    scs = []
    for text in (SPIN, DROP, STIFF):
        name = text.split('"')[1]
        (src / f"{name}.toml").write_text(text, encoding="utf-8")
        scs.append(parse_scenario(text, source=str(src / f"{name}.toml")))
    scs.append(parse_scenario(TINY_LONG_RUN))    # a long run: integrators.html's figures, the polhode's too
    with private_cache(folder / "cache"):
        run_sweep(scs, VARIANTS, folder / "res", jobs=2,
                  finish=lambda d: reports.render(d, jobs=2, progress=False))


@pytest.fixture(scope="session")
def results(tmp_path_factory):
    """A real sweep's report, built once per test run and shared (copy it before changing anything)."""
    return built_once(tmp_path_factory, "browser_report", _browser_sweep) / "res"


@pytest.fixture(scope="module")
def browser():
    if not Browser.find():
        pytest.skip("no Chromium found (chromium, chromium-browser, google-chrome or $RBCHECK_CHROMIUM): "
                    "install the Debian package 'chromium' (.ci/run does) to run the browser tests")
    with Browser() as b:
        yield b


def _url(d, page):
    return (Path(d) / page).resolve().as_uri()


@pytest.mark.integration
@pytest.mark.parametrize("width", [1024, 1400])
def test_every_page_loads_without_console_error_broken_image_or_link_and_fits(results, browser, width):
    for page in PAGES:
        r = browser.load(_url(results, page), width=width)
        assert r["errors"] == [], (page, r["errors"])
        assert r["broken"] == [], (page, r["broken"])
        assert r["overflow_px"] <= 0, f"{page} is {r['overflow_px']} px wider than {width} px"


def _column(browser, table_sel, col):
    return browser.evaluate(f"""[...document.querySelector({json.dumps(table_sel)}).tBodies].map(tb =>
        [...tb.rows].map(r => r.classList.contains('group') ? 'GROUP' :
        (r.cells[{col}].getAttribute('data-sort') ?? r.cells[{col}].textContent.trim())))""")


def _click(browser, selector):
    browser.evaluate(f"document.querySelector({json.dumps(selector)}).click()")


@pytest.mark.integration
def test_headers_sort_rows_both_ways_and_family_headings_stay_on_top(results, browser):
    browser.load(_url(results, "index.html"), width=1024)
    _click(browser, "table.matrix th[data-col='3']")       # stiff_spring: explicit Euler's red/purple first
    first = _column(browser, "table.matrix", 3)
    assert all(tb[0] == "GROUP" for tb in first)
    ref = [float(x) for x in first[0][1:]]
    assert ref == sorted(ref) and len(ref) == 3
    _click(browser, "table.matrix th[data-col='3']")
    again = [float(x) for x in _column(browser, "table.matrix", 3)[0][1:]]
    assert again == sorted(ref, reverse=True)
    browser.load(_url(results, "scenario-spin_only.html"), width=1024)
    _click(browser, "table.runs th[data-col='1']")         # Δt: numbers, not text ("0.04" after "0.01")
    dts = [float(x) for x in _column(browser, "table.runs", 1)[0]]
    assert dts == sorted(dts) and len(set(dts)) == 3


@pytest.mark.integration
def test_table_headers_stay_visible_while_scrolling(results, browser):
    browser.load(_url(results, "scenario-spin_only.html"), width=1024, height=500)
    top = browser.evaluate("""(() => { const t = document.querySelector('table.results');
        window.scrollTo(0, t.getBoundingClientRect().top + window.scrollY + 40);
        return [t.tHead.getBoundingClientRect().top, t.getBoundingClientRect().top]; })()""")
    assert abs(top[0]) < 1.0 and top[1] < -30      # the table scrolled under, its header did not


def _matrix_class(browser, variant, col):
    return browser.evaluate(f"""[...document.querySelectorAll('table.matrix tbody tr')]
        .filter(r => r.cells[0].title === {json.dumps(variant)}).map(r => [r.cells[{col}].className,
                                                                           r.cells[{col}].innerText])""")


@pytest.mark.integration
def test_first_screen_names_the_divergence_and_the_matrix_does_not_paint_it_green(results, browser):
    browser.load(_url(results, "index.html"), width=1024, height=768)
    box = browser.evaluate("(() => { const b = document.querySelector('#verdict').getBoundingClientRect();"
                           " return [b.top, document.querySelector('#verdict').innerText]; })()")
    assert box[0] < 200                                 # the verdict box is the first thing on the page
    assert "reference:explicit_euler: 2 run(s) — stiff_spring" in box[1]
    [(cls, text)] = _matrix_class(browser, "reference:explicit_euler", 3)
    assert cls == "bad" and text.startswith("† t=") and "x†" in text    # diverging where it should converge
    [(cls, text)] = _matrix_class(browser, "reference:rk4", 2)          # drop_once: exact, no ladder
    assert cls == "acc1" and all(m in text for m in "xθvω")            # every quantity's mark, no hovering


@pytest.mark.integration
def test_scenario_pages_link_their_toml_rows_and_series(results, browser):
    for name, text in (("spin_only", SPIN), ("stiff_spring", STIFF)):
        browser.load(_url(results, f"scenario-{name}.html"))
        hrefs = browser.evaluate("[...document.querySelectorAll('p.files "
                                 "a')].map(a => a.getAttribute('href'))")
        assert hrefs == [f"scenarios/{name}.toml", f"rows/{name}.csv", f"series/{name}.npz", "#runs"]
        assert (results / f"scenarios/{name}.toml").read_text(encoding="utf-8") == text
        with (results / "results.csv").open(newline="") as fh:
            want = [r for r in csv.reader(fh) if r[0] in ("scenario", name)]
        assert list(csv.reader(io.StringIO((results / f"rows/{name}.csv").read_text()))) == want
        marker = json.loads((results / ".rbcheck-results.json").read_text())
        assert {f"scenarios/{name}.toml", f"rows/{name}.csv"} <= set(marker["files"])


def test_plots_leave_out_what_carries_no_information(results):
    plots = {p.name for p in (results / "plots").glob("*.png")}
    for kind in ("convergence", "local", "work"):          # one Δt: no ladder, no such plot
        assert f"drop_once__{kind}.png" not in plots
        assert f"spin_only__{kind}.png" in plots
    page = (results / "scenario-drop_once.html").read_text()
    assert "no Δt ladder (one Δt only)" in page
    spin = (results / "scenario-spin_only.html").read_text()
    assert "Not drawn, constant along the reference: x = 0, y = 0, z = 0." in spin


@pytest.mark.integration
def test_planted_contradiction_divergence_and_second_references_reach_the_first_screen(
        results, tmp_path, browser):
    """One re-render of planted records: a contradiction, an expected divergence (its own colour, not
    green), a second reference that disagrees and one that failed."""
    d = tmp_path / "res"
    shutil.copytree(results, d)
    s = json.loads((d / "summary.json").read_text())
    for r in s["convergence"]:
        if r["engine"] == "reference:explicit_euler" and r["scenario"] == "stiff_spring":
            r.update(expected_verdict="diverged", matches_expectation=True,
                     assessment="diverged, as expected")
    rec = next(r for r in s["convergence"] if r["engine"] == "reference:rk4" and r["scenario"] == "spin_only"
               and r["quantity"] == "orientation")
    rec.update(matches_expectation=False, assessment="does not converge (planted), expected order 4")
    s["scenarios"][0]["second_reference"] = {"label": "drake:rk3", "target_accuracy": 1e-10,
                                             "distance": {"position": 0.0, "orientation": 3e-6,
                                                          "velocity": 0.0, "angular_velocity": 2e-6},
                                             "stated_accuracy": {"position": 1e-9, "orientation": 1e-9,
                                                                 "velocity": 1e-9, "angular_velocity": 1e-9},
                                             "agrees": False}
    s["scenarios"][2]["second_reference"] = {"label": "drake:rk3", "target_accuracy": 1e-10, "agrees": None,
                                             "error": "RuntimeError: step size underflow"}
    (d / "summary.json").write_text(json.dumps(s))
    reports.render(d, jobs=1, progress=False)
    browser.load(_url(d, "index.html"), width=1024)
    text = browser.evaluate("document.querySelector('#verdict').innerText")
    assert "reference:rk4 on spin_only: orientation does not converge (planted)" in text
    assert "second reference (drake:rk3) disagrees" in text
    assert "stiff_spring: the second reference (drake:rk3) failed: RuntimeError: step size underflow" in text
    [(cls, _)] = _matrix_class(browser, "reference:rk4", 1)    # spin_only
    assert cls == "bad"
    [(cls, _)] = _matrix_class(browser, "reference:explicit_euler", 3)
    assert cls == "diverged" and "every verdict of these scenarios is still as expected" in text
    browser.load(_url(d, "scenario-spin_only.html"))
    page = browser.evaluate("document.body.innerText")
    assert "disagrees with the reference" in page and "3.0e-6" in page
    # absent (no Drake): the pages say nothing about a second reference
    from reports.data import load_results
    from reports.html import render_pages
    res = load_results(results)
    for sc in res.summary["scenarios"]:
        sc.pop("second_reference", None)
    pages = render_pages(res, {})
    assert not any("second reference" in html.lower() or "2nd ref" in html for html in pages.values())


def test_report_rendering_prints_progress_lines_while_drawing(results, tmp_path, capfd, monkeypatch):
    d = tmp_path / "res"
    shutil.copytree(results, d)
    monkeypatch.setattr(reports, "LINE_INTERVAL_S", 0.0)          # a line after every figure
    reports.render(d, jobs=2, progress=True)
    err = capfd.readouterr().out.splitlines()   # stdout: stderr is for errors only
    assert [line.split(" (")[0] for line in err[:-1]] == [f"rbcheck report: figures {i}/21"
                                                          for i in range(1, 22)]
    assert "left" in err[0] and err[-2].startswith("rbcheck report: figures 21/21 (100%) in ")
    assert err[-1].startswith("rbcheck report: 6 pages and ") and "figures written in" in err[-1]


def test_a_diverged_run_does_not_flatten_the_others(results, tmp_path, monkeypatch):
    """Explicit Euler blows up to 1e8 on stiff_spring; the error axes still span the other runs' errors
    (read from the series file, not from the plot), and its curve ends at its divergence."""
    import numpy as np

    from reports import canvas, plots
    from reports.data import load_results
    drawn = {}
    monkeypatch.setattr(canvas, "save_png", lambda fig, path, **kw: drawn.setdefault("fig", fig))
    res = load_results(results)
    assert plots.draw(res, "stiff_spring", "errors", tmp_path)[1] is not None
    ax = drawn["fig"].axes[0]                                   # position error, reference family
    with np.load(results / "series" / "stiff_spring.npz") as z:
        others = np.concatenate([z[f"{v}::err_position"][1:] for v in ("reference:course", "reference:rk4")])
        blown = z["reference:explicit_euler::err_position"]
    lo, hi = ax.get_ylim()
    assert blown.max() > 1e3 * others.max()                     # the planted blow-up is real
    assert others.max() <= hi <= 10 * others.max() * 1.01 and lo <= others[others > 0].min()
    euler = [ln for ln in ax.get_lines() if ln.get_marker() == "x"]
    assert len(euler) == 1                                      # one divergence mark, on explicit Euler


def _canvas_ink(browser, k):
    """How many pixels of the k-th animation canvas are not white, and a digest of them (to tell frames)."""
    return browser.evaluate(f"""(() => {{ const c = document.querySelectorAll('#anim-panels canvas')[{k}];
        const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data; let n = 0, h = 0;
        for (let i = 0; i < d.length; i += 4) {{ if (d[i] < 250 || d[i + 1] < 250 || d[i + 2] < 250) {{
            n++; h = (h * 31 + i) % 1000000007; }} }}
        return [n, h]; }})()""")


@pytest.mark.integration
@pytest.mark.parametrize("width", [1024, 1400])
def test_a_turning_scenario_shows_its_polhode_and_the_body_moving(results, browser, width):
    """spin_only (a free asymmetric body): the polhode figure is loaded, the animation draws the reference and
    the default variant, plays (frames change), follows the slider, and a ticked variant gets its panel."""
    import time
    r = browser.load(_url(results, "scenario-spin_only.html"), width=width)
    assert r["errors"] == [] and r["broken"] == [] and r["overflow_px"] <= 0
    img = browser.evaluate("""(() => {
        const i = document.querySelector('img[src="plots/spin_only__polhode.png"]');
        return i ? [i.naturalWidth, i.getBoundingClientRect().width] : null; })()""")
    assert img is not None and img[0] > 1000 and 0 < img[1] <= width
    runs = browser.evaluate("[...document.querySelectorAll('#anim-panels canvas')].map(c => c.dataset.run)")
    picked = browser.evaluate("[...document.querySelectorAll('input.anim-pick:checked')].map(c => c.value)")
    assert runs[0] == "reference" and runs[1:] == picked and len(picked) == 1
    ink0 = _canvas_ink(browser, 0)
    assert ink0[0] > 1500                                  # a box is drawn, not an empty canvas
    t0 = browser.evaluate("document.getElementById('anim-slider').value")
    time.sleep(0.6)
    assert browser.evaluate("document.getElementById('anim-slider').value") != t0   # it plays
    assert _canvas_ink(browser, 0) != ink0                 # and the body turns
    browser.evaluate("""(() => { const s = document.getElementById('anim-slider'); s.value = 0;
        s.dispatchEvent(new Event('input')); })()""")
    assert browser.evaluate("document.getElementById('anim-time').textContent") == "t = 0.000 s"
    other = browser.evaluate("""(() => { const c = [...document.querySelectorAll('input.anim-pick')]
        .find(c => !c.checked); c.checked = true; c.dispatchEvent(new Event('change'));
        return c.value; })()""")
    runs = browser.evaluate("[...document.querySelectorAll('#anim-panels canvas')].map(c => c.dataset.run)")
    assert other in runs and len(runs) == 3
    assert _canvas_ink(browser, 2)[0] > 1500


@pytest.mark.integration
def test_a_scenario_that_does_not_turn_has_neither(results, browser):
    browser.load(_url(results, "scenario-drop_once.html"), width=1024)
    assert browser.evaluate("document.getElementById('animation')") is None
    assert not (results / "plots" / "drop_once__polhode.png").exists()


@pytest.mark.integration
def test_the_animation_works_self_contained_without_the_plots_folder(results, tmp_path, browser):
    d = tmp_path / "res"
    shutil.copytree(results, d)
    reports.render(d, self_contained=True, jobs=1, progress=False)
    shutil.rmtree(d / "plots")
    r = browser.load(_url(d, "scenario-spin_only.html"), width=1400)
    assert r["errors"] == [] and r["broken"] == []
    assert browser.evaluate("document.querySelectorAll('img[src^=\"data:image/png\"]').length") >= 5
    assert _canvas_ink(browser, 1)[0] > 1500


@pytest.mark.integration
def test_integrators_page_shows_the_long_runs_polhode(results, browser):
    r = browser.load(_url(results, "integrators.html"), width=1024)
    assert r["errors"] == [] and r["broken"] == [] and r["overflow_px"] <= 0
    got = browser.evaluate("""(() => { const i = document.querySelector('#polhode img');
        return i ? [i.naturalWidth, i.complete, i.getBoundingClientRect().width] : null; })()""")
    assert got is not None and got[0] > 300 and got[1] and got[2] <= 1024
