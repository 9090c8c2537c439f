"""The invariance checks of a sweep (cross_checks.sweep.invariance, docs/invariance.md) on the zoo of planted
engine files (tests/helpers/zoo_engine.py): a correct engine passes every transform, one that uses only the
diagonal of the inertia tensor and one that keeps positions in float32 while it declares float64 are caught
— through check_invariance, `rbcheck sweep --invariance` (invariance.csv, summary.json, exit 1), `compare` (a
new broken invariance is a regression) and assert_engine(..., invariance=True)."""
import csv
import json
import shutil
import sys

import pytest

from cross_checks.cli import main
from cross_checks.engines import engine_files_registered, resolve
from cross_checks.scenario import parse_scenario
from cross_checks.sweep.invariance import INVARIANCE_COLUMNS, check_invariance
from cross_checks.testing import assert_engine
from tests.helpers.byo import TUMBLE
from tests.helpers.repo import ROOT

ZOO = ROOT / "tests" / "helpers" / "zoo_engine.py"
MODES = ("correct", "diagonal_inertia", "float32_positions", "ignores_com_offset", "drops_welded_child")


def _engine_file(folder):
    lines = ['name = "zoo"', 'version = "1.0"', "timeout = 120",
             'body_forms = ["com_offset", "welded_parts"]']   # it reads body.com and body.parts
    for mode in MODES:
        lines += ["", f"[variants.{mode}]", "order = 1", f'description = "cbody.py\'s scheme, {mode}"',
                  f'command = ["{sys.executable}", "{ZOO}", "{mode}", "{{scenario_json}}", "{{out_csv}}"]']
    p = folder / "zoo.toml"
    p.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return p


@pytest.fixture(scope="module")
def zoo(tmp_path_factory):
    folder = tmp_path_factory.mktemp("zoo")
    scenario = folder / "byo_tumble.toml"
    scenario.write_text(TUMBLE, encoding="utf-8")
    return _engine_file(folder), scenario


@pytest.fixture(scope="module")
def zoo_rows(zoo):
    engine_file, scenario = zoo
    sc = parse_scenario(TUMBLE, str(scenario))
    with engine_files_registered([engine_file]):
        return {mode: {(r["transform"], r["magnitude"]): r
                       for r in check_invariance(sc, resolve(f"zoo:{mode}"))} for mode in MODES}


def test_the_correct_engine_file_passes_every_transform(zoo_rows):
    rows = zoo_rows["correct"]
    assert len(rows) == 9
    for (kind, mag), r in rows.items():
        allowed = ("holds", "precision loss") if kind == "translation" else ("holds",)
        assert r["verdict"] in allowed, (kind, mag, r["assessment"])
        assert r["worst_ratio"] <= 1.0


def test_the_diagonal_only_inertia_is_caught_by_the_body_frame_alone(zoo_rows):
    # (the welded split's composite is the original's diagonal tensor again: it holds there)
    rows = zoo_rows["diagonal_inertia"]
    broken = {k for k, r in rows.items() if r["verdict"] == "broken"}
    assert broken == {("body_frame", "41 deg")}, {k: r["assessment"] for k, r in rows.items()}
    r = rows[("body_frame", "41 deg")]
    assert r["worst_ratio"] > 1e6, r["assessment"]
    assert r["worst_quantity"] in ("orientation", "angular_velocity"), r["assessment"]


def test_float32_positions_declared_float64_are_caught_far_from_the_origin(zoo_rows):
    rows = zoo_rows["float32_positions"]
    far = rows[("translation", "1e+04 m")]
    assert far["verdict"] == "broken" and far["worst_quantity"] == "position", far["assessment"]
    assert far["pos_dev"] > 1e-5                      # float32 at 1e4 m: an ulp of 1 mm, lost every step
    assert far["pos_dev"] > 1e3 * far["pos_allowance"]


def test_an_engine_file_ignoring_the_com_offset_is_caught_by_it_alone(zoo_rows):
    # it takes the body frame origin's initial position (1.5 radii of gyration from the COM) for the COM's
    rows = zoo_rows["ignores_com_offset"]
    broken = {k for k, r in rows.items() if r["verdict"] == "broken"}
    assert broken == {("com_offset", "1.5 gyration radii")}, {k: r["assessment"] for k, r in rows.items()}
    r = rows[("com_offset", "1.5 gyration radii")]
    assert r["worst_ratio"] > 1e6 and "does not vanish as Δt shrinks" in r["assessment"], r["assessment"]


