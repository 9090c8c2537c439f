"""Genesis is optional: without genesis-world (its absence simulated), the adapter says "not installed"
(EngineNotInstalled), `rbcheck list` and `--version` say so, a default sweep skips its variants with that
reason, and asking for it is bad input; an installed distribution whose packages are missing is told apart
from an absent one. Nothing here imports Genesis."""

import sys

import pytest

from cross_checks import engines
from cross_checks.cli import main
from cross_checks.cli.parser import _version_text
from cross_checks.engines import genesis_engine, install


@pytest.fixture
def no_genesis(monkeypatch):
    real = install.installed_version
    monkeypatch.setattr(
        install, "installed_version", lambda dist: None if dist == "genesis-world" else real(dist)
    )
    engines.reset_registry()
    yield
    engines.reset_registry()


def test_version_raises_engine_not_installed_with_the_extra_to_install(no_genesis):
    with pytest.raises(
        install.EngineNotInstalled,
        match=r"genesis-world is not installed \(pip install 'rbcheck\[genesis\]'\)"
    ):
        genesis_engine.version()


def test_a_broken_install_is_not_an_absent_one(monkeypatch):
    monkeypatch.setattr(install, "installed_version",
                        lambda dist: "1.4.5" if dist == "genesis-world" else None)
    monkeypatch.setattr(genesis_engine, "_findable", lambda name: name != "torch")
    with pytest.raises(
        ImportError, match="genesis-world 1.4.5 is installed but cannot be imported: no module named 'torch'"
    ) as e:
        genesis_engine.version()
    assert not isinstance(e.value, install.EngineNotInstalled)


def test_list_and_version_say_genesis_is_not_installed(no_genesis, capsys):
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    assert "genesis:euler" in out and "genesis-world is not installed (pip install 'rbcheck[genesis]')" in out
    infos = [v for v in engines.all_variants() if v.engine == "genesis"]
    assert len(infos) == len(genesis_engine.VARIANTS)
    assert not any(v.available or v.installed or v.required for v in infos)
    assert "genesis: genesis-world is not installed" in _version_text()


def test_a_default_sweep_skips_genesis_and_asking_for_it_is_bad_input(no_genesis, tmp_path, capsys):
    from cross_checks.cli.engines import resolve_engines

    run, skipped = resolve_engines(None)
    assert not any(v.startswith("genesis:") for v in run)
    assert {v for v in skipped if v.startswith("genesis:")} == {
        f"genesis:{v}" for v in genesis_engine.VARIANTS
    }
    assert all("genesis-world is not installed" in skipped[f"genesis:{v}"] for v in genesis_engine.VARIANTS)
    assert main(["sweep", "projectile", "--engines", "genesis", "--out", str(tmp_path / "r")]) == 2
    assert "genesis-world is not installed" in capsys.readouterr().err


def test_the_registry_never_imports_genesis():
    # listing and versioning every engine (what the CLI does at start, before a sweep forks) leaves Genesis
    # out
    if "genesis" in sys.modules:
        pytest.skip("Genesis was imported by another test in this process")
    engines.reset_registry()
    engines.all_variants()
    assert "genesis" not in sys.modules and "quadrants" not in sys.modules
