"""Time integrators of the full rigid-body equations, batched over a leading axis.

Every step function has the signature ``step(problem, y, dt) -> y_new`` with ``y`` of shape
``(..., 13)`` packed as ``[x_W, v_W, q_WB (w, x, y, z), w_W]`` (see :mod:`reference_sim.state`), so
``N`` bodies (or ``N`` initial states) advance at once. ``dt`` (s) is a scalar or broadcasts against
``y[..., 0]``.

The continuous equations (world ω, course convention; Euler's equations in world axes)::

    ẋ = v,   v̇ = f / m,   q̇ = ½ [0, ω] q,   I_W ω̇ = τ − ω × (I_W ω),   I_W = R I_B Rᵀ

Variants (names fixed by docs/engines.md and the README):

``course``        the course's step exactly: v += Δt f/m; x += Δt v; ω += Δt I_W⁻¹ τ;
                  q += [0, Δt/2 ω] q; q /= |q|. No gyroscopic term.
``course_gyro``   the same with the explicit gyroscopic torque −ω × (I_W ω).
``expmap_gyro``   symplectic Euler with explicit gyroscopic term, q ← exp(Δt ω_new) q (MuJoCo Euler).
``explicit_euler`` y ← y + Δt F(y).
``implicit_euler`` y ← y + Δt F(y_new), solved by Newton's method (see ``IMPLICIT_TOL``).
``midpoint``      explicit mid-point (RK2): y ← y + Δt F(y + Δt/2 F(y)).
``leapfrog``      Störmer–Verlet kick–drift–kick; the first half kick is implicit in the velocities
                  (fixed point, ``IMPLICIT_TOL``) so the scheme stays second order with
                  velocity-dependent forces and the gyroscopic term; velocities reported at integer steps.
``rk4``           classical Runge–Kutta 4.

Whole-state schemes renormalise the quaternion after the step.

Velocity decay: the course's per-step factors γ are given at the scenario's step dt; physically they
are exponential damping at the rates ``k = −ln γ / dt`` (``ForceModel.decay_rates_per_s``). The three
course-type schemes (course, course_gyro, expmap_gyro) multiply v and ω by ``e^{−kΔt}``
(``ForceModel.decay_factors``) right after their velocity update — exactly the course's γ when
Δt = dt; the whole-state schemes have ``−k v`` and ``−k ω`` in their right-hand side (:func:`rhs`), so
each converges at its order to the continuously damped motion.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from reference_sim.quaternion import matrix_from_quat, quat_exp, quat_mul
from reference_sim.state import STATE_SIZE, Problem, Q, V, W, X
from reference_sim.vec import cross3 as _cross
from reference_sim.vec import mat_t_vec3 as _mtv
from reference_sim.vec import matvec3 as _mv

__all__ = ["VARIANTS", "Scheme", "get_step", "rhs", "IMPLICIT_TOL", "ImplicitSolveError"]

#: Convergence tolerance of the implicit solves (implicit Euler's Newton iteration and leapfrog's
#: implicit half kick): max-norm of the update, relative to 1 + |y|. Two orders above double
#: round-off, so the iteration error is invisible at every dt of the ladders (errors ≥ 1e-9 there).
IMPLICIT_TOL = 1e-13
_MAX_ITER = 50


class ImplicitSolveError(ArithmeticError):
    """An implicit solve did not converge (the step is too large for the problem's stiffness)."""


def _omega_quat(w_W):
    """[0, ω] as a quaternion (..., 4)."""
    return np.concatenate([np.zeros(w_W.shape[:-1] + (1,)), w_W], axis=-1)


def rhs(problem: Problem, y):
    """Time derivative ``F(y)`` (..., 13) of the full rigid-body equations (gyroscopic term included).

    The quaternion part is ``½ [0, ω] q`` with ``q`` as given (not normalised); the rotation used for
    forces and inertia is that of ``q / |q|``. Velocity decay enters as the continuous damping
    ``−k_v v`` and ``−k_ω ω`` (``ForceModel.decay_rates_per_s``).
    """
    body, forces = problem.body, problem.forces
    x, v, q, w = y[..., X], y[..., V], y[..., Q], y[..., W]
    qn = q / np.linalg.norm(q, axis=-1, keepdims=True)
    R = matrix_from_quat(qn)
    f, tau = forces.force_torque(body, x, v, qn, R)
    dv = f / body.mass_kg
    dw = _angular_acceleration(body, R, w, tau, gyro=True)
    if forces.has_decay:
        k_v, k_w = forces.decay_rates_per_s()
        dv = dv - k_v * v
        dw = dw - k_w * w
    dq = 0.5 * quat_mul(_omega_quat(w), q)
    return np.concatenate([v, dv, dq, dw], axis=-1)


def _angular_acceleration(body, R, w_W, tau_W, *, gyro: bool):
    """``I_W⁻¹ (τ − ω × I_W ω)`` (world axes, rad/s²), computed in body axes where I_B is constant:
    ``R I_B⁻¹ (Rᵀτ − ω_B × I_B ω_B)`` with ``ω_B = Rᵀω`` — the same quantity without forming I_W."""
    tau_B = _mtv(R, tau_W)
    if gyro:
        w_B = _mtv(R, w_W)
        tau_B = tau_B - _cross(w_B, body.inertia_times_B(w_B))
    return _mv(R, body.inertia_solve_B(tau_B))


def _dt(dt, y):
    return np.asarray(dt, dtype=float)[..., None] if np.ndim(dt) else float(dt)


def _normalized(y):
    y = y.copy()
    y[..., Q] /= np.linalg.norm(y[..., Q], axis=-1, keepdims=True)
    return y


# --- course-type (semi-implicit) schemes --------------------------------------------------------

def _course_type(problem: Problem, y, dt, *, gyro: bool, expmap: bool):
    body, fm = problem.body, problem.forces
    h = _dt(dt, y)
    x, v, q, w = y[..., X], y[..., V], y[..., Q], y[..., W]
    R = matrix_from_quat(q)
    # All forces and torques from the start-of-step state (course: f_i ← Force_i(x, v); τ uses R(q)).
    f, tau = fm.force_torque(body, x, v, q, R)
    # Decay e^{−kΔt} right after the velocity update (exactly the course's γ at the scenario's dt).
    g_v, g_w = fm.decay_factors(dt)
    g_v, g_w = _dt(g_v, y), _dt(g_w, y)
    v1 = v + h * (f / body.mass_kg)
    if fm.velocity_decay != 1.0:
        v1 = g_v * v1
    x1 = x + h * v1
    w1 = w + h * _angular_acceleration(body, R, w, tau, gyro=gyro)
    if fm.angular_velocity_decay != 1.0:
        w1 = g_w * w1
    if expmap:
        q1 = quat_mul(quat_exp(h * w1), q)
    else:
        q1 = q + quat_mul(_omega_quat((0.5 * h) * w1), q)
    q1 = q1 / np.linalg.norm(q1, axis=-1, keepdims=True)
    return np.concatenate([x1, v1, q1, w1], axis=-1)


def step_course(problem, y, dt):
    """The course's simulator step exactly (docs/course_equations.md), no gyroscopic term."""
    return _course_type(problem, y, dt, gyro=False, expmap=False)


def step_course_gyro(problem, y, dt):
    """The course's step plus the explicit gyroscopic torque −ω × (I_W ω)."""
    return _course_type(problem, y, dt, gyro=True, expmap=False)


def step_expmap_gyro(problem, y, dt):
    """Symplectic Euler + explicit gyroscopic term + exact exponential-map quaternion update."""
    return _course_type(problem, y, dt, gyro=True, expmap=True)


# --- whole-state schemes --------------------------------------------------------------------------

def step_explicit_euler(problem, y, dt):
    h = _dt(dt, y)
    return _normalized(y + h * rhs(problem, y))


def step_midpoint(problem, y, dt):
    h = _dt(dt, y)
    k1 = rhs(problem, y)
    k2 = rhs(problem, y + (0.5 * h) * k1)
    return _normalized(y + h * k2)


def step_rk4(problem, y, dt):
    h = _dt(dt, y)
    k1 = rhs(problem, y)
    k2 = rhs(problem, y + (0.5 * h) * k1)
    k3 = rhs(problem, y + (0.5 * h) * k2)
    k4 = rhs(problem, y + h * k3)
    return _normalized(y + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4))


