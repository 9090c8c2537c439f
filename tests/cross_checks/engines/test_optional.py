"""Every optional engine (rbcheck's registered engines but the required ones) without its distribution (its
absence simulated, as each adapter finds it: package metadata, a module-level import, an import spec): its
adapter says "not installed" (EngineNotInstalled) with the extra to install, `rbcheck list` and `--version`
list its variants as unavailable with that reason, a default sweep skips them and records why, asking for it
is bad input, and every other engine runs. An installed distribution that cannot be imported (a missing
package it runs on, a library that fails to load) is told apart from an absent one. Importing the adapters
and listing the engines starts none of the heavy engines (a sweep's parent must not start JAX or Warp before
it forks)."""
import importlib.util
import json
import subprocess
import sys
from dataclasses import dataclass

import pytest

from cross_checks import engines
from cross_checks.cli import main
from cross_checks.cli.engines import resolve_engines as _resolve_engines
from cross_checks.cli.parser import _version_text
from cross_checks.engines import (
    brax_engine,
    dart_engine,
    drake_engine,
    genesis_engine,
    install,
    jaxsim_engine,
    mjx_engine,
    mujoco_warp_engine,
    newton_engine,
    physx_engine,
    rapier_engine,
)


def _import_stand_in(attr: str, error: str):
    """An adapter module that imports its engine at import time (optional_import): that import failed."""
    def patch(mp, module):
        mp.setattr(module, attr, None)
        mp.setattr(module, "_IMPORT_ERROR", ImportError(error))
    return patch


def _spec_missing(*names):
    """The import spec of these packages not found (the distribution's metadata still there)."""
    def patch(mp, module):
        real = importlib.util.find_spec
        mp.setattr(importlib.util, "find_spec", lambda name, *a: None if name in names else real(name, *a))
    return patch


@dataclass(frozen=True)
class Optional:
    """One optional engine: its adapter module, the distribution that says it is installed, its extra; how
    its absence and a broken install are simulated, and what the broken install says."""
    engine: str
    module: object
    dist: str
    extra: str
    broken_version: str                     # the version its metadata gives in the broken install
    broken: object                          # patch(mp, module): the broken install, beside that metadata
    broken_words: str                       # what version() says then (a regular expression)
    absent: object = None                   # patch(mp, module) besides the metadata, where needed
    broken_metadata_only: bool = False      # the broken install: only this distribution's metadata, no other
    n_variants: int | None = None           # pinned where its docs count them

    @property
    def not_installed(self) -> str:
        return f"{self.dist} is not installed (pip install 'rbcheck[{self.extra}]')"


OPTIONAL = {o.engine: o for o in [
    Optional("drake", drake_engine, "drake", "drake", "1.51.1",
             _import_stand_in("pydrake", "libdrake.so: cannot open shared object file"),
             "drake 1.51.1 is installed but cannot be imported: ImportError: libdrake.so",
             absent=_import_stand_in("pydrake", "No module named 'pydrake'"), n_variants=4),
    Optional("dart", dart_engine, "dartpy", "dart", "6.20.0",
             _import_stand_in("dart", "libfcl.so.0.7: cannot open shared object file"),
             "dartpy 6.20.0 is installed but cannot be imported: ImportError: libfcl",
             absent=_import_stand_in("dart", "No module named 'dartpy'")),
    Optional("jaxsim", jaxsim_engine, "jaxsim", "jaxsim", "0.9.0", _spec_missing("jaxsim"),
             "jaxsim 0.9.0 is installed but cannot be imported"),
    Optional("genesis", genesis_engine, "genesis-world", "genesis", "1.4.5",
             lambda mp, m: mp.setattr(m, "_findable", lambda name: name != "torch"),
             "genesis-world 1.4.5 is installed but cannot be imported: no module named 'torch'"),
    # brax without jax and jaxlib (their metadata absent): told apart from an absent brax
    Optional("brax", brax_engine, "brax", "brax", "0.14.2", lambda mp, m: None,
             r"brax 0.14.2 is installed but cannot be imported: jax is missing "
             r"\(pip install 'rbcheck\[brax\]'\)",
             broken_metadata_only=True),
    Optional("mjx", mjx_engine, "mujoco-mjx", "mjx", "3.17.0", _spec_missing("jaxlib"),
             "mujoco-mjx 3.17.0 is installed but cannot be imported: jaxlib is missing"),
    Optional("rapier", rapier_engine, "rapier3d", "rapier", "0.36.1",
             _import_stand_in("rapier", "_rapier3d.abi3.so: undefined symbol: PyObject_Vectorcall"),
             "rapier3d 0.36.1 is installed but cannot be imported: ImportError: _rapier3d",
             absent=_import_stand_in("rapier", "No module named 'rapier3d'")),
    Optional("physx", physx_engine, "sapien", "physx", "3.0.3", _spec_missing("sapien"),
             "sapien 3.0.3 is installed but cannot be imported: sapien is missing"),
    Optional("mujoco_warp", mujoco_warp_engine, "mujoco-warp", "mujoco_warp", "4.0.0", _spec_missing("warp"),
             "mujoco-warp 4.0.0 is installed but cannot be imported: warp-lang is missing", n_variants=5),
    Optional("newton", newton_engine, "newton", "newton", "1.8.0", _spec_missing("warp"),
             "newton 1.8.0 is installed but cannot be imported: warp-lang is missing"),
]}
#: Caches of what an adapter read from the metadata once per process.
_CACHES = (brax_engine._lib, physx_engine._dist_version)


