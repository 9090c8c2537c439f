"""The reference for N DIFFERENT fuzz cases at once, on 13 (N,) state columns: the one definition
(reference_sim.integrators, per-member parameters) and its compiled runs (reference_sim.simulate.run_members).

State layout as everywhere: 13 (N,) columns [x_W (3), v_W (3), q_WB (w, x, y, z), w_W (3)] (m, m/s, -, rad/s).
"""
from __future__ import annotations

import numpy as np

from reference_sim.forces import Members
from reference_sim.integrators import get_step
from reference_sim.quaternion import matrix_from_quat
from reference_sim.simulate import run_members

__all__ = ["CaseKernel", "columns", "rows", "runs_compiled", "clear_cache"]


def columns(y) -> list:
    """(N, 13) states -> the 13 contiguous (N,) columns."""
    y = np.asarray(y, dtype=float)
    return [np.ascontiguousarray(y[:, i]) for i in range(13)]


def rows(cols) -> np.ndarray:
    """13 (N,) columns -> (N, 13) states."""
    return np.stack([np.asarray(c, dtype=float) for c in cols], axis=-1)


class CaseKernel:
    """One scheme (``variant``) stepping N cases, member i with ``problems[i]`` at step ``h_s[i]`` (s): the
    definition's step on the members' stacked parameters. ``step(cols) -> cols`` on 13 (N,) columns."""

    def __init__(self, members: Members, variant: str, h_s):
        self.members, self.variant, self.h_s = members, variant, np.asarray(h_s, dtype=float)
        self._step = get_step(variant)

    @classmethod
    def stack(cls, problems, variant: str, h_s) -> CaseKernel:
        return cls(Members.stack(problems), variant, np.broadcast_to(np.asarray(h_s, dtype=float), (len(problems),)))

    def take(self, idx) -> CaseKernel:
        """The kernel of the members ``idx`` only."""
        idx = np.atleast_1d(np.asarray(idx, dtype=int))
        return CaseKernel(self.members.take(idx), self.variant, self.h_s[idx])

    def step(self, y):
        return columns(self._step(self.members, rows(y), self.h_s))

    def force_torque_cols(self, y):
        """World force at the COM and world torque (6 (N,) columns) at states ``y`` (13 columns), the
        rotation taken from q/|q| (Members.force_torque)."""
        Y = rows(y)
        q = Y[:, 6:10] / np.linalg.norm(Y[:, 6:10], axis=1, keepdims=True)
        f, tau = self.members.force_torque(Y[:, 0:3], Y[:, 3:6], matrix_from_quat(q))
        return [*f.T, *tau.T]


def clear_cache() -> None:
    """Nothing is kept between batches (the drivers call this at the end of one)."""


def runs_compiled(variant: str, problems, h_s, y0, n_steps):
    """Each member's free run of ``variant`` (run_members: compiled where numba is available): ``[(y
    (n_steps[i] + 1, 13), k)]`` with ``k`` the step at which the member diverged (its rows from ``k`` on
    are NaN) or None."""
    runs = run_members(Members.stack(problems), variant, h_s, n_steps, np.asarray(y0, dtype=float))
    out = []
    for run, n in zip(runs, n_steps):
        y = np.full((int(n) + 1, 13), np.nan)
        y[:len(run.y)] = run.y
        out.append((y, None if run.diverged_at_s is None else len(run.y)))
    return out