def _converged(delta, y):
    return np.max(np.abs(delta) / (1.0 + np.abs(y))) <= IMPLICIT_TOL


def _jacobian_fd(problem, z, h):
    """Forward-difference Jacobian of ``G(z) = z − Δt F(z)`` (..., 13, 13), one batched RHS call."""
    eps = 1e-7 * (1.0 + np.abs(z))  # ~sqrt(machine eps) relative: balances truncation and round-off
    zp = z[..., None, :] + np.eye(STATE_SIZE) * eps[..., None, :]  # row j: z with component j bumped
    Fz = rhs(problem, z)
    Fp = rhs(problem, zp)
    hh = h[..., None] if np.ndim(h) else h
    dF = (Fp - Fz[..., None, :]) / eps[..., :, None]  # row j = ∂F/∂z_j
    return np.eye(STATE_SIZE) - hh * np.swapaxes(dF, -1, -2)


def step_implicit_euler(problem, y, dt):
    """Backward Euler on the whole state: solve ``G(z) = z − y − Δt F(z) = 0`` by simplified Newton.

    The Jacobian is a forward-difference approximation evaluated once per step at the explicit
    Euler predictor; the iteration stops when the update is below ``IMPLICIT_TOL`` (relative). The
    root is exact to that tolerance whatever the Jacobian's accuracy (only the convergence rate
    depends on it).
    """
    h = _dt(dt, y)
    z = y + h * rhs(problem, y)  # explicit Euler predictor
    J = _jacobian_fd(problem, z, h)
    for _ in range(_MAX_ITER):
        G = z - y - h * rhs(problem, z)
        delta = np.linalg.solve(J, -G[..., None])[..., 0]
        z = z + delta
        if _converged(delta, z):
            return _normalized(z)
    raise ImplicitSolveError(f"implicit Euler: Newton did not converge in {_MAX_ITER} iterations (dt={dt})")


