"""Bring your own engine, end to end: an engine-file engine (the example in C, examples/c_engine) and an
entry-point engine (a fake installed distribution) each go through run, sweep, report, compare and
assert_engine; their deliberately broken copies (gyroscopic term with the wrong sign) are caught by
each of them, and the correct ones pass."""
import contextlib
import io
import json
import re
import shutil
import subprocess
import sys

import numpy as np
import pytest

from cross_checks import engines
from cross_checks.cli import main
from cross_checks.core.trajectory import Trajectory
from cross_checks.gates.compare import compare_dirs, to_text
from cross_checks.scenario import load_scenario
from cross_checks.sweep import run_sweep
from cross_checks.testing import assert_engine
from tests.helpers.byo import (
    EXAMPLE,
    build_cbody,
    c_compiler,
    compile_cbody,
    make_fake_distribution,
    write_scenarios,
)

GOOD, BROKEN = ("cbody:euler", "fakesim:euler"), ("cbody_broken:euler", "fakesim:broken")


@pytest.fixture(scope="module")
def byo(tmp_path_factory):
    """The example engine built, the fake distribution on sys.path, two scenarios, a private cache."""
    tmp = tmp_path_factory.mktemp("byo")
    site = make_fake_distribution(tmp / "site")
    with pytest.MonkeyPatch.context() as mp:
        mp.syspath_prepend(str(site))
        mp.setenv("RBCHECK_CACHE_DIR", str(tmp / "cache"))
        engines.reset_registry()
        built = build_cbody(tmp / "engine")
        yield {"tmp": tmp, "site": site, **built, **write_scenarios(tmp / "scenarios")}
    engines.reset_registry()


@pytest.fixture(autouse=True)
def _fresh_registry():
    """Engine files registered by one test (e.g. through the CLI) never leak into the next."""
    yield
    engines.reset_registry()


@pytest.fixture(scope="module")
def swept(byo):
    """`rbcheck sweep` of the tumbling scenario with both engines and both broken copies (report included)."""
    out = byo["tmp"] / "results"
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        code = main(["sweep", str(byo["byo_tumble"]), "--engines", *GOOD, *BROKEN,
                     "--engine-file", str(byo["good"]), "--engine-file", str(byo["broken"]),
                     "--out", str(out), "--jobs", "2"])
    engines.reset_registry()
    return {"code": code, "stderr": err.getvalue(), "dir": out,
            "summary": json.loads((out / "summary.json").read_text())}


def test_run_of_each_engine_kind_follows_every_force_of_the_resolved_scenario(byo, tmp_path):
    """The example engine reads the resolved JSON (particles, spring off the COM, body-frame force at a
    point, body torque, drag) and implements reference:expmap_gyro's scheme independently, in C: the
    trajectories agree to round-off; the entry-point engine too."""
    ref = tmp_path / "ref.csv"
    assert main(["run", str(byo["byo_pushed"]), "--engine", "reference:expmap_gyro", "--out", str(ref)]) == 0
    expected = Trajectory.read(ref).y
    for variant, extra in (("cbody:euler", ["--engine-file", str(byo["good"])]), ("fakesim:euler", [])):
        out = tmp_path / f"{variant.split(':')[0]}.csv"
        assert main(["run", str(byo["byo_pushed"]), "--engine", variant, *extra, "--out", str(out)]) == 0
        traj = Trajectory.read(out)
        assert traj.y.shape == expected.shape and traj.meta["status"] == "ok"
        np.testing.assert_allclose(traj.y, expected, rtol=0, atol=1e-12, err_msg=variant)
        assert traj.meta["engine_version"] == ("1.0" if variant.startswith("cbody") else "2.5")


def test_python_twin_of_the_c_engine_computes_the_same_trajectory(byo, tmp_path):
    """The no-compiler fallback (examples/c_engine/cbody.py) is the same algorithm as cbody.c."""
    if byo["kind"] != "C":
        pytest.skip("no C compiler: only the Python twin exists here")
    from cross_checks.scenario.resolved import resolved_json
    sc = load_scenario(byo["byo_pushed"])
    (tmp_path / "s.json").write_text(resolved_json(sc, 0.01))
    c_csv, py_csv = tmp_path / "c.csv", tmp_path / "py.csv"
    subprocess.run([str(byo["good"].parent / "cbody"), str(tmp_path / "s.json"), str(c_csv)], check=True)
    subprocess.run([sys.executable, str(EXAMPLE / "cbody.py"),
                    str(tmp_path / "s.json"), str(py_csv)], check=True)
    a, b = Trajectory.read(c_csv), Trajectory.read(py_csv)
    assert len(a.t_s) == 101
    np.testing.assert_allclose(a.y, b.y, rtol=0, atol=1e-13)


