"""The HTML report: parses, every image resolves, user text is escaped, re-rendering is reproducible."""
import base64
import json
import re
from html.parser import HTMLParser
from pathlib import Path

import pytest

import reports
from cross_checks.cli import main
from cross_checks.scenario import parse_scenario
from cross_checks.sweep import run_sweep
from tests.helpers.sweeps import built_once, private_cache

HOSTILE = '<script>alert("pwned")</script> & <b>bold</b>'
SCENARIO = f"""
name = "hostile_spin"
description = '{HOSTILE}'
duration = 0.4
dt = 0.01
dt_ladder = [0.02, 0.01, 0.005]
[body]
mass = 1.0
inertia = [1.0, 2.0, 3.0]
[initial]
velocity = [0.0, 0.0, 2.0]
angular_velocity = [0.3, 2.0, 0.2]
[forces]
gravity = [0.0, 0.0, -9.81]
"""
VOID = {"area", "base", "br", "col", "embed", "hr", "img", "input", "link", "meta", "source", "track", "wbr"}


class StrictParser(HTMLParser):
    """Collects tags, <img src>, <a href> and checks that every non-void element is closed in order."""

    def __init__(self):
        super().__init__(convert_charrefs=True)
        self.stack, self.errors, self.imgs, self.links, self.tags, self.text = [], [], [], [], [], []

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        self.tags.append(tag)
        if tag == "img":
            self.imgs.append(a.get("src"))
            if not a.get("alt"):
                self.errors.append("img without alt")
        if tag == "a" and a.get("href"):
            self.links.append(a["href"])
        if tag not in VOID:
            self.stack.append(tag)

    def handle_endtag(self, tag):
        if not self.stack or self.stack[-1] != tag:
            self.errors.append(f"unexpected </{tag}> (open: {self.stack[-3:]})")
        else:
            self.stack.pop()

    def handle_data(self, data):
        self.text.append(data)


def parse(html):
    p = StrictParser()
    p.feed(html)
    p.close()
    assert not p.errors, p.errors[:5]
    assert p.stack == [], p.stack
    return p


def _hostile_sweep(folder):
    with private_cache(folder / "cache"):
        run_sweep([parse_scenario(SCENARIO, source="hostile.toml")], ["reference:course", "reference:rk4"],
                  folder / "res", jobs=1, finish=lambda d: reports.render(d, jobs=1))


@pytest.fixture(scope="session")
def results(tmp_path_factory):
    """The report of a real sweep, built once per test run (shared by the xdist workers: copy it before
    changing anything)."""
    return built_once(tmp_path_factory, "hostile_report", _hostile_sweep) / "res"


def pages(d):
    return {p.name: p.read_text(encoding="utf-8") for p in sorted(Path(d).glob("*.html"))}


def test_pages_parse_and_every_image_resolves(results):
    ps = pages(results)
    assert set(ps) == {"index.html", "ranking.html", "integrators.html", "scenario-hostile_spin.html"}
    n_img = 0
    for html in ps.values():
        p = parse(html)
        assert p.tags.count("html") == 1 and "title" in p.tags
        for src in p.imgs:
            assert (results / src).is_file(), src
            assert (results / src).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
            n_img += 1
        for href in p.links:
            if href.startswith("#"):                   # an anchor of the page itself
                assert f'id="{href[1:]}"' in html, href
            else:
                assert (results / href).exists(), href
    assert n_img >= 5


def test_scenario_description_is_escaped(results):
    for name, html in pages(results).items():
        # only the sorter, and on a page whose body turns the animation's player and its data (JSON, inert)
        low = html.lower()
        data = low.count('<script type="application/json" id="anim-data">')
        assert "<script>alert" not in low and low.count("<script") == 1 + 2 * data and data <= 1, name
        if data:
            import json
            blob = html.split('<script type="application/json" id="anim-data">')[1].split("</script>")[0]
            assert "</" not in blob and json.loads(blob)["runs"][0]["name"] == "reference"
        assert "<b>bold</b>" not in html
    html = pages(results)["scenario-hostile_spin.html"]
    assert "&lt;script&gt;alert(&#34;pwned&#34;)&lt;/script&gt; &amp; &lt;b&gt;bold&lt;/b&gt;" in html
    assert HOSTILE in "".join(parse(html).text)   # shown to the reader as the literal text


