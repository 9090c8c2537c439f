"""The exact motion of a whole batch of cases in one DOP853 solve, and what a case's verdicts need from it.

Every member ``i`` (a case, a perturbed copy of one, or a one-step start state) is integrated over its
own span ``T_i`` in normalised time ``s = t / T_i`` ∈ [0, 1]: ``dy/ds = T_i F_i(y)``, with ``F_i`` the full
rigid-body equations of its own scenario (gyroscopic term and the continuous velocity decay −k v, −k ω
included): :class:`StackedRHS`, the batched NumPy definition ``reference_sim.integrators.rhs`` with every
member's parameters as rows, so that one evaluation serves all members — deliberately NOT the kernel the
schemes under test step with (``reference_sim.scalar``), so that a bug there cannot hide in the reference
too. All members share the output grid in ``s``, and SciPy's DOP853 advances the stacked system.

What a case's verdicts take from it, each MEASURED, as the sweep measures them
(``cross_checks.sweep.jobs.measure_reference``):

* :func:`reference` — the trajectory on the finest rung's grid at rtol GROUND_TRUTH_RTOL, and its error:
  the largest difference (per quantity, over the run) from a second solve at a
  REFERENCE_CHECK_RTOL_FACTOR times looser tolerance (that solution's error, an upper bound of the
  reference's own);
* :func:`amplification` — how much the dynamics grow an initial error: the initial state moved by
  AMPLIFICATION_EPS × its scale along each of its 12 directions (``references.perturbed_initial_states``),
  the largest relative change of each quantity over the run per unit of relative perturbation (the sweep
  takes it at the final time; the largest over the run is never smaller);
* :func:`step_flows` — the exact state one step after each start state, for the one-step defects, with
  its error measured the same way.
"""
from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp

from cross_checks.core import tolerances as tol
from cross_checks.core.quantities import QUANTITIES, state_errors
from reference_sim.ground_truth import GROUND_TRUTH_ATOL, GROUND_TRUTH_RTOL
from reference_sim.quaternion import matrix_from_quat, quat_mul
from reference_sim.state import Q, V, W, X
from reference_sim.vec import cross3, mat_t_vec3, matvec3

__all__ = ["StackedRHS", "solve_members", "reference", "amplification", "step_flows", "ExactError"]


class ExactError(RuntimeError):
    """The batched solve failed (DOP853's own message)."""


def solve_members(problems, spans_s, s_eval, *, rtol: float, atol: float = GROUND_TRUTH_ATOL, y0=None,
                  fast: bool = False) -> np.ndarray:
    """States of every member at the normalised times ``s_eval`` (K,) in [0, 1]: ``(K, M, 13)``.

    problems : M single-body Problems (their right-hand sides); spans_s : (M,) spans T_i (s);
    y0 : (M, 13) start states (default: each problem's initial state). Quaternions renormalised.
    fast : evaluate the right-hand side with the N-case kernel (``reference_sim.scalar``, one NumPy-wide
        call for every member) instead of the definition (:class:`StackedRHS`) — only for
        magnitudes (the pilot's rates, the amplification), never for what a verdict compares against.
    """
    M = len(problems)
    spans = np.asarray(spans_s, dtype=float).reshape(M)
    Y0 = np.array([p.initial_packed() for p in problems]) if y0 is None else np.asarray(y0, dtype=float)
    f = _kernel_rhs(problems, spans) if fast else _definition_rhs(problems, spans)
    s_eval = np.asarray(s_eval, dtype=float)
    sol = solve_ivp(f, (0.0, float(s_eval[-1])), Y0.T.ravel(), method="DOP853", t_eval=s_eval, rtol=rtol, atol=atol)
    if not sol.success:
        raise ExactError(f"DOP853 failed on the batch: {sol.message}")
    y = np.moveaxis(sol.y.reshape(13, M, len(s_eval)), (0, 1, 2), (2, 1, 0)).copy()
    y[..., Q] /= np.linalg.norm(y[..., Q], axis=-1, keepdims=True)
    return y


