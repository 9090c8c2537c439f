"""What `rbcheck sweep` prints at the end (issue 44): why a run of an engine file failed, in the command's own
words, once per distinct reason and with its likely cause; counts that agree with each other."""
import sys

import pytest

from cross_checks import engines
from cross_checks.cli import main

TINY = """
name = "tiny"
duration = 0.1
dt = 0.01
dt_ladder = [0.02, 0.01]
[body]
mass = 1.0
inertia = [1.0, 2.0, 3.0]
[initial]
velocity = [1.0, 0.0, 0.0]
angular_velocity = [0.0, 0.0, 0.5]
"""

#: A script that fails as python3 does on a script name it cannot find: in its private working directory.
FAILS = r'''
import os, sys
sys.stderr.write(f"python3: can't open file '{os.getcwd()}/simm.py': [Errno 2] No such file or directory\n")
sys.exit(2)
'''


@pytest.fixture(autouse=True)
def _fresh_registry():
    yield
    engines.reset_registry()


def test_a_failed_engine_file_run_is_said_in_the_commands_words_once(tmp_path, capsys, isolated_cache):
    (tmp_path / "student").mkdir()
    (tmp_path / "student" / "launch.py").write_text(FAILS)
    ef = tmp_path / "student" / "student.toml"
    ef.write_text(f'name = "student"\nversion = "1"\n[variants.euler]\norder = 1\n'
                  f'command = ["{sys.executable}", "launch.py", "{{scenario_json}}", "{{out_csv}}"]\n')
    (tmp_path / "tiny.toml").write_text(TINY)
    rc = main(["sweep", str(tmp_path / "tiny.toml"), "--engines", "student", "--engine-file", str(ef),
               "--jobs", "1", "--out", str(tmp_path / "res")])
    err = capsys.readouterr().err
    assert rc == 1
    reason = ("student:euler failed on 2 runs (tiny at Δt = 0.02, 0.01 s): the command exited with status "
              "2 — it said: python3: can't open file '<its working directory>/simm.py': [Errno 2] No such "
              "file or directory")
    assert err.count(reason) == 1, err
    assert "2 run(s) failed, for 1 distinct reason(s):" in err
    assert "likely cause: a file the command names is not where it runs" in err
    assert "/rbcheck-student-" not in err   # no private temporary path


def test_sweep_writes_junit_annotations_and_the_step_summary(tmp_path, capsys, isolated_cache, monkeypatch):
    import xml.etree.ElementTree as ET
    (tmp_path / "student").mkdir()
    (tmp_path / "student" / "launch.py").write_text(FAILS)
    ef = tmp_path / "student" / "student.toml"
    ef.write_text(f'name = "student"\nversion = "1"\n[variants.euler]\norder = 1\n'
                  f'command = ["{sys.executable}", "launch.py", "{{scenario_json}}", "{{out_csv}}"]\n')
    (tmp_path / "tiny.toml").write_text(TINY)
    monkeypatch.setenv("GITHUB_STEP_SUMMARY", str(tmp_path / "summary.md"))
    junit = tmp_path / "sweep.xml"
    rc = main(["sweep", str(tmp_path / "tiny.toml"), "--engines", "student", "reference:rk4", "--engine-file",
               str(ef), "--jobs", "1", "--out", str(tmp_path / "res"), "--junit", str(junit),
               "--github-annotations"])
    out = capsys.readouterr().out
    assert rc == 1
    root = ET.parse(junit).getroot()
    cases = {(tc.get("classname"), tc.get("name")): tc for tc in root.iter("testcase")}
    assert ("rbcheck.reference:rk4", "tiny: orientation") in cases
    runs = cases[("rbcheck.student:euler", "tiny: runs")].find("failure")
    assert runs.get("message").startswith("student:euler failed on 2 runs (tiny at Δt = 0.02, 0.01 s): the "
                                          "command exited with status 2")
    assert f"::error title=rbcheck sweep::{runs.get('message')}" in out.splitlines()
    md = (tmp_path / "summary.md").read_text()
    assert md.startswith("## rbcheck sweep: ❌") and "student:euler failed on 2 runs" in md


def test_a_junit_file_inside_the_results_directory_is_refused_before_any_work(tmp_path, capsys):
    (tmp_path / "tiny.toml").write_text(TINY)
    (tmp_path / "res").mkdir()   # an empty --out is accepted: the sweep replaces it as a whole
    rc = main(["sweep", str(tmp_path / "tiny.toml"), "--engines", "reference:rk4", "--out",
               str(tmp_path / "res"), "--junit", str(tmp_path / "res" / "j.xml")])
    err = capsys.readouterr().err
    assert rc == 2 and "lies inside --out" in err and "rbcheck sweep: error: --junit" in err
