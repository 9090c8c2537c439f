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