def test_sweep_passes_the_correct_engines_and_exits_1_naming_the_broken_ones(swept):
    assert swept["code"] == 1
    lines = [ln.strip() for ln in swept["stderr"].splitlines()]
    for v in BROKEN:
        # orientation is claimed for any order-1 engine here; angular velocity may be left unclaimed
        # (pre-asymptotic) for an engine whose traits rbcheck does not know (expectations.DEFAULT_TRAITS)
        assert any(ln.startswith(f"{v} on byo_tumble: orientation does not converge")
                   and ln.endswith("expected order 1")
                   for ln in lines), swept["stderr"]
    assert not any(ln.startswith(GOOD) for ln in lines), swept["stderr"]
    recs = {(r["engine"], r["quantity"]): r for r in swept["summary"]["convergence"]}
    for v in GOOD:
        for q in ("position", "orientation", "angular_velocity"):
            r = recs[(v, q)]
            if q == "angular_velocity" and r["expected_verdict"] == "pre_asymptotic":
                continue  # unknown traits: no claim where a first-order scheme could still be pre-asymptotic
            assert r["matches_expectation"] and r["expected_order"] == 1.0, (v, q, r)
            assert r["verdict"] == "converges" and abs(r["order"] - 1.0) < 0.1, (v, q, r["order"])
    for v in BROKEN:  # a plateau: the wrong motion, whatever the step
        assert recs[(v, "orientation")]["verdict"] == "does_not_converge"
        assert min(e for e in recs[(v, "orientation")]["errors"]) > 0.1


def test_summary_records_each_engine_its_version_origin_and_hashes(swept, byo):
    s = swept["summary"]
    variants = {v["name"]: v for v in s["variants"]}
    c = variants["cbody:euler"]
    assert c["version"] == "1.0" and c["declared_order"] == 1.0 and c["one_step"] is False
    assert c["engine_file"] == str(byo["good"].resolve())
    import hashlib
    assert c["engine_file_sha256"] == hashlib.sha256(byo["good"].read_bytes()).hexdigest()
    f = variants["fakesim:euler"]
    assert f["version"] == "2.5" and f["one_step"] is True and "fake-engine" in f["source"]
    assert s["provenance"]["engines"]["cbody"]["engine_file_sha256"] == c["engine_file_sha256"]
    # an entry-point engine has a one-step mode: its local errors shrink one order faster
    local = {(r["engine"], r["quantity"]): r for r in s["local_convergence"]}
    assert ("cbody:euler", "orientation") not in local
    assert local[("fakesim:euler", "orientation")]["matches_expectation"]
    assert abs(local[("fakesim:euler", "orientation")]["order"] - 2.0) < 0.3


def test_report_shows_user_engines_like_built_in_ones(swept):
    index = (swept["dir"] / "index.html").read_text()
    page = (swept["dir"] / "scenario-byo_tumble.html").read_text()
    for v in BROKEN:
        assert f'<li class="bad">{v} on byo_tumble: orientation does not converge' in index
    for v in GOOD:
        assert f'<li class="bad">{v}' not in index
        assert f'<tr><th title="{v}" data-sort="{v}">' in index      # a matrix row, under its family
        # its family
        assert re.search(rf'<tr class="group"><th colspan="\d+">{v.split(":")[0]}</th></tr>', index)
    assert "cbody:euler and cbody_broken:euler have no one-step mode" in index
    assert "<dt>engine cbody</dt>" in index and "SHA-256" in index
    assert 'title="no one-step mode' in page
    assert (swept["dir"] / "plots" / "byo_tumble__convergence.png").is_file()


def test_compare_catches_a_regressed_build_and_passes_an_unchanged_one(swept, byo, monkeypatch):
    """The committed-baseline workflow: the same engine names, rebuilt. An unchanged engine compares clean;
    the C engine rebuilt with the sign bug (same engine file, new program hash: no stale cache) and the
    Python engine with the bug planted are regressions."""
    sc = load_scenario(byo["byo_tumble"])
    same = byo["tmp"] / "same"
    with engines.engine_files_registered([byo["good"]]):
        run_sweep([sc], list(GOOD), same, jobs=2, progress=False)
    ok = compare_dirs(swept["dir"], same)
    assert ok.exit_code(allow_missing=True) == 0, to_text(ok, True)
    assert ok.matched_rows == 8

    rebuilt = byo["tmp"] / "rebuilt"
    shutil.copytree(byo["good"].parent, rebuilt)
    if byo["kind"] == "C":
        compile_cbody(c_compiler(), rebuilt, broken=True)  # ./cbody is now the broken build
    else:
        text = (rebuilt / "cbody.toml").read_text().replace('"cbody.py", ', '"cbody.py", "--broken-gyro", ')
        (rebuilt / "cbody.toml").write_text(text)
    import rbcheck_fake_engine
    monkeypatch.setattr(rbcheck_fake_engine, "GYRO_SIGN", 1.0)  # same file, same version: a cache of its own
    monkeypatch.setenv("RBCHECK_CACHE_DIR", str(byo["tmp"] / "regressed-cache"))
    new = byo["tmp"] / "regressed"
    with engines.engine_files_registered([rebuilt / "cbody.toml"]):
        summary = run_sweep([sc], list(GOOD), new, jobs=2, progress=False)
    assert summary["run"]["failed_runs"] == 0
    c = compare_dirs(swept["dir"], new)
    assert c.exit_code(allow_missing=True) == 1
    (_, old_v, new_v), = [d for d in c.version_diffs if d[0] == "engine cbody"]  # the rebuild is named
    assert (old_v.startswith("1.0 (engine file ")
            and old_v.split("programs ")[1] != new_v.split("programs ")[1])
    regressed = {(ch.engine, ch.what) for ch in c.of("regression")}
    for v in GOOD:
        assert (v, "dt=0.0025 orient_err_final") in regressed, to_text(c, True)
        assert (v, "verdict of orientation") in regressed


