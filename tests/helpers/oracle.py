"""The readable path: one body, one step, written line by line as the course writes it.

This module exists to be checked by eye against docs/course_equations.md and to test the definition,
:mod:`reference_sim.integrators`, against it (``test_batched_equals_readable`` in
tests/reference_sim/test_readable.py), as MuJoCo keeps its Python rollout in its tests.
Every quantity is a plain 3-vector or 3×3 matrix of ONE body; nothing here is vectorised.
"""
from __future__ import annotations

import warnings

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
    if variant in ENGINE_GYRO:
        return _engine_gyro_readable(problem, y, dt, variant)
    if variant in FREE_MAPS:
        return _strang_readable(problem, y, dt, FREE_MAPS[variant])
    raise KeyError(variant)


# --- the gyroscopic schemes of engines and of the rigid-body literature, one body, from their sources ----
# Independent of reference_sim.integrators: scipy's Rotation for every attitude update, the engines' code
# transcribed statement by statement (Jolt in its principal frame, as Jolt stores the inertia), the free maps
# from their papers' own variables (DLM rotating Π in the principal frame, Moser–Veselov's matrix equation
# solved over rotation vectors by scipy's fsolve).

def _rot(q):
    """R(q) (3, 3) from a (w, x, y, z) quaternion, by scipy."""
    from scipy.spatial.transform import Rotation
    return Rotation.from_quat([q[1], q[2], q[3], q[0]]).as_matrix()


def _quat_of(R, near):
    """The quaternion (w, x, y, z) of R of the sign nearest ``near`` (the attitude's previous quaternion)."""
    from scipy.spatial.transform import Rotation
    x, y, z, w = Rotation.from_matrix(R).as_quat()
    q = np.array([w, x, y, z])
    return q if q @ near >= 0.0 else -q


def _rotvec_then(rotvec, q):
    """exp(rotvec) q, world axes, by scipy."""
    from scipy.spatial.transform import Rotation
    x, y, z, w = (Rotation.from_rotvec(rotvec) * Rotation.from_quat([q[1], q[2], q[3], q[0]])).as_quat()
    return np.array([w, x, y, z])


def _principal(I_B):
    """Principal moments (ascending) and axes as a proper rotation (a cross product in a reflected frame
    would flip its sign)."""
    d, P = np.linalg.eigh(I_B)
    return d, (P if np.linalg.det(P) > 0 else P * np.array([1.0, 1.0, -1.0]))


def _skew(a):
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


def _bullet_implicit_body(I_B, R, w, dt):
    # btRigidBody::computeGyroscopicImpulseImplicit_Body
    omegab = R.T @ w                                         # quatRotate(q.inverse(), omega1)
    ibo = I_B @ omegab
    f = dt * np.cross(omegab, ibo)                           # residual
    J = I_B + (_skew(omegab) @ I_B - _skew(I_B @ omegab)) * dt
    omegab = omegab - np.linalg.solve(J, f)                  # single Newton-Raphson update
    return R @ omegab


def _bullet_implicit_world(I_B, R, w0, dt):
    # btRigidBody::computeGyroscopicImpulseImplicit_World with evalEulerEqn / evalEulerEqnDeriv, T = 0
    I = R @ I_B @ R.T
    w1 = w0.copy()
    fw = I @ w1 + np.cross(w1, I @ w1) * dt - (np.zeros(3) * dt + I @ w0)
    dfw = I + (_skew(w1) @ I - _skew(I @ w1)) * dt
    return w1 - np.linalg.solve(dfw, fw)


def _bullet_explicit(I_B, R, w, dt):
    # btRigidBody::computeGyroscopicForceExplicit(m_maxGyroscopicForce = 100), subtracted times I⁻¹ Δt
    I = R @ I_B @ R.T
    gf = np.cross(w, I @ w)
    if gf @ gf > 100.0 ** 2:
        gf = gf / np.sqrt(gf @ gf) * 100.0
    return w - np.linalg.solve(I, gf) * dt


def _jolt(I_B, R, w, dt):
    # MotionProperties::ApplyGyroscopicForceInternal, in Jolt's principal frame (mInertiaRotation)
    local_inertia, inertia_rotation = _principal(I_B)
    to_world = R @ inertia_rotation
    local_w = to_world.T @ w
    local_L = local_inertia * local_w
    new_L = local_L - dt * np.cross(local_w, local_L)
    n2 = new_L @ new_L
    new_L = new_L * np.sqrt((local_L @ local_L) / n2) if n2 > 0.0 else np.zeros(3)
    return to_world @ (new_L / local_inertia)


ENGINE_GYRO = {"implicit_gyro_body": _bullet_implicit_body, "implicit_gyro_world": _bullet_implicit_world,
               "explicit_gyro_clamped": _bullet_explicit, "jolt_gyro": _jolt}


def _engine_gyro_readable(problem: Problem, y, dt, variant):
    body, fm = problem.body, problem.forces
    x, v, q, w = y[0:3], y[3:6], y[6:10], y[10:13]
    R = _rot(q)
    f, tau = _forces(body, fm, x, v, R)          # start-of-step forces
    g_v, g_w = fm.decay_factors(dt)
    v = g_v * (v + dt * f / body.mass_kg)
    x = x + dt * v
    I = R @ body.inertia_B @ R.T
    w = g_w * (ENGINE_GYRO[variant](body.inertia_B, R, w, dt) + dt * np.linalg.solve(I, tau))
    return np.concatenate([x, v, _rotvec_then(dt * w, q), w])


