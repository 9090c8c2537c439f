"""Newton is optional: without newton (its absence simulated), the adapter says "not installed"
(EngineNotInstalled) with the extra to install, `rbcheck list` and `--version` list its variants as
unavailable with that reason, a default sweep skips them, and asking for it is bad input; an installed newton
whose warp-lang is missing is told apart from an absent one. None of it imports Newton or Warp."""
import importlib.util

import pytest

from cross_checks import engines
from cross_checks.cli import main
from cross_checks.cli.parser import _version_text
from cross_checks.engines import install, newton_engine


@pytest.fixture
def no_newton(monkeypatch):
    real = install.installed_version
    monkeypatch.setattr(newton_engine, "installed_version",
                        lambda dist: None if dist == "newton" else real(dist))
    engines.reset_registry()
    yield
    engines.reset_registry()


def test_version_raises_engine_not_installed_with_the_extra_to_install(no_newton):
    with pytest.raises(install.EngineNotInstalled,
                       match=r"newton is not installed \(pip install 'rbcheck\[newton\]'\)"):
        newton_engine.version()


def test_a_broken_install_is_not_an_absent_one(monkeypatch):
    real = importlib.util.find_spec
    monkeypatch.setattr(newton_engine, "installed_version",
                        lambda dist: "1.8.0" if dist == "newton" else None)
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name == "warp" else real(name, *a))
    said = "newton 1.8.0 is installed but cannot be imported: warp-lang is missing"
    with pytest.raises(ImportError, match=said) as e:
        newton_engine.version()
    assert not isinstance(e.value, install.EngineNotInstalled)


def test_list_and_version_say_newton_is_not_installed(no_newton, capsys):
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    for v in newton_engine.VARIANTS:
        assert f"newton:{v}" in out
    assert "newton is not installed (pip install 'rbcheck[newton]')" in out
    infos = [v for v in engines.all_variants() if v.engine == "newton"]
    assert len(infos) == len(newton_engine.VARIANTS)
    assert not any(v.available or v.installed or v.required for v in infos)
    assert "newton: newton is not installed" in _version_text()


def test_a_default_sweep_skips_newton_and_asking_for_it_is_bad_input(no_newton, tmp_path, capsys):
    from cross_checks.cli.engines import resolve_engines
    run, skipped = resolve_engines(None)
    assert not any(v.startswith("newton:") for v in run)
    assert {v for v in skipped if v.startswith("newton:")} == {f"newton:{v}" for v in newton_engine.VARIANTS}
    assert all("newton is not installed" in skipped[f"newton:{v}"] for v in newton_engine.VARIANTS)
    assert main(["sweep", "projectile", "--engines", "newton", "--out", str(tmp_path / "r")]) == 2
    assert "newton is not installed" in capsys.readouterr().err


def test_a_sweep_of_the_other_engines_runs_cleanly_without_newton(no_newton, tmp_path, capsys):
    out = tmp_path / "r"
    assert main(["sweep", "projectile", "--engines", "reference:course", "--jobs", "1",
                 "--out", str(out)]) == 0
    assert "newton" not in (out / "results.csv").read_text()
