"""What a standalone reproducer measures (NumPy and the standard library only: ``rbcheck repro`` embeds
the functions a claim reaches, after the engine's world: cross_checks/sweep/repro.py, docs/repro.md).

It runs ``world(BODIES, GRAVITY_W, VARIANT, dt_s)`` (cross_checks/engines/worlds/<engine>.py) from ``Y0``
with ``F_W``, ``TAU_W`` held, and measures one claim against the values rbcheck embedded: an ORDER over a
Δt ladder (errors from the exact final states, points above their round-off floors), a DRIFT of a long
run (energy, |L|, the separatrix distance δ = (2E I₂ − |L|²)/|L|²), a missing torque-free FLIP, or an
INVARIANCE: the run from ``Y0_T`` of the transformed body ``BODIES_T`` under ``GRAVITY_T`` with ``F_T``,
``TAU_T`` held, mapped back (:func:`map_back`), its largest deviation from the original's per quantity against
the sweep's ``ALLOWANCE`` at each of ``DT_S`` (the sweep's Δt, then its refinements). States
are packed ``[x_W (m), v_W (m/s), q_WB (w, x, y, z), ω_W (rad/s, world axes)]``. Each ``main_*`` prints the
versions and the measured value beside the expected one, and returns 1 while the defect holds, else 0.
"""
import importlib.metadata
import platform

import numpy as np


def versions(dists):
    print(", ".join(f"{d} {importlib.metadata.version(d)}" for d in dists)
          + f", numpy {np.__version__}, Python {platform.python_version()}, {platform.platform()}")


def run(world, s, dt_s, n_steps):
    """The packed states (n_steps + 1, 13) of the body of ``s`` (the script's globals), forces held."""
    w = world(s["BODIES"], s["GRAVITY_W"], s["VARIANT"], dt_s)
    w.set_state(np.array([s["Y0"]], dtype=float))
    f, tau = np.array([s["F_W"]], dtype=float), np.array([s["TAU_W"]], dtype=float)
    raw = [np.array(s["Y0"], dtype=float)]
    w.read()
    for _ in range(n_steps):
        w.apply(f, tau)
        w.step()
        raw.append(w.packed(np.asarray(w.read(), dtype=float)[None])[0, 0])
    return np.array(raw)


def error(quantity, y, y_ref):
    """The error of packed state ``y`` against ``y_ref`` (13,): a norm, the geodesic angle for orientation."""
    if quantity == "orientation":
        a, b = y_ref[6:10] / np.linalg.norm(y_ref[6:10]), y[6:10] / np.linalg.norm(y[6:10])
        w = a[0] * b[0] + a[1:] @ b[1:]
        v = a[0] * b[1:] - b[0] * a[1:] - np.cross(a[1:], b[1:])
        return float(2.0 * np.arctan2(np.linalg.norm(v), abs(w)))
    k = {"position": 0, "velocity": 3, "angular_velocity": 10}[quantity]
    return float(np.linalg.norm(y[k:k + 3] - y_ref[k:k + 3]))


def fitted_order(dt_s, errors, floors, resolved):
    """The least-squares slope of log error over log Δt, over the points ``resolved`` times above their
    floors (None when fewer than two are)."""
    use = [i for i, (e, f) in enumerate(zip(errors, floors)) if np.isfinite(e) and e > resolved * f]
    if len(use) < 2:
        return None
    x, y = np.log([dt_s[i] for i in use]), np.log([errors[i] for i in use])
    return float(np.sum((x - x.mean()) * (y - y.mean())) / np.sum((x - x.mean()) ** 2))


def diverged_at(y, dt_s):
    """The time (s) of the first state of ``y`` (n, 13) that is non-finite or has a component beyond 1e8
    (rbcheck's divergence: reference_sim.simulate.BLOWUP_LIMIT), or None."""
    bad = np.nonzero(~np.all(np.isfinite(y), axis=1) | (np.abs(y).max(axis=1) > 1e8))[0]
    return None if len(bad) == 0 else float(bad[0] * dt_s)


def main_order(world, s):
    versions(s["DIST"])
    errors, blown = [], []
    for h, n, r, f in zip(s["DT_S"], s["STEPS"], s["Y_REF"], s["FLOORS"]):
        y = run(world, s, h, n)
        errors.append(error(s["QUANTITY"], y[-1], np.array(r)))
        blown.append(t := diverged_at(y, h))
        print(f"dt = {h:g} s: " + (f"{s['QUANTITY']} error {errors[-1]:.3e} (round-off floor {f:.1e})"
                                   if t is None else f"the state diverged at t = {t:.4g} s"))
    k = sum(t is not None for t in blown)   # a blow-up has no order: the run does not converge
    p = None if k else fitted_order(s["DT_S"], errors, s["FLOORS"], s["RESOLVED"])
    holds = k > 0 or (p is not None and p < s["DECLARED"] - s["ORDER_TOL"])
    print(f"{s['VARIANT']} {s['QUANTITY']} order: " + (
        f"the run diverged at {k} of {len(blown)} Δt, expected order {s['DECLARED']:g}" if k else "measured "
        + ("at round-off (exact)" if p is None else f"{p:.2f}") + f", expected {s['DECLARED']:g} (defect "
        f"when below {s['DECLARED'] - s['ORDER_TOL']:g})") + (": DEFECT" if holds else ": no defect"))
    return int(holds)