def _definition_rhs(problems, spans):
    """d(flat state)/ds of the definition's equations (``StackedRHS``), every member in one evaluation."""
    M = len(problems)
    F = StackedRHS(problems)

    def f(_s, flat):
        with np.errstate(all="ignore"):
            return (F(flat.reshape(13, M).T) * spans[:, None]).T.ravel()
    return f


def _stack_entries(lists, width):
    """Per member a list of row tuples -> (M, width, k) array, missing entries zero (they add exact zeros)."""
    k = max((len(np.concatenate([np.ravel(a) for a in e])) for es in lists for e in es), default=1)
    out = np.zeros((len(lists), width, k))
    for i, es in enumerate(lists):
        for j, e in enumerate(es):
            out[i, j] = np.concatenate([np.ravel(np.asarray(a, dtype=float)) for a in e])
    return out


class StackedRHS:
    """``reference_sim.integrators.rhs`` for M members of DIFFERENT problems in one evaluation: the same
    equations built from the same primitives (``matrix_from_quat``, ``quat_mul``, ``cross3``, ``matvec3``,
    ``mat_t_vec3``), with each problem's parameters as per-member rows and every force list padded with
    zero entries. Equal to ``rhs(problem_i, y_i)`` to round-off (the order of summing the torques list
    differs; tested); the kernel the schemes step with (``reference_sim.scalar``) is not used.

    ``StackedRHS(problems)(Y)``: Y (M, 13) packed states [x_W, v_W, q_WB (w x y z), w_W] -> dY/dt (M, 13).
    """

    def __init__(self, problems):
        uniq: dict = {}
        rows = [uniq.setdefault(id(p), (len(uniq), p))[0] for p in problems]
        ps = [p for _, p in uniq.values()]
        sel = np.array(rows, dtype=int)
        b = [p.body for p in ps]
        fm = [p.forces for p in ps]
        self.m = np.array([x.mass_kg for x in b])[sel, None]
        self.I_B = np.array([x.inertia_B for x in b], dtype=float)[sel]
        self.I_inv_B = np.array([x.inertia_inv_B for x in b], dtype=float)[sel]
        self.mg = (np.array([x.mass_kg for x in b])[:, None] * np.array([f.gravity_W for f in fm], dtype=float))[sel]
        self.c = np.array([f.linear_drag_N_s_per_m for f in fm], dtype=float)[sel, None]
        self.k_v, self.k_w = (np.array([f.decay_rates_per_s()[j] for f in fm], dtype=float)[sel, None] for j in (0, 1))
        S = max((len(f.springs) for f in fm), default=0)
        sp = _stack_entries([[(s.anchor_W, s.attach_B, s.stiffness_N_per_m, s.rest_length_m) for s in f.springs]
                             for f in fm], S)[sel]
        self.springs = [(sp[:, j, 0:3], sp[:, j, 3:6], sp[:, j, 6:7], sp[:, j, 7:8]) for j in range(S)]
        self.points = {}
        for frame in ("world", "body"):
            lists = [[(pf.force, pf.point_B) for pf in f.point_forces if pf.frame == frame] for f in fm]
            P = max(len(x) for x in lists)
            pt = _stack_entries(lists, P)[sel]
            self.points[frame] = [(pt[:, j, 0:3], pt[:, j, 3:6]) for j in range(P)]
        self.tau = {frame: np.array([np.sum([t.torque for t in f.torques if t.frame == frame] or [np.zeros(3)], axis=0)
                                     for f in fm], dtype=float)[sel] for frame in ("world", "body")}
        self.decay = any(f.has_decay for f in fm)

    def force_torque(self, x, v, R):
        """World force at the COM and world torque about it (M, 3), as ForceModel.force_torque."""
        f = self.mg - self.c * v
        tau = self.tau["world"] + matvec3(R, self.tau["body"])
        for anchor, attach, k, L0 in self.springs:
            r = matvec3(R, attach)
            d = x + r - anchor
            L = np.linalg.norm(d, axis=-1, keepdims=True)
            fs = np.where(L > 0.0, -k * (L - L0) * d / L, 0.0)
            f = f + fs
            tau = tau + cross3(r, fs)
        for frame, entries in self.points.items():
            for force, point in entries:
                fp = matvec3(R, force) if frame == "body" else force
                f = f + fp
                tau = tau + cross3(matvec3(R, point), fp)
        return f, tau

    def __call__(self, Y):
        x, v, q, w = Y[:, X], Y[:, V], Y[:, Q], Y[:, W]
        qn = q / np.linalg.norm(q, axis=-1, keepdims=True)
        R = matrix_from_quat(qn)
        f, tau = self.force_torque(x, v, R)
        dv = f / self.m
        w_B = mat_t_vec3(R, w)
        tau_B = mat_t_vec3(R, tau) - cross3(w_B, matvec3(self.I_B, w_B))
        dw = matvec3(R, matvec3(self.I_inv_B, tau_B))
        if self.decay:
            dv = dv - self.k_v * v
            dw = dw - self.k_w * w
        dq = 0.5 * quat_mul(np.concatenate([np.zeros((len(Y), 1)), w], axis=-1), q)
        return np.concatenate([v, dv, dq, dw], axis=-1)