def test_an_engine_file_dropping_the_welded_child_s_inertia_is_caught_by_the_split_alone(zoo_rows):
    rows = zoo_rows["drops_welded_child"]
    broken = {k for k, r in rows.items() if r["verdict"] == "broken"}
    assert broken == {("welded_split", "child 0.75 of the mass")}, \
        {k: r["assessment"] for k, r in rows.items()}
    r = rows[("welded_split", "child 0.75 of the mass")]
    assert r["worst_quantity"] in ("orientation", "angular_velocity"), r["assessment"]
    assert r["worst_ratio"] > 1e6, r["assessment"]


def test_sweep_invariance_end_to_end_then_compare(zoo, tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("RBCHECK_CACHE_DIR", str(tmp_path / "cache"))
    engine_file, scenario = zoo
    out = tmp_path / "res"
    rc = main(["sweep", str(scenario), "--engines", "zoo:correct", "zoo:diagonal_inertia", "--engine-file",
               str(engine_file), "--invariance", "--out", str(out), "--jobs", "1"])
    text = capsys.readouterr()
    assert rc == 1, text.out[-2000:]
    assert "zoo:diagonal_inertia on byo_tumble: invariance under body_frame 41 deg broken" in text.err
    assert text.out.strip().splitlines()[-1].endswith(f"1 broken invariance(s) (see {out / 'index.html'})")
    with open(out / "invariance.csv", encoding="utf-8", newline="") as fh:
        reader = csv.DictReader(fh)
        assert reader.fieldnames == INVARIANCE_COLUMNS
        rows = list(reader)
    assert len(rows) == 18 and {r["engine"] for r in rows} == {"zoo:correct", "zoo:diagonal_inertia"}
    summary = json.loads((out / "summary.json").read_text())
    assert summary["run"]["invariance"]["checks"] == 18 and summary["run"]["invariance"]["broken"] == 1
    assert [r["transform"] for r in summary["invariance"] if r["verdict"] == "broken"] == ["body_frame"]
    from cross_checks.gates import ci
    junit = ci.junit_text(ci.sweep_junit(summary))
    assert "invariance under body_frame 41 deg broken" in junit and 'failures="1"' in junit
    md = ci.sweep_markdown(summary, out)
    assert md.startswith("## rbcheck sweep: ❌ invariance broken") and "1 broken invariance(s)" in md
    page = (out / "index.html").read_text(encoding="utf-8")
    assert "1 broken invariance(s)</a>" in page and 'href="invariance.csv"' in page
    assert "zoo:diagonal_inertia on byo_tumble: under body_frame 41 deg, broken" in page   # a finding

    # compare: the same results are no regression; a baseline where it held makes it a new one (exit 1)
    assert main(["compare", str(out), str(out)]) == 0
    base = tmp_path / "base"
    shutil.copytree(out, base)
    summary["invariance"] = [r for r in summary["invariance"] if r["verdict"] != "broken"]
    (base / "summary.json").write_text(json.dumps(summary), encoding="utf-8")
    capsys.readouterr()
    assert main(["compare", str(base), str(out)]) == 1
    said = capsys.readouterr().out
    assert "invariance under body_frame 41 deg" in said, said[-2000:]
    assert main(["compare", str(out), str(base)]) == 0          # fixed: an improvement
    compact = tmp_path / "compact"                              # a compact baseline keeps the records
    assert main(["baseline", str(out), str(compact)]) == 0
    kept = json.loads((compact / "summary.json").read_text())["invariance"]
    assert [r["transform"] for r in kept if r["verdict"] == "broken"] == ["body_frame"]
    assert main(["compare", str(compact), str(out)]) == 0


def test_without_the_flag_nothing_changes(zoo, tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("RBCHECK_CACHE_DIR", str(tmp_path / "cache"))
    engine_file, scenario = zoo
    out = tmp_path / "res"
    rc = main(["sweep", str(scenario), "--engines", "zoo:diagonal_inertia", "--engine-file", str(engine_file),
               "--out", str(out), "--jobs", "1"])
    assert rc == 0, capsys.readouterr().err[-2000:]
    assert not (out / "invariance.csv").exists()
    assert "invariance" not in json.loads((out / "summary.json").read_text())


def test_assert_engine_with_invariance(zoo, tmp_path, monkeypatch):
    monkeypatch.setenv("RBCHECK_CACHE_DIR", str(tmp_path / "cache"))
    engine_file, scenario = zoo
    assert_engine("zoo:correct", [scenario], engine_file=engine_file, invariance=True)
    assert_engine("zoo:diagonal_inertia", [scenario], engine_file=engine_file)   # its orders are right
    with pytest.raises(AssertionError) as exc:
        assert_engine("zoo:diagonal_inertia", [scenario], engine_file=engine_file, invariance=True)
    assert "invariance under body_frame 41 deg broken" in str(exc.value)


def test_a_refused_transform_is_a_row_naming_the_field(zoo):
    far = parse_scenario(TUMBLE.replace("velocity = [0.3, 0.0, 2.0]",
                                        "position = [999995.0, 0.0, 0.0]\nvelocity = [0.3, 0.0, 2.0]"), "far")
    rows = check_invariance(far, resolve("reference:course_gyro"))
    refused = [r for r in rows if r["verdict"] == "refused"]
    # 10 m along (2, -3, 6)/7 moves x by 2.9 m only: within 1e6 m; 1 km, 10 km and the 100x scale are not
    assert [r["magnitude"] for r in refused] == ["1e+03 m", "1e+04 m", "k=100 mu=100"]
    assert all("initial.position" in r["assessment"] for r in refused)


def test_a_declared_gyroscopic_clamp_makes_the_large_scale_cannot_express():
    """reference:explicit_gyro_clamped clamps |ω × Iω| to 100 N m (Bullet's m_maxGyroscopicForce): scaled by
    μk² = 1e6, tennis_racket's 4.6 N m is 4.6e6 N m: it moves otherwise by design, said, never broken; the
    small scale stays below the clamp and holds."""
    from cross_checks.scenario import load_scenario
    rows = {r["magnitude"]: r for r in check_invariance(load_scenario("tennis_racket"),
                                                         resolve("reference:explicit_gyro_clamped"))
            if r["transform"] == "scale"}
    assert rows["k=100 mu=100"]["verdict"] == "cannot express"
    assert "clamps the gyroscopic torque to 100 N m" in rows["k=100 mu=100"]["assessment"]
    assert rows["k=0.01 mu=0.01"]["verdict"] == "holds"


def test_the_pytest_fixture_takes_invariance(assert_engine, zoo):
    """The plugin's assert_engine passes ``invariance=True`` through (a user's suite: docs/invariance.md)."""
    engine_file, scenario = zoo
    summary = assert_engine("zoo:correct", [scenario], engine_file=engine_file, invariance=True)
    assert summary["run"]["invariance"]["checks"] == 9 and summary["run"]["invariance"]["broken"] == 0


def test_an_error_of_the_harness_leaves_the_pair_not_judged():
    from cross_checks.sweep.invariance import _run_item
    sc = parse_scenario(TUMBLE, "t.toml")
    rows = _run_item((sc, "nosuchengine:x", None, None, []))
    assert len(rows) == 9 and {r["verdict"] for r in rows} == {"not judged"}
    assert "internal error while checking" in rows[0]["assessment"]


def test_a_splitting_along_a_degenerate_eigenspace_is_step_dependent_not_broken():
    """reference:dlm_splitting splits the kinetic energy along the principal axes eigh returns; a symmetric
    top's two equal moments leave eigh free to return any pair in their plane, and a turned body frame gets
    another pair: the split (rotations about different axes do not commute) parts the runs by its O(Δt²)
    truncation error, not by round-off (measured 7.05e-9, 1.76e-9, 4.41e-10 rad/s at Δt, Δt/2, Δt/4)."""
    from cross_checks.scenario import load_scenario
    from cross_checks.scenario.transforms import default_transforms
    t = [x for x in default_transforms() if x.kind == "body_frame"]
    (r,) = check_invariance(load_scenario("symmetric_top"), resolve("reference:dlm_splitting"), t)
    assert r["verdict"] == "step-dependent", r["assessment"]
    assert "7.05e-09, 1.76e-09, 4.41e-10 rad/s" in r["assessment"], r["assessment"]
    assert "order 2.00 (then within round-off), 2.00" in r["assessment"] and r["worst_ratio"] > 1.0
    # a body whose principal axes are unique (1, 2, 3 kg m²): the same scheme holds to round-off
    (r,) = check_invariance(load_scenario("tennis_racket"), resolve("reference:dlm_splitting"), t)
    assert r["verdict"] == "holds", r["assessment"]


def test_an_adapter_that_does_not_build_a_body_form_says_cannot_express():
    from cross_checks.scenario.transforms import ComOffset, WeldedSplit
    rows = check_invariance(parse_scenario(TUMBLE, "t.toml"), resolve("reference:course_gyro"),
                            [ComOffset(), WeldedSplit()])
    assert [r["verdict"] for r in rows] == ["cannot express"] * 2
    assert "reference cannot express a body whose frame origin is not at its COM" in rows[0]["assessment"]
    assert "reference cannot express a body of welded parts" in rows[1]["assessment"]


# --- declared findings (engines.base.InvarianceFinding; docs/invariance.md "Declared findings") -------------

#: zood's variants: the zoo's scheme (MODE) with what each declares under [[variants.V.invariance_findings]].
DECLARING = {
    # the diagonal-only inertia's body-frame break, declared where it is measured: a known finding
    "declared": ("diagonal_inertia", [("body_frame", "angle_deg = [40.0, 42.0]", "")]),
    # declared, but for another transform and for another range of the same one: still caught
    "declared_elsewhere": ("diagonal_inertia", [("translation", "distance_m = [1e3, 1e4]", ""),
                                                ("body_frame", "angle_deg = [0.0, 10.0]", "")]),
    # declared for the right transform but in position only: its rotation break is beyond it, still caught
    "declared_in_position": ("diagonal_inertia", [("body_frame", "angle_deg = [40.0, 42.0]",
                                                   'quantities = ["position"]')]),
    # a correct scheme that declares the finding: "no longer broken"
    "fixed": ("correct", [("body_frame", "angle_deg = [40.0, 42.0]", "")]),
}
REASON = "the zoo's planted bug: its step reads only the diagonal of the inertia tensor"


@pytest.fixture(scope="module")
def zood(tmp_path_factory):
    folder = tmp_path_factory.mktemp("zood")
    lines = ['name = "zood"', 'version = "1.0"', "timeout = 120"]
    for name, (mode, findings) in DECLARING.items():
        lines += ["", f"[variants.{name}]", "order = 1",
                  f'command = ["{sys.executable}", "{ZOO}", "{mode}", "{{scenario_json}}", "{{out_csv}}"]']
        for kind, within, extra in findings:
            lines += [f"[[variants.{name}.invariance_findings]]", f'transform = "{kind}"',
                      f"within = {{ {within} }}", f'reason = "{REASON}"', extra]
    p = folder / "zood.toml"
    p.write_text("\n".join(lines) + "\n", encoding="utf-8")
    scenario = folder / "byo_tumble.toml"
    scenario.write_text(TUMBLE, encoding="utf-8")
    return p, scenario


@pytest.fixture(scope="module")
def zood_rows(zood):
    from cross_checks.scenario.transforms import default_transforms
    engine_file, scenario = zood
    sc = parse_scenario(TUMBLE, str(scenario))
    t = [x for x in default_transforms() if x.kind in ("body_frame", "translation")]
    with engine_files_registered([engine_file]):
        return {v: {(r["transform"], r["magnitude"]): r
                    for r in check_invariance(sc, resolve(f"zood:{v}"), t)} for v in DECLARING}


def test_a_declared_finding_is_a_known_finding_with_its_number_and_reason(zood_rows):
    r = zood_rows["declared"][("body_frame", "41 deg")]
    assert r["verdict"] == "known finding" and r["declared"] == "known finding", r["assessment"]
    assert REASON in r["assessment"] and "under body_frame at angle_deg 40–42" in r["assessment"]
    assert r["worst_ratio"] > 1e6 and "measured here: largest deviation" in r["assessment"], r["assessment"]
    # the other transforms of the variant are judged as usual
    assert {k: x["verdict"] for k, x in zood_rows["declared"].items() if k[0] == "translation"} == {
        k: x["verdict"] for k, x in zood_rows["fixed"].items() if k[0] == "translation"}


def test_a_declaration_is_narrow_a_different_break_of_the_same_variant_is_caught(zood_rows):
    r = zood_rows["declared_elsewhere"][("body_frame", "41 deg")]
    assert r["verdict"] == "broken" and r["declared"] == "", r["assessment"]      # 41° is outside [0, 10]
    r = zood_rows["declared_in_position"][("body_frame", "41 deg")]
    assert r["verdict"] == "broken" and r["declared"] == "beyond the declaration", r["assessment"]
    assert "beyond its declared finding, which names position only" in r["assessment"]


def test_a_declared_finding_that_does_not_break_is_said_no_longer_broken(zood_rows):
    r = zood_rows["fixed"][("body_frame", "41 deg")]
    assert r["verdict"] == "holds" and r["declared"] == "not broken here", r["assessment"]
    from cross_checks.sweep.invariance import declared_summary, invariance_summary, no_longer_broken_lines
    rows = [x for v in ("fixed", "declared") for x in zood_rows[v].values()]
    said = {d["engine"]: d for d in declared_summary(rows)}
    assert said["zood:fixed"] == {"engine": "zood:fixed", "transform": "body_frame", "checks": 1,
                                  "known_findings": 0, "beyond": 0, "verdict": "no longer broken"}
    assert said["zood:declared"]["verdict"] == "known finding"
    assert invariance_summary(rows)[1]["no longer broken"] == 1
    assert no_longer_broken_lines({"invariance_declared": list(said.values())}) == [
        "zood:fixed: its declared invariance finding under body_frame broke on none of the 1 check(s) it "
        "covers here: no longer broken (the declaration can go)"]


def test_the_entry_points_read_the_same_declarations(zood, zood_rows, tmp_path, monkeypatch, capsys):
    """The sweep (invariance.csv, summary.json, the report, JUnit, exit code), assert_engine(invariance=True)
    and the fuzz's invariance property agree: the declared break is a known finding, not a failure; the
    undeclared one fails each of them."""
    monkeypatch.setenv("RBCHECK_CACHE_DIR", str(tmp_path / "cache"))
    engine_file, scenario = zood
    out = tmp_path / "res"
    rc = main(["sweep", str(scenario), "--engines", "zood:declared", "zood:fixed", "--engine-file",
               str(engine_file), "--invariance", "--out", str(out), "--jobs", "1"])
    text = capsys.readouterr()
    assert rc == 0, text.out[-2000:] + text.err[-2000:]
    assert "1 known finding" in text.out and "1 no longer broken" in text.out, text.out[-2000:]
    assert "zood:fixed: its declared invariance finding under body_frame broke on none" in text.out
    with open(out / "invariance.csv", encoding="utf-8", newline="") as fh:
        rows = {(r["engine"], r["transform"]): r for r in csv.DictReader(fh)}
    known = rows[("zood:declared", "body_frame")]
    assert known["verdict"] == "known finding" and REASON in known["assessment"]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["run"]["invariance"]["known finding"] == 1 and summary["run"]["invariance"]["broken"] == 0
    rec = {r["engine"]: r for r in summary["invariance"] if r["transform"] == "body_frame"}
    assert rec["zood:declared"]["verdict"] == "known finding" and REASON in rec["zood:declared"]["assessment"]
    assert "zood:fixed" not in rec          # it holds: not among the checks that do not hold
    assert {d["engine"]: d["verdict"] for d in summary["invariance_declared"]} == {
        "zood:declared": "known finding", "zood:fixed": "no longer broken"}
    from cross_checks.gates import ci
    junit = ci.junit_text(ci.sweep_junit(summary))
    assert 'failures="0"' in junit and REASON in junit
    md = ci.sweep_markdown(summary, out)
    assert md.startswith("## rbcheck sweep: ✅") and "1 known invariance finding(s)" in md
    assert "1 declared one(s) no longer broken" in md
    page = (out / "index.html").read_text(encoding="utf-8")
    assert "zood:declared on byo_tumble: under body_frame 41 deg, known finding" in page
    # compare: the known finding is no regression against a baseline where it held
    base = tmp_path / "base"
    shutil.copytree(out, base)
    summary["invariance"] = [r for r in summary["invariance"] if r["verdict"] != "known finding"]
    (base / "summary.json").write_text(json.dumps(summary), encoding="utf-8")
    assert main(["compare", str(base), str(out)]) == 0
    page = (out / "index.html").read_text(encoding="utf-8")
    assert "zood:fixed: its declared invariance finding under body_frame broke on none" in page

    summary = assert_engine("zood:declared", [scenario], engine_file=engine_file, invariance=True)
    assert summary["run"]["invariance"]["known finding"] == 1
    with pytest.raises(AssertionError) as exc:
        assert_engine("zood:declared_elsewhere", [scenario], engine_file=engine_file, invariance=True)
    assert "invariance under body_frame 41 deg broken" in str(exc.value)

    import types

    from cross_checks.fuzz import properties
    ctx = types.SimpleNamespace(scenario=parse_scenario(TUMBLE, str(scenario)))
    for variant, violations in (("declared", 0), ("declared_elsewhere", 1), ("declared_in_position", 1)):
        row = zood_rows[variant][("body_frame", "41 deg")]
        out_, tally = properties.invariance(ctx, f"zood:{variant}", row)
        assert len(out_) == violations and tally["invariance"] == [1, 0], (variant, out_)
