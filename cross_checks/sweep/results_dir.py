"""The results directory as a place on disk: recognised by its marker ``.rbcheck-results.json`` (format,
schema_version, every file rbcheck wrote there), never replaced while it holds anything rbcheck did not
write, replaced by two renames from a staging sibling, and the siblings of a killed run (named by host,
pid and process start time) cleaned up or put back by the next one. The rules: docs/hardening.md,
"The results directory".
"""
from __future__ import annotations

import errno
import hashlib
import json
import os
import re
import secrets
import shutil
import socket
import sys
import tempfile
from pathlib import Path

from cross_checks.core import processes
from cross_checks.core.files import umask

__all__ = ["fix_permissions", "MARKER", "MARKER_FORMAT", "ResultsDirError", "read_marker", "write_marker",
           "listed_files", "check_output_dir", "check_writable_dir", "foreign_entries", "staging_dir",
           "replace_dir", "remove_stale_siblings", "owned_name", "is_owned_stale", "is_temp_leftover",
           "safe_file_stem", "inside", "is_mount_point", "work_place"]

MARKER = ".rbcheck-results.json"
MARKER_FORMAT = "rbcheck results directory"


class ResultsDirError(ValueError):
    """A directory that cannot be used as a results directory (message names it and the reason)."""


def _schema_version() -> int:
    from cross_checks.sweep.jobs import SCHEMA_VERSION
    return SCHEMA_VERSION


# --- the marker --------------------------------------------------------------------------------------

def read_marker(d: Path) -> dict | None:
    """The marker of ``d`` as a dict, or None when ``d`` has no valid marker (absent or damaged)."""
    p = Path(d) / MARKER
    try:
        m = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, ValueError, RecursionError):
        return None
    if not (isinstance(m, dict) and m.get("format") == MARKER_FORMAT and type(m.get("schema_version")) is int
            and isinstance(m.get("files"), list) and all(isinstance(f, str) for f in m["files"])):
        return None
    return m


def _all_files(d: Path) -> list:
    out = []
    for root, _dirs, files in os.walk(d):
        for f in files:
            rel = (Path(root) / f).relative_to(d).as_posix()
            if rel != MARKER:
                out.append(rel)
    return sorted(out)


def write_marker(d: Path, files=None) -> None:
    """Write the marker of ``d`` listing ``files`` (default: every file now in ``d``)."""
    import reference_sim
    from cross_checks.core.files import atomic_write_text
    listed = sorted(set(_all_files(d) if files is None else files))
    atomic_write_text(Path(d) / MARKER, json.dumps({
        "format": MARKER_FORMAT, "schema_version": _schema_version(),
        "written_by": f"rbcheck {reference_sim.__version__}", "files": listed}, indent=1) + "\n")


def listed_files(d: Path) -> set:
    m = read_marker(d)
    return set(m["files"]) if m else set()


# --- what rbcheck's own temporary names look like ---------------------------------------------------

def _host() -> str:
    return hashlib.sha256(socket.gethostname().encode()).hexdigest()[:8]


def owned_name(prefix: str, kind: str) -> str:
    """``<prefix>rbcheck-<kind>-<host>-<pid>-<start>-<random>``: a name that says who made it."""
    pid = os.getpid()
    return f"{prefix}rbcheck-{kind}-{_host()}-{pid}-{processes.start_ticks(pid)}-{secrets.token_hex(4)}"


_OWNED = re.compile(
    r"rbcheck-(?P<kind>[a-z]+)-(?P<host>[0-9a-f]{8})-(?P<pid>\d+)-(?P<start>\d+)-[0-9a-f]{8}$")


def is_owned_stale(name: str, prefix: str, kind: str | None = None) -> bool:
    """True when ``name`` is ``owned_name(prefix, kind)`` of a process on this host that is gone."""
    if not name.startswith(prefix):
        return False
    m = _OWNED.match(name[len(prefix):])
    if not m or (kind is not None and m["kind"] != kind) or m["host"] != _host():
        return False
    return processes.is_gone(int(m["pid"]), int(m["start"]))


