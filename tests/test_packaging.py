"""A non-editable install (`pip install .`, a wheel) carries every module and data file, and works.

The README installs editable (`pip install -e .`), which finds every file in the clone whatever the
package data says; a user's project or a CI job that installs the wheel gets only what pyproject.toml
names. A hand-written list once left `cross_checks.fuzz` out, and a data pattern left the report's
`sort.js` out (every sweep then ended in "error: sort.js"). So the wheel is built from the clone's
tracked files, compared with the tree, and installed into a fresh virtual environment outside the
clone, where the commands a user runs first run for real: a sweep of two scenarios with its report,
`rbcheck check`, and a user's pytest file calling `assert_engine` with `--rbcheck-keep-reports`.

The fresh environment takes rbcheck from the wheel only (`--no-deps`, checked: every rbcheck module is
imported from the environment, none from the clone); its third-party dependencies (numpy, mujoco, ...)
are those of the interpreter running the tests, made visible by a `.pth` line, so no download is needed.
"""
import os
import subprocess
import sys
import sysconfig
import textwrap
import venv
import zipfile
from pathlib import Path

import pytest

from reports.install import TEMPLATE_FILES
from tests.helpers.repo import ROOT
from tests.helpers.sweeps import built_once

PACKAGES = ("reference_sim", "cross_checks", "reports")


def _tracked() -> list:
    try:
        out = subprocess.run(["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"],
                             cwd=ROOT, capture_output=True, check=True).stdout.decode()
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout: cannot tell a clone's files from local ones")
    return [p for p in out.split("\0") if p and (ROOT / p).is_file()]


def _build_wheel(folder: Path) -> None:
    src = folder / "src"
    for rel in _tracked():
        (src / rel).parent.mkdir(parents=True, exist_ok=True)
        (src / rel).write_bytes((ROOT / rel).read_bytes())
    built = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w",
                            str(folder / "dist"), str(src)], capture_output=True, text=True)
    if built.returncode != 0 and ("No matching distribution" in built.stderr
                                  or "Could not find" in built.stderr):
        pytest.skip(f"pip cannot fetch the build backend here: {built.stderr.strip()[-200:]}")
    assert built.returncode == 0, built.stderr[-2000:]


@pytest.fixture(scope="session")
def wheel(tmp_path_factory) -> Path:
    (path,) = (built_once(tmp_path_factory, "wheel", _build_wheel) / "dist").glob("rbcheck-*.whl")
    return path


@pytest.mark.integration
def test_the_wheel_holds_every_module_and_data_file_of_the_packages(wheel):
    files = _tracked()
    in_wheel = set(zipfile.ZipFile(wheel).namelist())
    wanted = {rel for rel in files if rel.split("/", 1)[0] in PACKAGES}   # every file, whatever its suffix
    assert len(wanted) > 100   # the tree was read (rbcheck has ~150 modules and data files)
    assert not wanted - in_wheel, f"left out of a non-editable install: {sorted(wanted - in_wheel)}"
    assert {f"reports/templates/{n}" for n in TEMPLATE_FILES} <= in_wheel


