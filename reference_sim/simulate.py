"""Run a problem with a reference variant (batched), record every step, and detect divergence."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from reference_sim import compiled
from reference_sim.forces import Members
from reference_sim.integrators import ImplicitSolveError, get_step
from reference_sim.state import Problem

__all__ = ["Run", "simulate", "run_members", "BLOWUP_LIMIT",
           "COMPILED_CHUNK", "bad_rows", "none_bad", "blowup_words", "diverged", "recorded_run"]

#: A state component beyond this magnitude (m, m/s, rad/s) counts as a blow-up: far outside the catalog's
#: runs (below 1e3) yet well below float overflow, so an exponential instability is caught before it turns
#: into inf/NaN.
BLOWUP_LIMIT = 1e8


@dataclass
class Run:
    """A recorded run.

    t_s : (n+1,) times, s, starting at 0.
    y : (n+1, ..., 13) packed states (see reference_sim.state) at those times.
    diverged_at_s : time of the first non-finite or blown-up state, or None. When set, ``t_s`` and
        ``y`` stop at the last good state.
    message : why it diverged ("" when it did not).
    engine_s : seconds spent inside the engine's own step (or compiled loop) for this run, None where the
        engine cannot tell them apart from its caller's.
    host_s : seconds the caller (rbcheck's loop: forces, recording, checks) spent on this run besides.
    """

    t_s: np.ndarray
    y: np.ndarray
    diverged_at_s: float | None = None
    message: str = ""
    engine_s: float | None = None
    host_s: float | None = None


def bad_rows(y):
    """True for each state of ``y`` (..., 13) that is non-finite or has a component beyond BLOWUP_LIMIT:
    the one divergence test of every engine's run (shape (...))."""
    with np.errstate(invalid="ignore"):
        return ~np.all(np.isfinite(y), axis=-1) | (np.max(np.abs(y), axis=-1) > BLOWUP_LIMIT)


def none_bad(y) -> bool:
    """True when :func:`bad_rows` flags no state of ``y``: every component finite and within BLOWUP_LIMIT,
    in two reductions over the whole array (NaN propagates through both, and compares false) and no
    temporary the size of ``y``."""
    y = np.asarray(y)
    if y.size == 0:
        return True
    with np.errstate(invalid="ignore"):
        return bool(y.max() <= BLOWUP_LIMIT) and bool(y.min() >= -BLOWUP_LIMIT)


def blowup_words(y) -> str:
    """What is wrong with a state that :func:`bad_rows` flags: "non-finite state" or "state beyond 1e+08"."""
    return "non-finite state" if not np.all(np.isfinite(y)) else f"state beyond {BLOWUP_LIMIT:g}"


def diverged(y_good, dt_s: float, why: str) -> Run:
    """A run that diverged in its step n = len(y_good): the states before it, ``diverged_at_s`` = n Δt and
    the message ``diverged at t = … s`` followed by ``why`` (e.g. " (non-finite state)")."""
    n = len(y_good)
    return Run(dt_s * np.arange(n), y_good, n * dt_s, f"diverged at t = {n * dt_s:.6g} s{why}")


def recorded_run(y, dt_s: float) -> Run:
    """The run whose recorded states are ``y`` (n + 1, 13), one every ``dt_s`` from t = 0: all of them, or,
    at the first state :func:`bad_rows` flags, the states before it as a :func:`diverged` run."""
    bad = bad_rows(y)
    if bad.any():
        n_bad = int(np.argmax(bad))
        return diverged(y[:n_bad].copy(), dt_s, f" ({blowup_words(y[n_bad])})")
    return Run(dt_s * np.arange(len(y)), y)


def simulate(problem: Problem, variant: str, dt_s: float, n_steps: int, y0=None) -> Run:
    """Advance ``problem`` ``n_steps`` steps of ``dt_s`` with a reference variant, recording each state.

    One state (``y0`` (13,), default: the problem's initial state) runs through :func:`run_members` (the
    compiled path). Batched: ``y0`` (B, 13) (or any leading shape) advances with the definition, all rows
    at once. A run that produces a non-finite state, a component above ``BLOWUP_LIMIT``, or an implicit
    solve that fails stops there and reports ``diverged_at_s``.
    """
    step = get_step(variant)
    y = problem.initial_packed() if y0 is None else np.array(y0, dtype=float)
    if y.ndim == 1:
        return run_members(problem.members, variant, [dt_s], [n_steps], y[None])[0]
    out = np.empty((n_steps + 1,) + y.shape)
    out[0] = y
    for n in range(1, n_steps + 1):
        try:
            with np.errstate(all="ignore"):
                y = step(problem, y, dt_s)
        except _STEP_ERRORS as exc:
            return diverged(out[:n], dt_s, f": {exc}")
        if np.any(bad_rows(y)):
            return diverged(out[:n], dt_s, f" ({blowup_words(y)})")
        out[n] = y
    return Run(dt_s * np.arange(n_steps + 1), out)


#: Steps of one call into the compiled loop per member (a fraction of a second): between calls Python runs,
#: so a run's time limit (a SIGALRM handler, cross_checks.sweep.lifecycle) stops it within that long —
#: inside compiled code a signal handler waits until the call returns.
COMPILED_CHUNK = 65536

_STEP_ERRORS = (ImplicitSolveError, np.linalg.LinAlgError, OverflowError, ZeroDivisionError, ValueError)


def run_members(members: Members, variant, dt_s, n_steps, y0) -> list:
    """The free runs of N members together: member i (``members.take([i])``) advances ``n_steps[i]`` steps
    of ``dt_s[i]`` (s) from ``y0[i]`` (13,) with ``variant`` (a variant name, or a step function
    ``step(members, y, dt)`` of the definition's signature, which always steps uncompiled); returns N
    :class:`Run`, each equal to that member's run alone (every row of the definition advances on its own).

    The steps are compiled (reference_sim.compiled) in chunks of COMPILED_CHUNK steps per member, or, without
    numba or for a variant that has no kernel (not in ``compiled.VARIANT_CODES``), taken by the definition
    for all members at once. A step the compiled loop does not take, or one
    whose batched result is not good, is taken by the definition for that member alone: it raises (the
    member diverged: ``": <error type>: <message>"``), gives a bad state (``" (<what is wrong>)"``), or
    solves it, and the member goes on. A member that diverges stops alone."""
    N = len(members)
    h = np.broadcast_to(np.asarray(dt_s, dtype=float), (N,)).copy()
    n = np.broadcast_to(np.asarray(n_steps, dtype=np.int64), (N,)).copy()
    offsets = np.concatenate([[0], np.cumsum(n + 1)[:-1]]).astype(np.int64)
    rows = np.empty((int(np.sum(n + 1)), 13))
    rows[offsets] = y0
    pos = np.zeros(N, dtype=np.int64)
    why: dict = {}
    failed = np.zeros(N, dtype=bool)
    step = variant if callable(variant) else get_step(variant)
    # compiled where the variant has a kernel (compiled.VARIANT_CODES); a variant without one steps by its
    # definition, all members at once
    params = (compiled.parameters(members, h)
              if isinstance(variant, str) and variant in compiled.VARIANT_CODES
              and compiled.kernel() is not None else None)
    with np.errstate(all="ignore"):
        while True:
            todo = np.flatnonzero((pos < n) & ~failed)
            if todo.size == 0:
                break
            stop = pos.copy()
            stop[todo] = np.minimum(pos[todo] + COMPILED_CHUNK, n[todo])
            if params is not None:
                compiled.advance(variant, rows, offsets, pos, stop, BLOWUP_LIMIT, params)
            else:
                _advance_defined(members, step, h, rows, offsets, pos, stop)
            for i in todo[pos[todo] < stop[todo]]:   # the next step is not routine: the definition, alone
                _one_step(members.take([i]), step, h[i], rows, offsets[i], pos, i, why)
                failed[i] = i in why
    times: dict = {}   # one time axis per (step, length)
    return [diverged(rows[o:o + pos[i] + 1], h[i], why[i]) if i in why else
            Run(times.setdefault((h[i], n[i]), h[i] * np.arange(n[i] + 1)), rows[o:o + n[i] + 1])
            for i, o in enumerate(offsets.tolist())]


def _advance_defined(members: Members, step, h, rows, offsets, pos, stop) -> None:
    """:func:`compiled.advance` with the definition's ``step``: every member short of its ``stop`` steps at
    once; a member whose new state is bad, or every member when the batched step raises, stops where it is."""
    live = np.flatnonzero(pos < stop)
    while live.size:
        try:
            nxt = step(members.take(live), rows[offsets[live] + pos[live]], h[live])
        except _STEP_ERRORS:
            return
        good = ~bad_rows(nxt)
        rows[offsets[live[good]] + pos[live[good]] + 1] = nxt[good]
        pos[live[good]] += 1
        live = live[good][pos[live[good]] < stop[live[good]]]


def _one_step(member: Members, step, h: float, rows, offset: int, pos, i: int, why: dict) -> None:
    """Step member ``i`` once with the definition's ``step`` from ``rows[offset + pos[i]]``; record why it
    diverged."""
    try:
        nxt = step(member, rows[offset + pos[i]][None], h)[0]
    except _STEP_ERRORS as exc:
        why[i] = f": {type(exc).__name__}: {exc}"
        return
    if bad_rows(nxt):
        why[i] = f" ({blowup_words(nxt)})"
        return
    rows[offset + pos[i] + 1] = nxt
    pos[i] += 1