_TEMP = re.compile(r"^\.(?P<base>.+)\.[A-Za-z0-9_]{8}(\.npz)?$")
_OUTPUT = re.compile(r"^(index\.html|ranking\.html|results\.csv|summary\.json|\.rbcheck-results\.json"
                     r"|scenario-.+\.html|.+\.png|.+\.npz|.+\.csv|.+\.toml)$")


def is_temp_leftover(name: str) -> bool:
    """A temporary file of an atomic write (``.<file>.<8 random>``) of a file rbcheck writes."""
    m = _TEMP.match(name)
    return bool(m and _OUTPUT.match(m["base"]))


# --- checking an output directory before any work ---------------------------------------------------

def check_writable_dir(d: Path, option: str, shown: str) -> None:
    """ResultsDirError unless a file can be created in ``d`` (tried for real: root ignores modes)."""
    try:
        fd, probe = tempfile.mkstemp(prefix=".rbcheck-probe-", dir=d)
    except OSError as exc:
        raise ResultsDirError(f"{option} {shown}: cannot write in {d}: {exc.strerror or exc}") from None
    os.close(fd)
    os.unlink(probe)


def foreign_entries(d: Path, listed: set) -> list:
    """Files under ``d`` that its marker does not list (and are not rbcheck's leftovers), sorted."""
    out = []
    for root, dirs, files in os.walk(d):
        rel_root = Path(root).relative_to(d)
        for name in list(dirs):
            # rbcheck's own working folders, of a live process (a report drawing into DIR right now) or a
            # dead one: never the user's files
            if name.startswith(".") and _OWNED.match(name[1:]) and _OWNED.match(name[1:])["host"] == _host():
                dirs.remove(name)
        for f in files:
            rel = (rel_root / f).as_posix()
            if rel == MARKER or rel in listed or is_temp_leftover(f) or f.startswith(".rbcheck-probe-"):
                continue
            out.append(rel)
    return sorted(out)


def check_output_dir(out_text: str, option: str = "--out") -> Path:
    """The absolute path of a directory a sweep may replace; ResultsDirError (one line) otherwise.

    Refused: an empty path; the current directory or one of its parents; a path whose parent is
    missing, not a directory, or not writable; an existing non-directory; a non-empty directory
    without rbcheck's marker, with a marker of a newer schema, or holding files the marker does not list.
    """
    if not str(out_text).strip():
        raise ResultsDirError(f"{option}: empty path; name the results directory (e.g. {option} results)")
    out = Path(out_text).expanduser().resolve()
    cwd = Path.cwd().resolve()
    if out == cwd or out in cwd.parents:
        raise ResultsDirError(f"{option} {out_text}: is the current directory or contains it; name a new "
                              "subdirectory (a sweep replaces its results directory as a whole)")
    if out.exists() and not out.is_dir():
        raise ResultsDirError(f"{option} {out_text}: exists and is not a directory")
    if not out.parent.is_dir():
        what = "is not a directory" if out.parent.exists() else "does not exist"
        raise ResultsDirError(f"{option} {out_text}: parent directory {out.parent} {what}")
    check_writable_dir(work_place(out), option, out_text)
    if out.is_dir() and any(out.iterdir()):
        marker = read_marker(out)
        if marker is None:
            old = (" (results of an rbcheck older than the marker are never replaced either)"
                   if (out / "summary.json").is_file() else "")
            raise ResultsDirError(f"{option} {out_text}: is not empty and is not an rbcheck "
                                  f"results directory (no valid {MARKER}); refusing to "
                                  f"replace it: name a new or empty directory{old}")
        if marker["schema_version"] > _schema_version():
            raise ResultsDirError(f"{option} {out_text}: written by a newer rbcheck (results schema "
                                  f"{marker['schema_version']}, this one knows {_schema_version()}); "
                                  "refusing to replace it")
        foreign = foreign_entries(out, set(marker["files"]))
        if foreign:
            shown = ", ".join(foreign[:3]) + (f" and {len(foreign) - 3} more" if len(foreign) > 3 else "")
            raise ResultsDirError(f"{option} {out_text}: holds files rbcheck did not write ({shown}); "
                                  "refusing to replace it: move them away or name another directory")
    return out


# --- staging, swapping, and what a killed run leaves ------------------------------------------------

def _sibling_prefix(out: Path) -> str:
    return f".{out.name}."


