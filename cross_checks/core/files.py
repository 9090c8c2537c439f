"""Writing files so that a reader never sees a half-written one: atomic text and npz writes, and the one
JSON encoder of NumPy values every JSON rbcheck writes uses."""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

from reference_sim.compiled import unwritable


def cache_dir(sub: str = "") -> Path:
    """The user's rbcheck cache directory: ``$RBCHECK_CACHE_DIR``, else ``$XDG_CACHE_HOME/rbcheck``, else
    ``~/.cache/rbcheck`` (never inside a results directory); with ``sub``, that folder inside it (where an
    engine keeps its compiled kernels: ``jax``, ``warp``, ...). Nothing is created."""
    if os.environ.get("RBCHECK_CACHE_DIR"):
        root = Path(os.environ["RBCHECK_CACHE_DIR"])
    else:
        base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
        root = Path(base) / "rbcheck"
    return root / sub if sub else root


def kernel_cache_dir(engine: str) -> Path:
    """Where ``engine`` keeps what it compiles (JAX's persistent compilation cache, Warp's and Genesis's
    kernels): ``$RBCHECK_KERNEL_CACHE_DIR/ENGINE``, else ``$XDG_CACHE_HOME/rbcheck/kernels/ENGINE``
    (``~/.cache/rbcheck/kernels/ENGINE``). Deliberately NOT under ``$RBCHECK_CACHE_DIR``: a fresh result
    cache (a test's, a ``--no-cache`` sweep's) must not recompile kernels that take seconds to minutes, and a
    kernel never decides a result (the result cache's key covers the engine's version). Nothing is created."""
    if os.environ.get("RBCHECK_KERNEL_CACHE_DIR"):
        return Path(os.environ["RBCHECK_KERNEL_CACHE_DIR"]) / engine
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "rbcheck" / "kernels" / engine


_SKIPPED_CACHES: dict = {}


def usable_cache_dir(folder, what: str) -> Path:
    """``folder`` (created) when a file can be written there; else a private temporary folder of this process
    (removed at exit) in its place, and one line on stderr, once per folder, naming it and the reason: a
    cache is a cache, and a read-only or full one must not stop what it only speeds up."""
    folder = Path(folder)
    if str(folder) in _SKIPPED_CACHES:
        return _SKIPPED_CACHES[str(folder)]
    why = unwritable(folder)
    if not why:
        return folder
    import atexit
    import shutil
    import sys
    private = Path(tempfile.mkdtemp(prefix="rbcheck-kernels-"))
    atexit.register(shutil.rmtree, private, True)
    _SKIPPED_CACHES[str(folder)] = private
    print(f"rbcheck: {what} cache folder {folder} skipped ({why}); using {private} for this run instead",
          file=sys.stderr, flush=True)
    return private


def usable_cores() -> int:
    """Cores this process may run on (its CPU affinity where the OS reports it): the default number of
    worker processes of a sweep and of report drawing."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def umask() -> int:
    """The process's umask (read without changing it)."""
    mask = os.umask(0)
    os.umask(mask)
    return mask


def atomic_write(path, write, *, suffix: str = "") -> None:
    """Call ``write(tmp)`` on a temporary file beside ``path``, give it the user's usual mode (mkstemp
    creates 0600) and rename it onto ``path``: a reader never sees a half-written file and an interrupted
    write leaves the old one intact."""
    path = Path(path)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=suffix, dir=path.parent or ".")
    except OSError as exc:
        raise _naming(exc, path) from None
    os.close(fd)
    try:
        write(tmp)
        os.chmod(tmp, 0o666 & ~umask())
        os.replace(tmp, path)
    except OSError as exc:   # a full disk, a quota, an I/O error: said with the file rbcheck was writing
        Path(tmp).unlink(missing_ok=True)
        raise _naming(exc, path) from None
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _naming(exc: OSError, path: Path) -> OSError:
    """``exc`` with the file it concerns (the target, not the temporary beside it): "No space left on
    device" alone does not say what could not be written."""
    if exc.filename and not Path(str(exc.filename)).name.startswith(f".{path.name}."):
        return exc
    return type(exc)(exc.errno, exc.strerror or str(exc), str(path))


def atomic_write_text(path, text: str) -> None:
    """Write ``text`` (UTF-8, newlines as given) to ``path`` atomically (:func:`atomic_write`)."""
    atomic_write(path, lambda tmp: Path(tmp).write_text(text, encoding="utf-8", newline=""))


def json_default(o):
    """``json.dumps(default=...)`` for NumPy scalars and arrays (shared by every JSON rbcheck writes)."""
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def save_npz_atomic(path: Path, arrays: dict, *, compress: bool = True) -> None:
    """Write ``arrays`` as an npz at ``path`` atomically (its folder is created). ``compress=False`` for
    files only rbcheck reads back (cache entries, a sweep's working files): float64 states compress little,
    at many times the cost of writing them."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    save = np.savez_compressed if compress else np.savez
    atomic_write(path, lambda tmp: save(tmp, **arrays), suffix=".npz")


def npz_array_bytes(path) -> dict:
    """``{member: bytes}`` of the arrays of an ``.npz``, from their npy headers only (shape x itemsize): what
    reading each would allocate, known before any is read. ValueError for a member that is not a plain
    array (an object array, a damaged header)."""
    import zipfile

    import numpy as np
    out = {}
    with zipfile.ZipFile(path) as zf:
        for info in zf.infolist():
            name = info.filename[:-4] if info.filename.endswith(".npy") else info.filename
            with zf.open(info) as fh:
                version = np.lib.format.read_magic(fh)
                read = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                        else np.lib.format.read_array_header_2_0)
                shape, _fortran, dtype = read(fh, max_header_size=10000)
            if dtype.hasobject:
                raise ValueError(f"{name}: an object array")
            out[name] = int(np.prod(shape, dtype=object)) * dtype.itemsize
    return out


def check_npz_size(path, max_bytes: int) -> None:
    """ValueError naming the member when reading the ``.npz`` at ``path`` would allocate more than
    ``max_bytes`` in all (checked from the npy headers, before reading any data)."""
    sizes = npz_array_bytes(path)
    total = sum(sizes.values())
    if total > max_bytes:
        big = max(sizes, key=lambda name: sizes[name])
        raise ValueError(f"its arrays would take {total / 2 ** 20:.0f} MiB to read ({big}: "
                         f"{sizes[big] / 2 ** 20:.0f} MiB), more than the {max_bytes / 2 ** 20:.0f} MiB "
                         "allowed (cross_checks/core/tolerances.py)")