def test_a_rebuilt_engine_program_is_never_served_from_the_cache(byo, tmp_path):
    sc = load_scenario(byo["byo_tumble"])
    folder = tmp_path / "engine"
    shutil.copytree(byo["good"].parent, folder)
    with engines.engine_files_registered([folder / "cbody.toml"]):
        first = run_sweep([sc], ["cbody:euler"], tmp_path / "a", jobs=1, progress=False)
        again = run_sweep([sc], ["cbody:euler"], tmp_path / "b", jobs=1, progress=False)
    assert first["run"]["cached_runs"] == 0 < again["run"]["cached_runs"] == again["run"]["runs"]
    prog = folder / ("cbody" if byo["kind"] == "C" else "cbody.py")
    prog.write_bytes(prog.read_bytes() + b"\n")  # same behaviour, new content: a rebuild
    with engines.engine_files_registered([folder / "cbody.toml"]):
        rebuilt = run_sweep([sc], ["cbody:euler"], tmp_path / "c", jobs=1, progress=False)
    assert rebuilt["run"]["cached_runs"] == 0


def test_assert_engine_passes_correct_engines(byo):
    summary = assert_engine("cbody:euler", [byo["byo_tumble"], byo["byo_pushed"]], engine_file=byo["good"])
    assert {r["scenario"] for r in summary["convergence"]} == {"byo_tumble", "byo_pushed"}
    assert assert_engine("fakesim:euler", byo["byo_tumble"])["variants"][0]["version"] == "2.5"
    # the engine file was registered for the call only
    assert "cbody" not in [e.name for e in engines.engine_entries()]


@pytest.mark.parametrize("variant", BROKEN)
def test_assert_engine_raises_with_the_verdict_sentences_for_a_broken_engine(byo, variant):
    with pytest.raises(AssertionError) as info:
        assert_engine(variant, [byo["byo_tumble"]], engine_file=byo["broken"])
    text = str(info.value)
    assert (text.startswith(f"assert_engine('{variant}') on byo_tumble: ")
            and "problem(s)" in text.splitlines()[0])
    assert f"{variant} on byo_tumble: orientation does not converge" in text
    assert "expected order 1 — final errors" in text and "rad at Δt = 0.02, 0.01, 0.005, 0.0025 s" in text


def test_an_installed_entry_point_is_found_by_a_fresh_rbcheck_process(byo, tmp_path):
    import os
    env = dict(os.environ, PYTHONPATH=str(byo["site"]))
    out = tmp_path / "f.csv"
    proc = subprocess.run([sys.executable, "-m", "cross_checks.cli", "run", str(byo["byo_tumble"]),
                           "--engine", "fakesim:euler", "--dt", "0.01", "--out", str(out)], env=env,
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert "fakesim:euler (2.5): 100 steps" in proc.stdout
    assert Trajectory.read(out).meta["engine"] == "fakesim"


def test_check_with_engine_files_identifies_the_user_engine_and_catches_its_broken_copy(
        byo, tmp_path, capsys):
    """`check --engine-file`: the engine's variants are run free at the file's Δt and compared, so a file
    written by the correct engine IS cbody:euler; the broken engine's file fails (gyroscopic sign)."""
    good, bad = tmp_path / "good.csv", tmp_path / "bad.csv"
    common = [str(byo["byo_tumble"]), "--dt", "0.01"]
    assert main(["run", *common, "--engine", "cbody:euler",
                 "--engine-file", str(byo["good"]), "--out", str(good)]) == 0
    assert main(["run", *common, "--engine", "cbody_broken:euler", "--engine-file", str(byo["broken"]),
                 "--out", str(bad)]) == 0
    capsys.readouterr()
    files = ["--engine-file", str(byo["good"]), "--engine-file", str(byo["broken"])]
    assert main(["check", str(good), "--scenario", str(byo["byo_tumble"]),
                 *files, "--json", str(tmp_path / "g.json")]) == 0
    out = capsys.readouterr().out
    assert out.startswith("PASS: ")
    engines_seen = {e["engine"]: e for e in json.loads((tmp_path / "g.json").read_text())["engines"]}
    assert engines_seen["cbody:euler"]["same_to_roundoff"] is True
    assert engines_seen["cbody_broken:euler"]["same_to_roundoff"] is False
    assert main(["check", str(bad), "--scenario", str(byo["byo_tumble"]), *files]) == 1
    assert capsys.readouterr().out.startswith("FAIL: ")
