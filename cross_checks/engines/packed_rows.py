"""A world's whole record of raw rows as packed states, written in each run's own layout.

The loop (cross_checks.engines.loop) records a world's raw rows step by step, (n + 1, B, R), and hands each
run its packed states (n + 1, 13) as one contiguous block: it converts the record (``World.packed``) and
copies it into per-run layout (B, n + 1, 13). For MuJoCo's rows (and MuJoCo Warp's), :func:`qpos_qvel_packed`
does both in one pass of a compiled kernel, and returns the (n + 1, B, 13) view of a (B, n + 1, 13) array:
the same numbers as ``worlds.mujoco.to_packed`` bit for bit, whose layout the loop's per-run copy then keeps
as it is (no second pass over the record). Without numba, the NumPy conversion itself.
"""
from __future__ import annotations

import numpy as np

__all__ = ["qpos_qvel_packed", "source_files", "warm"]

#: ``cache=`` of the kernels (numba's on-disk cache), False once its folder proved unusable
#: (reference_sim.compiled.load_compiled: the kernels are then compiled in memory).
_CACHE = [True]
_KERNELS: list = []


def source_files() -> list:
    """This module's file and its kernels' (hashed into the result cache's key of an engine that uses them),
    found without importing numba."""
    from pathlib import Path
    here = Path(__file__)
    return [here, here.with_name("_packed_kernels.py")]


def cache_wanted() -> bool:
    """``cache=`` for ``_packed_kernels``' functions (read when that module is imported)."""
    return _CACHE[0]


def _first_calls(k) -> None:
    k.qpos_qvel_per_run(np.zeros((1, 1, 13)), np.empty((1, 1, 13)))


def _kernels():
    """The kernels module, loaded (from numba's cache, else compiled) once per process, or None where numba
    cannot be imported."""
    if not _KERNELS:
        from reference_sim.compiled import load_compiled
        _KERNELS.append(load_compiled("cross_checks.engines._packed_kernels", _first_calls, _CACHE))
    return _KERNELS[0]


def warm() -> bool:
    """Load (the first time on a machine: compile) the kernels in this process — before a process pool
    forks, so that every worker inherits them. True when they are available."""
    return _kernels() is not None


def qpos_qvel_packed(raw, numpy_packed) -> np.ndarray:
    """Raw rows ``raw`` (n, B, 13) ``[qpos, qvel]`` (MuJoCo's: ω in body axes) as packed states (n, B, 13),
    laid out per run (the view of a C-contiguous (B, n, 13) array): ``numpy_packed(raw)``'s numbers
    (worlds.mujoco.to_packed's), in one pass of the compiled kernel; ``numpy_packed(raw)`` itself for any
    other shape or without numba."""
    raw = np.asarray(raw, dtype=float)
    k = _kernels() if raw.ndim == 3 and raw.shape[-1] == 13 else None
    if k is None:
        return numpy_packed(raw)
    out = np.empty((raw.shape[1], raw.shape[0], 13))
    k.qpos_qvel_per_run(np.ascontiguousarray(raw), out)
    return out.transpose(1, 0, 2)
