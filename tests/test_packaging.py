"""A non-editable install (`pip install .`, a wheel) carries every module and data file of the source tree.

The README installs editable (`pip install -e .`), which finds modules in the clone whatever the package
list says; a user or a CI job that installs a wheel gets only what the list names. A hand-written list once
left `cross_checks.fuzz` out: `rbcheck fuzz` then stopped with "No module named 'cross_checks.fuzz'". This
test builds the wheel from the clone's files and compares its contents with the tree."""
import subprocess
import sys
import zipfile

import pytest

from tests.helpers.repo import ROOT

PACKAGES = ("reference_sim", "cross_checks", "reports")
DATA_SUFFIXES = (".toml", ".html", ".css")   # the catalog and the report's templates


def _tracked() -> list:
    try:
        out = subprocess.run(["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"], cwd=ROOT,
                             capture_output=True, check=True).stdout.decode()
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout: cannot tell a clone's files from local ones")
    return [p for p in out.split("\0") if p]


def test_the_wheel_holds_every_module_and_data_file_of_the_packages(tmp_path):
    files = _tracked()
    src = tmp_path / "src"
    for rel in files:
        if (ROOT / rel).is_file():
            (src / rel).parent.mkdir(parents=True, exist_ok=True)
            (src / rel).write_bytes((ROOT / rel).read_bytes())
    built = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(tmp_path / "dist"),
                            str(src)], capture_output=True, text=True)
    if built.returncode != 0 and ("No matching distribution" in built.stderr or "Could not find" in built.stderr):
        pytest.skip(f"pip cannot fetch the build backend here: {built.stderr.strip()[-200:]}")
    assert built.returncode == 0, built.stderr[-2000:]
    (wheel,) = (tmp_path / "dist").glob("rbcheck-*.whl")
    in_wheel = set(zipfile.ZipFile(wheel).namelist())
    wanted = {rel for rel in files if rel.split("/", 1)[0] in PACKAGES and rel.endswith((".py",) + DATA_SUFFIXES)}
    assert len(wanted) > 100   # the tree was read (rbcheck has ~150 modules and data files)
    assert not wanted - in_wheel, f"left out of a non-editable install: {sorted(wanted - in_wheel)}"
