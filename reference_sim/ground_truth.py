"""High-accuracy ground truth of any free-body problem: the full equations integrated by DOP853."""
from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp

from reference_sim.integrators import rhs
from reference_sim.state import Problem, Q

__all__ = ["ground_truth", "GROUND_TRUTH_RTOL", "GROUND_TRUTH_ATOL"]

#: DOP853 tolerances: rtol 1e-13, as 1e-12 leaves the tennis racket 4e-10 off its closed form
#: (docs/semantics.md, "References"); atol 1e-14: every state component of the catalog is O(0.01–10) in SI
#: units, so the absolute part never dominates.
GROUND_TRUTH_RTOL = 1e-13
GROUND_TRUTH_ATOL = 1e-14


def ground_truth(problem: Problem, t_s, y0=None, rtol: float = GROUND_TRUTH_RTOL,
                 atol: float = GROUND_TRUTH_ATOL):
    """Solve ``ẏ = F(y)`` (reference_sim.integrators.rhs: gyroscopic term and the continuous velocity
    decay ``−k v``, ``−k ω`` included) with DOP853.

    ``problem``: a single-body Problem; ``y0`` (B, 13) solves B initial states as one system (the same steps
    for all). ``t_s`` (T,): increasing output times, s, from 0. Returns ``y`` (T, 13) (or (T, B, 13)) packed
    states [x_W, v_W, q_WB (w x y z, renormalised), w_W].
    """
    t_s = np.asarray(t_s, dtype=float)
    y0 = problem.initial_packed() if y0 is None else np.asarray(y0, dtype=float)
    shape = y0.shape
    # The definition (integrators.rhs), never the compiled path the schemes run on: a fault there cannot
    # move the reference the runs are judged against.

    def f(_t, y):
        return rhs(problem, y.reshape(shape)).reshape(-1)

    sol = solve_ivp(f, (t_s[0], t_s[-1]), y0.reshape(-1), method="DOP853", t_eval=t_s, rtol=rtol, atol=atol)
    if not sol.success:
        raise RuntimeError(f"ground truth integration failed: {sol.message}")
    y = sol.y.T.reshape((len(t_s),) + shape).copy()
    y[..., Q] /= np.linalg.norm(y[..., Q], axis=-1, keepdims=True)
    return y