@pytest.fixture(scope="session")
def installed(tmp_path_factory, wheel) -> Path:
    """A fresh virtual environment, outside the clone, with the wheel installed non-editable."""
    def build(folder: Path) -> None:
        env_dir = folder / "venv"
        venv.EnvBuilder(with_pip=True).create(env_dir)
        py = env_dir / "bin" / "python"
        site = Path(subprocess.run([str(py), "-c",
                                    "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                                   capture_output=True, text=True, check=True).stdout.strip())
        # the dependencies of the interpreter running the tests (appended after the environment's own
        # site-packages, whose rbcheck comes first; .pth files of the added folders are not run, so the
        # clone's editable install stays out)
        deps = dict.fromkeys(sysconfig.get_paths()[k] for k in ("purelib", "platlib"))
        (site / "rbcheck-test-deps.pth").write_text("".join(f"{d}\n" for d in deps))
        pip = subprocess.run([str(py), "-m", "pip", "install", "-q", "--no-deps", "--no-index", str(wheel)],
                             capture_output=True, text=True)
        assert pip.returncode == 0, pip.stderr[-2000:]
    return built_once(tmp_path_factory, "wheel-venv", build) / "venv"


def _run(env_dir: Path, cwd: Path, *argv, timeout=600):
    """A command of the fresh environment, run in ``cwd`` (outside the clone), with no path to the clone."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")}
    env.update(PATH=f"{env_dir / 'bin'}{os.pathsep}{env.get('PATH', '')}", MPLBACKEND="Agg",
               RBCHECK_CACHE_DIR=str(cwd / "cache"), PYTHONDONTWRITEBYTECODE="1")
    return subprocess.run([str(a) for a in argv], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=timeout)


@pytest.mark.integration
def test_the_installed_wheel_imports_rbcheck_from_itself_not_from_the_clone(installed, tmp_path):
    code = ("import cross_checks, reference_sim, reports; "
            "print(cross_checks.__file__, reference_sim.__file__, reports.__file__)")
    proc = _run(installed, tmp_path, installed / "bin" / "python", "-c", code)
    assert proc.returncode == 0, proc.stderr
    for f in proc.stdout.split():
        assert Path(f).is_relative_to(installed) and not Path(f).is_relative_to(ROOT), f


@pytest.mark.integration
def test_a_sweep_with_its_report_runs_from_the_installed_wheel(installed, tmp_path):
    proc = _run(installed, tmp_path, installed / "bin" / "rbcheck", "sweep", "projectile", "constant_spin",
                "--engines", "reference:course", "mujoco:euler", "--jobs", "2", "--out", "sw")
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    pages = sorted(p.name for p in (tmp_path / "sw").glob("*.html"))
    assert pages == ["index.html", "integrators.html", "ranking.html", "scenario-constant_spin.html",
                     "scenario-projectile.html"]
    assert "function" in (tmp_path / "sw" / "index.html").read_text()   # sort.js, inlined
    again = _run(installed, tmp_path, installed / "bin" / "rbcheck", "report", "sw")
    assert again.returncode == 0, again.stderr


@pytest.mark.integration
def test_check_runs_from_the_installed_wheel(installed, tmp_path):
    rbcheck = installed / "bin" / "rbcheck"
    run = _run(installed, tmp_path, rbcheck, "run", "projectile",
               "--engine", "reference:course", "--out", "t.csv")
    assert run.returncode == 0, run.stderr
    check = _run(installed, tmp_path, rbcheck, "check", "t.csv",
                 "--scenario", "projectile", "--plot", "c.png")
    assert check.returncode == 0 and check.stdout.startswith("PASS"), check.stdout + check.stderr
    assert (tmp_path / "c.png").stat().st_size > 0


@pytest.mark.integration
def test_a_users_pytest_file_calls_assert_engine_from_the_installed_plugin(installed, tmp_path):
    (tmp_path / "test_mine.py").write_text(textwrap.dedent("""
        def test_the_reference_rk4_is_fourth_order(assert_engine):
            assert_engine("reference:rk4", ["projectile", "constant_spin"])
    """))
    proc = _run(installed, tmp_path, installed / "bin" / "python", "-m", "pytest", "-q", "-p",
                "no:cacheprovider", "--rbcheck-keep-reports", "kept", "test_mine.py")
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-2000:]
    assert "1 passed" in proc.stdout
    assert list((tmp_path / "kept").rglob("index.html")), "the kept report was not written"


@pytest.mark.integration
def test_a_missing_template_is_named_as_an_incomplete_installation(installed, tmp_path):
    """The same wheel with sort.js deleted from the environment: one line naming the
    file, exit 2, before any run."""
    import shutil
    broken = tmp_path / "broken"
    shutil.copytree(installed, broken, symlinks=True)
    (sort_js,) = broken.rglob("reports/templates/sort.js")
    sort_js.unlink()
    for exe in (broken / "bin").iterdir():   # scripts name their interpreter by absolute path: repoint them
        if exe.is_file() and not exe.is_symlink() and exe.read_bytes().startswith(b"#!"):
            exe.write_text(exe.read_text().replace(str(installed), str(broken)))
    proc = _run(broken, tmp_path, broken / "bin" / "rbcheck", "sweep", "projectile",
                "--engines", "reference:course", "--out", "sw")
    assert proc.returncode == 2, proc.stderr
    assert (proc.stderr.count("\n") == 1
            and "sort.js: missing from this installation of rbcheck" in proc.stderr)
    assert "installation is incomplete" in proc.stderr and not (tmp_path / "sw").exists()


def test_the_plugin_has_an_extra_that_brings_pytest_and_the_readme_names_it():
    """Issue 44, point 5: after `pip install -e .` a user's pytest file got "fixture 'assert_engine' not
    found" (pytest was not in rbcheck's environment). `.[pytest]` brings the pytest the tests run with."""
    import tomllib
    extras = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]
    [pin] = extras["pytest"]
    assert pin.startswith("pytest>=") and pin in extras["test"]
    readme = (ROOT / "README.md").read_text()
    plugin = " ".join(readme[readme.index("In your own pytest suite"):][:600].split())
    assert 'pip install -e ".[pytest]"' in plugin and "fixture 'assert_engine' not found" in plugin
