"""The CI gate explains a real engine change: MuJoCo 3.17.0 integrates the quaternion at order 2 in its RK4,
4.0.0 at order 4 (docs/results.md, "Comparing two results directories").

The older MuJoCo is installed into a separate virtual environment outside the clone (rbcheck and its other
dependencies are this interpreter's, made visible by a .pth line; the environment's own mujoco comes first),
the rotating scenarios are swept there, and `rbcheck compare` against the committed baseline must name
mujoco:rk4's orientation order 4 -> 2 on its first screen, list the other MuJoCo variants and the references
as unchanged, and exit 1; the reverse direction is an improvement (exit 0, and 1 with --fail-on-change).
Slow (a pip install and two sweeps): `pytest -m slow tests/test_engine_change.py`; skipped, saying why, where
no older wheel can be installed."""
import os
import subprocess
import sys
import sysconfig
import venv

import pytest

from tests.helpers.repo import BASELINE, ROOT

OLD = "3.17.0"
ROTATING = ["tennis_racket", "tumbling_box", "symmetric_top",
            "applied_torque", "particle_body", "constant_spin"]


@pytest.fixture(scope="module")
def old_mujoco(tmp_path_factory):
    env_dir = tmp_path_factory.mktemp("mujoco-old") / "venv"
    venv.EnvBuilder(with_pip=True).create(env_dir)
    py = env_dir / "bin" / "python"
    pip = subprocess.run([str(py), "-m", "pip", "install", "-q", "--no-deps",
                          f"mujoco=={OLD}", "typing_extensions"],
                         capture_output=True, text=True, timeout=900)
    if pip.returncode != 0:
        pytest.skip(f"mujoco {OLD} cannot be installed here: {pip.stderr.strip()[-200:]}")
    site = subprocess.run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                          capture_output=True, text=True, check=True).stdout.strip()
    deps = dict.fromkeys([str(ROOT)] + [sysconfig.get_paths()[k] for k in ("purelib", "platlib")])
    with open(os.path.join(site, "zz-rbcheck.pth"), "w") as fh:
        fh.write("".join(f"{d}\n" for d in deps))
    return py


def _rbcheck(py, *argv, cwd):
    env = {**os.environ, "MPLBACKEND": "Agg", "RBCHECK_CACHE_DIR": str(cwd / "cache")}
    env.pop("PYTHONPATH", None)
    return subprocess.run([str(py), "-m", "cross_checks.cli", *argv], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=1800)


@pytest.mark.slow
def test_compare_names_mujoco_rk4s_order_as_the_cause_of_the_change(old_mujoco, tmp_path):
    version = subprocess.run([str(old_mujoco), "-c", "import mujoco; print(mujoco.__version__)"],
                             capture_output=True, text=True, check=True).stdout.strip()
    assert version == OLD
    old = _rbcheck(old_mujoco, "sweep", *ROTATING,
                   "--engines", "reference", "mujoco", "--out", "old", cwd=tmp_path)
    assert old.returncode == 1, old.stderr[-2000:]   # its RK4 contradicts the declared order 4
    md = tmp_path / "compare.md"
    cmp_ = _rbcheck(sys.executable, "compare", str(BASELINE), "old", "--markdown", str(md), cwd=tmp_path)
    assert cmp_.returncode == 1, cmp_.stdout[-3000:]
    first = md.read_text().splitlines()[:25]   # the CI job summary's first screen
    screen = "\n".join(first)
    assert "REGRESSION: 1 variant(s) regressed (mujoco:rk4)" in screen
    assert f"mujoco 4.0.0 → {OLD}" in screen
    row = next(ln for ln in first if ln.startswith("| mujoco:rk4 | regression |"))
    assert "orientation order 4.00–4.03 → 2.00" in row and "one-step order" in row
    unchanged = next(ln for ln in first if ln.startswith("Unchanged:"))
    for v in ("mujoco:euler", "mujoco:implicit", "mujoco:implicitfast", "reference:rk4", "reference:course"):
        assert v in unchanged
    # the reverse direction: the upgrade is an improvement, and a stale baseline only with --fail-on-change
    new = _rbcheck(sys.executable, "sweep", *ROTATING, "--engines", "reference", "mujoco", "--out", "new",
                   cwd=tmp_path)
    assert new.returncode == 0, new.stderr[-2000:]
    up = _rbcheck(sys.executable, "compare", "old", "new", cwd=tmp_path)
    assert (up.returncode == 0 and "mujoco:rk4: IMPROVEMENT — " in up.stdout
            and "baseline is stale" in up.stdout)
    assert _rbcheck(sys.executable, "compare", "old", "new", "--fail-on-change", cwd=tmp_path).returncode == 1
