"""cross_checks.testing.assert_engine through rbcheck's pytest plugin, as a user runs it: the README's
five-line test file, run with pytest in a subprocess beside a correct and a broken build of the
example engine; the plugin's options (kept reports, session cache, engine files)."""
import os
import re
import shutil
import subprocess
import sys

import pytest

from tests.helpers.byo import ROOT, build_cbody, write_scenarios


def readme_test_file() -> str:
    """The user test file shown in README.md, verbatim."""
    text = (ROOT / "README.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    found = [b for b in blocks if "assert_engine(" in b and "def test_" in b]
    assert len(found) == 1, "README.md must show exactly one user test file"
    return found[0]


def _pytest(args, cwd, timeout=300):
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PYTEST_", "RBCHECK_CACHE"))}
    return subprocess.run([sys.executable, "-m", "pytest", "-p", "no:cacheprovider",
                           "--import-mode=importlib", "-q", *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=timeout)


def test_readme_test_file_is_five_lines_and_passes_a_correct_engine_and_fails_a_broken_one(tmp_path):
    code = readme_test_file()
    assert len(code.strip().splitlines()) == 5
    built = build_cbody(tmp_path / "build")
    for which, folder in (("good", tmp_path / "good"), ("broken", tmp_path / "broken")):
        folder.mkdir()
        (folder / "test_cbody.py").write_text(code)
        shutil.copy(built["good"], folder / "cbody.toml")  # the same engine file ...
        prog = "cbody" if built["kind"] == "C" else "cbody.py"
        src = built["good"].parent / (prog if which == "good" or built["kind"] != "C" else "cbody_broken")
        shutil.copy(src, folder / prog)  # ... with the correct build, or the broken one
        if built["kind"] != "C" and which == "broken":
            toml = folder / "cbody.toml"
            toml.write_text(toml.read_text().replace('"cbody.py", ', '"cbody.py", "--broken-gyro", '))
    proc = _pytest(["good", "broken"], cwd=tmp_path)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 1, out
    assert "1 failed, 1 passed" in out, out
    assert "FAILED broken/test_cbody.py::test_cbody_is_first_order" in out
    assert "cbody:euler on applied_torque: orientation does not converge" in out
    assert "expected order 1 — final errors" in out
    # the likely cause from check's catalog of mistakes; the user sees the verdict, not rbcheck's frames
    assert "likely cause (cbody:euler on applied_torque): the gyroscopic term has the wrong sign" in out
    assert "cross_checks/testing.py" not in out and "run_engine_checks" not in out


def test_identical_failures_are_one_complete_sentence_naming_every_run(tmp_path):
    """An engine whose script raises a KeyError on every run: one problem, with the runs it hit and the
    script's own words, no sentence with empty fields (no final errors to quote)."""
    folder = tmp_path / "e"
    folder.mkdir()
    (folder / "eng.py").write_text("import json, sys\n"
                                   "d = json.load(open(sys.argv[1]))\nprint(d['no_such_key'])\n")
    (folder / "eng.toml").write_text('name = "keyerr"\n'
                                     'version = "1"\n'
                                     '[variants.euler]\n'
                                     'order = 1\n'
                                     f'command = ["{sys.executable}", "eng.py", "{{scenario_json}}", '
                                     '"{out_csv}"]\n')
    (folder / "test_mine.py").write_text(
        "from pathlib import Path\nENGINE = Path(__file__).parent / 'eng.toml'\n\n"
        "def test_it(assert_engine):\n    assert_engine('keyerr:euler', ['projectile', 'constant_spin'], "
        "engine_file=ENGINE)\n")
    proc = _pytest(["test_mine.py", "--rbcheck-keep-reports", str(tmp_path / "kept")], cwd=folder)
    out = proc.stdout
    assert proc.returncode == 1 and "1 problem(s):" in out, out[-3000:]
    assert ("keyerr:euler failed on 10 runs (projectile at Δt = 0.02, 0.01, 0.005, 0.0025, 0.00125 s; "
            "constant_spin at Δt = 0.02, 0.01, 0.005, 0.0025, 0.00125 s): "
            "the command exited with status 1") in out
    assert out.count("KeyError: 'no_such_key'") <= 2   # the message once (and pytest's one-line summary)
    assert "final errors  " not in out and "at Δt =  s" not in out
    assert f"results and report kept in {tmp_path / 'kept'}" in out
    assert "cross_checks/testing.py" not in out


PLUGIN_TESTS = '''
def test_first(assert_engine):
    s = assert_engine("cbody:euler", "{scenario}")
    assert s["run"]["cached_runs"] == 0

def test_second_reuses_the_session_cache(assert_engine):
    s = assert_engine("cbody:euler", "{scenario}")
    assert s["run"]["cached_runs"] == s["run"]["runs"] == 4
'''


def _plugin_run(tmp_path, *options):
    built = build_cbody(tmp_path / "build")
    scen = write_scenarios(tmp_path / "scen")["byo_tumble"]
    (tmp_path / "t").mkdir()
    (tmp_path / "t" / "test_plugin.py").write_text(PLUGIN_TESTS.replace("{scenario}", str(scen)))
    return _pytest(["t", "--rbcheck-engine-file", str(built["good"]), *options], cwd=tmp_path)


def test_plugin_registers_engine_files_and_caches_runs_for_the_session(tmp_path):
    proc = _plugin_run(tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "2 passed" in proc.stdout


@pytest.mark.slow
def test_plugin_keeps_each_call_s_results_and_report(tmp_path):
    keep = tmp_path / "kept"
    proc = _plugin_run(tmp_path, "--rbcheck-keep-reports", str(keep), "--rbcheck-jobs", "2")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    kept = sorted(p.relative_to(keep).as_posix() for p in keep.glob("*/*/index.html"))
    assert kept == ["t_test_plugin.py_test_first/1-cbody_euler/index.html",
                    "t_test_plugin.py_test_second_reuses_the_session_cache/1-cbody_euler/index.html"]


def test_assert_engine_rejects_bad_input_with_value_errors(tmp_path):
    from cross_checks.engines.external import EngineFileError
    from cross_checks.testing import assert_engine
    with pytest.raises(ValueError, match="unknown engine 'nosuch'"):
        assert_engine("nosuch:euler", "projectile")
    with pytest.raises(ValueError,
                       match=r"dt_ladder: needs at least two steps to fit an order, got \[0.01\]"):
        p = tmp_path / "one.toml"
        p.write_text('name = "one"\nduration = 1.0\ndt = 0.01\n[body]\nmass = 1.0\n'
                     'inertia = [1.0, 1.0, 1.0]\n[initial]\n')
        assert_engine("reference:course", p)
    with pytest.raises(EngineFileError, match="no such file"):
        assert_engine("x:y", "projectile", engine_file=tmp_path / "missing.toml")