def test_every_registered_engine_is_required_or_listed_here():
    # a new optional engine gets its absence and broken install checked here, not in a file of its own
    builtin = [e.name for e in engines.engine_entries() if e.builtin]
    assert set(builtin) == set(OPTIONAL) | set(engines.REQUIRED_ENGINES)
    assert not set(OPTIONAL) & set(engines.REQUIRED_ENGINES)


def _metadata(mp, fake):
    mp.setattr(install, "installed_version", fake)


def _clear():
    for cache in _CACHES:
        cache.cache_clear()
    engines.reset_registry()


@pytest.fixture
def hide(monkeypatch):
    """``hide(*engines)``: those engines' distributions absent, as each adapter finds them; the registry
    scanned again (and again after the test, with everything back)."""
    real = install.installed_version

    def _hide(*names):
        dists = {OPTIONAL[n].dist for n in names}
        _metadata(monkeypatch, lambda dist: None if dist in dists else real(dist))
        for n in names:
            if OPTIONAL[n].absent is not None:
                OPTIONAL[n].absent(monkeypatch, OPTIONAL[n].module)
        _clear()

    yield _hide
    monkeypatch.undo()
    _clear()


@pytest.fixture
def broken(monkeypatch):
    """``broken(engine)``: that engine's distribution installed (its metadata) but not importable."""
    real = install.installed_version

    def _broken(name):
        o = OPTIONAL[name]
        _metadata(monkeypatch, lambda dist: o.broken_version if dist == o.dist
                  else None if o.broken_metadata_only else real(dist))
        o.broken(monkeypatch, o.module)
        _clear()
        return o

    yield _broken
    monkeypatch.undo()
    _clear()


@pytest.mark.parametrize("name", OPTIONAL)
def test_version_raises_engine_not_installed_with_the_extra_to_install(name, hide):
    hide(name)
    o = OPTIONAL[name]
    with pytest.raises(install.EngineNotInstalled) as e:
        o.module.version()
    assert str(e.value) == o.not_installed


@pytest.mark.parametrize("name", OPTIONAL)
def test_a_broken_install_is_not_an_absent_one(name, broken):
    o = broken(name)
    with pytest.raises(ImportError, match=o.broken_words) as e:
        o.module.version()
    assert not isinstance(e.value, install.EngineNotInstalled)
    # the registry keeps it apart too: installed, unavailable, and why
    infos = [v for v in engines.all_variants() if v.engine == name]
    assert infos and all(v.installed and not v.available and o.broken_version in v.reason for v in infos)


@pytest.mark.parametrize("name", OPTIONAL)
def test_the_adapter_lists_its_variants_and_files_without_its_engine(name, hide):
    hide(name)
    o = OPTIONAL[name]
    adapter = next(e.adapter for e in engines.engine_entries() if e.name == name)
    assert adapter.source_files()[0].name == f"{o.module.__name__.rsplit('.', 1)[1]}.py"
    assert list(adapter.variants) == list(o.module.VARIANTS)


@pytest.mark.parametrize("name", OPTIONAL)
def test_list_and_version_say_it_is_not_installed(name, hide, capsys):
    hide(name)
    o = OPTIONAL[name]
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    for v in o.module.VARIANTS:
        assert f"{name}:{v}" in out
    assert o.not_installed in out
    infos = [v for v in engines.all_variants() if v.engine == name]
    assert len(infos) == len(o.module.VARIANTS) == (o.n_variants or len(o.module.VARIANTS))
    assert not any(v.available or v.installed or v.required for v in infos)
    assert all(v.reason == o.not_installed for v in infos)
    assert f"{name}: {o.dist} is not installed" in _version_text()
    # the required engines are untouched
    available = {v.engine for v in engines.all_variants() if v.available}
    assert name not in available and set(engines.REQUIRED_ENGINES) <= available


