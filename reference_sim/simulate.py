"""Run a problem with a reference variant (batched), record every step, and detect divergence."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from reference_sim.integrators import ImplicitSolveError, get_step
from reference_sim.state import Problem

__all__ = ["Run", "simulate", "BLOWUP_LIMIT"]

#: A state component beyond this magnitude (m, m/s, rad/s) counts as a blow-up. Free-body scenarios
#: of the catalog stay below 1e3 in every quantity; 1e8 is far outside any physical run yet well
#: below float overflow, so an exponential instability is caught before it turns into inf/NaN.
BLOWUP_LIMIT = 1e8


@dataclass
class Run:
    """A recorded run.

    t_s : (n+1,) times, s, starting at 0.
    y : (n+1, ..., 13) packed states (see reference_sim.state) at those times.
    diverged_at_s : time of the first non-finite or blown-up state, or None. When set, ``t_s`` and
        ``y`` stop at the last good state.
    message : why it diverged ("" when it did not).
    """

    t_s: np.ndarray
    y: np.ndarray
    diverged_at_s: float | None = None
    message: str = ""


def simulate(problem: Problem, variant: str, dt_s: float, n_steps: int, y0=None) -> Run:
    """Advance ``problem`` ``n_steps`` steps of ``dt_s`` with a reference variant, recording each state.

    Batched: ``y0`` (default: the problem's initial state) may have any leading shape. A run that
    produces a non-finite state, a component above ``BLOWUP_LIMIT``, or an implicit solve that fails
    stops there and reports ``diverged_at_s``.
    """
    step = get_step(variant)
    y = problem.initial_packed() if y0 is None else np.array(y0, dtype=float)
    if y.ndim == 1:
        return _simulate_single(problem, variant, dt_s, n_steps, y)
    out = np.empty((n_steps + 1,) + y.shape)
    out[0] = y
    for n in range(1, n_steps + 1):
        try:
            with np.errstate(all="ignore"):
                y = step(problem, y, dt_s)
        except (ImplicitSolveError, np.linalg.LinAlgError) as exc:
            return Run(dt_s * np.arange(n), out[:n], n * dt_s, f"diverged at t = {n * dt_s:.6g} s: {exc}")
        if not np.all(np.isfinite(y)) or np.max(np.abs(y)) > BLOWUP_LIMIT:
            what = "non-finite state" if not np.all(np.isfinite(y)) else f"state beyond {BLOWUP_LIMIT:g}"
            return Run(dt_s * np.arange(n), out[:n], n * dt_s, f"diverged at t = {n * dt_s:.6g} s ({what})")
        out[n] = y
    return Run(dt_s * np.arange(n_steps + 1), out)


def _simulate_single(problem: Problem, variant: str, dt_s: float, n_steps: int, y) -> Run:
    """One body: the plain-float path of reference_sim.scalar (same equations, ~10x less overhead)."""
    from reference_sim.scalar import ScalarStepper

    step = ScalarStepper(problem, variant, dt_s).step
    rows = [y.tolist()]
    cur = rows[0]
    limit = BLOWUP_LIMIT
    for n in range(1, n_steps + 1):
        try:
            cur = step(cur)
        except (ImplicitSolveError, np.linalg.LinAlgError, OverflowError, ZeroDivisionError, ValueError) as exc:
            return Run(dt_s * np.arange(n), np.array(rows), n * dt_s,
                       f"diverged at t = {n * dt_s:.6g} s: {type(exc).__name__}: {exc}")
        big = max(map(abs, cur))
        if not big <= limit:  # also catches NaN
            what = "non-finite state" if big != big or big == float("inf") else f"state beyond {limit:g}"
            return Run(dt_s * np.arange(n), np.array(rows), n * dt_s, f"diverged at t = {n * dt_s:.6g} s ({what})")
        rows.append(cur)
    return Run(dt_s * np.arange(n_steps + 1), np.array(rows))
