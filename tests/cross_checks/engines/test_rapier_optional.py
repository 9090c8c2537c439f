"""Rapier is optional: without rapier3d (its absence simulated), the adapter says "not installed"
(EngineNotInstalled) with the extra to install, `rbcheck list` and `--version` say so, a default sweep skips
its variants with that reason, and asking for it is bad input; an installed rapier3d that fails to import is
told apart from an absent one."""
import pytest

from cross_checks import engines
from cross_checks.cli import main
from cross_checks.cli.parser import _version_text
from cross_checks.engines import install, rapier_engine


@pytest.fixture
def no_rapier(monkeypatch):
    real = install.installed_version
    monkeypatch.setattr(install, "installed_version", lambda dist: None if dist == "rapier3d" else real(dist))
    monkeypatch.setattr(rapier_engine, "rapier", None)
    monkeypatch.setattr(rapier_engine, "_IMPORT_ERROR", ImportError("No module named 'rapier3d'"))
    engines.reset_registry()
    yield
    engines.reset_registry()


def test_version_raises_engine_not_installed_with_the_extra_to_install(no_rapier):
    with pytest.raises(install.EngineNotInstalled,
                       match=r"rapier3d is not installed \(pip install 'rbcheck\[rapier\]'\)"):
        rapier_engine.version()


def test_a_broken_install_is_not_an_absent_one(monkeypatch):
    monkeypatch.setattr(install, "installed_version", lambda dist: "0.36.1" if dist == "rapier3d" else None)
    monkeypatch.setattr(rapier_engine, "rapier", None)
    monkeypatch.setattr(rapier_engine, "_IMPORT_ERROR",
                        ImportError("_rapier3d.abi3.so: undefined symbol: PyObject_Vectorcall"))
    with pytest.raises(ImportError, match="rapier3d 0.36.1 is installed but cannot be imported: "
                                          "ImportError: _rapier3d") as e:
        rapier_engine.version()
    assert not isinstance(e.value, install.EngineNotInstalled)


def test_the_adapter_module_imports_and_lists_its_files_without_rapier(no_rapier):
    adapter = rapier_engine.RapierAdapter()
    assert adapter.source_files()[0].name == "rapier_engine.py"
    assert list(adapter.variants) == ["symplectic_euler", "symplectic_euler_no_gyro"]


def test_list_and_version_say_rapier_is_not_installed(no_rapier, capsys):
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    assert ("rapier:symplectic_euler" in out and "rapier:symplectic_euler_no_gyro" in out
            and "rapier3d is not installed (pip install 'rbcheck[rapier]')" in out)
    infos = [v for v in engines.all_variants() if v.engine == "rapier"]
    assert (len(infos) == len(rapier_engine.VARIANTS)
            and not any(v.available or v.installed or v.required for v in infos))
    assert "rapier: rapier3d is not installed" in _version_text()


def test_a_default_sweep_skips_rapier_and_asking_for_it_is_bad_input(no_rapier, tmp_path, capsys):
    from cross_checks.cli.engines import resolve_engines
    run, skipped = resolve_engines(None)
    assert not any(v.startswith("rapier:") for v in run)
    assert {v for v in skipped if v.startswith("rapier:")} == {f"rapier:{v}" for v in rapier_engine.VARIANTS}
    assert all("rapier3d is not installed" in skipped[f"rapier:{v}"] for v in rapier_engine.VARIANTS)
    assert main(["sweep", "projectile", "--engines", "rapier", "--out", str(tmp_path / "r")]) == 2
    assert "rapier3d is not installed" in capsys.readouterr().err


def test_a_sweep_without_rapier_runs_the_others_and_records_the_skip(no_rapier, tmp_path, monkeypatch):
    # the default sweep's skipped variants (the CLI's resolve_engines(None)) reach summary.json with the
    # reason; a tiny scenario and one reference variant keep it short
    from cross_checks.cli.engines import resolve_engines
    from cross_checks.scenario import parse_scenario
    from cross_checks.sweep import run_sweep
    from tests.helpers.scenarios import TINY
    monkeypatch.setenv("RBCHECK_CACHE_DIR", str(tmp_path / "cache"))
    _, skipped = resolve_engines(None)
    summary = run_sweep([parse_scenario(TINY)], ["reference:expmap_gyro"], tmp_path / "r", jobs=1,
                        skipped={k: v for k, v in skipped.items() if k.startswith("rapier:")},
                        second_reference=False)
    assert {v["name"] for v in summary["skipped_variants"]} == {f"rapier:{v}" for v in rapier_engine.VARIANTS}
    assert all("rapier3d is not installed (pip install 'rbcheck[rapier]')" in v["reason"]
               for v in summary["skipped_variants"])
    assert summary["run"]["failed_runs"] == 0 and summary["convergence"]
    assert not any(c["engine"].startswith("rapier:") for c in summary["convergence"])
