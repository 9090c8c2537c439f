"""MJX is optional: without mujoco-mjx (its absence simulated), the adapter says "not installed"
(EngineNotInstalled), `rbcheck list` and `--version` say so, a default sweep skips its variants with that
reason, and asking for it is bad input; an installed mujoco-mjx whose JAX is missing is told apart from an
absent one. None of it imports JAX."""
import importlib.util

import pytest

from cross_checks import engines
from cross_checks.cli import main
from cross_checks.cli.parser import _version_text
from cross_checks.engines import install, mjx_engine


@pytest.fixture
def no_mjx(monkeypatch):
    real = install.installed_version
    monkeypatch.setattr(install, "installed_version",
                        lambda dist: None if dist == "mujoco-mjx" else real(dist))
    engines.reset_registry()
    yield
    engines.reset_registry()


def test_version_raises_engine_not_installed_with_the_extra_to_install(no_mjx):
    with pytest.raises(install.EngineNotInstalled,
                       match=r"mujoco-mjx is not installed \(pip install 'rbcheck\[mjx\]'\)"):
        mjx_engine.version()


def test_a_broken_install_is_not_an_absent_one(monkeypatch):
    real = importlib.util.find_spec
    monkeypatch.setattr(install, "installed_version",
                        lambda dist: "3.17.0" if dist == "mujoco-mjx" else None)
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name == "jaxlib" else real(name, *a))
    said = r"mujoco-mjx 3.17.0 is installed but cannot be imported: jaxlib is missing"
    with pytest.raises(ImportError, match=said) as e:
        mjx_engine.version()
    assert not isinstance(e.value, install.EngineNotInstalled)


def test_list_and_version_say_mjx_is_not_installed(no_mjx, capsys):
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    assert "mjx:euler" in out and "mujoco-mjx is not installed (pip install 'rbcheck[mjx]')" in out
    infos = [v for v in engines.all_variants() if v.engine == "mjx"]
    assert len(infos) == len(mjx_engine.VARIANTS)
    assert not any(v.available or v.installed or v.required for v in infos)
    assert "mjx: mujoco-mjx is not installed" in _version_text()


def test_a_default_sweep_skips_mjx_and_asking_for_it_is_bad_input(no_mjx, tmp_path, capsys):
    from cross_checks.cli.engines import resolve_engines
    run, skipped = resolve_engines(None)
    assert not any(v.startswith("mjx:") for v in run)
    assert {v for v in skipped if v.startswith("mjx:")} == {f"mjx:{v}" for v in mjx_engine.VARIANTS}
    assert all("mujoco-mjx is not installed" in skipped[f"mjx:{v}"] for v in mjx_engine.VARIANTS)
    assert main(["sweep", "projectile", "--engines", "mjx", "--out", str(tmp_path / "r")]) == 2
    assert "mujoco-mjx is not installed" in capsys.readouterr().err
