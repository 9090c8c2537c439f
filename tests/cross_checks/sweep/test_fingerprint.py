"""The cache key fingerprints whole packages: editing, adding or renaming any source file of the layers
that compute a job's numbers changes every key; the layers above (gates, reports, cli) do not; and
every module a sweep job actually runs is inside the fingerprint."""
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cross_checks.scenario import load_scenario
from cross_checks.sweep import fingerprint
from cross_checks.sweep.jobs import _job_key, _reference_key

ROOT = Path(__file__).resolve().parents[3]
#: The packages whose numbers a job computes, listed here by hand (not read from production code).
PACKAGES = ["reference_sim", "cross_checks/core", "cross_checks/scenario", "cross_checks/engines",
            "cross_checks/analysis", "cross_checks/sweep"]
SC = load_scenario("projectile")


def _sources(top: Path) -> list:
    """Every Python file of those packages, and cross_checks/__init__.py (run when they are imported)."""
    return sorted(["cross_checks/__init__.py"] + [p.relative_to(top).as_posix() for pkg in PACKAGES
                                                  for p in (top / pkg).rglob("*.py")])


@pytest.fixture
def copy(tmp_path, monkeypatch):
    """A copy of the packages' sources; the fingerprint is pointed at it and recomputed on each call."""
    top = tmp_path / "src"
    for rel in _sources(ROOT) + ["cross_checks/gates/compare.py", "reports/html.py"]:
        (top / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(ROOT / rel, top / rel)
    monkeypatch.setattr(fingerprint, "_package_dir", lambda name: top / name.replace(".", "/"))
    monkeypatch.setattr(fingerprint, "_BASE", [])
    monkeypatch.setattr(fingerprint, "_FINGERPRINTS", {})

    def keys():
        fingerprint._BASE.clear()
        fingerprint._FINGERPRINTS.clear()
        return (_job_key(SC, "reference:rk4", 0.01, "0.1.0"), _job_key(SC, "mujoco:euler", 0.01, "4.0.0"),
                _reference_key(SC, np.array([0.0, 0.01])))
    return top, keys


def test_editing_any_source_file_of_the_fingerprinted_packages_changes_every_key(copy):
    top, keys = copy
    sources = _sources(top)
    assert (len(sources) > 40 and "cross_checks/sweep/run.py" in sources
            and "reference_sim/simulate.py" in sources)
    before = keys()
    for rel in sources:
        f = top / rel
        original = f.read_bytes()
        f.write_bytes(original + b"\n# edited\n")
        changed = keys()
        f.write_bytes(original)
        assert all(a != b for a, b in zip(before, changed)), f"editing {rel} kept a cache key"
    assert keys() == before


def test_a_new_or_renamed_module_changes_the_key_and_the_layers_above_do_not(copy):
    top, keys = copy
    before = keys()
    new = top / "cross_checks" / "analysis" / "new_metric.py"
    new.write_text("SCALE = 2.0\n")
    assert keys() != before
    new.rename(top / "cross_checks" / "analysis" / "renamed_metric.py")
    renamed = keys()
    assert renamed != before
    (top / "cross_checks" / "analysis" / "renamed_metric.py").unlink()
    assert keys() == before
    nested = top / "cross_checks" / "engines" / "vendored" / "kernel.py"  # a sub-package of a package
    nested.parent.mkdir()
    nested.write_text("GAIN = 1.0\n")
    assert keys() != before
    nested.unlink()
    for rel in ("cross_checks/gates/compare.py", "reports/html.py"):
        (top / rel).write_text((top / rel).read_text() + "\n# a change that computes no number\n")
    assert keys() == before


def test_every_version_that_changes_a_number_is_in_the_key(monkeypatch):
    import platform

    import numpy
    import scipy
    env = fingerprint.environment()
    assert {numpy.__version__, scipy.__version__, platform.python_version(), platform.machine(),
            fingerprint.cpu_model()} <= set(env)
    key = _job_key(SC, "reference:rk4", 0.01, "0.1.0")
    for i in range(len(env)):
        changed = list(env)
        changed[i] += "-other"
        monkeypatch.setattr(fingerprint, "environment", lambda c=changed: c)
        assert _job_key(SC, "reference:rk4", 0.01, "0.1.0") != key, env[i]
    monkeypatch.undo()
    assert _job_key(SC, "reference:rk4", 0.01, "0.1.1") != key  # the engine's version


def test_every_module_a_sweep_job_runs_is_fingerprinted(tmp_path):
    # A fresh interpreter runs a small sweep through each built-in engine (no report), then lists the
    # files of every module it loaded from this repository: each must be in the fingerprint.
    code = """
import json, sys
from pathlib import Path
from cross_checks.engines import available_variants
from cross_checks.scenario import load_scenario
from cross_checks.sweep import run_sweep
variants = [v for v in available_variants() if v in ("reference:rk4", "mujoco:euler", "pybullet:multibody")]
run_sweep([load_scenario("projectile")], variants, sys.argv[1], jobs=1, use_cache=False, progress=False)
print(json.dumps(sorted(m.__file__ for m in list(sys.modules.values()) if getattr(m, "__file__", None))))
"""
    env = {**os.environ, "RBCHECK_CACHE_DIR": str(tmp_path / "cache")}
    out = subprocess.run([sys.executable, "-c", code, str(tmp_path / "res")], capture_output=True, text=True,
                         env=env, cwd=tmp_path, timeout=300, check=True).stdout
    loaded = {Path(f).resolve() for f in json.loads(out.splitlines()[-1])}
    env_dir = Path(sys.prefix).resolve()  # the virtual environment may live inside the checkout
    ours = {f for f in loaded if f.is_relative_to(ROOT) and not f.is_relative_to(env_dir)}
    covered = {path.resolve() for _, path in fingerprint.fingerprinted_files()}
    assert ours and not (ours - covered), sorted(str(f.relative_to(ROOT)) for f in ours - covered)