@pytest.mark.parametrize("name", OPTIONAL)
def test_a_default_sweep_skips_it_and_asking_for_it_is_bad_input(name, hide, tmp_path, capsys):
    hide(name)
    o = OPTIONAL[name]
    run, skipped = _resolve_engines(None)
    assert not any(v.startswith(f"{name}:") for v in run)
    assert {v for v in skipped if v.startswith(f"{name}:")} == {f"{name}:{v}" for v in o.module.VARIANTS}
    assert all(skipped[f"{name}:{v}"] == o.not_installed for v in o.module.VARIANTS)
    # any other variant skipped is an optional engine that is not installed here either
    assert all("is not installed" in r for r in skipped.values())
    assert main(["sweep", "projectile", "--engines", name, "--out", str(tmp_path / "r")]) == 2
    assert f"{o.dist} is not installed" in capsys.readouterr().err
    assert not (tmp_path / "r").exists()


def test_a_default_sweep_without_the_optional_engines_records_each_skip_and_has_no_second_reference(
        hide, tmp_path):
    # what `rbcheck sweep` does with no --engines, run on one variant to stay quick: the skipped variants
    # reach summary.json with their reasons (what compare reads to count an engine's baseline rows in one
    # line instead of failing on them); without Drake there is no second reference
    from cross_checks.scenario import load_scenario
    from cross_checks.sweep.run import run_sweep
    hide(*OPTIONAL)
    _, skipped = _resolve_engines(None)
    assert set(skipped) == {f"{n}:{v}" for n, o in OPTIONAL.items() for v in o.module.VARIANTS}
    out = tmp_path / "r"
    summary = run_sweep([load_scenario("projectile")], ["reference:rk4"], out, jobs=1, use_cache=False,
                        skipped=skipped, progress=False)
    recorded = {s["name"]: s for s in json.loads((out / "summary.json").read_text())["skipped_variants"]}
    assert set(recorded) == set(skipped)
    for n, o in OPTIONAL.items():
        for v in o.module.VARIANTS:
            s = recorded[f"{n}:{v}"]
            assert s["reason"] == o.not_installed and s["installed"] is False and s["required"] is False
    assert summary["scenarios"][0]["second_reference"] is None
    assert summary["run"]["failed_runs"] == 0
    assert {c["engine"] for c in summary["convergence"]} == {"reference:rk4"}


def test_a_sweep_of_another_engine_runs_cleanly_through_the_cli_without_the_optional_engines(hide, tmp_path):
    # the whole path of a sweep (list, resolve, run, report) with every optional engine hidden: the other
    # engine's rows only, exit 0
    hide(*OPTIONAL)
    out = tmp_path / "r"
    assert main(["sweep", "projectile", "--engines", "reference:course", "--jobs", "1",
                 "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert {r["engine"] for r in summary["convergence"]} == {"reference:course"}
    assert not any(v["name"].split(":")[0] in OPTIONAL for v in summary["variants"])
    rows = (out / "results.csv").read_text()
    assert not any(f"{n}:" in rows for n in OPTIONAL)


#: The packages each lazily-imported engine would start, by the engine that imports them on first use.
HEAVY = {"brax": ("brax", "jax", "jaxlib"), "jaxsim": ("jaxsim", "jax", "jaxlib"), "mjx": ("jax", "jaxlib"),
         "genesis": ("genesis", "torch", "quadrants"), "physx": ("sapien",),
         "mujoco_warp": ("mujoco_warp", "warp"), "newton": ("newton", "warp")}


def test_importing_the_adapters_and_listing_every_engine_starts_none_of_the_heavy_engines():
    # in a fresh process (this one may have started them in another test): every adapter module imported,
    # each adapter's files listed, and what the CLI does at start (list and version every engine), before a
    # sweep forks its workers
    code = ("import sys, json\nfrom cross_checks import engines\n"
            + "".join(f"import cross_checks.engines.{n}_engine\n" for n in HEAVY)
            + "for e in engines.engine_entries():\n    e.adapter.source_files()\n"
            "engines.all_variants()\n"
            "print(json.dumps(sorted(m for m in sys.modules if m.split('.')[0] in "
            f"{sorted({m for ms in HEAVY.values() for m in ms})!r})))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    started = set(json.loads(out.stdout.strip().splitlines()[-1]))
    assert started == set(), {n: [m for m in ms if m in started] for n, ms in HEAVY.items()}