def test_findings_are_sentences_from_the_data(results):
    html = pages(results)["index.html"]
    text = " ".join("".join(parse(html).text).split())
    assert "reference:course does not converge on hostile_spin" in text
    assert "gyroscopic term" in text
    summary = json.loads((results / "summary.json").read_text())
    assert summary["provenance"]["started_at"] in text


def test_the_provenance_shows_every_engine_version_the_results_record(results):
    """Each engine version summary.json records (Drake's included when installed) is on the page."""
    text = " ".join("".join(parse(pages(results)["index.html"]).text).split())
    prov = json.loads((results / "summary.json").read_text())["provenance"]
    for key, label in (("mujoco", "MuJoCo"), ("pybullet", "PyBullet"), ("drake", "Drake")):
        if prov.get(key):
            assert re.search(re.escape(label) + r"\s*" + re.escape(prov[key]), text), key
    for name, e in prov["engines"].items():     # every other engine swept (DART, the JAX engines, ...)
        if name not in ("reference", "mujoco", "pybullet", "drake"):
            assert re.search(re.escape(f"engine {name}") + r"\s*" + re.escape(e["version"]), text), name


def test_the_provenance_names_the_version_of_every_other_engine_swept(tmp_path):
    """An optional engine of rbcheck's own (DART, a JAX engine) shows its version beside the fixed ones."""
    from cross_checks.engines import available_variants
    other = next((v for v in available_variants()
                  if v.split(":")[0] not in ("reference", "mujoco", "pybullet", "drake")), None)
    if other is None:
        pytest.skip("no optional engine besides Drake installed here")
    sc = parse_scenario('name = "p"\nduration = 0.02\ndt = 0.01\ndt_ladder = [0.02, 0.01]\n'
                        '[body]\nmass = 1.0\ninertia = [1.0, 2.0, 3.0]\n[initial]\n'
                        'angular_velocity = [0.0, 1.0, 0.0]\n[forces]\n', "p.toml")
    out = tmp_path / "r"
    run_sweep([sc], [other], out, jobs=1, use_cache=False, progress=False, second_reference=False)
    reports.render(out)
    text = " ".join("".join(parse((out / "index.html").read_text()).text).split())
    engine = other.split(":")[0]
    version = json.loads((out / "summary.json").read_text())["provenance"]["engines"][engine]["version"]
    assert re.search(re.escape(f"engine {engine}") + r"\s*" + re.escape(version), text)


def test_rerendering_from_saved_data_gives_the_same_html(results, tmp_path, capfd):
    import shutil
    again = tmp_path / "again"
    shutil.copytree(results, again)
    reports.render(again, jobs=1)
    assert capfd.readouterr().err == ""      # a library call without a terminal prints no progress
    assert pages(again) == pages(results)
    pngs = [sorted(p.name for p in (d / "plots").glob("*.png")) for d in (results, again)]
    assert pngs[0] == pngs[1]


def test_self_contained_pages_embed_every_image(results, tmp_path):
    import shutil
    d = tmp_path / "copy"
    shutil.copytree(results, d)
    assert main(["report", str(d), "--self-contained", "--jobs", "1"]) == 0
    for html in pages(d).values():
        for src in parse(html).imgs:
            assert src.startswith("data:image/png;base64,")
            assert base64.b64decode(src.split(",", 1)[1])[:4] == b"\x89PNG"
    shutil.rmtree(d / "plots")
    shutil.rmtree(d / "series")   # pages stand alone once rendered
    assert "data:image/png" in (d / "scenario-hostile_spin.html").read_text()


def test_report_on_something_else_exits_2(tmp_path, capsys):
    assert main(["report", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "summary.json" in err and "Traceback" not in err


def test_a_body_at_rest_gets_its_report_with_notes_instead_of_empty_figures(tmp_path):
    """Nothing moves (no force, no velocity): every figure that would weigh an error says so in a note, and
    the report is written (found by rbcheck fuzz: the work-precision figure asked matplotlib for zero
    columns)."""
    sc = parse_scenario('name = "at_rest"\nduration = 0.01\ndt = 0.001\ndt_ladder = [0.002, 0.001]\n'
                        '[body]\nmass = 1.0\ninertia = [1.0, 5.0, 5.0]\n[initial]\n[forces]\n',
                        "at_rest.toml")
    out = tmp_path / "r"
    run_sweep([sc], ["reference:course", "mujoco:euler"], out, jobs=1, use_cache=False, progress=False,
              second_reference=False)
    reports.render(out)
    page = (out / "scenario-at_rest.html").read_text()
    assert "nothing moves" in page and (out / "index.html").is_file()
