"""``rbcheck check``, step 2: the physics every verdict is measured against (docs/check.md, "The evidence").

* :func:`exact_flow` — the true motion over each row interval, from each recorded state at once (batched
  RK4 with substeps on ``reference_sim.integrators.rhs``), with a Richardson estimate of its own error.
* :func:`majorant` — M2 = ``Σ_b |J_b F_b|``, a block bound on |y''| per quantity: every consistent
  one-step scheme of order ≥ 1 leaves a local defect ≤ ½ h² M2 + O(h³), a wrong equation O(h).
* :func:`local_allowances` — what a consistent scheme may leave per row interval, plus the data's precision.
* :func:`error_growth` — how the scenario's dynamics amplify an error made at t = 0, quantity to quantity.

Quantities: position (m), velocity (m/s), orientation (rad: twice the quaternion distance, which for
unit quaternions is the geodesic angle to first order and also counts a change of |q|), angular
velocity (rad/s, world).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from cross_checks.core import tolerances as tol
from cross_checks.core.quantities import BLOCKS, QUANTITIES
from reference_sim.integrators import rhs
from reference_sim.quaternion import geodesic_angle, quat_exp, quat_mul
from reference_sim.state import Q, W

__all__ = ["flow_rhs", "rk4_flow", "exact_flow", "FlowResult", "majorant", "motion_rate", "spring_turn_rate",
           "quantity_distance", "distances", "local_allowances", "Allowances", "error_growth",
           "conservation_allowance"]


def flow_rhs(scenario):
    """F(y) (..., 13): the full rigid-body equations (gyroscopic term included) with the scenario's
    velocity decay as the continuous damping −k_v v, −k_ω ω (k = −ln γ / dt) — which
    ``reference_sim.integrators.rhs`` itself includes (``ForceModel.decay_rates_per_s``)."""
    problem = scenario.problem
    return lambda y: rhs(problem, y)


def rk4_flow(F, y0, span_s, substeps: int, *, mid: bool = False):
    """RK4 with ``substeps`` equal substeps over ``span_s`` (scalar or (N,)) from each row of ``y0``.

    Returns the end states (quaternion renormalised to the start's norm), and with ``mid`` also the
    states after half the substeps (``substeps`` even)."""
    y = np.array(y0, dtype=float)
    h_span = np.asarray(span_s, dtype=float) / substeps
    h = h_span[..., None] if np.ndim(h_span) else float(h_span)
    n0 = np.linalg.norm(y[..., Q], axis=-1, keepdims=True)
    y_mid = None
    with np.errstate(all="ignore"):
        for s in range(substeps):
            k1 = F(y)
            k2 = F(y + 0.5 * h * k1)
            k3 = F(y + 0.5 * h * k2)
            k4 = F(y + h * k3)
            y = y + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
            if mid and s == substeps // 2 - 1:
                y_mid = y.copy()
        y[..., Q] *= n0 / np.linalg.norm(y[..., Q], axis=-1, keepdims=True)
    return (y, y_mid) if mid else y


def quantity_distance(a, b, quantity):
    """Distance between states ``a`` and ``b`` (..., 13) in one quantity (see module doc), shape (...)."""
    sl = BLOCKS[quantity]
    if quantity != "orientation":
        return np.linalg.norm(a[..., sl] - b[..., sl], axis=-1)
    qa, qb = a[..., Q], b[..., Q]
    return 2.0 * np.minimum(np.linalg.norm(qa - qb, axis=-1), np.linalg.norm(qa + qb, axis=-1))


def distances(a, b, quantities=QUANTITIES) -> dict:
    return {q: quantity_distance(a, b, q) for q in quantities}


def motion_rate(scenario, y) -> np.ndarray:
    """L (1/s) per row of ``y`` (N, 13): the fastest rate of the motion there — the spin |ω|, spring
    frequencies √(k/m) and √(k r²/I_min), drag c/m and decay rates, and the rate at which a spring with a
    rest length turns (:func:`spring_turn_rate`)."""
    p = scenario.problem
    m, I_min = p.body.mass_kg, float(np.linalg.eigvalsh(p.body.inertia_B)[0])
    fixed = [p.forces.linear_drag_N_s_per_m / m, *p.forces.decay_rates_per_s()]
    for sp in p.forces.springs:
        fixed += [math.sqrt(sp.stiffness_N_per_m / m),
                  math.sqrt(sp.stiffness_N_per_m * float(np.dot(sp.attach_B, sp.attach_B)) / I_min)]
    w = np.linalg.norm(np.nan_to_num(y[..., W]), axis=-1)
    return np.maximum(np.maximum(w, max(fixed)), spring_turn_rate(p, y))


def spring_turn_rate(problem, y) -> np.ndarray:
    """|v⊥| / |d| (1/s) per row of ``y`` (N, 13), the largest over the springs with a rest length: d the
    spring (attachment point minus anchor, world), v⊥ the attachment point's velocity across it.

    A spring of rest length L0 pulls with −k d + k L0 d/|d|: the second part has constant magnitude and
    turns with d, at this rate, however soft the spring (a body passing close to the anchor turns it
    fast). Zero-length springs are linear in d and add nothing here."""
    from reference_sim.quaternion import matrix_from_quat
    y = np.nan_to_num(np.asarray(y, dtype=float))
    out = np.zeros(y.shape[:-1])
    springs = [sp for sp in problem.forces.springs if sp.rest_length_m != 0.0]
    if not springs:
        return out
    q = y[..., Q]
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    R_WB = matrix_from_quat(np.divide(q, n, out=np.tile([1.0, 0.0, 0.0, 0.0], q.shape[:-1] + (1,)),
                                      where=n > 0))
    for sp in springs:
        r_W = np.einsum("...ij,j->...i", R_WB, np.asarray(sp.attach_B, dtype=float))
        d_W = y[..., 0:3] + r_W - np.asarray(sp.anchor_W, dtype=float)
        v_W = y[..., 3:6] + np.cross(y[..., W], r_W)
        dist = np.linalg.norm(d_W, axis=-1)
        across = np.linalg.norm(np.cross(v_W, d_W), axis=-1)   # |v⊥| |d|
        # at d = 0 exactly the spring pulls with no force (no direction, as ForceModel): rate 0 there
        out = np.maximum(out, np.divide(across, dist * dist, out=np.zeros_like(dist), where=dist > 0.0))
    return out


def majorant(F, y, rate) -> dict:
    """M2 per quantity (..., ): ``Σ_b |J_b F_b|`` at states ``y`` by central differences along each
    block of F (step tol.CHECK_FD_STEP_S / max(1, L)). Orientation in angle units (2 × quaternion)."""
    f = F(y)
    tau = (tol.CHECK_FD_STEP_S / np.maximum(1.0, np.asarray(rate, dtype=float)))[..., None]
    out = {q: np.zeros(y.shape[:-1]) for q in QUANTITIES}
    with np.errstate(all="ignore"):
        for sl in BLOCKS.values():
            e = np.zeros_like(y)
            e[..., sl] = f[..., sl]
            d = (F(y + tau * e) - F(y - tau * e)) / (2.0 * tau)
            for q, sq in BLOCKS.items():
                out[q] += np.linalg.norm(d[..., sq], axis=-1)
    out["orientation"] *= 2.0
    return out


@dataclass
class FlowResult:
    """The exact flow over each row interval.

    y_end : (N, 13) states after each interval.  error : quantity -> (N,) estimate of the flow's own
    error: the Richardson estimate of its truncation, or its round-off (``roundoff``) when larger.
    M2 : quantity -> (N,) max of the majorant at the start, middle and end.  rate : (N,) motion rate
    L at the start.  substeps : RK4 substeps used.  roundoff : quantity -> (N,) the flow's round-off,
    ``substeps · CHECK_ROUNDINGS_PER_STEP · ε · |y|``.
    """

    y_end: np.ndarray
    error: dict
    M2: dict
    rate: np.ndarray
    substeps: int
    roundoff: dict


def _magnitude(y, quantity):
    """|y| in one quantity (orientation: 2 × max(|q|, 1), an angle scale)."""
    mag = np.linalg.norm(np.nan_to_num(y[..., BLOCKS[quantity]]), axis=-1)
    return 2.0 * np.maximum(mag, 1.0) if quantity == "orientation" else mag


def exact_flow(scenario, y0, span_s, max_doublings: int = 4, allowance_fn=None, span_steps=1) -> FlowResult:
    """Advance each row of ``y0`` (N, 13) by the exact flow over ``span_s`` (N,) seconds.

    RK4 with S and 2S substeps (S from tol.CHECK_FLOW_RATE_PER_SUBSTEP); the 2S result is kept and
    ``|y_S − y_2S| / 15`` estimates its truncation error. Rows whose h L exceeds CHECK_MAX_HL
    (``h = span / span_steps``) are not decisive, so S resolves L at most up to that. With
    ``allowance_fn(M2, rate) -> {quantity: (N,)}``, S doubles (at most ``max_doublings`` times) until every
    estimate is below tol.CHECK_FLOW_ERROR_FRACTION of its allowance or at the flow's own round-off.
    """
    F = flow_rhs(scenario)
    span = np.asarray(span_s, dtype=float)
    rate = motion_rate(scenario, y0)
    # rows where h L exceeds CHECK_MAX_HL are not decisive: the start need not resolve faster motion
    worst = float(np.max(np.minimum(rate * span, tol.CHECK_MAX_HL * np.asarray(span_steps, dtype=float))))
    S = max(2, int(math.ceil(worst / tol.CHECK_FLOW_RATE_PER_SUBSTEP)))
    S += S % 2
    eps = 2.0 ** -53
    for _ in range(max_doublings + 1):
        y_S = rk4_flow(F, y0, span, S)
        y_2S, y_mid = rk4_flow(F, y0, span, 2 * S, mid=True)
        roundoff = {q: 2 * S * tol.CHECK_ROUNDINGS_PER_STEP * eps
                       * np.maximum(_magnitude(y0, q), _magnitude(y_2S, q))
                    for q in QUANTITIES}
        trunc = {q: quantity_distance(y_S, y_2S, q) / 15.0 for q in QUANTITIES}
        M2 = majorant(F, y0, rate)
        for y_at in (y_mid, y_2S):
            m = majorant(F, y_at, rate)
            M2 = {q: np.fmax(M2[q], m[q]) for q in QUANTITIES}
        res = FlowResult(y_2S, {q: np.fmax(trunc[q], roundoff[q]) for q in QUANTITIES},
                         M2, rate, 2 * S, roundoff)
        if allowance_fn is None:
            return res
        allow = allowance_fn(M2, rate)
        if all(np.all((trunc[q] <= tol.CHECK_FLOW_ERROR_FRACTION * allow[q]) | (trunc[q] <= roundoff[q]))
               for q in QUANTITIES):
            return res
        S *= 2
    return res


@dataclass
class Allowances:
    """Per row interval (N,) and quantity: ``physics`` (C h Δ M2 with drift), ``arith`` (roundings of the
    steps in the data's precision), ``print_`` (written digits of both rows), ``total``."""

    physics: dict
    arith: dict
    print_: dict
    total: dict


def lever_arm_roundoff(scenario, y, unit_roundoff: float, h_s):
    """(N,) rad/s: what the roundings of the positions leave in ω over one step of ``h_s`` from each row of
    ``y`` (N, 13). An engine forms a torque from a lever arm, ``r × F``, with r the difference of two points
    near x_W (a point of application or the centre of mass it recomputes from its frames), so r carries
    ``u |x_W|`` and the torque ``u |x_W| |F|`` even when the exact lever arm is zero; over one step ω moves by
    ``Δt u |x_W| |F| / I_min``. Without it a body that never turns, whose recorded ω is that round-off,
    would read as a wrong equation. |F| = m |a_W| of the exact equations at the row (gravity included)."""
    p = scenario.problem
    y = np.asarray(y, dtype=float)
    a_W = rhs(p, y)[..., 3:6]
    force_N = float(p.body.mass_kg) * np.linalg.norm(np.nan_to_num(a_W), axis=-1)
    i_min = float(np.min(np.linalg.eigvalsh(np.asarray(p.body.inertia_B, dtype=float))))
    x_m = np.linalg.norm(np.nan_to_num(y[..., 0:3]), axis=-1)
    return np.asarray(h_s) * unit_roundoff * x_m * force_N / i_min


def local_allowances(inp, y_start, M2, rate, flow_roundoff=None, y_end=None, scenario=None) -> Allowances:
    """What a consistent scheme of order ≥ 1 may leave over each row interval of ``inp`` (a CheckInput).

    Over a row of ``m`` steps of h (Δ = m h): m local defects ``C h² M2`` that the flow carries along,
    ``C h Δ M2 · e^{L(Δ − h)}``, and a velocity defect drifts into position (orientation) by ~(Δ − h)/2.
    ``arith`` adds the roundings of the user's steps (data precision, relative to the larger of the two
    rows' magnitudes, ``y_start`` and ``y_end``) and of the exact flow itself; with ``scenario``, also the
    lever arm's rounding in ω (:func:`lever_arm_roundoff`), per step.
    """
    span = inp.span_s
    h = span / inp.span_steps
    grow = np.exp(np.minimum(rate * (span - h), 50.0))
    base = {q: tol.CHECK_LOCAL_C * h * span * M2[q] * grow for q in QUANTITIES}
    physics = dict(base)
    physics["position"] = base["position"] + 0.5 * (span - h) * base["velocity"]
    physics["orientation"] = base["orientation"] + 0.5 * (span - h) * base["angular_velocity"]
    u = inp.unit_roundoff
    arith, print_ = {}, {}
    for q in BLOCKS:
        mag = (_magnitude(y_start, q) if y_end is None
               else np.fmax(_magnitude(y_start, q), _magnitude(y_end, q)))
        arith[q] = inp.span_steps * tol.CHECK_ROUNDINGS_PER_STEP * u * mag
        if q == "angular_velocity" and scenario is not None:
            arith[q] = arith[q] + inp.span_steps * tol.CHECK_ROUNDINGS_PER_STEP * lever_arm_roundoff(
                scenario, y_start, u, h)
        if flow_roundoff is not None:
            arith[q] = arith[q] + flow_roundoff[q]
        pf = inp.print_floor.get(q)
        print_[q] = np.zeros(len(span)) if pf is None else pf[:-1] + pf[1:]
    total = {q: physics[q] + arith[q] + print_[q] for q in QUANTITIES}
    return Allowances(physics, arith, print_, total)


def _perturbed_initial_states(y0, scales):
    """13 states: y0 and 12 perturbations, 3 per quantity (each axis), of size CHECK_GROWTH_EPS × scale."""
    ys, sizes = [y0.copy()], []
    for q, sl in BLOCKS.items():
        for i in range(3):
            y = y0.copy()
            d = tol.CHECK_GROWTH_EPS * scales[q]
            if q == "orientation":
                rv = np.zeros(3)
                rv[i] = d
                y[Q] = quat_mul(quat_exp(rv), y0[Q])
            else:
                y[sl.start + i] += d
            ys.append(y)
            sizes.append(d)
    return np.array(ys), sizes


def error_growth(scenario, t_s, scales) -> dict:
    """How an error made at t = 0 in quantity p has grown in quantity q by each time of ``t_s``.

    Returns ``{(p, q): (T,)}`` with the running maximum over time of ``max_axis |Δq(t)| / |δp|``
    (units of q per unit of p; ≥ 1 on the diagonal), from RK4 runs of the flow (12 perturbations of
    size CHECK_GROWTH_EPS × ``scales[p]`` and the unperturbed run) on a grid of steps ≤
    CHECK_GROWTH_RATE_PER_STEP / L. The growth is an envelope factor: the RK4 error of a difference of
    two runs at L τ = 0.25 (~1e-5 relative per step) does not move it visibly.
    """
    F = flow_rhs(scenario)
    y0 = scenario.problem.initial_packed()
    t_s = np.asarray(t_s, dtype=float)
    T = float(t_s[-1]) if len(t_s) else 0.0
    out = {(p, q): np.ones(len(t_s)) if p == q else np.zeros(len(t_s))
           for p in QUANTITIES for q in QUANTITIES}
    if T <= 0.0:
        return out
    ys, sizes = _perturbed_initial_states(y0, scales)
    L = float(motion_rate(scenario, y0[None, :])[0])
    n = int(min(20000, max(100, math.ceil(T * max(L, 1.0) / tol.CHECK_GROWTH_RATE_PER_STEP))))
    grid = np.linspace(0.0, T, n + 1)
    Y = np.empty((n + 1,) + ys.shape)
    Y[0] = ys
    for k in range(1, n + 1):
        Y[k] = rk4_flow(F, Y[k - 1], grid[k] - grid[k - 1], 1)
    base = Y[:, :1, :]
    idx = np.minimum(np.searchsorted(grid, t_s - 1e-12 * T), n)   # first grid time at or after each t
    with np.errstate(all="ignore"):
        for pi, p in enumerate(BLOCKS):          # the order _perturbed_initial_states used
            block = Y[:, 1 + 3 * pi: 4 + 3 * pi, :]
            for q in QUANTITIES:
                if q == "orientation":
                    qa = base[..., Q] / np.linalg.norm(base[..., Q], axis=-1, keepdims=True)
                    qb = block[..., Q] / np.linalg.norm(block[..., Q], axis=-1, keepdims=True)
                    dq = geodesic_angle(np.broadcast_to(qa, qb.shape), qb)
                else:
                    dq = np.linalg.norm(block[..., BLOCKS[q]] - base[..., BLOCKS[q]], axis=-1)
                env = np.maximum.accumulate(np.nan_to_num(np.max(dq, axis=1) / sizes[3 * pi], nan=np.inf))
                if p == q:
                    env = np.maximum(env, 1.0)
                out[(p, q)] = env[idx]
    return out


def conservation_sensitivities(scenario, y) -> dict:
    """How much a unit defect in each quantity moves each conserved quantity, at states ``y`` (K, 13):
    ``{"energy": {quantity: (K,)}, "angular_momentum": {quantity: (K,)}}`` — bounds of ``|∂Q/∂y_b|``:
    energy ``|f|`` (position), ``m|v|`` (velocity), ``|τ| + |ω × L|`` (orientation), ``|L|`` (angular
    velocity); world angular momentum L = I_W ω: ``|∂L/∂θ| ≤ |L| + I_max |ω|``, ``|∂L/∂ω| ≤ I_max``, 0 for
    the translation. The one definition ``rbcheck check`` (its conserved evidence) and the fuzz
    (:func:`conservation_allowance`) weight local defects by."""
    from reference_sim.quaternion import matrix_from_quat
    p = scenario.problem
    y = np.asarray(y, dtype=float)
    q = y[:, Q] / np.linalg.norm(y[:, Q], axis=1, keepdims=True)
    R = matrix_from_quat(q)
    w = y[:, W]
    L = np.einsum("kij,kj->ki", p.body.world_inertia(R), w)
    f, tau = p.forces.force_torque(p.body, y[:, BLOCKS["position"]], y[:, BLOCKS["velocity"]], q, R)
    I_max = float(np.linalg.eigvalsh(p.body.inertia_B)[-1])
    l_mag, w_mag = np.linalg.norm(L, axis=1), np.linalg.norm(w, axis=1)
    zero = np.zeros(len(y))
    return {"energy": {"position": np.linalg.norm(f, axis=1),
                       "velocity": p.body.mass_kg * np.linalg.norm(y[:, BLOCKS["velocity"]], axis=1),
                       "orientation": np.linalg.norm(tau, axis=1) + np.linalg.norm(np.cross(w, L), axis=1),
                       "angular_velocity": l_mag},
            "angular_momentum": {"position": zero, "velocity": zero, "orientation": l_mag + I_max * w_mag,
                                 "angular_velocity": np.full(len(y), I_max)}}


def conservation_allowance(scenario, y, h_s: float, duration_s: float) -> dict:
    """How far a consistent scheme of order ≥ 1 with step ``h_s`` may move each conserved quantity over
    ``duration_s``, from the motion sampled at states ``y`` (K, 13) along it.

    Each step's defect is at most ``C h² M2`` per quantity (:func:`local_allowances`' physics part, C =
    tol.CHECK_LOCAL_C); a defect d moves a conserved quantity Q by at most ``Σ_b |∂Q/∂y_b| d_b``
    (:func:`conservation_sensitivities`), so over ``T / h`` steps Q moves by at most
    ``C h T max_t Σ_b |∂Q/∂y_b| M2_b`` (the largest over the samples stands for every step).

    Returns ``{"energy": J, "angular_momentum": kg m²/s}`` (absolute, not relative).
    """
    y = np.asarray(y, dtype=float)
    M2 = majorant(flow_rhs(scenario), y, motion_rate(scenario, y))
    sens = conservation_sensitivities(scenario, y)
    scale = tol.CHECK_LOCAL_C * float(h_s) * float(duration_s)
    return {k: scale * float(np.max(sum(sens[k][b] * M2[b] for b in QUANTITIES))) for k in sens}


@dataclass(frozen=True)
class _RunRows:
    """The row intervals of a run recorded at every step of Δt, in the form :func:`local_allowances` reads
    (a CheckInput's time fields): float64 arithmetic, no written-digit floor."""

    span_s: np.ndarray
    span_steps: np.ndarray
    unit_roundoff: float = 2.0 ** -53
    print_floor: dict = field(default_factory=dict)


def run_local_defect(scenario, y, dt_s: float, max_rows: int | None = None,
                     unit_roundoff: float = 2.0 ** -53, velocity_from_positions: bool = False) -> tuple:
    """The one-step defect of a run recorded at every step (``y`` (N + 1, 13), float64): from each recorded
    state the exact flow over Δt is compared with the next row, over what a consistent scheme of order ≥ 1
    may leave there (:func:`local_allowances`) — ``rbcheck check``'s local evidence, for a sweep's own runs.

    Returns ``(ratio, quantity, t_s)``: the largest defect / allowance over the decisive rows (h L ≤
    CHECK_MAX_HL, finite states) and where; ``(nan, "", nan)`` when no row is decisive. A wrong equation
    leaves an O(Δt) defect (ratio ∝ 1/Δt), a consistent scheme at most its allowance (ratio ≤ 1).
    ``max_rows``: judge that many rows, evenly spread over the run (each row's defect stands on its own).
    ``unit_roundoff``: of the precision the run's steps compute in (tolerances.UNIT_ROUNDOFF).
    ``velocity_from_positions``: the steps recompute v as Δx/Δt (engines.base.Traits), so the velocity may
    also carry the two positions' roundings over Δt, ``2 u (|x₀| + |x₁|)/Δt``."""
    y = np.asarray(y, dtype=float)
    n = len(y) - 1
    if n < 1:
        return math.nan, "", math.nan
    idx = np.arange(n)
    if max_rows is not None and n > max_rows:
        idx = np.unique(np.linspace(0, n - 1, max_rows).round().astype(int))
    y0, y1 = y[idx], y[idx + 1]
    good = np.all(np.isfinite(y0), axis=1) & np.all(np.isfinite(y1), axis=1)
    if not np.any(good):
        return math.nan, "", math.nan
    idx, y0, y1 = idx[good], y0[good], y1[good]
    rows = _RunRows(np.full(len(idx), float(dt_s)), np.ones(len(idx)), float(unit_roundoff))

    def allowance_fn(M2, rate):
        return local_allowances(rows, y0, M2, rate, y_end=y1, scenario=scenario).total
    flow = exact_flow(scenario, y0, rows.span_s, allowance_fn=allowance_fn)
    allow = local_allowances(rows, y0, flow.M2, flow.rate, flow.roundoff, y_end=y1, scenario=scenario)
    d = distances(y1, flow.y_end)
    decisive = dt_s * flow.rate <= tol.CHECK_MAX_HL
    total = dict(allow.total)
    if velocity_from_positions:
        total["velocity"] = total["velocity"] + 2.0 * unit_roundoff * (
            _magnitude(y0, "position") + _magnitude(y1, "position")) / dt_s
    best = (math.nan, "", math.nan)
    for q in QUANTITIES:
        with np.errstate(divide="ignore", invalid="ignore"):
            r = np.where(total[q] > 0.0, d[q] / total[q], np.where(d[q] > 0.0, np.inf, 0.0))
        # a quantity exactly zero at both ends of the exact step (a body that never turns) has nothing to
        # measure: what an engine leaves there is the round-off of the other quantities' terms, and a gross
        # error shows in the free runs
        moving = (_magnitude(y0, q) > 0.0) | (_magnitude(flow.y_end, q) > 0.0)
        r = np.where(decisive & moving, r, np.nan)
        if np.all(np.isnan(r)):
            continue
        k = int(np.nanargmax(r))
        if math.isnan(best[0]) or r[k] > best[0]:
            best = (float(r[k]), q, float((idx[k] + 1) * dt_s))
    return best
