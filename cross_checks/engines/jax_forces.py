"""The host loop's harness forces evaluated inside a compiled JAX loop (MJX, Brax, jaxsim), bit for bit.

The loop's :class:`~cross_checks.engines.loop.Harness` evaluates a body's forces with the compiled
definition (reference_sim.compiled.ForceEvaluator: numba, ``fastmath`` off) and scales them by the pre-step
decay factors, less the weight an engine applies itself: ``f = γ_v f_W − m g``, ``τ = γ_ω τ_W``. A JAX engine
whose forces depend on the state (a spring, drag, a force at a body point, a torque fixed in body axes) used
to call that evaluation back from its compiled loop on the host at every step. :func:`wrench` is the same
arithmetic in JAX, for one body (vmapped over a world's bodies by the engine's loop), from the arrays of
:class:`BodyForces`: the operations of ``reference_sim/_compiled_kernels.py``'s ``_force_torque`` in its
order, every branch of it a ``where`` on a per-body mask (a member's missing spring adds nothing, as in its
own evaluation).

Bit for bit: XLA's CPU compiler always contracts a product feeding a sum into a fused multiply-add (LLVM's
``AllowFPOpFusion = Fast``; no flag turns it off) and rewrites ``a / sqrt(b)`` into ``a * rsqrt(b)``, each of
which rounds differently from the definition. Every product and every square root here passes through
:func:`_opaque`: its bits OR-ed with an integer zero that is an argument of the compiled function (``zero``),
which neither XLA nor LLVM can see through, so the product is rounded on its own and the division divides.
``tests/cross_checks/engines/test_jax_forces.py`` checks the numbers against the harness's on every kind of
force, bit for bit, compiled alone and inside a vmapped loop.

JAX is imported on first use (cross_checks.engines.runtimes.start_jax), never at import.
"""
from __future__ import annotations

import numpy as np

__all__ = ["BodyForces", "wrench", "wrench_apart", "zero"]

#: The arrays of :class:`BodyForces`, each with the bodies on its first axis.
FIELDS = ("base", "drag", "springs", "smask", "wp", "wmask", "bp", "bmask", "tau_B", "tbmask", "g_v", "g_w",
          "weight")


class BodyForces:
    """The harness's forces of the bodies ``bodies`` (indices, default all) of ``harness`` (the loop's
    :class:`~cross_checks.engines.loop.Harness`) as arrays, for :func:`wrench` inside a compiled loop.

    ``arrays``: a dict of NumPy arrays, the bodies on the first axis — ``base`` (B, 6): the weight plus the
    world forces at the COM (N), then the world torque (N m) (reference_sim.forces.Members' ``weight_W +
    force_W`` and ``torque_W``); ``drag`` (B,) N s/m; ``springs`` (B, S, 8) [anchor_W (m), attach_B (m), k
    (N/m), L0 (m)] and ``smask`` (B, S); world point forces ``wp`` (B, P, 6) [f_W (N), r_B (m)] and ``wmask``;
    body point forces ``bp`` (B, Q, 6) [f_B (N), r_B (m)] and ``bmask``; the body-axes torque ``tau_B`` (B, 3)
    N m and ``tbmask`` (B,); the pre-step decay factors ``g_v``, ``g_w`` (B,); ``weight`` (B, 3) N, the weight
    the engine applies itself (taken off the force). ``key``: the static structure (S, P, Q), part of a
    compiled loop's key."""

    def __init__(self, harness, bodies=None):
        from reference_sim.compiled import parameters
        from reference_sim.forces import Members
        idx = list(range(len(harness.problems))) if bodies is None else [int(i) for i in bodies]
        first: dict = {}   # each distinct problem once
        for i in idx:
            first.setdefault(id(harness.problems[i]), (len(first), harness.problems[i]))
        which = np.array([first[id(harness.problems[i])][0] for i in idx], dtype=int)
        unique = [p for _, p in first.values()]
        sc, _, _, mg, fW, tW, tB, springs, wp, bp, _, _ = parameters(Members.stack(unique),
                                                                     np.ones(len(unique)))
        counts = np.array([_counts(p.forces) for p in unique], dtype=int).reshape(len(unique), 3)

        def mask(n, width):
            return np.arange(width)[None, :] < n[:, None]
        per_problem = {
            "base": np.concatenate([mg + fW, tW], axis=1), "drag": sc[:, 2],
            "springs": springs, "smask": mask(counts[:, 0], springs.shape[1]),
            "wp": wp, "wmask": mask(counts[:, 1], wp.shape[1]),
            "bp": bp, "bmask": mask(counts[:, 2], bp.shape[1]),
            "tau_B": tB, "tbmask": np.any(tB != 0.0, axis=1)}
        self.arrays = {k: np.ascontiguousarray(a[which]) for k, a in per_problem.items()}
        self.arrays["g_v"] = np.asarray(harness.g_v, dtype=float)[idx]
        self.arrays["g_w"] = np.asarray(harness.g_w, dtype=float)[idx]
        self.arrays["weight"] = np.asarray(harness.weight, dtype=float)[idx]
        self.key = (springs.shape[1], wp.shape[1], bp.shape[1])

    def __len__(self) -> int:
        return len(self.arrays["g_v"])

    def take(self, rows) -> dict:
        """The arrays of the bodies ``rows`` (indices into this object's bodies, repeats allowed: a padded
        batch)."""
        rows = np.asarray(rows, dtype=int)
        return {k: a[rows] for k, a in self.arrays.items()}


