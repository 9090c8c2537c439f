"""Run a problem with a reference variant (batched), record every step, and detect divergence."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from reference_sim import compiled
from reference_sim.integrators import ImplicitSolveError, get_step
from reference_sim.state import Problem

__all__ = ["Run", "simulate", "BLOWUP_LIMIT", "bad_rows", "blowup_words", "diverged"]

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


def bad_rows(y):
    """True for each state of ``y`` (..., 13) that is non-finite or has a component beyond BLOWUP_LIMIT:
    the one divergence test of every engine's run (shape (...))."""
    with np.errstate(invalid="ignore"):
        return ~np.all(np.isfinite(y), axis=-1) | (np.max(np.abs(y), axis=-1) > BLOWUP_LIMIT)


def blowup_words(y) -> str:
    """What is wrong with a state that :func:`bad_rows` flags: "non-finite state" or "state beyond 1e+08"."""
    return "non-finite state" if not np.all(np.isfinite(y)) else f"state beyond {BLOWUP_LIMIT:g}"


def diverged(y_good, dt_s: float, why: str) -> Run:
    """A run that diverged in its step n = len(y_good): the states before it, ``diverged_at_s`` = n Δt and
    the message ``diverged at t = … s`` followed by ``why`` (e.g. " (non-finite state)")."""
    n = len(y_good)
    return Run(dt_s * np.arange(n), y_good, n * dt_s, f"diverged at t = {n * dt_s:.6g} s{why}")


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
            return diverged(out[:n], dt_s, f": {exc}")
        if np.any(bad_rows(y)):
            return diverged(out[:n], dt_s, f" ({blowup_words(y)})")
        out[n] = y
    return Run(dt_s * np.arange(n_steps + 1), out)


#: Steps between two divergence tests of the plain-float path: a blown-up state is found (and the run cut
#: at its first bad state) at most this many steps later, at 1/CHECK_EVERY of the per-step test's cost.
CHECK_EVERY = 64


def _simulate_single(problem: Problem, variant: str, dt_s: float, n_steps: int, y) -> Run:
    """One body: the plain-float path of reference_sim.scalar (same equations, ~10x less overhead).

    States are tested for divergence (:func:`bad_rows`) in blocks of CHECK_EVERY steps; the run stops at
    the FIRST bad state of a block (or, when a step raises, at the first bad state before it), so the
    result is the same as testing every step."""
    from reference_sim.scalar import ScalarStepper

    stepper = ScalarStepper(problem, variant, dt_s)
    # a step that blows up inside NumPy (implicit Euler's Newton solve) is a divergence, reported as such,
    # not a stream of overflow warnings — as in the batched path
    with np.errstate(all="ignore"):
        if compiled.usable(stepper):
            return _simulate_compiled(stepper, dt_s, n_steps, y)
        return _python_loop(stepper.step, dt_s, n_steps, y)


def _python_loop(step, dt_s: float, n_steps: int, y) -> Run:
    """The Python float path's loop (:func:`_simulate_single`)."""
    rows = [y.tolist()]
    cur = rows[0]
    checked = 1  # rows[:checked] are known good
    for n in range(1, n_steps + 1):
        try:
            cur = step(cur)
        except _STEP_ERRORS as exc:
            return _first_bad(rows, checked, dt_s) or diverged(np.array(rows), dt_s, f": {type(exc).__name__}: {exc}")
        rows.append(cur)
        if n % CHECK_EVERY == 0 or n == n_steps:
            bad = _first_bad(rows, checked, dt_s)
            if bad is not None:
                return bad
            checked = len(rows)
    return Run(dt_s * np.arange(n_steps + 1), np.array(rows))


#: Steps of one call into the compiled loop (0.05–0.3 s): between calls Python runs, so a run's time limit
#: (a SIGALRM handler, cross_checks.sweep.lifecycle) stops it within that long — inside compiled code a
#: signal handler waits until the call returns.
COMPILED_CHUNK = 65536

_STEP_ERRORS = (ImplicitSolveError, np.linalg.LinAlgError, OverflowError, ZeroDivisionError, ValueError)


def _simulate_compiled(stepper, dt_s: float, n_steps: int, y) -> Run:
    """:func:`_simulate_single` with the steps compiled (:func:`steps_compiled`). States, divergence time and
    message are those of the Python path."""
    rows = np.empty((n_steps + 1, 13))
    rows[0] = y
    k, why = steps_compiled(stepper, rows, n_steps, stepper.step)
    if k is None:
        return Run(dt_s * np.arange(n_steps + 1), rows)
    return diverged(rows[:k].copy(), dt_s, why)


def steps_compiled(stepper, rows, n_steps: int, python_step, variant: str | None = None):
    """Fill ``rows`` (n_steps + 1, 13) from ``rows[0]`` with the compiled loop of ``stepper``'s scheme (or
    ``variant``'s), in chunks of COMPILED_CHUNK steps; a step the loop does not take (not routine:
    reference_sim.compiled) is taken by ``python_step`` — which raises, gives a bad state, or solves a stalled
    implicit step exactly as the Python path does — and the loop resumes after it.

    Returns ``(None, "")``, or ``(k, why)`` when step k diverged: ``rows[:k]`` are the good states and ``why``
    the Python path's words (": <error>" or " (<what is wrong with the state>)")."""
    n = 0
    params = compiled.parameters(stepper)
    while True:
        stop = min(n + COMPILED_CHUNK, n_steps)
        n = compiled.run_until_exceptional(stepper, rows, n, stop, BLOWUP_LIMIT, variant, params)
        if n == n_steps:
            return None, ""
        if n == stop:
            continue   # back in Python between chunks: a time limit (SIGALRM) can stop the run here
        try:
            nxt = np.array(python_step(rows[n].tolist()), dtype=float)
        except _STEP_ERRORS as exc:
            return n + 1, f": {type(exc).__name__}: {exc}"
        if bad_rows(nxt):
            return n + 1, f" ({blowup_words(nxt)})"
        rows[n + 1] = nxt
        n += 1


def _first_bad(rows, start, dt_s):
    """The diverged Run cut at the first bad state among ``rows[start:]``, or None when they are all good."""
    block = np.array(rows[start:])
    if block.size == 0:
        return None
    bad = bad_rows(block)
    if not bad.any():
        return None
    k = start + int(np.argmax(bad))
    return diverged(np.array(rows[:k]), dt_s, f" ({blowup_words(np.array(rows[k]))})")
