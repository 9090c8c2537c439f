"""What a cached number depends on besides a job's inputs (scenario content, variant, Δt): the code
that computes it (:func:`code_fingerprint`: every source file of ``FINGERPRINTED_PACKAGES`` plus the
adapter's ``cache_token()``) and the versions and machine that run it (:func:`environment`; the engine's
version is added per job). Both go into every cache key (:mod:`cross_checks.sweep.jobs`), so a change to
either recomputes; what a key holds: docs/hardening.md, "The cache".
"""
from __future__ import annotations

import hashlib
import importlib.util
import platform
from pathlib import Path

__all__ = ["FINGERPRINTED_PACKAGES", "fingerprinted_files", "source_fingerprint", "code_fingerprint",
           "environment", "cpu_model", "numerical_stack"]

#: The packages whose source determines a job's numbers: the course in NumPy and every cross_checks
#: layer a job runs through (README "Layout": core → scenario → engines → analysis → sweep). The
#: layers above (gates, reports, cli) only read results: editing them keeps the cache.
FINGERPRINTED_PACKAGES = ("reference_sim", "cross_checks.core", "cross_checks.scenario",
                          "cross_checks.engines", "cross_checks.analysis", "cross_checks.sweep")


def _package_dir(name: str) -> Path:
    return Path(importlib.util.find_spec(name).origin).resolve().parent


def fingerprinted_files(packages=FINGERPRINTED_PACKAGES) -> list:
    """``(name, path)`` of every ``*.py`` file below each package, recursively, and of the ``__init__.py``
    of the packages above it (importing a sub-package runs them), once each, in a fixed order; ``name``
    is the path relative to the folder holding the top package (``cross_checks/core/files.py``)."""
    found = {}
    for pkg in packages:
        root = _package_dir(pkg)
        base = root.parents[pkg.count(".")]
        parents = [root.parents[i] / "__init__.py" for i in range(pkg.count("."))]
        for p in [*parents, *root.rglob("*.py")]:
            found.setdefault(p.relative_to(base).as_posix(), p)
    return sorted(found.items())


def source_fingerprint(files) -> bytes:
    """SHA-256 of ``(name, path)`` files: each name and its bytes, length-prefixed (no two different
    sets of files hash alike; a renamed or moved file changes it as an edited one does)."""
    h = hashlib.sha256()
    for name, path in files:
        data = Path(path).read_bytes()
        h.update(f"{len(name)}:{name}:{len(data)}:".encode())
        h.update(data)
    return h.digest()


_BASE: list = []
_FINGERPRINTS: dict = {}


def _base_fingerprint() -> bytes:
    """:func:`source_fingerprint` of the fingerprinted packages, once per process (a sweep computes it
    before forking its workers, which inherit it)."""
    if not _BASE:
        _BASE.append(source_fingerprint(fingerprinted_files()))
    return _BASE[0]


def code_fingerprint(engine: str) -> str:
    """SHA-256 (16 hex digits) of the code that determines a job's result for ``engine``: the
    fingerprinted packages and the adapter's own ``cache_token()`` (its module; for an engine file,
    the file and the programs it names, as loaded). Memoised per engine name and adapter instance (held,
    matched by identity), so an engine file re-registered under the same name (a rebuilt program) gets
    its own fingerprint."""
    from cross_checks.engines import get_adapter
    adapter = get_adapter(engine)
    hit = _FINGERPRINTS.get(engine)
    if hit is None or hit[0] is not adapter:
        h = hashlib.sha256(_base_fingerprint())
        h.update(str(adapter.cache_token()).encode())
        hit = _FINGERPRINTS[engine] = (adapter, h.hexdigest()[:16])
    return hit[1]


def cpu_model() -> str:
    """The CPU's model name (Linux /proc/cpuinfo; else what the platform says)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor()


def _blas(module) -> str:
    """Name and version of the BLAS ``module`` (numpy or scipy) was built with ("" when it does not say)."""
    try:
        blas = module.show_config(mode="dicts")["Build Dependencies"]["blas"]
        return f"{blas.get('name', '')} {blas.get('version', '')}".strip()
    except Exception:  # noqa: BLE001 - an older or unusual build: its version number still keys the cache
        return ""


_ENVIRONMENT: list = []


def environment() -> list:
    """Versions that change a number: rbcheck, numpy, scipy, Python, the machine architecture and CPU
    model, and the BLAS builds of numpy and SciPy (computed once per process)."""
    if not _ENVIRONMENT:
        import numpy
        import scipy

        import reference_sim
        _ENVIRONMENT.extend([reference_sim.__version__, numpy.__version__, scipy.__version__,
                             platform.python_version(), platform.machine(), cpu_model(), _blas(numpy),
                             _blas(scipy)])
    return list(_ENVIRONMENT)


def _owner(library: str) -> str:
    """The package a loaded library ships with (``.../numpy.libs/libscipy_openblas64_-x.so`` -> numpy)."""
    folder = Path(library).parent.name
    return folder[:-len(".libs")] if folder.endswith(".libs") else Path(library).name


def _blas_kernels() -> dict:
    """``{package: "BLAS version (kernel architecture)"}`` of the BLAS libraries loaded (threadpoolctl):
    OpenBLAS picks its kernels per CPU (e.g. Haswell, SkylakeX, or what OPENBLAS_CORETYPE forces)."""
    try:
        import scipy.linalg  # noqa: F401 - loads SciPy's BLAS beside NumPy's
        from threadpoolctl import threadpool_info
        return {_owner(i["filepath"]): f"{i.get('internal_api', '')} {i.get('version', '')} "
                f"({i.get('architecture', '?')} kernels)"
                for i in threadpool_info() if i.get("user_api") == "blas"}
    except Exception:  # noqa: BLE001 - no threadpoolctl or an unusual build: the BLAS versions still say much
        return {}


def _compiled_target() -> str:
    """The CPU numba compiles the reference's fast path for ("" without numba): the instructions it may use
    (fused multiply-add, vector width) change last bits."""
    try:
        import llvmlite.binding as llvm
        return llvm.get_host_cpu_name()
    except Exception:  # noqa: BLE001 - no numba here: the Python steps run, nothing compiled
        return ""


def numerical_stack() -> str:
    """One line naming what decides a result's last bits beyond the versions of the libraries: the CPU
    architecture, the BLAS builds and the kernels they chose for this CPU, and the CPU numba compiles for.
    Two machines with equal versions and an equal numerical stack give bit-identical results (what the
    exact baseline test relies on); the kernel build or the machine's name do not enter."""
    kernels = "; ".join(f"{pkg} BLAS {what}" for pkg, what in sorted(_blas_kernels().items()))
    target = _compiled_target()
    return "; ".join(x for x in (platform.machine(), kernels, f"numba code for {target}" if target else "")
                     if x)
