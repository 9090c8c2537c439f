"""numba kernels of cross_checks.engines.packed_rows (imported by it only): an engine's raw rows as packed
states, written in each run's own layout, with the operations of the NumPy conversion they replace in the
same order and ``fastmath`` off (no reassociation, no fused multiply-add), so that every number is that
conversion's bit for bit (tests/cross_checks/engines/test_packed_rows.py)."""
from __future__ import annotations

from numba import njit

from cross_checks.engines.packed_rows import cache_wanted

_JIT = dict(cache=cache_wanted(), nogil=True, error_model="numpy")


@njit(**_JIT)
def qpos_qvel_per_run(raw, out):
    """Raw rows ``raw`` (n, B, 13) ``[qpos (x_W, q_WB (w x y z)), qvel (v_W, ω_B body axes)]`` as packed
    states into ``out`` (B, n, 13) ``[x_W, v_W, q_WB, ω_W]``: worlds.mujoco.to_packed's numbers (ω_W =
    ``v + s t + u × t`` with ``t = 2 u × v``, ``q = (s, u)``, v = ω_B) for each run's rows in turn."""
    n, B = raw.shape[0], raw.shape[1]
    for b in range(B):
        for k in range(n):
            r = raw[k, b]
            o = out[b, k]
            o[0], o[1], o[2] = r[0], r[1], r[2]
            o[3], o[4], o[5] = r[7], r[8], r[9]
            s, u0, u1, u2 = r[3], r[4], r[5], r[6]
            o[6], o[7], o[8], o[9] = s, u0, u1, u2
            v0, v1, v2 = r[10], r[11], r[12]
            t0 = 2.0 * (u1 * v2 - u2 * v1)
            t1 = 2.0 * (u2 * v0 - u0 * v2)
            t2 = 2.0 * (u0 * v1 - u1 * v0)
            o[10] = (v0 + s * t0) + (u1 * t2 - u2 * t1)
            o[11] = (v1 + s * t1) + (u2 * t0 - u0 * t2)
            o[12] = (v2 + s * t2) + (u0 * t1 - u1 * t0)
