"""DART is optional: without dartpy (its absence simulated), the adapter says "not installed"
(EngineNotInstalled), `rbcheck list` and `--version` say so, a default sweep skips its variants
with that reason, and asking for it is bad input; an installed dartpy that fails to import is
told apart from an absent one."""
import pytest

from cross_checks import engines
from cross_checks.cli import main
from cross_checks.cli.parser import _version_text
from cross_checks.engines import dart_engine, install


@pytest.fixture
def no_dart(monkeypatch):
    real = install.installed_version
    monkeypatch.setattr(install, "installed_version", lambda dist: None if dist == "dartpy" else real(dist))
    monkeypatch.setattr(dart_engine, "dart", None)
    monkeypatch.setattr(dart_engine, "_IMPORT_ERROR", ImportError("No module named 'dartpy'"))
    engines.reset_registry()
    yield
    engines.reset_registry()


def test_version_raises_engine_not_installed_with_the_extra_to_install(no_dart):
    with pytest.raises(install.EngineNotInstalled,
                       match=r"dartpy is not installed \(pip install 'rbcheck\[dart\]'\)"):
        dart_engine.version()


def test_a_broken_install_is_not_an_absent_one(monkeypatch):
    monkeypatch.setattr(install, "installed_version", lambda dist: "6.20.0" if dist == "dartpy" else None)
    monkeypatch.setattr(dart_engine, "dart", None)
    monkeypatch.setattr(dart_engine, "_IMPORT_ERROR",
                        ImportError("libfcl.so.0.7: cannot open shared object file"))
    with pytest.raises(ImportError,
                       match="dartpy 6.20.0 is installed but cannot be imported: ImportError: libfcl") as e:
        dart_engine.version()
    assert not isinstance(e.value, install.EngineNotInstalled)


def test_list_and_version_say_dart_is_not_installed(no_dart, capsys):
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    assert ("dart:semi_implicit_euler" in out
            and "dartpy is not installed (pip install 'rbcheck[dart]')" in out)
    infos = [v for v in engines.all_variants() if v.engine == "dart"]
    assert (len(infos) == len(dart_engine.VARIANTS)
            and not any(v.available or v.installed or v.required for v in infos))
    assert "dart: dartpy is not installed" in _version_text()


def test_a_default_sweep_skips_dart_and_asking_for_it_is_bad_input(no_dart, tmp_path, capsys):
    from cross_checks.cli.engines import resolve_engines
    run, skipped = resolve_engines(None)
    assert not any(v.startswith("dart:") for v in run)
    assert {v for v in skipped if v.startswith("dart:")} == {f"dart:{v}" for v in dart_engine.VARIANTS}
    assert all("dartpy is not installed" in skipped[f"dart:{v}"] for v in dart_engine.VARIANTS)
    assert main(["sweep", "projectile", "--engines", "dart", "--out", str(tmp_path / "r")]) == 2
    assert "dartpy is not installed" in capsys.readouterr().err