def invariants(y, inertia_B, I2):
    """Energy (J), |L| (N m s) and δ of packed states ``y`` (n, 13) of a torque-free body."""
    q = y[:, 6:10] / np.linalg.norm(y[:, 6:10], axis=-1, keepdims=True)
    w0, x, yy, z = q.T
    R = np.stack([1 - 2 * (yy * yy + z * z), 2 * (x * yy - w0 * z), 2 * (x * z + w0 * yy),
                  2 * (x * yy + w0 * z), 1 - 2 * (x * x + z * z), 2 * (yy * z - w0 * x),
                  2 * (x * z - w0 * yy), 2 * (yy * z + w0 * x), 1 - 2 * (x * x + yy * yy)], -1)
    R = R.reshape(-1, 3, 3)   # R(q_WB)
    L = np.einsum("nij,nj->ni", R @ np.asarray(inertia_B) @ np.swapaxes(R, -1, -2), y[:, 10:13])
    E, Lm = 0.5 * np.sum(y[:, 10:13] * L, axis=-1), np.linalg.norm(L, axis=-1)
    return E, Lm, (2.0 * E * I2 - Lm ** 2) / Lm ** 2


def main_drift(world, s):
    versions(s["DIST"])
    y = run(world, s, s["DT"], s["N"])
    t = diverged_at(y, s["DT"])
    if t is not None:   # a blow-up keeps nothing
        print(f"{s['N']} steps of {s['DT']:g} s: the state diverged at t = {t:.4g} s; "
              "expected the energy, |L| and δ conserved: DEFECT")
        return 1
    E, Lm, d = invariants(y, s["INERTIA_B"], s["I2"])
    k = max(1, int(len(d) * s["END_FRACTION"]))
    end, scatter = float(np.mean(d[-k:])), 2.0 * float(np.std(np.abs(d[-k:])))
    change = abs(d[0]) - float(np.mean(np.abs(d[-k:])))     # how much |δ| fell (start vs the last part)
    moved = abs(end - d[0])
    holds = bool(moved >= s["MIN_CHANGE"] * abs(d[0]) and moved >= s["TREND_TO_SCATTER"] * scatter)
    what = ("crosses the separatrix" if np.sign(end) != np.sign(d[0]) and holds else
            "drifts toward the intermediate axis" if holds and change > 0 else
            "drifts away from the intermediate axis" if holds else "keeps δ")
    print(f"{s['N']} steps of {s['DT']:g} s: energy {E[-1] / E[0] - 1:+.3e}, |L| {Lm[-1] / Lm[0] - 1:+.3e} "
          f"(relative, expected 0: both conserved)")
    print(f"separatrix distance δ: measured {d[0]:.4g} -> {end:.4g} (mean of the last {k} states), expected "
          f"{d[0]:.4g} -> {d[0]:.4g}: {what}: " + ("DEFECT" if holds else "no defect"))
    return int(holds)


def first_flip_s(y, q_BP, axis, dt_s):
    """The time (s) of the first sign change of ω about the intermediate principal ``axis`` in body axes, or
    None."""
    q = y[:, 6:10] / np.linalg.norm(y[:, 6:10], axis=-1, keepdims=True)
    qc = q * np.array([1.0, -1.0, -1.0, -1.0])
    p = np.asarray(q_BP, dtype=float)
    w = y[:, 10:13]
    for qq in (qc, np.broadcast_to(p * np.array([1.0, -1.0, -1.0, -1.0]), qc.shape)):   # world -> B -> P
        t = 2.0 * np.cross(qq[:, 1:], w)
        w = w + qq[:, :1] * t + np.cross(qq[:, 1:], t)
    s = np.sign(w[:, axis])
    flips = np.nonzero(s[1:] * s[0] < 0)[0]
    return None if len(flips) == 0 else float((flips[0] + 1) * dt_s)


def main_gyroscopic(world, s):
    versions(s["DIST"])
    t = first_flip_s(run(world, s, s["DT"], s["N"]), s["Q_BP"], s["AXIS"], s["DT"])
    print(f"{s['N']} steps of {s['DT']:g} s: ω about the intermediate axis (body) first reverses at "
          + ("no time (no flip)" if t is None else f"t = {t:.4g} s")
          + f", expected t = {s['FLIP_S']:.4g} s (the torque-free flip): "
          + ("DEFECT" if t is None else "no defect"))
    return int(t is None)


def quat_mul(a, b):
    """Hamilton products of quaternions (..., 4) (w, x, y, z)."""
    s = a[..., :1] * b[..., :1] - np.sum(a[..., 1:] * b[..., 1:], axis=-1, keepdims=True)
    return np.concatenate([s, a[..., :1] * b[..., 1:] + b[..., :1] * a[..., 1:]
                           + np.cross(a[..., 1:], b[..., 1:])], axis=-1)


