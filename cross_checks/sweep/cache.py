"""Self-verifying cache entries: an entry is trusted only when it proves it is the entry asked for.

An entry is an ``.npz`` of plain arrays (no pickles) plus ``__key__`` (the key it was stored under) and
``__mac__`` (an HMAC-SHA256 of the key and of every array's name, dtype, shape and bytes under the
secret ``.secret`` of the cache directory). :func:`load` returns None for anything that does not verify
and never raises; :func:`store` never breaks a sweep. Entries live in :func:`cache_dir`, never inside a
results directory. What is refused and what keys hold: docs/hardening.md, "The cache".
"""
from __future__ import annotations

import contextlib
import hashlib
import hmac
import json
import os
import secrets
from pathlib import Path

import numpy as np

from cross_checks.core.files import cache_dir, json_default

__all__ = ["load", "store", "mac", "cache_dir", "using_cache_dir", "pack", "unpack", "entry_path"]

_SECRETS: dict = {}


@contextlib.contextmanager
def using_cache_dir(path):
    """Use ``path`` as rbcheck's cache directory ($RBCHECK_CACHE_DIR, read by :func:`cache_dir`) for the
    duration; the previous setting is put back."""
    old = os.environ.get("RBCHECK_CACHE_DIR")
    os.environ["RBCHECK_CACHE_DIR"] = str(path)
    try:
        yield
    finally:
        if old is None:
            os.environ.pop("RBCHECK_CACHE_DIR", None)
        else:
            os.environ["RBCHECK_CACHE_DIR"] = old


def _read_secret(path: Path) -> bytes:
    """The secret's bytes, when ``path`` is a regular file (not a link: /dev/zero would be read for ever),
    at most 33 of them read; b"" otherwise."""
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0))
    except OSError:
        return b""
    with os.fdopen(fd, "rb") as fh:
        import stat
        if not stat.S_ISREG(os.fstat(fh.fileno()).st_mode):
            return b""
        return fh.read(33)


def _secret(root: Path) -> bytes:
    """The cache's HMAC secret (created on first use, readable by the owner only)."""
    root = Path(root)
    if str(root) in _SECRETS:
        return _SECRETS[str(root)]
    path = root / ".secret"
    data = _read_secret(path)
    if len(data) != 32:
        root.mkdir(parents=True, exist_ok=True)
        data = secrets.token_bytes(32)
        tmp = root / f".secret.{os.getpid()}.{secrets.token_hex(4)}"
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        try:
            os.link(tmp, path)  # first writer wins; the others read its secret
        except FileExistsError:
            theirs = _read_secret(path)
            if len(theirs) == 32:
                data = theirs
            else:   # not a secret (a symlink to /dev/zero, a damaged file): replaced, the link itself
                os.replace(tmp, path)
        finally:
            tmp.unlink(missing_ok=True)
    _SECRETS[str(root)] = data
    return data


def mac(root: Path, key: str, arrays: dict) -> str:
    """HMAC-SHA256 (hex) of ``key`` and every array of ``arrays`` (by sorted name)."""
    h = hmac.new(_secret(root), key.encode(), hashlib.sha256)
    for name in sorted(arrays):
        a = np.ascontiguousarray(arrays[name])
        h.update(f"\0{name}\0{a.dtype.str}\0{a.shape}\0".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def store(root: Path, path: Path, key: str, arrays: dict) -> None:
    """Write an entry (atomically); a read-only or full cache never breaks a sweep."""
    from cross_checks.core.files import save_npz_atomic
    try:
        save_npz_atomic(Path(path),
                        {**arrays, "__key__": np.array(key), "__mac__": np.array(mac(root, key, arrays))},
                        compress=False)   # read back by rbcheck only
    except OSError:
        pass


def entry_path(root, kind: str, key: str) -> Path:
    """Where the entry of ``key`` lives in the cache ``root``: ``<kind>/<first 2 hex digits>/<key>.npz``."""
    return Path(root) / kind / key[:2] / f"{key}.npz"


def pack(fields: dict, series: dict | None) -> dict:
    """A record as an entry's arrays: ``fields`` as JSON (``__json__``: no pickles) and each array of
    ``series`` as ``series::<name>``."""
    arrays = {"__json__": np.array(json.dumps(fields, default=json_default))}
    for k, a in (series or {}).items():
        arrays[f"series::{k}"] = a
    return arrays


def unpack(arrays: dict) -> tuple:
    """``(fields, series or None)`` of :func:`pack`'s arrays (KeyError or ValueError when unreadable)."""
    fields = json.loads(str(arrays["__json__"]))
    series = {k[len("series::"):]: v for k, v in arrays.items() if k.startswith("series::")}
    return fields, series or None


def _size_ok(path) -> bool:
    from cross_checks.core import tolerances as tol
    from cross_checks.core.files import check_npz_size
    try:
        check_npz_size(path, tol.CACHE_ENTRY_MAX_BYTES)
    except (ValueError, OSError):
        return False
    return True


def load(root: Path, path: Path, key: str) -> dict | None:
    """The arrays of the entry at ``path`` when it verifies as the entry of ``key``; else None (and
    the bad file is removed, so it is replaced by the recomputed entry)."""
    path = Path(path)
    if not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as data:
            # the sizes from the npy headers, then the key: an entry too large to be a job's, or of another
            # key, is never read
            if _size_ok(path) and str(data["__key__"]) == key:
                arrays = {k: data[k] for k in data.files}
                stored_mac = str(arrays.pop("__mac__"))
                arrays.pop("__key__")
                if hmac.compare_digest(stored_mac, mac(root, key, arrays)):
                    return arrays
    except Exception:  # noqa: BLE001 - a damaged entry in any way is simply not an entry
        pass
    try:
        path.unlink()
    except OSError:
        pass
    return None