def is_mount_point(out: Path) -> bool:
    """``out`` is a mount point (a Docker volume, a tmpfs): it cannot be renamed (EBUSY), and a sibling is on
    another file system."""
    try:
        return out.is_dir() and os.path.ismount(out)
    except OSError:
        return False


def work_place(out: Path) -> Path:
    """Where the staging folder of ``out`` goes: beside it, or inside it when it is a mount point (then it is
    filled in place, entry by entry: :func:`replace_dir`)."""
    return out if is_mount_point(out) else out.parent


def staging_dir(out: Path) -> Path:
    """A new, empty staging folder for ``out`` whose name says which process owns it: a sibling, or a hidden
    folder inside ``out`` when ``out`` is a mount point."""
    p = (out / owned_name(".", "staging") if is_mount_point(out)
         else out.parent / owned_name(_sibling_prefix(out), "staging"))
    p.mkdir()
    return p


def _dispose_old(old: Path, out: Path, owned=None) -> None:
    """Remove the previous results directory ``old`` (renamed aside) file by listed file (``owned``, by
    default what its marker lists). Anything else is moved into ``out``; on a name clash ``old`` is
    kept, renamed visibly."""
    listed = listed_files(old) if owned is None else set(owned)
    clash = []
    for rel in foreign_entries(old, listed):
        src, dst = old / rel, out / rel
        if dst.exists():
            clash.append(rel)
            continue
        dst.parent.mkdir(parents=True, exist_ok=True)
        os.replace(src, dst)
    if clash:
        keep = (out / f"previous-{secrets.token_hex(3)}" if old.parent == out   # inside a mount point
                else out.parent / f"{out.name}.previous-{secrets.token_hex(3)}")
        os.replace(old, keep)
        print(f"rbcheck: kept the previous {out.name} as {keep} ({', '.join(clash[:3])} "
              f"appeared in it during the run and clash with new files)", file=sys.stderr)
        return
    shutil.rmtree(old, ignore_errors=True)


def replace_dir(staging: Path, out: Path, owned=None) -> None:
    """Put ``staging`` in place of ``out`` with renames only: at every instant ``out`` is the old
    complete directory or the new one (between the two renames, briefly, absent — and the next run
    puts the old one back if this process dies right there). ``owned``: the files of ``out`` that may
    be removed (default: those its marker lists); any other is moved into the new ``out``."""
    if staging.parent == out:   # a mount point: filled in place
        _replace_contents(staging, out, owned)
        return
    if not out.exists():
        os.replace(staging, out)
        return
    old = out.parent / owned_name(_sibling_prefix(out), "old")
    try:
        os.replace(out, old)
    except OSError as exc:
        if exc.errno not in (errno.EBUSY, errno.EXDEV, errno.EPERM, errno.EACCES):
            raise
        # ``out`` cannot be renamed (a mount point seen only now, a bind mount inside it): fill it in place
        _replace_contents(staging, out, owned)
        return
    try:
        os.replace(staging, out)
    except BaseException:
        os.replace(old, out)
        raise
    _dispose_old(old, out, owned)


def _own_folder(name: str) -> bool:
    """A hidden working folder of rbcheck's inside a results directory (staging, old, a report's)."""
    return name.startswith(".") and bool(_OWNED.match(name[1:]))


def _move(src: Path, dst: Path) -> None:
    try:
        os.replace(src, dst)
    except OSError as exc:
        if exc.errno != errno.EXDEV:
            raise
        shutil.move(str(src), str(dst))   # from a sibling staging folder on another file system: copied


def _replace_contents(staging: Path, out: Path, owned=None) -> None:
    """Replace what ``out`` holds (not ``out`` itself, which cannot be renamed: a mount point) by what
    ``staging`` holds, entry by entry: ``out``'s entries go into a hidden ``.rbcheck-old-...`` folder inside
    it, the new ones in, the marker last (what says the new results are complete), then the old folder is
    disposed of as after a swap (:func:`_dispose_old`). Not atomic: a run killed in between is put right
    by the next one (:func:`remove_stale_siblings`)."""
    old = out / owned_name(".", "old")
    old.mkdir()
    for entry in sorted(out.iterdir()):
        if entry != old and entry != staging and not _own_folder(entry.name):
            os.replace(entry, old / entry.name)
    entries = sorted(staging.iterdir(), key=lambda e: e.name == MARKER)   # the marker last
    for entry in entries:
        _move(entry, out / entry.name)
    shutil.rmtree(staging, ignore_errors=True)
    _dispose_old(old, out, owned)