def map_back(y, s):
    """States (n, 13) of the transformed run in the original's frames: ``x = Rᵀ(x' − d)/k``, ``v = Rᵀv'/k``,
    ``q = r⁻¹ q' p⁻¹``, ``ω = Rᵀω'`` (``MAP_R`` = R(r), ``MAP_R_INV`` = r⁻¹, ``MAP_P_INV`` = p⁻¹, ``MAP_D``
    (m), ``MAP_K``: a transform sets one of them; the others are the identity)."""
    y, R = np.array(y, dtype=float), np.array(s["MAP_R"])
    y[:, 0:3] = (y[:, 0:3] - np.array(s["MAP_D"])) @ R / s["MAP_K"]
    y[:, 3:6] = y[:, 3:6] @ R / s["MAP_K"]
    y[:, 10:13] = y[:, 10:13] @ R
    y[:, 6:10] = quat_mul(quat_mul(np.array(s["MAP_R_INV"]), y[:, 6:10]), np.array(s["MAP_P_INV"]))
    return y


def deviations(y0, y1):
    """The largest deviation over the run per quantity between runs ``y0`` and ``y1`` (n, 13) where ``y0`` is
    finite (inf where ``y1`` is not): norms, the geodesic angle for orientation."""
    a = y0[:, 6:10] / np.linalg.norm(y0[:, 6:10], axis=-1, keepdims=True)
    b = y1[:, 6:10] / np.linalg.norm(y1[:, 6:10], axis=-1, keepdims=True)
    d = quat_mul(a * np.array([1.0, -1.0, -1.0, -1.0]), b)
    e = {"position": np.linalg.norm(y1[:, 0:3] - y0[:, 0:3], axis=-1),
         "orientation": 2.0 * np.arctan2(np.linalg.norm(d[:, 1:], axis=-1), np.abs(d[:, 0])),
         "velocity": np.linalg.norm(y1[:, 3:6] - y0[:, 3:6], axis=-1),
         "angular_velocity": np.linalg.norm(y1[:, 10:13] - y0[:, 10:13], axis=-1)}
    ok = np.all(np.isfinite(y0), axis=-1)
    e = {q: np.where(ok, v, 0.0) for q, v in e.items()}
    return {q: float(np.max(v, initial=0.0)) if np.all(np.isfinite(v)) else float("inf")
            for q, v in e.items()}


def main_invariance(world, s):
    versions(s["DIST"])
    t = dict(s, BODIES=s["BODIES_T"], GRAVITY_W=s["GRAVITY_T"], Y0=s["Y0_T"], F_W=s["F_T"], TAU_W=s["TAU_T"])
    devs, allow, base = [], s["ALLOWANCE"][0], s["BASE"]
    for h, n in zip(s["DT_S"], s["STEPS"]):
        with np.errstate(all="ignore"):
            devs.append(deviations(run(world, s, h, n), map_back(run(world, t, h, n), s)))
        dev = devs[0]
        if len(devs) == 1:
            for q in allow:
                print(f"dt = {h:g} s, {n} steps: {q} largest deviation {dev[q]:.3g} {s['UNITS'][q]}, allowed "
                      f"{allow[q]:.3g} (round-off {base[q]:.3g})")
            worst = max(allow, key=lambda q: dev[q] / allow[q] if allow[q] > 0 else float("inf"))
            verdict = ("holds" if all(dev[q] <= base[q] for q in allow) else "precision loss (expected)"
                       if all(dev[q] <= allow[q] for q in allow) else "broken")
            if verdict != "broken" or not np.all(np.isfinite(list(dev.values()))):
                break
    if len(devs) > 1:   # broken at Δt: does the deviation vanish at the step's order as Δt shrinks?
        d, dts = [v[worst] for v in devs], s["DT_S"]
        with np.errstate(all="ignore"):
            orders = [float(np.log(a / b) / np.log(h / g)) for a, b, h, g in zip(d, d[1:], dts, dts[1:])]
        gone = [v[worst] <= a[worst] for v, a in zip(devs[1:], s["ALLOWANCE"][1:])]
        print(f"{worst} largest deviation {', '.join(f'{v:.3g}' for v in d)} {s['UNITS'][worst]} at dt = "
              f"{', '.join(f'{h:g}' for h in dts)} s: order {', '.join(f'{o:.2f}' for o in orders)} (the "
              f"step's own truncation error vanishes at order {s['STEP_ORDER'][worst]:g} or more)")
        if np.all(np.isfinite(d)) and all(g or o >= s["STEP_ORDER"][worst] for o, g in zip(orders, gone)):
            verdict = "step-dependent (the step is not covariant under it; no defect of the model)"
    holds = verdict == "broken"
    print(f"{s['VARIANT']} on {s['SCENARIO']} under {s['TRANSFORM']}: {verdict}, expected it to hold: "
          + ("DEFECT" if holds else "no defect"))
    return int(holds)
