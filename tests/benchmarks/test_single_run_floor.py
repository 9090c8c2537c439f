"""benchmarks/single_run_floor.py runs on every installed engine it knows and writes what docs/speed.md quotes
(no time is asserted: only that each row is measured and its ratios are its own figures')."""
import importlib.util
import json
from pathlib import Path

import pytest

from cross_checks.engines import get_adapter

SCRIPT = Path(__file__).resolve().parents[2] / "benchmarks" / "single_run_floor.py"


def _module():
    spec = importlib.util.spec_from_file_location("single_run_floor", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _installed(name):
    try:
        get_adapter(name.split(":", 1)[0]).version()
        return True
    except Exception:  # noqa: BLE001 - an engine not installed here
        return False


def test_every_installed_engine_gets_a_row_of_its_own_figures(tmp_path, capsys):
    mod = _module()
    out = tmp_path / "floor.json"
    assert mod.main(["--steps", "300", "--repeats", "1", "--json", str(out)]) == 0
    data = json.loads(out.read_text())
    want = [v for v in mod.VARIANTS if _installed(v)]
    if not want:
        pytest.skip("none of PyBullet, DART, PhysX is installed here")
    assert [r["variant"] for r in data["rows"]] == want and data["steps"] == 300
    for r in data["rows"]:
        assert min(r["step_us"], r["floor_us"], r["rbcheck_us"], r["engine_s_us"]) > 0.0
        assert r["floor_over_step"] == r["floor_us"] / r["step_us"]
        assert r["rbcheck_over_step"] == r["rbcheck_us"] / r["step_us"]
        assert r["rbcheck_over_floor"] == r["rbcheck_us"] / r["floor_us"]
    printed = capsys.readouterr().out
    assert all(v in printed for v in want) and "floor/step" in printed
