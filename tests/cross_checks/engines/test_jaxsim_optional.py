"""jaxsim is optional: without it (its absence simulated), the adapter says "not installed"
(EngineNotInstalled), `rbcheck list` and `--version` say so, a default sweep skips its variants with that
reason, and asking for it is bad input; an installed jaxsim that cannot be found on the path is told apart
from an absent one. None of this imports JAX."""

import importlib.util

import pytest

from cross_checks import engines
from cross_checks.cli import main
from cross_checks.cli.parser import _version_text
from cross_checks.engines import install, jaxsim_engine


@pytest.fixture
def no_jaxsim(monkeypatch):
    real = install.installed_version
    monkeypatch.setattr(
        install, "installed_version", lambda dist: None if dist == "jaxsim" else real(dist)
    )
    engines.reset_registry()
    yield
    engines.reset_registry()


def test_version_raises_engine_not_installed_with_the_extra_to_install(no_jaxsim):
    with pytest.raises(
        install.EngineNotInstalled, match=r"jaxsim is not installed \(pip install 'rbcheck\[jaxsim\]'\)"
    ):
        jaxsim_engine.version()


def test_a_broken_install_is_not_an_absent_one(monkeypatch):
    monkeypatch.setattr(
        install, "installed_version", lambda dist: "0.9.0" if dist == "jaxsim" else None
    )
    real = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util, "find_spec", lambda name, *a: None if name == "jaxsim" else real(name, *a)
    )
    with pytest.raises(ImportError, match="jaxsim 0.9.0 is installed but cannot be imported") as e:
        jaxsim_engine.version()
    assert not isinstance(e.value, install.EngineNotInstalled)


def test_list_and_version_say_jaxsim_is_not_installed(no_jaxsim, capsys):
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    assert (
        "jaxsim:semi_implicit_euler" in out
        and "jaxsim is not installed (pip install 'rbcheck[jaxsim]')" in out
    )
    infos = [v for v in engines.all_variants() if v.engine == "jaxsim"]
    assert len(infos) == len(jaxsim_engine.VARIANTS) and not any(
        v.available or v.installed or v.required for v in infos
    )
    assert "jaxsim: jaxsim is not installed" in _version_text()
    # the other engines are untouched
    assert any(v.available for v in engines.all_variants() if v.engine == "mujoco")


def test_a_default_sweep_skips_jaxsim_and_asking_for_it_is_bad_input(no_jaxsim, tmp_path, capsys):
    from cross_checks.cli.engines import resolve_engines

    run, skipped = resolve_engines(None)
    assert not any(v.startswith("jaxsim:") for v in run)
    assert {v for v in skipped if v.startswith("jaxsim:")} == {f"jaxsim:{v}" for v in jaxsim_engine.VARIANTS}
    assert all("jaxsim is not installed" in skipped[f"jaxsim:{v}"] for v in jaxsim_engine.VARIANTS)
    assert main(["sweep", "projectile", "--engines", "jaxsim", "--out", str(tmp_path / "r")]) == 2
    assert "jaxsim is not installed" in capsys.readouterr().err


def test_the_adapter_module_does_not_import_jax():
    import subprocess
    import sys

    code = (
        "import sys\nimport cross_checks.engines.jaxsim_engine as je\nje.JaxsimAdapter().source_files()\n"
        "print(any(m.split('.')[0] in ('jax', 'jaxlib', 'jaxsim') for m in sys.modules))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120
    )
    assert out.stdout.strip() == "False"
