"""MuJoCo and PyBullet are required (rbcheck depends on them): one that is installed but fails to import
is an installation to repair, said with its import error, and `rbcheck sweep` exits 2 instead of
sweeping around it. An optional engine (Drake) that is absent is skipped and said so; one that is
installed but broken is never called "not installed".

The broken wheel is planted for real, in a fresh interpreter: a ``pybullet`` module ahead on the path
that raises the ImportError a PyBullet built for NumPy 1 raises under NumPy 2, while the installed
distribution's metadata (its version) stays what pip installed."""
import os
import subprocess
import sys

import pytest

from cross_checks.engines import install

NUMPY1_WHEEL_ERROR = "numpy.core.multiarray failed to import"


def _broken_pybullet_env(tmp_path) -> dict:
    shadow = tmp_path / "shadow"
    shadow.mkdir()
    (shadow / "pybullet.py").write_text(f"raise ImportError({NUMPY1_WHEEL_ERROR!r})\n")
    env = {**os.environ,
           "PYTHONPATH": os.pathsep.join([str(shadow), *filter(None, [os.environ.get("PYTHONPATH")])]),
           "RBCHECK_CACHE_DIR": str(tmp_path / "cache"), "MPLBACKEND": "Agg"}
    return env


def _rbcheck(tmp_path, env, *argv):
    return subprocess.run([sys.executable, "-m", "cross_checks.cli", *argv], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=300)


def test_a_required_engine_that_fails_to_import_stops_the_sweep_with_its_import_error(tmp_path):
    pytest.importorskip("pybullet")
    env = _broken_pybullet_env(tmp_path)
    proc = _rbcheck(tmp_path, env, "sweep", "projectile", "--out", "res")
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert proc.stderr.count("\n") == 1 and "Traceback" not in proc.stderr
    assert "pybullet is required by rbcheck and cannot run here" in proc.stderr
    assert f"is installed but cannot be imported: ImportError: {NUMPY1_WHEEL_ERROR}" in proc.stderr
    assert "not installed" not in proc.stderr and not (tmp_path / "res").exists()
    listed = _rbcheck(tmp_path, env, "list")
    assert listed.returncode == 0
    line = next(ln for ln in listed.stdout.splitlines() if ln.strip().startswith("pybullet:multibody"))
    assert "is installed but cannot be imported" in line and "not installed" not in line
    assert "pybullet is required by rbcheck and cannot run here" in listed.stderr
    fuzz = _rbcheck(tmp_path, env, "fuzz", "--budget", "1", "--out", "fz")
    assert fuzz.returncode == 2 and "pybullet is required" in fuzz.stderr


def test_an_absent_distribution_is_not_installed_a_broken_one_says_its_error(monkeypatch):
    with pytest.raises(install.EngineNotInstalled, match=r"^drake is not installed \(pip install x\)$"):
        monkeypatch.setattr(install, "installed_version", lambda d: None)
        install.require(None, ImportError("No module named 'pydrake'"), "drake", hint="pip install x")
    monkeypatch.setattr(install, "installed_version", lambda d: "1.51.1")
    with pytest.raises(ImportError) as info:
        install.require(None, ImportError("libdrake.so: undefined symbol"), "drake")
    assert not isinstance(info.value, install.EngineNotInstalled)
    assert str(info.value) == ("drake 1.51.1 is installed but cannot be imported: "
                               "ImportError: libdrake.so: undefined symbol")


def test_the_required_engines_are_rbcheck_own_dependencies():
    import tomllib

    from cross_checks.engines import REQUIRED_ENGINES
    from tests.helpers.repo import ROOT
    deps = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["dependencies"]
    pinned = {d.split("==")[0] for d in deps if "==" in d}
    assert set(REQUIRED_ENGINES) - {"reference"} == pinned & {"mujoco", "pybullet", "drake"}
