"""Brax is optional: without brax (its absence simulated), the adapter says "not installed"
(EngineNotInstalled), `rbcheck list` and `--version` say so, a default sweep skips its variants with that
reason, and asking for it is bad input; brax without jax is told apart from an absent brax. The adapter module
itself never imports brax or jax."""
import pytest

from cross_checks import engines
from cross_checks.cli import main
from cross_checks.cli.parser import _version_text
from cross_checks.engines import brax_engine, install


@pytest.fixture
def no_brax(monkeypatch):
    real = install.installed_version
    monkeypatch.setattr(install, "installed_version", lambda dist: None if dist == "brax" else real(dist))
    brax_engine._lib.cache_clear()
    engines.reset_registry()
    yield
    brax_engine._lib.cache_clear()
    engines.reset_registry()


def test_version_raises_engine_not_installed_with_the_extra_to_install(no_brax):
    words = r"brax is not installed \(pip install 'rbcheck\[brax\]'\)"
    with pytest.raises(install.EngineNotInstalled, match=words):
        brax_engine.version()


def test_brax_without_jax_is_not_an_absent_brax(monkeypatch):
    monkeypatch.setattr(install, "installed_version", lambda dist: "0.14.2" if dist == "brax" else None)
    with pytest.raises(ImportError, match="brax 0.14.2 is installed but jax or jaxlib is not") as e:
        brax_engine.version()
    assert not isinstance(e.value, install.EngineNotInstalled)


def test_list_and_version_say_brax_is_not_installed(no_brax, capsys):
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    assert "brax:generalized" in out and "brax is not installed (pip install 'rbcheck[brax]')" in out
    infos = [v for v in engines.all_variants() if v.engine == "brax"]
    assert len(infos) == len(brax_engine.VARIANTS)
    assert not any(v.available or v.installed or v.required for v in infos)
    assert "brax: brax is not installed" in _version_text()


def test_a_default_sweep_skips_brax_and_asking_for_it_is_bad_input(no_brax, tmp_path, capsys):
    from cross_checks.cli.engines import resolve_engines
    run, skipped = resolve_engines(None)
    assert not any(v.startswith("brax:") for v in run)
    assert {v for v in skipped if v.startswith("brax:")} == {f"brax:{v}" for v in brax_engine.VARIANTS}
    assert all("brax is not installed" in skipped[f"brax:{v}"] for v in brax_engine.VARIANTS)
    assert main(["sweep", "projectile", "--engines", "brax", "--out", str(tmp_path / "r")]) == 2
    assert "brax is not installed" in capsys.readouterr().err


def test_importing_the_adapter_imports_neither_brax_nor_jax():
    import subprocess
    import sys
    code = ("import sys\nimport cross_checks.engines.brax_engine\n"
            "print([m for m in ('brax', 'jax') if m in sys.modules])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and out.stdout.strip() == "[]", out.stderr
