"""Small-vector helpers for (..., 3) arrays, faster than np.cross / np.einsum on tiny batches."""
from __future__ import annotations

import numpy as np

__all__ = ["cross3", "matvec3", "mat_t_vec3", "floating"]


def floating(a) -> np.ndarray:
    """``a`` as a floating-point array, its precision kept (float64 for anything else, e.g. integers)."""
    a = np.asarray(a)
    return a if a.dtype.kind == "f" else a.astype(float)


def cross3(a, b):
    """Cross product ``a × b`` of (..., 3) arrays (broadcasting); same value as np.cross, less overhead."""
    a = floating(a)
    b = floating(b)
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def matvec3(M, v):
    """``M @ v`` for matrices (..., 3, 3) and vectors (..., 3), broadcasting over the leading axes."""
    v = floating(v)
    return M[..., :, 0] * v[..., 0:1] + M[..., :, 1] * v[..., 1:2] + M[..., :, 2] * v[..., 2:3]


def mat_t_vec3(M, v):
    """``Mᵀ @ v`` for matrices (..., 3, 3) and vectors (..., 3): e.g. world → body with ``M = R_WB``."""
    v = floating(v)
    return M[..., 0, :] * v[..., 0:1] + M[..., 1, :] * v[..., 1:2] + M[..., 2, :] * v[..., 2:3]