def step_leapfrog(problem, y, dt):
    """Störmer–Verlet (leapfrog) with velocities at integer steps.

    ``u = (v, ω)`` are the velocities, ``p = (x, q)`` the positions, ``a(p, u)`` the accelerations::

        u_{n+½} = u_n + Δt/2 a(p_n, u_{n+½})        (implicit: fixed point to IMPLICIT_TOL)
        x_{n+1} = x_n + Δt v_{n+½};  q_{n+1} = exp(Δt ω_{n+½}) q_n
        u_{n+1} = u_{n+½} + Δt/2 a(p_{n+1}, u_{n+½})

    For velocity-independent accelerations this is the textbook leapfrog ``v^{n+½} = v^{n−½} + Δt a^n``
    (second order, symmetric); the implicit first half keeps second order with drag and the
    gyroscopic term.
    """
    h = _dt(dt, y)
    half = 0.5 * h

    def accel(z):
        d = rhs(problem, z)
        return np.concatenate([d[..., V], d[..., W]], axis=-1)

    u0 = np.concatenate([y[..., V], y[..., W]], axis=-1)
    z = y.copy()
    u = u0 + half * accel(y)
    for _ in range(_MAX_ITER):
        z[..., V], z[..., W] = u[..., :3], u[..., 3:]
        u_new = u0 + half * accel(z)
        done = _converged(u_new - u, u_new)
        u = u_new
        if done:
            break
    else:
        raise ImplicitSolveError(f"leapfrog: implicit half kick did not converge in {_MAX_ITER} iterations (dt={dt})")
    z[..., V], z[..., W] = u[..., :3], u[..., 3:]
    z[..., X] = y[..., X] + h * u[..., :3]
    q1 = quat_mul(quat_exp(h * u[..., 3:]), y[..., Q])
    z[..., Q] = q1 / np.linalg.norm(q1, axis=-1, keepdims=True)
    u1 = u + half * accel(z)
    z[..., V], z[..., W] = u1[..., :3], u1[..., 3:]
    return z


@dataclass(frozen=True)
class Scheme:
    """One reference variant: its step function, its global order on the problems it models (proven by
    tests/reference_sim/test_integrators.py; docs/course_equations.md), a one-line description, and
    whether its step ends an iterative solve (stopped at IMPLICIT_TOL, not at the exact root)."""

    step: Callable
    order: int
    description: str
    iterative: bool = False


#: The reference variants: the one registry every other list of them (the scalar kernels, the adapter's
#: declared variants and orders, the checker's candidates) derives from.
VARIANTS = {
    "course": Scheme(step_course, 1, "the course's step exactly: symplectic Euler, q += [0, dt/2 w] q, normalise; "
                                     "NO gyroscopic term"),
    "course_gyro": Scheme(step_course_gyro, 1, "the course's step plus the explicit gyroscopic torque -w x (I w)"),
    "expmap_gyro": Scheme(step_expmap_gyro, 1, "symplectic Euler, explicit gyroscopic term, exact exp-map quaternion "
                                               "update (= MuJoCo Euler)"),
    "explicit_euler": Scheme(step_explicit_euler, 1, "explicit (forward) Euler on the whole state, gyroscopic term "
                                                     "included"),
    "implicit_euler": Scheme(step_implicit_euler, 1, "implicit (backward) Euler on the whole state, Newton solve to "
                                                     f"{IMPLICIT_TOL:g}", iterative=True),
    "midpoint": Scheme(step_midpoint, 2, "explicit mid-point (RK2) on the whole state"),
    "leapfrog": Scheme(step_leapfrog, 2, "Stormer-Verlet kick-drift-kick, exp-map drift; velocities at integer steps",
                       iterative=True),
    "rk4": Scheme(step_rk4, 4, "classical Runge-Kutta 4 on the whole state"),
}


def get_step(variant: str):
    """The step function of a variant name (without the ``reference:`` prefix)."""
    try:
        return VARIANTS[variant].step
    except KeyError:
        raise KeyError(f"unknown reference variant {variant!r}; choose from {', '.join(VARIANTS)}") from None