def _buss(I_B, q, w, dt):
    # Buss 2000, augmented second-order method: L held, α = I⁻¹(τ − ω × L) with τ = 0
    R = _rot(q)
    I = R @ I_B @ R.T
    L = I @ w
    alpha = np.linalg.solve(I, -np.cross(w, L))
    wbar = w + dt / 2 * alpha + dt ** 2 / 12 * np.cross(alpha, w)
    q1 = _rotvec_then(dt * wbar, q)
    R1 = _rot(q1)
    return q1, np.linalg.solve(R1 @ I_B @ R1.T, L)


def _dlm(I_B, q, w, dt):
    # DLM 1997: H = Σ Π_i²/2I_i, each flowed exactly: the body turns about e_i by φ = t Π_i/I_i and Π turns
    # back by −φ about e_i (Π̇ = Π × ∂H/∂Π); composed 1(h/2) 2(h/2) 3(h) 2(h/2) 1(h/2), I_1 ≤ I_2 ≤ I_3
    from scipy.spatial.transform import Rotation
    d, P = _principal(I_B)
    R_P = _rot(q) @ P                             # world <- principal
    Pi = R_P.T @ (_rot(q) @ I_B @ _rot(q).T @ w)  # principal-axes momentum
    for i, t in ((0, dt / 2), (1, dt / 2), (2, dt), (1, dt / 2), (0, dt / 2)):
        e = np.eye(3)[i]
        turn = Rotation.from_rotvec(t * Pi[i] / d[i] * e).as_matrix()
        R_P = R_P @ turn
        Pi = turn.T @ Pi
    R1 = R_P @ P.T
    return _quat_of(R1, q), R_P @ (Pi / d)


def _midpoint(I_B, q, w, dt):
    # implicit midpoint on (R, Π): Π_m by fixed-point iteration; R₁ = R (1 + h Ω_m/2)(1 − h Ω_m/2)⁻¹
    R = _rot(q)
    Pi = I_B @ (R.T @ w)
    m = Pi.copy()
    for _ in range(200):
        m_new = Pi + dt / 2 * np.cross(m, np.linalg.solve(I_B, m))
        done = np.max(np.abs(m_new - m)) < 1e-17 * (1 + np.max(np.abs(m)))
        m = m_new
        if done:
            break
    W = _skew(dt / 2 * np.linalg.solve(I_B, m))
    R1 = R @ (np.eye(3) + W) @ np.linalg.inv(np.eye(3) - W)
    return _quat_of(R1, q), R1 @ np.linalg.solve(I_B, 2 * m - Pi)


def _moser_veselov(I_B, q, w, dt):
    # Moser–Veselov (Marsden–West 2001 §3.3): h Π̂ = F J_d − J_d Fᵀ, J_d = ½ tr(I) 1 − I; Π₁ = Fᵀ Π; R₁ = R F.
    # F sought as a rotation vector by scipy's fsolve (not the Cayley form the definition solves).
    from scipy.optimize import fsolve
    from scipy.spatial.transform import Rotation
    R = _rot(q)
    Pi = I_B @ (R.T @ w)
    Jd = 0.5 * np.trace(I_B) * np.eye(3) - I_B

    def residual(phi):
        F = Rotation.from_rotvec(phi).as_matrix()
        M = F @ Jd - Jd @ F.T
        return np.array([M[2, 1], M[0, 2], M[1, 0]]) - dt * Pi

    with warnings.catch_warnings():   # "not making good progress" once it has converged: its residual says
        warnings.simplefilter("ignore", RuntimeWarning)
        phi = fsolve(residual, dt * np.linalg.solve(I_B, Pi), xtol=1e-13)
    assert np.max(np.abs(residual(phi))) <= 1e-14 * (1.0 + dt * np.max(np.abs(Pi)))
    F = Rotation.from_rotvec(phi).as_matrix()
    R1 = R @ F
    return _quat_of(R1, q), R1 @ np.linalg.solve(I_B, F.T @ Pi)


FREE_MAPS = {"buss_augmented": _buss, "dlm_splitting": _dlm, "lp_midpoint": _midpoint,
             "moser_veselov": _moser_veselov}


def _strang_readable(problem: Problem, y, dt, free):
    """Half kick (implicit in v and ω: they enter linearly), free map, half kick (explicit)."""
    body, fm = problem.body, problem.forces
    m, (k_v, k_w) = body.mass_kg, fm.decay_rates_per_s()
    x, v, q, w = y[0:3], y[3:6], y[6:10], y[10:13]
    R = _rot(q)
    f, tau = _forces(body, fm, x, np.zeros(3), R)           # the forces without the drag
    v_half = (v + dt / 2 * f / m) / (1 + dt / 2 * (fm.linear_drag_N_s_per_m / m + k_v))
    w_half = (w + dt / 2 * np.linalg.solve(R @ body.inertia_B @ R.T, tau)) / (1 + dt / 2 * k_w)
    x1 = x + dt * v_half
    q1, w1 = free(body.inertia_B, q, w_half, dt)
    R1 = _rot(q1)
    f1, tau1 = _forces(body, fm, x1, v_half, R1)            # the drag at v½ included
    v1 = v_half + dt / 2 * (f1 / m - k_v * v_half)
    w1 = w1 + dt / 2 * (np.linalg.solve(R1 @ body.inertia_B @ R1.T, tau1) - k_w * w1)
    return np.concatenate([x1, v1, q1, w1])
