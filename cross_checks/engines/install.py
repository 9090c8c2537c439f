"""The optional engines' install plumbing: an engine imported on first use (never at rbcheck's start), its
installed version from package metadata, the files its results depend on found without importing it, and
the difference said between an engine that is not installed (:class:`EngineNotInstalled`, with the pip
extra that installs it) and one installed but broken (an ImportError with its version and the import's own
words): a broken install must never read as an absent one.
"""
from __future__ import annotations

import contextlib
import functools
import importlib
import os
import sys
import types
from pathlib import Path

from cross_checks.engines.base import EngineError

__all__ = ["EngineNotInstalled", "quiet_fd2", "optional_import", "optional_world", "package_root",
           "package_files", "installed_version", "release", "library_files", "require", "check_installed",
           "first_import", "engine_or_error"]


class EngineNotInstalled(ImportError):
    """The engine's distribution is not installed at all (as opposed to installed and failing to import)."""


@contextlib.contextmanager
def quiet_fd2():
    """File descriptor 2 sent to /dev/null for the duration: what a native library prints there (PyBullet's
    build time at import, Warp's missing CUDA driver at ``wp.init``) would land in every CLI run's error
    output. Nothing is silenced where fd 2 cannot be duplicated."""
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError, AttributeError):   # pragma: no cover - no usable fd 2
        yield
        return
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 2)
    os.close(devnull)
    try:
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def optional_import(name: str, *, quiet_stderr: bool = False):
    """``(module, None)``, or ``(None, the ImportError)`` when ``name`` cannot be imported: an adapter
    module imports without its engine so that the registry can say why the engine is unavailable.
    ``quiet_stderr``: fd 2 silenced during the import (:func:`quiet_fd2`)."""
    with quiet_fd2() if quiet_stderr else contextlib.nullcontext():
        try:
            return importlib.import_module(name), None
        except ImportError as exc:  # pragma: no cover - exercised only where the engine is missing
            return None, exc


def optional_world(name: str, world: str, *placeholders: str, quiet_stderr: bool = False):
    """``(engine module, None, world module)`` for an adapter built on ``cross_checks.engines.worlds.<world>``
    (the rbcheck-free model that ``rbcheck repro`` embeds, which imports the engine itself), or, where
    ``name`` cannot be imported, ``(None, the ImportError, a namespace of empty classes named
    placeholders)``: the adapter's classes built on the world's still load, and the registry says why the
    engine is unavailable (:func:`optional_import`)."""
    module, error = optional_import(name, quiet_stderr=quiet_stderr)
    if error is None:
        return module, None, importlib.import_module(f"cross_checks.engines.worlds.{world}")
    return None, error, types.SimpleNamespace(**{k: type(k, (), {}) for k in placeholders})


def package_root(module: str) -> Path | None:
    """The folder of the installed package ``module`` (dotted: its parent packages are imported, it is not),
    or None where it is not installed: how an adapter lists the engine's sources for the cache key without
    starting the engine (a sweep's parent must not start JAX or Warp before forking)."""
    import importlib.util
    try:
        spec = importlib.util.find_spec(module)
    except (ImportError, ValueError):
        return None
    if spec is None:
        return None
    if spec.submodule_search_locations:
        return Path(next(iter(spec.submodule_search_locations)))
    return Path(spec.origin).parent if spec.origin else None


def package_files(module: str, *parts: str, pattern: str = "*.py") -> list:
    """The files matching ``pattern`` in the folders ``parts`` (paths relative to the installed package
    ``module``, found by :func:`package_root` without importing it; a part naming a file is taken as it is;
    ``*_test.py`` left out), sorted; [] where the package is not installed. With no ``parts``: the package
    folder itself."""
    root = package_root(module)
    if root is None:
        return []
    files: list = []
    for part in parts or ("",):
        p = root / part
        found = sorted(p.glob(pattern)) if p.is_dir() else [p] if p.is_file() else []
        files += [f for f in found if not f.name.endswith("_test.py")]
    return files


