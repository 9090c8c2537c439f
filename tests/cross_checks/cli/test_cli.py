"""`rbcheck list` and `rbcheck run`: the contract CSV, exit codes, and clear errors without tracebacks."""
import json
import subprocess
import sys

import numpy as np
import pytest

from cross_checks.cli import main
from cross_checks.core.trajectory import COLUMNS, Trajectory

BAD_SCENARIO = """
name = "bad"
duration = 1.0
dt = 0.01
[body]
mass = -2.0
inertia = [1.0, 2.0, 3.0]
[initial]
"""

DIVERGING = """
name = "fast_spin"
description = "tennis racket spun 10x faster at a coarse step: symplectic Euler with explicit gyro blows up"
duration = 20.0
dt = 0.01
[body]
mass = 1.0
inertia = [1.0, 2.0, 3.0]
[initial]
angular_velocity = [0.1, 20.0, 0.1]
"""


def test_run_writes_the_contract_csv_and_sidecar(tmp_path, capsys):
    out = tmp_path / "t.csv"
    assert main(["run", "tennis_racket", "--engine", "reference:course", "--out", str(out)]) == 0
    lines = out.read_text().splitlines()
    assert lines[0] == ",".join(COLUMNS)
    assert len(lines) == 1 + 10001  # t = 0 included, 10 s / 1e-3
    traj = Trajectory.read(out)
    np.testing.assert_allclose(traj.t_s[-1], 10.0)
    np.testing.assert_allclose(np.linalg.norm(traj.q_WB, axis=1), 1.0, atol=1e-15)
    meta = json.loads(out.with_suffix(".json").read_text())
    assert meta["engine"] == "reference" and meta["variant"] == "reference:course"
    assert meta["scenario"] == "tennis_racket" and meta["status"] == "ok" and meta["engine_version"]
    assert "tennis_racket" in capsys.readouterr().out


def test_run_dt_and_duration_override(tmp_path):
    out = tmp_path / "p.csv"
    assert main(["run", "projectile", "--engine", "reference:rk4", "--dt", "0.05", "--duration", "0.5",
                 "--out", str(out)]) == 0
    traj = Trajectory.read(out)
    assert len(traj.t_s) == 11 and traj.meta["dt_s"] == 0.05


@pytest.mark.parametrize("argv, words", [
    (["run", "projectile", "--engine", "reference:nope", "--out", "{tmp}/a.csv"], "unknown variant"),
    (["run", "projectile", "--engine", "nope:x", "--out", "{tmp}/a.csv"], "unknown engine"),
    (["run", "projectile", "--engine", "course", "--out", "{tmp}/a.csv"], "did you mean reference:course?"),
    (["run", "projectile", "--engine", "reference:course", "--out", "{tmp}/missing/a.csv"], "does not exist"),
    (["run", "projectile", "--engine", "reference:course", "--out", "{tmp}/a.txt"], "must end in .csv"),
    (["run", "projectile", "--engine", "reference:course", "--dt", "-1", "--out", "{tmp}/a.csv"], "--dt"),
    (["run", "projectile", "--engine", "reference:course", "--dt", "nan", "--out", "{tmp}/a.csv"], "--dt"),
    (["run", "projectile", "--engine", "reference:course", "--dt", "5", "--out", "{tmp}/a.csv"], "duration"),
    (["run", "no_such_thing", "--engine", "reference:course", "--out", "{tmp}/a.csv"], "no catalog scenario"),
    (["run", "{tmp}/bad.toml", "--engine", "reference:course", "--out", "{tmp}/a.csv"],
     "bad.toml: body.mass"),
    (["frobnicate"], "invalid choice"),
    (["run", "projectile", "--out", "{tmp}/a.csv"], "--engine"),
])
def test_bad_input_exits_2_with_a_message_and_writes_nothing(tmp_path, capsys, argv, words):
    (tmp_path / "bad.toml").write_text(BAD_SCENARIO)
    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    rc = main(argv)
    err = capsys.readouterr().err
    assert rc == 2
    assert words in err, err
    assert "Traceback" not in err
    assert not (tmp_path / "a.csv").exists()


def test_bad_scenario_in_a_subprocess_has_no_traceback(tmp_path):
    (tmp_path / "bad.toml").write_text(BAD_SCENARIO)
    proc = subprocess.run([sys.executable, "-m", "cross_checks.cli", "run", str(tmp_path / "bad.toml"),
                           "--engine", "reference:course", "--out", str(tmp_path / "a.csv")],
                          capture_output=True, text=True, cwd=tmp_path)
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [
        f"rbcheck run: error: {tmp_path / 'bad.toml'}: body.mass: must be > 0, got -2"]


def test_diverged_run_is_reported_with_its_time(tmp_path, capsys):
    (tmp_path / "fast.toml").write_text(DIVERGING)
    out = tmp_path / "f.csv"
    rc = main(["run", str(tmp_path / "fast.toml"), "--engine", "reference:expmap_gyro", "--out", str(out)])
    err = capsys.readouterr().err
    assert rc == 1
    assert "diverged at t = " in err
    traj = Trajectory.read(out)
    assert traj.meta["status"] == "diverged"
    # docs/engine_conventions.md: MuJoCo Euler (the same scheme) diverges on this case at t = 8.65 s.
    assert traj.meta["diverged_at_s"] == pytest.approx(8.65, abs=0.02)
    assert np.all(np.isfinite(traj.y))  # the steps before the blow-up, never NaN rows


def test_list_shows_scenarios_and_variants(capsys):
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    for word in ["tennis_racket", "reference:course", "reference:rk4", "mujoco:euler", "pybullet:multibody"]:
        assert word in out


from tests.cross_checks.scenario.test_parse import BAD, GOOD  # noqa: E402  (the loader's table of bad inputs)


@pytest.mark.parametrize("old, new, field, reason", BAD,
                         ids=[f"{b[2] or 'syntax'}-{i}" for i, b in enumerate(BAD)])
def test_every_bad_scenario_exits_2_through_the_cli(tmp_path, capsys, old, new, field, reason):
    bad = tmp_path / "bad.toml"
    bad.write_text(GOOD.replace(old, new, 1))
    out = tmp_path / "t.csv"
    assert main(["run", str(bad), "--engine", "reference:course", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert (err.startswith(f"rbcheck run: error: {bad}: {field + ': ' if field else ''}")
            and reason in err), err
    assert err.count("\n") == 1 and not out.exists()


def test_the_skipped_line_gives_every_skipped_engines_reason(capsys):
    # two optional engines missing: the one line names both engines and both reasons, not the first only
    from cross_checks.cli.sweep import _sweep_outcome
    summary = {"run": {"runs": 0, "cached_runs": 0, "diverged_runs": 0,
                       "failed_runs": 0, "jobs": 1, "wall_s": 0.0},
               "skipped_variants": [{"name": "drake:a", "reason": "drake is not installed"},
                                    {"name": "drake:b", "reason": "drake is not installed"},
                                    {"name": "dart:c", "reason": "dartpy is not installed"}],
               "convergence": [], "local_convergence": [], "agreement": [], "references": []}
    _sweep_outcome(summary, "out", 0, 0, 0.0)
    line = next(ln for ln in capsys.readouterr().out.splitlines() if "skipped" in ln)
    assert line == ("rbcheck sweep: skipped 3 variant(s) of drake, dart: drake is not installed; "
                    "dartpy is not installed")