def _counts(fm) -> tuple:
    """(springs, world point forces off the COM, body point forces) of a force model: the entries
    reference_sim.forces.Members.stack gives it, in its categories."""
    world = sum(1 for p in fm.point_forces if p.frame == "world" and np.any(p.point_B))
    body = sum(1 for p in fm.point_forces if p.frame == "body")
    return len(fm.springs), world, body


def zero():
    """The integer zero a compiled function that calls :func:`wrench` takes as an argument (``np.int64(0)``):
    given as an argument, not a constant, so that XLA cannot fold :func:`_opaque` away."""
    return np.int64(0)


def _opaque(t, z):
    """``t`` itself (float64), its bits OR-ed with the traced integer zero ``z``: a value XLA and LLVM cannot
    see through, so that a product is rounded alone (no fused multiply-add) and a square root stays one."""
    import jax.numpy as jnp
    from jax import lax
    return lax.bitcast_convert_type(lax.bitcast_convert_type(t, jnp.int64) | z, jnp.float64)


def wrench(a: dict, x, v, q, z):
    """The harness's applied force and torque of ONE body (the arrays ``a`` of :class:`BodyForces`, one body's
    row each) at position ``x`` (3,) m, velocity ``v`` (3,) m/s (COM, world axes) and attitude ``q`` (4,) (w,
    x, y, z; normalised here, as the harness does): the (6,) JAX array ``[γ_v f_W − m g, γ_ω τ_W]`` (N, N m,
    world axes), bit for bit ``Harness.wrench`` (reference_sim/_compiled_kernels.py ``force_torque_at``, then
    the decay and the weight). ``z``: the traced integer zero (:func:`zero`). Vmap it over bodies."""
    import jax.numpy as jnp

    def m(s, t):
        return _opaque(s * t, z)

    def mv(R, a0, a1, a2):
        return (m(R[0], a0) + m(R[1], a1) + m(R[2], a2), m(R[3], a0) + m(R[4], a1) + m(R[5], a2),
                m(R[6], a0) + m(R[7], a1) + m(R[8], a2))

    def cross_add(tx, ty, tz, rx, ry, rz, gx, gy, gz):
        return tx + (m(ry, gz) - m(rz, gy)), ty + (m(rz, gx) - m(rx, gz)), tz + (m(rx, gy) - m(ry, gx))

    def pick(mask, new, old):
        return tuple(jnp.where(mask, n, o) for n, o in zip(new, old))

    n = _opaque(jnp.sqrt(m(q[0], q[0]) + m(q[1], q[1]) + m(q[2], q[2]) + m(q[3], q[3])), z)
    qw, qx, qy, qz = q[0] / n, q[1] / n, q[2] / n, q[3] / n
    R = (1.0 - m(2.0, m(qy, qy) + m(qz, qz)), m(2.0, m(qx, qy) - m(qw, qz)), m(2.0, m(qx, qz) + m(qw, qy)),
         m(2.0, m(qx, qy) + m(qw, qz)), 1.0 - m(2.0, m(qx, qx) + m(qz, qz)), m(2.0, m(qy, qz) - m(qw, qx)),
         m(2.0, m(qx, qz) - m(qw, qy)), m(2.0, m(qy, qz) + m(qw, qx)), 1.0 - m(2.0, m(qx, qx) + m(qy, qy)))
    base = a["base"]
    f = (base[0], base[1], base[2])
    t = (base[3], base[4], base[5])
    c = a["drag"]
    f = pick(c != 0.0, (f[0] - m(c, v[0]), f[1] - m(c, v[1]), f[2] - m(c, v[2])), f)
    for j in range(a["springs"].shape[0]):
        s = a["springs"][j]
        rx, ry, rz = mv(R, s[3], s[4], s[5])
        dx, dy, dz = x[0] + rx - s[0], x[1] + ry - s[1], x[2] + rz - s[2]
        L = _opaque(jnp.sqrt(m(dx, dx) + m(dy, dy) + m(dz, dz)), z)
        k = jnp.where(L > 0.0, m(-s[6], L - s[7]) / L, 0.0)
        gx, gy, gz = m(k, dx), m(k, dy), m(k, dz)
        f = pick(a["smask"][j], (f[0] + gx, f[1] + gy, f[2] + gz), f)
        t = pick(a["smask"][j], cross_add(*t, rx, ry, rz, gx, gy, gz), t)
    for j in range(a["wp"].shape[0]):
        p = a["wp"][j]
        rx, ry, rz = mv(R, p[3], p[4], p[5])
        f = pick(a["wmask"][j], (f[0] + p[0], f[1] + p[1], f[2] + p[2]), f)
        t = pick(a["wmask"][j], cross_add(*t, rx, ry, rz, p[0], p[1], p[2]), t)
    for j in range(a["bp"].shape[0]):
        p = a["bp"][j]
        gx, gy, gz = mv(R, p[0], p[1], p[2])
        rx, ry, rz = mv(R, p[3], p[4], p[5])
        f = pick(a["bmask"][j], (f[0] + gx, f[1] + gy, f[2] + gz), f)
        t = pick(a["bmask"][j], cross_add(*t, rx, ry, rz, gx, gy, gz), t)
    tb = a["tau_B"]
    bx, by, bz = mv(R, tb[0], tb[1], tb[2])
    t = pick(a["tbmask"], (t[0] + bx, t[1] + by, t[2] + bz), t)
    gv, gw, w = a["g_v"], a["g_w"], a["weight"]
    return jnp.stack([m(f[0], gv) - w[0], m(f[1], gv) - w[1], m(f[2], gv) - w[2],
                      m(t[0], gw), m(t[1], gw), m(t[2], gw)])


def wrench_apart(a: dict, x, v, q, z):
    """:func:`wrench` computed apart from the engine's step: inside a ``lax.cond`` on the unbatched ``z == 0``
    (always true; under vmap it stays a conditional, as ``z`` is not batched), whose branch XLA compiles as a
    computation of its own and whose result it materialises — as it did the host callback's this replaces —
    so that the engine's own arithmetic around it is fused, and rounded, as before."""
    import jax
    import jax.numpy as jnp
    return jax.lax.cond(z == 0, lambda: wrench(a, x, v, q, z), lambda: jnp.zeros(6))
