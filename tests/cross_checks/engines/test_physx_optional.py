"""PhysX (through SAPIEN) is optional: without sapien (its absence simulated), the adapter says "not
installed" (EngineNotInstalled) with the pip hint, `rbcheck list` and `--version` say so, a default sweep
skips its variants with that reason, and asking for it is bad input; an installed sapien that cannot be
found or imported is told apart from an absent one."""
import importlib.util

import pytest

from cross_checks import engines
from cross_checks.cli import main
from cross_checks.cli.parser import _version_text
from cross_checks.engines import install, physx_engine


@pytest.fixture
def no_sapien(monkeypatch):
    real = install.installed_version
    monkeypatch.setattr(install, "installed_version", lambda dist: None if dist == "sapien" else real(dist))
    monkeypatch.setattr(physx_engine, "installed_version",
                        lambda dist: None if dist == "sapien" else real(dist))
    physx_engine._dist_version.cache_clear()
    engines.reset_registry()
    yield
    physx_engine._dist_version.cache_clear()
    engines.reset_registry()


def test_version_raises_engine_not_installed_with_the_extra_to_install(no_sapien):
    with pytest.raises(install.EngineNotInstalled,
                       match=r"sapien is not installed \(pip install 'rbcheck\[physx\]'\)"):
        physx_engine.version()


def test_a_broken_install_is_not_an_absent_one(monkeypatch):
    monkeypatch.setattr(physx_engine, "installed_version", lambda dist: "3.0.3" if dist == "sapien" else None)
    real_find = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name == "sapien" else real_find(name, *a))
    with pytest.raises(ImportError, match="sapien 3.0.3 is installed but cannot be imported") as e:
        physx_engine.version()
    assert not isinstance(e.value, install.EngineNotInstalled)


def test_list_and_version_say_physx_is_not_installed(no_sapien, capsys):
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    assert "physx:tgs" in out and "physx:pgs" in out
    assert "sapien is not installed (pip install 'rbcheck[physx]')" in out
    infos = [v for v in engines.all_variants() if v.engine == "physx"]
    assert (len(infos) == len(physx_engine.VARIANTS)
            and not any(v.available or v.installed or v.required for v in infos))
    assert "physx: sapien is not installed" in _version_text()


def test_a_default_sweep_skips_physx_and_asking_for_it_is_bad_input(no_sapien, tmp_path, capsys):
    from cross_checks.cli.engines import resolve_engines
    run, skipped = resolve_engines(None)
    assert not any(v.startswith("physx:") for v in run)
    assert {v for v in skipped if v.startswith("physx:")} == {f"physx:{v}" for v in physx_engine.VARIANTS}
    assert all("sapien is not installed" in skipped[f"physx:{v}"] for v in physx_engine.VARIANTS)
    assert main(["sweep", "projectile", "--engines", "physx", "--out", str(tmp_path / "r")]) == 2
    assert "sapien is not installed" in capsys.readouterr().err


def test_a_sweep_of_another_engine_runs_cleanly_without_physx(no_sapien, tmp_path):
    # the default sweep of one scenario with the reference engine only: physx listed as skipped, exit 0
    assert main(["sweep", "projectile", "--engines", "reference:course", "--jobs", "1",
                 "--out", str(tmp_path / "r")]) == 0
