"""MuJoCo Warp is optional: without mujoco-warp (its absence simulated), the adapter says "not installed"
(EngineNotInstalled) with the pip hint, `rbcheck list` and `--version` say so, a default sweep skips its
variants with that reason, and asking for it is bad input; an installed mujoco-warp whose Warp is missing is
told apart from an absent one. None of it imports Warp."""
import importlib.util

import pytest

from cross_checks import engines
from cross_checks.cli import main
from cross_checks.cli.parser import _version_text
from cross_checks.engines import install, mujoco_warp_engine


@pytest.fixture
def no_mujoco_warp(monkeypatch):
    real = install.installed_version
    monkeypatch.setattr(install, "installed_version",
                        lambda dist: None if dist == "mujoco-warp" else real(dist))
    engines.reset_registry()
    yield
    engines.reset_registry()


def test_version_raises_engine_not_installed_with_the_extra_to_install(no_mujoco_warp):
    with pytest.raises(install.EngineNotInstalled,
                       match=r"mujoco-warp is not installed \(pip install 'rbcheck\[mujoco_warp\]'\)"):
        mujoco_warp_engine.version()


def test_a_broken_install_is_not_an_absent_one(monkeypatch):
    real = importlib.util.find_spec
    monkeypatch.setattr(install, "installed_version",
                        lambda dist: "4.0.0" if dist == "mujoco-warp" else None)
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name == "warp" else real(name, *a))
    said = r"mujoco-warp 4.0.0 is installed but cannot be imported: warp-lang is missing"
    with pytest.raises(ImportError, match=said) as e:
        mujoco_warp_engine.version()
    assert not isinstance(e.value, install.EngineNotInstalled)


def test_list_and_version_say_mujoco_warp_is_not_installed(no_mujoco_warp, capsys):
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    assert "mujoco_warp:euler" in out
    assert "mujoco-warp is not installed (pip install 'rbcheck[mujoco_warp]')" in out
    infos = [v for v in engines.all_variants() if v.engine == "mujoco_warp"]
    assert len(infos) == len(mujoco_warp_engine.VARIANTS) == 5
    assert not any(v.available or v.installed or v.required for v in infos)
    assert "mujoco_warp: mujoco-warp is not installed" in _version_text()


def test_a_default_sweep_skips_mujoco_warp_and_asking_for_it_is_bad_input(no_mujoco_warp, tmp_path, capsys):
    from cross_checks.cli.engines import resolve_engines
    run, skipped = resolve_engines(None)
    assert not any(v.startswith("mujoco_warp:") for v in run)
    assert {v for v in skipped if v.startswith("mujoco_warp:")} == {f"mujoco_warp:{v}"
                                                                   for v in mujoco_warp_engine.VARIANTS}
    assert all("mujoco-warp is not installed" in skipped[f"mujoco_warp:{v}"]
               for v in mujoco_warp_engine.VARIANTS)
    assert main(["sweep", "projectile", "--engines", "mujoco_warp", "--out", str(tmp_path / "r")]) == 2
    assert "mujoco-warp is not installed" in capsys.readouterr().err


@pytest.mark.slow
def test_a_sweep_of_other_engines_runs_cleanly_with_mujoco_warp_absent(no_mujoco_warp, tmp_path, capsys):
    # the whole path of a sweep (list, resolve, run, report) with the engine hidden: the other engine's rows
    # only, exit 0 (~2 min with a cold result cache: the reference solves and the report)
    import json
    out = tmp_path / "r"
    assert main(["sweep", "projectile", "--engines", "reference:expmap_gyro", "--jobs", "1",
                 "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert {r["engine"] for r in summary["convergence"]} == {"reference:expmap_gyro"}
    assert not any(v["name"].startswith("mujoco_warp") for v in summary["variants"])
