"""The readable path: one body, one step, written line by line as the course writes it.

This module exists to be checked by eye against docs/course_equations.md and to test the definition,
:mod:`reference_sim.integrators`, against it (``test_batched_equals_readable`` in
tests/reference_sim/test_readable.py), as MuJoCo keeps its Python rollout in its tests.
Every quantity is a plain 3-vector or 3×3 matrix of ONE body; nothing here is vectorised.
"""
from __future__ import annotations

import numpy as np

from reference_sim.body import RigidBody
from reference_sim.forces import ForceModel
from reference_sim.quaternion import matrix_from_quat, quat_exp, quat_mul
from reference_sim.state import Problem

__all__ = ["step_readable", "rhs_readable"]


def _forces(body: RigidBody, fm: ForceModel, x, v, R):
    """f_i ← Force_i(x, v); τ_i ← (R r_i) × f_i; summed. World axes."""
    f = body.mass_kg * np.asarray(fm.gravity_W, float)  # gravity at the COM: no torque
    tau = np.zeros(3)
    f = f - fm.linear_drag_N_s_per_m * v
    for s in fm.springs:
        r = R @ s.attach_B
        d = x + r - s.anchor_W
        L = np.linalg.norm(d)
        fs = -s.stiffness_N_per_m * (L - s.rest_length_m) * d / L if L > 0 else np.zeros(3)
        f = f + fs
        tau = tau + np.cross(r, fs)
    for p in fm.point_forces:
        fp = R @ p.force if p.frame == "body" else p.force
        f = f + fp
        tau = tau + np.cross(R @ p.point_B, fp)
    for t in fm.torques:
        tau = tau + (R @ t.torque if t.frame == "body" else t.torque)
    return f, tau


def rhs_readable(problem: Problem, y):
    """dy/dt of one body, y = [x, v, q, ω] (13,), world ω, gyroscopic term included."""
    body, fm = problem.body, problem.forces
    x, v, q, w = y[0:3], y[3:6], y[6:10], y[10:13]
    R = matrix_from_quat(q / np.linalg.norm(q))
    f, tau = _forces(body, fm, x, v, R)
    I = R @ body.inertia_B @ R.T  # world inertia
    dw = np.linalg.solve(I, tau - np.cross(w, I @ w))
    dq = 0.5 * quat_mul(np.concatenate([[0.0], w]), q)
    k_v, k_w = fm.decay_rates_per_s()            # velocity decay as the continuous damping −k v, −k ω
    return np.concatenate([v, f / body.mass_kg - k_v * v, dq, dw - k_w * w])


def _course_like(problem: Problem, y, dt, gyro, expmap):
    body, fm = problem.body, problem.forces
    x, v, q, w = y[0:3], y[3:6], y[6:10], y[10:13]
    R = matrix_from_quat(q)                      # R ← Rotate(q)
    f, tau = _forces(body, fm, x, v, R)          # f ← Σ f_i ;  τ ← Σ (R r_i) × f_i
    v = v + dt * f / body.mass_kg                # v ← v + Δt M⁻¹ f
    g_v, g_w = fm.decay_factors(dt)              # e^{−kΔt}: the course's γ when Δt = the scenario's dt
    v = g_v * v                                  # course decay (1 = off)
    x = x + dt * v                               # x ← x + Δt v
    I = R @ body.inertia_B @ R.T                 # I ← R I_ref Rᵀ
    if gyro:
        tau = tau - np.cross(w, I @ w)           # gyroscopic torque (NOT in the course)
    w = w + dt * np.linalg.solve(I, tau)         # ω ← ω + Δt I⁻¹ τ
    w = g_w * w
    if expmap:
        q = quat_mul(quat_exp(dt * w), q)        # q ← exp(Δt ω) q
    else:
        q = q + quat_mul(np.concatenate([[0.0], 0.5 * dt * w]), q)  # q ← q + [0, Δt/2 ω] q
    q = q / np.linalg.norm(q)                    # q ← q / |q|
    return np.concatenate([x, v, q, w])


def _finish(problem, y):
    y = y.copy()
    y[6:10] /= np.linalg.norm(y[6:10])
    return y


def step_readable(variant: str, problem: Problem, y, dt: float):
    """One step of ``variant`` for one body (13,). Same maths as the batched integrators."""
    F = lambda z: rhs_readable(problem, z)  # noqa: E731
    if variant == "course":
        return _course_like(problem, y, dt, gyro=False, expmap=False)
    if variant == "course_gyro":
        return _course_like(problem, y, dt, gyro=True, expmap=False)
    if variant == "expmap_gyro":
        return _course_like(problem, y, dt, gyro=True, expmap=True)
    if variant == "explicit_euler":
        return _finish(problem, y + dt * F(y))
    if variant == "midpoint":
        return _finish(problem, y + dt * F(y + 0.5 * dt * F(y)))
    if variant == "rk4":
        k1 = F(y)
        k2 = F(y + 0.5 * dt * k1)
        k3 = F(y + 0.5 * dt * k2)
        k4 = F(y + dt * k3)
        return _finish(problem, y + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4))
    if variant == "implicit_euler":
        # Fixed-point iteration z ← y + Δt F(z): slower than Newton but obviously right.
        z = y + dt * F(y)
        for _ in range(500):
            z_new = y + dt * F(z)
            if np.max(np.abs(z_new - z) / (1 + np.abs(z_new))) < 1e-15:
                return _finish(problem, z_new)
            z = z_new
        return _finish(problem, z)
    if variant == "leapfrog":
        u0 = np.concatenate([y[3:6], y[10:13]])
        z = y.copy()
        u = u0.copy()
        for _ in range(500):  # implicit half kick u½ = u0 + Δt/2 a(p0, u½)
            z[3:6], z[10:13] = u[:3], u[3:]
            d = F(z)
            u_new = u0 + 0.5 * dt * np.concatenate([d[3:6], d[10:13]])
            if np.max(np.abs(u_new - u) / (1 + np.abs(u_new))) < 1e-15:
                u = u_new
                break
            u = u_new
        z[3:6], z[10:13] = u[:3], u[3:]
        z[0:3] = y[0:3] + dt * u[:3]                              # drift x
        q = quat_mul(quat_exp(dt * u[3:]), y[6:10])               # drift q with ω½
        z[6:10] = q / np.linalg.norm(q)
        d = F(z)
        z[3:6] = u[:3] + 0.5 * dt * d[3:6]                        # second half kick
        z[10:13] = u[3:] + 0.5 * dt * d[10:13]
        return z
    raise KeyError(variant)
