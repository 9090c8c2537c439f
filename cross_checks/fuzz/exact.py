"""The exact motion of a whole batch of cases in one DOP853 solve, and what a case's verdicts need from it.

Every member ``i`` (a case, a perturbed copy of one, or a one-step start state) is integrated over its own
span ``T_i`` in normalised time ``s = t / T_i`` ∈ [0, 1]: ``dy/ds = T_i F_i(y)``, with ``F_i`` the full
rigid-body equations of its own scenario (gyroscopic term and the continuous velocity decay −k v, −k ω
included): the definition ``reference_sim.integrators.rhs`` with every member's parameters as rows
(reference_sim.forces.Members), so that one evaluation serves all members. All members share the output grid
in ``s``, and SciPy's DOP853 advances the stacked system.

What a case's verdicts take from it — :func:`reference` and its error, :func:`amplification`,
:func:`step_flows` — is measured as the sweep measures it (``cross_checks.sweep.jobs.measure_reference``),
except that the amplification is the largest over the run (never smaller than the sweep's, at the final
time).
"""
from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp

from cross_checks.core import tolerances as tol
from cross_checks.core.quantities import QUANTITIES, state_errors
from reference_sim.forces import Members
from reference_sim.ground_truth import GROUND_TRUTH_ATOL, GROUND_TRUTH_RTOL
from reference_sim.integrators import rhs
from reference_sim.state import Q

__all__ = ["solve_members", "reference", "amplification", "step_flows", "ExactError"]


class ExactError(RuntimeError):
    """The batched solve failed (DOP853's own message)."""


def solve_members(problems, spans_s, s_eval, *, rtol: float,
                  atol: float = GROUND_TRUTH_ATOL, y0=None) -> np.ndarray:
    """States of every member at the normalised times ``s_eval`` (K,) in [0, 1]: ``(K, M, 13)``.

    problems : M single-body Problems (their right-hand sides); spans_s : (M,) spans T_i (s);
    y0 : (M, 13) start states (default: each problem's initial state). Quaternions renormalised.
    """
    M = len(problems)
    spans = np.asarray(spans_s, dtype=float).reshape(M)
    Y0 = np.array([p.initial_packed() for p in problems]) if y0 is None else np.asarray(y0, dtype=float)
    f = _definition_rhs(problems, spans)
    s_eval = np.asarray(s_eval, dtype=float)
    sol = solve_ivp(f, (0.0, float(s_eval[-1])), Y0.T.ravel(),
                    method="DOP853", t_eval=s_eval, rtol=rtol, atol=atol)
    if not sol.success:
        raise ExactError(f"DOP853 failed on the batch: {sol.message}")
    y = np.moveaxis(sol.y.reshape(13, M, len(s_eval)), (0, 1, 2), (2, 1, 0)).copy()
    y[..., Q] /= np.linalg.norm(y[..., Q], axis=-1, keepdims=True)
    return y


def _definition_rhs(problems, spans):
    """d(flat state)/ds of the definition's equations (reference_sim.integrators.rhs on the members' stacked
    parameters), every member in one evaluation."""
    M = len(problems)
    p = Members.stack(problems)

    def f(_s, flat):
        with np.errstate(all="ignore"):
            return (rhs(p, flat.reshape(13, M).T) * spans[:, None]).T.ravel()
    return f


def _max_difference(a, b) -> dict:
    """Per member, the largest difference over the grid in each quantity: {quantity: (M,)}."""
    d = state_errors(a, b)
    return {q: np.max(np.nan_to_num(d[q], nan=np.inf), axis=0) for q in QUANTITIES}


def reference(problems, durations_s, n_fine: int):
    """The reference trajectory of each case on ``n_fine + 1`` equally spaced times over its duration.

    Returns ``(y (n_fine + 1, M, 13), error {quantity: (M,)})``: the error is the largest difference over
    the run from a solve at REFERENCE_CHECK_RTOL_FACTOR times the tolerance (an upper bound of its own).
    """
    s = np.linspace(0.0, 1.0, n_fine + 1)
    y = solve_members(problems, durations_s, s, rtol=GROUND_TRUTH_RTOL)
    y_check = solve_members(problems, durations_s, s,
                            rtol=tol.REFERENCE_CHECK_RTOL_FACTOR * GROUND_TRUTH_RTOL)
    return y, _max_difference(y_check, y)


def amplification(scenarios, scales, n_samples: int = 33, rtol: float = tol.AMPLIFICATION_RTOL):
    """{quantity: (M,)}: the largest relative change of each quantity over the run per unit of relative
    initial perturbation (≥ 1), over the 12 directions of ``references.perturbed_initial_states`` moved by
    AMPLIFICATION_EPS × their scale: ``references.amplification_of`` (the sweep's estimate) at ``n_samples``
    times of the run instead of its end alone.

    scenarios : M Scenarios; scales : M dicts {quantity: scale} (core.quantities.quantity_scales).
    """
    from cross_checks.scenario.references import amplification_of, perturbed_initial_states
    eps = tol.AMPLIFICATION_EPS
    y0 = np.concatenate([perturbed_initial_states(sc, eps, sc_scales)
                         for sc, sc_scales in zip(scenarios, scales)])
    problems = [sc.problem for sc in scenarios for _ in range(13)]
    spans = np.repeat([sc.duration_s for sc in scenarios], 13)
    y = solve_members(problems, spans, np.linspace(0.0, 1.0, n_samples), rtol=rtol, y0=y0)
    return amplification_of(y.reshape(n_samples, len(scenarios), 13, 13), scales)


def step_flows(problems, spans_s, y_start):
    """The exact state ``span`` after each start state: ``(y_end (M, 13), error {quantity: (M,)})``, the
    error measured as :func:`reference`'s."""
    s = np.array([0.0, 1.0])
    y = solve_members(problems, spans_s, s, rtol=GROUND_TRUTH_RTOL, y0=y_start)[-1]
    y_check = solve_members(problems, spans_s, s, rtol=tol.REFERENCE_CHECK_RTOL_FACTOR * GROUND_TRUTH_RTOL,
                            y0=y_start)[-1]
    d = state_errors(y_check, y)
    return y, {q: np.nan_to_num(d[q], nan=np.inf) for q in QUANTITIES}