def installed_version(dist: str) -> str | None:
    """The installed version of distribution ``dist`` from its metadata (None when it is not installed)."""
    from importlib.metadata import PackageNotFoundError
    from importlib.metadata import version as dist_version
    try:
        return dist_version(dist)
    except PackageNotFoundError:
        return None


@functools.cache
def release(dist: str, runs_on: tuple = ()) -> str:
    """Distribution ``dist``'s installed version ("unknown" without metadata), read once per process, and
    with ``runs_on = (label, distribution)`` the version of what it runs on: ``"4.0.0 (warp 1.19.0)"``."""
    ver = installed_version(dist) or "unknown"
    return f"{ver} ({runs_on[0]} {installed_version(runs_on[1])})" if runs_on else ver


def library_files(module) -> list:
    """The compiled files behind an engine's Python module, which its results depend on beyond a version
    string: the module itself when it is an extension (pybullet), else the shared libraries in its package
    folder and its ``lib/`` folder (libmujoco.so.X, pydrake/lib/libdrake.so). [] without the module."""
    if module is None or not getattr(module, "__file__", None):
        return []
    f = Path(module.__file__)
    if f.suffix == ".so" or ".so." in f.name:
        return [f]
    folder = f.parent
    return sorted(p for d in (folder, folder / "lib") if d.is_dir() for p in d.iterdir()
                  if p.is_file() and (p.suffix == ".so" or ".so." in p.name))


def require(module, import_error, name: str, dist: str | None = None, hint: str = "") -> None:
    """When :func:`optional_import` could not import the engine's module: :class:`EngineNotInstalled`
    if its distribution ``dist`` (default ``name``) is not installed, else an ImportError saying that it
    IS installed (with its version) and how the import failed: a broken install (e.g. a wheel built for
    another NumPy) must never read as an absent one. ``hint`` says how to install it."""
    if module is not None:
        return
    ver = installed_version(dist or name)
    if ver is None:
        raise EngineNotInstalled(f"{name} is not installed{f' ({hint})' if hint else ''}")
    why = " ".join(f"{type(import_error).__name__}: {import_error}".split())
    raise ImportError(f"{name} {ver} is installed but cannot be imported: {why}")


def check_installed(dist: str, hint: str, needs: tuple = (), version_of=None) -> None:
    """From package metadata and import specs only (nothing imported): :class:`EngineNotInstalled` when the
    distribution ``dist`` is not installed; ImportError when it is but one of ``needs`` — (module,
    distribution) pairs it runs on — is missing. ``hint`` says how to install it; ``version_of`` (default
    :func:`installed_version`) reads a distribution's installed version."""
    import importlib.util
    version_of = version_of or installed_version
    if version_of(dist) is None:
        raise EngineNotInstalled(f"{dist} is not installed ({hint})")
    for module, needed in needs:
        if importlib.util.find_spec(module) is None or version_of(needed) is None:
            raise ImportError(f"{dist} {version_of(dist)} is installed but cannot be imported: "
                              f"{needed} is missing ({hint})")


@contextlib.contextmanager
def first_import(dist: str, version_of=None):
    """Around an engine's import on first use: any exception in the block is raised as ImportError "DIST VER
    is installed but cannot be imported: TYPE: words" (a broken install, never read as an absent one);
    ``version_of`` (default :func:`installed_version`) reads the installed version."""
    try:
        yield
    except Exception as exc:  # noqa: BLE001 - a broken install: the engine's own words
        ver = (version_of or installed_version)(dist)
        raise ImportError(f"{dist} {ver} is installed but cannot be imported: {type(exc).__name__}: {exc}") \
            from exc


def engine_or_error(engine):
    """``engine()`` (an adapter's import on first use) with its ImportError raised as :class:`EngineError`."""
    try:
        return engine()
    except ImportError as exc:
        raise EngineError(str(exc)) from None