def _kernel_rhs(problems, spans):
    """The same from the N-case kernel: one NumPy-wide evaluation for every member (magnitudes only)."""
    from cross_checks.fuzz.kernel import CaseKernel
    M = len(problems)
    kern = CaseKernel.stack(problems, "rk4", spans)

    def f(_s, flat):
        with np.errstate(all="ignore"):
            return (np.stack(kern.rhs(list(flat.reshape(13, M)))) * spans).ravel()
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
    y_check = solve_members(problems, durations_s, s, rtol=tol.REFERENCE_CHECK_RTOL_FACTOR * GROUND_TRUTH_RTOL)
    return y, _max_difference(y_check, y)


def amplification(scenarios, scales, n_samples: int = 33, rtol: float = tol.AMPLIFICATION_RTOL):
    """{quantity: (M,)}: the largest relative change of each quantity over the run per unit of relative
    initial perturbation (≥ 1), over the 12 directions of ``references.perturbed_initial_states``.

    scenarios : M Scenarios; scales : M dicts {quantity: scale} (core.quantities.quantity_scales).
    """
    from cross_checks.scenario.references import perturbed_initial_states
    eps = tol.AMPLIFICATION_EPS
    y0 = np.concatenate([perturbed_initial_states(sc, eps, sc_scales) for sc, sc_scales in zip(scenarios, scales)])
    problems = [sc.problem for sc in scenarios for _ in range(13)]
    spans = np.repeat([sc.duration_s for sc in scenarios], 13)
    y = solve_members(problems, spans, np.linspace(0.0, 1.0, n_samples), rtol=rtol, y0=y0, fast=True)
    M = len(scenarios)
    y = y.reshape(n_samples, M, 13, 13)
    base = np.broadcast_to(y[:, :, :1, :], y.shape)
    d = state_errors(y[:, :, 1:, :], base[:, :, 1:, :])
    out = {}
    for q in QUANTITIES:
        sc_q = np.array([s[q] for s in scales])
        worst = np.max(np.nan_to_num(d[q], nan=np.inf), axis=(0, 2))
        out[q] = np.maximum(1.0, worst / sc_q / eps)
    return out


def step_flows(problems, spans_s, y_start):
    """The exact state ``span`` after each start state: ``(y_end (M, 13), error {quantity: (M,)})``."""
    s = np.array([0.0, 1.0])
    y = solve_members(problems, spans_s, s, rtol=GROUND_TRUTH_RTOL, y0=y_start)[-1]
    y_check = solve_members(problems, spans_s, s, rtol=tol.REFERENCE_CHECK_RTOL_FACTOR * GROUND_TRUTH_RTOL,
                            y0=y_start)[-1]
    d = state_errors(y_check, y)
    return y, {q: np.nan_to_num(d[q], nan=np.inf) for q in QUANTITIES}
