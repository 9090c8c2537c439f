"""The lint and type gates: ruff (its rules in pyproject.toml, [tool.ruff]) passes on the whole tree and mypy
([tool.mypy]) on the layers every result rests on. A planted unused import and a planted type error are
caught, so the gates can fail. Marked `integration`: `.ci/run` and CI run them after the README's test command
(`pytest -m integration`)."""
import shutil
import subprocess
import sys

import pytest

from tests.helpers.repo import ROOT

#: ruff and mypy over the whole tree (tens of seconds): run by .ci/run and CI with -m integration
pytestmark = pytest.mark.integration


def _ruff():
    exe = shutil.which("ruff") or str(ROOT / ".venv" / "bin" / "ruff")
    candidates = [[sys.executable, "-m", "ruff"], [exe]]
    for cmd in candidates:
        try:
            if subprocess.run(cmd + ["--version"], capture_output=True).returncode == 0:
                return cmd
        except OSError:
            continue
    pytest.skip("ruff is not installed (it comes with the test extra: pip install -e '.[test]')")


def test_ruff_passes_on_the_whole_tree():
    proc = subprocess.run(_ruff() + ["check", "--output-format", "concise", "."], cwd=ROOT,
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-1000:]


def test_the_gate_catches_a_planted_unused_import(tmp_path):
    (tmp_path / "pyproject.toml").write_text((ROOT / "pyproject.toml").read_text())
    (tmp_path / "bad.py").write_text("import os\n")
    proc = subprocess.run(_ruff() + ["check", "--output-format", "concise", "."], cwd=tmp_path,
                          capture_output=True, text=True)
    assert proc.returncode == 1 and "F401" in proc.stdout


def _mypy():
    try:
        import mypy  # noqa: F401
    except ImportError:
        pytest.skip("mypy is not installed (it comes with the test extra: pip install -e '.[test]')")
    return [sys.executable, "-m", "mypy"]


def test_mypy_passes_on_core_scenario_and_analysis(tmp_path):
    proc = subprocess.run(_mypy() + ["--cache-dir", str(tmp_path / "cache")], cwd=ROOT, capture_output=True,
                          text=True)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-1000:]


def test_the_type_gate_catches_a_planted_type_error(tmp_path):
    (tmp_path / "bad.py").write_text("def f(x: int) -> int:\n    return x\n\nf('one')\n")
    proc = subprocess.run(_mypy() + ["--cache-dir", str(tmp_path / "cache"), "bad.py"], cwd=tmp_path,
                          capture_output=True, text=True)
    assert proc.returncode == 1 and "arg-type" in proc.stdout
