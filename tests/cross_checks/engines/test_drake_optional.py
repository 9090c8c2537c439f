"""Drake is optional: without it (an ImportError simulated), its variants are listed as not installed by
`rbcheck list`, skipped with that reason by a default sweep and its report, there is no second
reference, and every other result is the same."""
import json

import pytest

from cross_checks import engines
from cross_checks.cli import main
from cross_checks.engines import drake_engine
from cross_checks.scenario import load_scenario


@pytest.fixture
def no_drake(monkeypatch):
    from cross_checks.engines import install
    real = install.installed_version
    monkeypatch.setattr(install, "installed_version", lambda dist: None if dist == "drake" else real(dist))
    monkeypatch.setattr(drake_engine, "pydrake", None)
    monkeypatch.setattr(drake_engine, "_IMPORT_ERROR", ImportError("No module named 'pydrake'"))
    engines.reset_registry()
    yield
    engines.reset_registry()


def test_list_says_drake_is_not_installed(no_drake, capsys):
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    for v in drake_engine.VARIANTS:
        assert f"drake:{v}" in out
    assert "drake is not installed (pip install 'rbcheck[drake]')" in out
    infos = [v for v in engines.all_variants() if v.engine == "drake"]
    assert len(infos) == 4 and not any(v.available for v in infos)
    # optional engines (dart) may be here
    available = {v.engine for v in engines.all_variants() if v.available}
    assert "drake" not in available and {"reference", "mujoco", "pybullet"} <= available


def test_a_default_sweep_skips_drake_and_says_why(no_drake, tmp_path):
    # what `rbcheck sweep` does with no --engines, run on one variant to stay quick
    from cross_checks.cli.engines import resolve_engines
    from cross_checks.sweep.run import run_sweep
    run, skipped = resolve_engines(None)
    assert not any(v.startswith("drake:") for v in run)
    drake_skipped = {v: r for v, r in skipped.items() if v.startswith("drake:")}
    assert set(drake_skipped) == {f"drake:{v}" for v in drake_engine.VARIANTS}
    assert all("drake is not installed" in r for r in drake_skipped.values())
    # any other variant skipped is an optional engine that is not installed here either (Genesis, say)
    assert all("is not installed" in r for r in skipped.values())
    out = tmp_path / "r"
    # (the report lists summary.json's skipped_variants with their reasons; rendering it takes ~15 s)
    summary = run_sweep([load_scenario("projectile")], ["reference:rk4"], out, jobs=1, use_cache=False,
                        skipped=skipped, progress=False)
    recorded = json.loads((out / "summary.json").read_text())["skipped_variants"]
    assert {s["name"] for s in recorded} == set(skipped)
    # what compare reads to count drake's baseline rows in one line instead of failing on them
    assert all(s["installed"] is False and s["required"] is False for s in recorded)
    assert summary["scenarios"][0]["second_reference"] is None


def test_asking_for_drake_without_it_is_bad_input(no_drake, tmp_path, capsys):
    assert main(["sweep", "projectile", "--engines", "drake", "--out", str(tmp_path / "r")]) == 2
    assert "drake is not installed" in capsys.readouterr().err