def _put_back_inside(old: Path, out: Path) -> str:
    """A killed in-place replacement (:func:`_replace_contents`): with the new marker in place, the new
    results are complete and ``old`` is disposed of; without it, the entries moved in are removed and the
    previous ones put back."""
    if (out / MARKER).exists():   # the old marker went into ``old`` first, the new one comes in last
        _dispose_old(old, out)
        return f"removed {old.name}"
    for entry in sorted(out.iterdir()):
        if entry != old and not _own_folder(entry.name) and not (old / entry.name).exists():
            shutil.rmtree(entry) if entry.is_dir() and not entry.is_symlink() else entry.unlink()
    for entry in sorted(old.iterdir()):
        dst = out / entry.name
        if dst.is_dir() and not dst.is_symlink():
            shutil.rmtree(dst)
        os.replace(entry, dst)
    old.rmdir()
    return f"restored the previous results from {old.name}"


def remove_stale_siblings(out: Path) -> list:
    """Remove what killed runs left beside ``out`` (staging directories of dead processes; put back a
    previous results directory left between the two renames of a swap). Returns what was done."""
    done = []
    prefix = _sibling_prefix(out)
    try:
        entries = sorted(out.parent.iterdir())
    except OSError:
        return done
    if is_mount_point(out):   # working folders inside it (:func:`_replace_contents`)
        for p in sorted(out.iterdir()):
            if p.is_dir() and not p.is_symlink() and is_owned_stale(p.name, ".", "staging"):
                shutil.rmtree(p, ignore_errors=True)
                done.append(f"removed {p.name}")
        for p in sorted(out.iterdir()):
            if p.is_dir() and not p.is_symlink() and is_owned_stale(p.name, ".", "old"):
                done.append(_put_back_inside(p, out))
    for p in entries:
        if not p.is_dir() or p.is_symlink() or not is_owned_stale(p.name, prefix):
            continue
        kind = _OWNED.match(p.name[len(prefix):])["kind"]
        if kind == "old" and not out.exists():
            os.replace(p, out)
            done.append(f"restored the previous results from {p.name}")
        elif kind == "old":
            _dispose_old(p, out)
            done.append(f"removed {p.name}")
        elif kind == "staging":
            shutil.rmtree(p, ignore_errors=True)
            done.append(f"removed {p.name}")
    return done


# --- file names derived from data -------------------------------------------------------------------

_SAFE = re.compile(r"^[a-z0-9_]{1,100}$")


def safe_file_stem(name) -> str:
    """A file-name stem for a name read from data (a scenario name in summary.json or results.csv).

    A valid scenario name (``[a-z0-9_]``, at most 100 characters) is kept as it is; anything else
    (``../../x``, ``/tmp/x``, NUL, 300 characters) becomes its letters, digits, ``_`` and ``-`` (at
    most 40) plus 12 hex digits of its SHA-256, so two different names never share a file."""
    name = str(name)
    if _SAFE.match(name):
        return name
    kept = re.sub(r"[^A-Za-z0-9_-]+", "_", name)[:40].strip("_-") or "x"
    return f"{kept}-{hashlib.sha256(name.encode('utf-8', 'surrogatepass')).hexdigest()[:12]}"


def inside(base, *parts) -> Path:
    """``base / parts...``, checked to resolve inside ``base`` (ResultsDirError if it would not)."""
    base_r = Path(base).resolve()
    p = base_r.joinpath(*parts)
    if "\x00" in str(p) or not p.resolve().is_relative_to(base_r) or p.resolve() == base_r:
        raise ResultsDirError(f"{Path(base) / Path(*parts)}: a file name "
                              f"taken from the data leaves {base}; refused")
    return p


def fix_permissions(directory) -> None:
    """Give files written through temporary files (mode 0600) the usual modes under the umask."""
    m = umask()
    for root, _dirs, files in os.walk(directory):
        os.chmod(root, 0o777 & ~m)
        for f in files:
            os.chmod(os.path.join(root, f), 0o666 & ~m)
