"""Where a sweep's numbers come from, as summary.json records it: versions, machine, commit, command,
and every engine and variant the sweep ran (an engine file with its SHA-256)."""
from __future__ import annotations

import os
import platform
import sys
from pathlib import Path

from cross_checks.sweep.fingerprint import cpu_model, numerical_stack

__all__ = ["provenance", "variant_record", "git_commit"]


def _git_dirs(checkout: Path) -> list:
    """The git directories of a checkout where HEAD and refs live: ``.git``, or for a linked worktree
    (``.git`` is a file ``gitdir: PATH``) its own directory and the repository's common one."""
    git = checkout / ".git"
    if not git.is_file():
        return [git]
    text = git.read_text().strip()
    if not text.startswith("gitdir:"):
        return []
    own = checkout / text.split(":", 1)[1].strip()
    common = own / "commondir"
    return [own, own / common.read_text().strip()] if common.is_file() else [own]


def git_commit() -> str:
    """The commit of the source checkout, read from .git without running git ("" when unknown)."""
    try:
        dirs = _git_dirs(Path(__file__).resolve().parents[2])
        head = (dirs[0] / "HEAD").read_text().strip()
        if not head.startswith("ref:"):
            return head
        ref = head.split(None, 1)[1]
        for d in dirs:
            if (d / ref).is_file():
                return (d / ref).read_text().strip()
            packed = d / "packed-refs"
            if packed.is_file():
                for line in packed.read_text().splitlines():
                    if line.endswith(" " + ref):
                        return line.split()[0]
    except (OSError, IndexError):
        pass
    return ""


def provenance(started_at: str, variants=()) -> dict:
    """summary.json's ``provenance``: rbcheck, numpy, scipy, MuJoCo and PyBullet versions, Python,
    platform, machine, the numerical stack (architecture, BLAS kernels, compiled target:
    :func:`~cross_checks.sweep.fingerprint.numerical_stack`), git commit, start time, command, and each
    engine the sweep ran."""
    import numpy
    import scipy

    import reference_sim
    from cross_checks.engines import all_variants
    engines = {}
    for v in all_variants():
        engines.setdefault(v.engine, v.version if v.available else f"unavailable ({v.reason})")
    return {
        "rbcheck": reference_sim.__version__, "numpy": numpy.__version__, "scipy": scipy.__version__,
        "mujoco": engines.get("mujoco", ""), "pybullet": engines.get("pybullet", ""),
        "drake": engines.get("drake", ""), "python": platform.python_version(),
        "platform": platform.platform(),
        "machine": f"{platform.machine()}, {os.cpu_count()} CPUs, {cpu_model()}",
        "numerics": numerical_stack(), "git_commit": git_commit(), "started_at": started_at,
        "command": ("rbcheck " + " ".join(sys.argv[1:])
                    if sys.argv and sys.argv[0].endswith("rbcheck") else ""),
        "engines": _engines_provenance(variants),
    }


def _engines_provenance(variants) -> dict:
    """Version and origin of every engine the sweep ran (an engine file's SHA-256 included)."""
    from cross_checks.engines import engine_provenance
    out = {}
    for v in variants:
        engine = v.split(":", 1)[0]
        if engine not in out:
            try:
                out[engine] = engine_provenance(engine)
            except Exception:  # noqa: BLE001
                out[engine] = {}
    return out


def variant_record(name: str, info) -> dict:
    """summary.json's record of a variant: description, version, declared order, whether it has a
    one-step mode, and where its engine comes from (an engine file with its SHA-256)."""
    from cross_checks.engines import engine_provenance
    out = {"name": str(name), "description": info.description if info else "",
           "version": info.version if info else "", "declared_order": info.order if info else None,
           "one_step": name.one_step}
    try:
        out.update({k: v for k, v in engine_provenance(name.engine).items() if k != "version"})
    except Exception:  # noqa: BLE001 - an engine that vanished from the registry keeps its basic record
        pass
    return out
