"""The host loop: every :class:`~cross_checks.engines.world.WorldEngine`'s runs, written once.

For each world of B bodies (the requests grouped by ``WorldEngine.group_key``), step n = 1, 2, …:

1. the harness force and torque of each body (forces.harness_force_torque_floats: forces from the
   start-of-step state, held over the step, scaled by the pre-step decay factors), from the requested initial
   state at step 1 and from the state the engine returned after; constant forces (no state dependence)
   evaluated once, and applied once to an engine that keeps them (``keeps_forces``); an engine that takes
   the torques fixed in body axes itself (``takes_body_torque``) is given them once, and the harness
   evaluates the other forces only;
2. the weight ``m g`` taken off when the engine applies gravity itself;
3. the pre-step decay ``v ← γ_v v``, ``ω ← γ_ω ω`` (``World.decay``; docs/semantics.md, "Velocity decay");
4. ``World.step()``: timed, the engine's own time (``Run.engine_s``); everything else is rbcheck's;
5. the state read back and recorded; every ``chunk`` steps, a body whose state is non-finite or beyond
   reference_sim.simulate.BLOWUP_LIMIT, or whose engine warned, ends its run as "diverged at t = …" at the
   first such step, with the words of what was found in the chunk (or at that step only:
   ``World.first_cause_only``).

The state recorded at t = 0 is the world's reading of the requested one, or, where the world says its
round trip is not exact (``World.exact_start``), the requested one itself.

When nothing changes between steps (no state-dependent force, no decay) and the world has a compiled
``rollout``, the steps run there in one call; a world whose rollout takes every kind of force runs every
run there: with the start-of-step forces applied by the loop and the harness called back per step or stage
(``World.rollout_forces``: MJX, MuJoCo Warp), or taking every force and the decay itself
(``World.rollout_takes_all_forces``: jaxsim, Brax; its one-step mode is then ``rollout(1, harness)`` from
the rows). An engine whose worlds hold several Δt (``WorldEngine.world_key``; ``WorldEngine.mixed_steps``)
gets each run's own Δt in the harness and its run. A world that evaluates forces at every stage
(``per_stage``) gets neither forces nor decay from the loop.

An engine that raises, returns the wrong shape, or returns a non-finite state without diverging is an
:class:`~cross_checks.engines.base.EngineError` naming the engine and the run, for that world's runs only.
"""
from __future__ import annotations

import dataclasses
import gc
import time

import numpy as np

from cross_checks.engines import base, forces
from cross_checks.engines.base import EngineError
from cross_checks.engines.world import MANY_BODIES
from reference_sim.compiled import ForceRows
from reference_sim.quaternion import same_side
from reference_sim.simulate import Run, bad_rows, blowup_words, diverged, none_bad

__all__ = ["run", "one_step", "Harness", "host_problem"]


def host_problem(problem, body_torque: bool):
    """``problem`` as the harness evaluates its forces: for an engine that applies the torques fixed in body
    axes itself (``WorldEngine.takes_body_torque``), without them; otherwise ``problem`` itself."""
    fm = problem.forces
    if not body_torque or not any(t.frame == "body" for t in fm.torques):
        return problem
    kept = tuple(t for t in fm.torques if t.frame != "body")
    return dataclasses.replace(problem, forces=dataclasses.replace(fm, torques=kept))


def body_torque_B(problem) -> np.ndarray:
    """The sum of ``problem``'s torques fixed in body axes (N m, body axes): what an engine that takes them
    itself is given (``World.apply_body_torque``)."""
    return sum((np.asarray(t.torque, dtype=float) for t in problem.forces.torques if t.frame == "body"),
               np.zeros(3))


class Harness:
    """The harness forces of B bodies (one request each) at step ``dt_s`` (one for all, or one per body):
    per body the plain-float evaluator of forces.harness_force_torque_floats, and the pre-step decay factors
    (B,). ``body_torque``: the engine applies the torques fixed in body axes itself (``body_torque_B``, the
    (B, 3) it is given); the harness's forces are then the rest (:func:`host_problem`)."""

    def __init__(self, scenarios, dt_s, applies_gravity: bool, body_torque: bool = False):
        # each distinct scenario's (and step's) numbers once, gathered per body by index: a batch is mostly
        # copies of a few scenarios
        first: dict = {}
        which = [first.setdefault(id(sc), len(first)) for sc in scenarios]
        unique = list({id(sc): sc for sc in scenarios}.values())
        host = []
        for sc in unique:
            p = host_problem(sc.problem, body_torque)
            host.append((p, forces.float_forces(sc if p is sc.problem else p).force_torque,
                         forces.weight_W(sc) if applies_gravity else np.zeros(3),
                         body_torque_B(sc.problem) if body_torque else None))
        index = np.array(which, dtype=int)
        #: each body's problem as the harness evaluates its forces (the one of ``ft``; jax_forces' arrays)
        self.problems = [host[k][0] for k in which]
        # the scenario's own evaluator where the harness evaluates all of its forces
        self.ft = [host[k][1] for k in which]
        # many bodies: one compiled call for all of them (the same numbers, member by member)
        self.rows = ForceRows.of([h[0] for h in host], index) if len(scenarios) > MANY_BODIES else None
        dts = [dt_s] * len(scenarios) if np.ndim(dt_s) == 0 else list(dt_s)
        each: dict = {}
        pair = [each.setdefault((k, h), len(each)) for k, h in zip(which, dts)]
        g = np.array([[float(x) for x in forces.decay_factors(unique[k], h)] for k, h in each]).reshape(-1, 2)
        self.g_v = g[pair, 0]
        self.g_w = g[pair, 1]
        self.weight = np.array([h[2] for h in host]).reshape(-1, 3)[index]
        self.state_dependent = any(p.forces.state_dependent for p, *_ in host)
        self.body_torque_B = np.array([h[3] for h in host]).reshape(-1, 3)[index] if body_torque else None
        self.decays = any(sc.problem.forces.has_decay for sc in unique)
        # a few bodies: per body, plain floats (ft, γ_v, γ_ω, the weight), two arrays built at the end
        self._floats = list(zip(self.ft, self.g_v.tolist(), self.g_w.tolist(), self.weight.tolist()))

    def wrench(self, y, bodies=None) -> tuple:
        """``(f_W, tau_W)`` (B, 3) each at packed states ``y`` (B, 13): the harness's force minus the weight
        the engine applies, and its torque. ``bodies``: the bodies whose states the rows of ``y`` are, when
        not all of them in order: a slice of them (many bodies: one compiled call, as for all), or indices
        (each row then evaluated alone, in plain floats)."""
        if isinstance(bodies, slice) and self.rows is not None:   # the same operations as for all, below
            w = self.rows.force_torque(y, bodies)
            f, tau = w[:, 0:3], w[:, 3:6]
            f *= self.g_v[bodies, None]
            f -= self.weight[bodies]
            tau *= self.g_w[bodies, None]
            return f, tau
        if isinstance(bodies, slice):
            bodies = np.arange(len(self.ft))[bodies]
        if bodies is not None:
            bodies = np.asarray(bodies, dtype=int)
            w = np.array([self.ft[i](row) for i, row in zip(bodies.tolist(), np.asarray(y).tolist())])
            g_v, g_w, weight = self.g_v[bodies], self.g_w[bodies], self.weight[bodies]
        elif self.rows is None:
            f_rows, tau_rows = self.wrench_rows(y)
            return np.array(f_rows), np.array(tau_rows)
        else:   # many bodies: the same operations in place, on the compiled call's own (B, 6) array
            w = self.rows.force_torque(y)
            f, tau = w[:, 0:3], w[:, 3:6]
            f *= self.g_v[:, None]
            f -= self.weight
            tau *= self.g_w[:, None]
            return f, tau
        f = w[:, 0:3] * g_v[:, None] - weight
        tau = w[:, 3:6] * g_w[:, None]
        return f, tau


    def wrench_rows(self, y) -> tuple:
        """:meth:`wrench` of a few bodies (no compiled call for all: ``rows`` None) as B rows of 3 plain
        floats each: the same IEEE operations as the array path (γ_v f − w, γ_ω τ), without the arrays (a few
        bodies' arrays cost more than the engine's step), for a world whose ``apply`` takes such rows
        (``World.float_rows``)."""
        f_rows, tau_rows = [], []
        for (ft, gv, gw, (wx, wy, wz)), row in zip(self._floats, y):
            fx, fy, fz, tx, ty, tz = ft(row)
            f_rows.append((gv * fx - wx, gv * fy - wy, gv * fz - wz))
            tau_rows.append((gw * tx, gw * ty, gw * tz))
        return f_rows, tau_rows


def _words(engine, variant: str, requests) -> str:
    names = ", ".join(sorted({r.scenario.name for r in requests}))
    return f"{engine.name}:{variant} on {names}"


def _checked(engine, variant, requests, y, B: int, what: str) -> np.ndarray:
    y = np.asarray(y, dtype=float)
    if y.ndim < 2 or y.shape[-2:] != (B, 13):
        raise EngineError(f"{_words(engine, variant, requests)}: the world's {what} has shape {y.shape}, "
                          f"not (..., {B}, 13)")
    return y


def run(engine, variant: str, requests) -> list:
    """The runs of ``requests`` (base.RunRequest) with ``engine``'s ``variant``, in order: each a
    reference_sim.simulate.Run with ``engine_s`` (the seconds inside the engine) and ``host_s`` (rbcheck's),
    or the EngineError of its world."""
    base.check_variant(engine.name, engine.variants, variant)
    out: list = [None] * len(requests)
    groups: dict = {}
    keys: dict = {}   # a request's world key, once per scenario, step and length (a batch repeats them)
    for j, r in enumerate(requests):
        rk = (id(r.scenario), float(r.dt_s), int(r.n_steps))
        key = keys.get(rk)
        if key is None:
            key = keys[rk] = engine.world_key(r, variant)
        groups.setdefault(key, []).append(j)
    for idx in groups.values():
        for j, r in zip(idx, _run_group(engine, variant, [requests[j] for j in idx])):
            out[j] = r
    return out


def _run_group(engine, variant: str, reqs) -> list:
    """The runs of one world; when the engine rejects the world (a model it refuses) and it holds several
    scenarios, each scenario in a world of its own, so that only the refused one fails."""
    try:
        return _run_world(engine, variant, reqs)
    except EngineError as exc:
        scenarios = list(dict.fromkeys(id(r.scenario) for r in reqs))
        if len(scenarios) < 2:
            return [exc] * len(reqs)
        out: list = [None] * len(reqs)
        for key in scenarios:
            idx = [j for j, r in enumerate(reqs) if id(r.scenario) == key]
            for j, run_j in zip(idx, _run_group(engine, variant, [reqs[j] for j in idx])):
                out[j] = run_j
        return out
    except Exception as exc:  # noqa: BLE001 - an engine's own failure: the run fails, the rest go on
        return [EngineError(f"{_words(engine, variant, reqs)}: {type(exc).__name__}: {exc}")] * len(reqs)


def _run_world(engine, variant: str, reqs) -> list:
    t_all = time.perf_counter()
    dts = [float(r.dt_s) for r in reqs]   # one step, unless the engine's worlds take several (world_key)
    B, n_max = len(reqs), max(int(r.n_steps) for r in reqs)
    scenarios = [r.scenario for r in reqs]
    harness = Harness(scenarios, dts, engine.applies_gravity, engine.takes_body_torque)
    first = {}
    for sc in scenarios:   # a scenario's initial state once, however many of its runs the world holds
        if id(sc) not in first:
            first[id(sc)] = sc.problem.initial_packed()
    y0 = np.array([first[id(sc)] for sc in scenarios])
    world = engine.build(reqs, variant, dts[0])
    engine_s = 0.0
    try:
        with np.errstate(all="ignore"):
            world.set_state(y0)
            raw0 = np.asarray(world.first(y0), dtype=float)
            start = _checked(engine, variant, reqs, world.packed(raw0[None]), B, "first state")
            if not np.all(np.isfinite(start)):
                raise EngineError(f"{_words(engine, variant, reqs)}: the world returned a non-finite state "
                                  "before any step (set_state then read)")
            rec = np.empty((n_max + 1, *raw0.shape))
            rec[0] = raw0
            per_stage = bool(world.per_stage)
            _body_torque(world, harness, per_stage)
            constant = not harness.state_dependent
            f, tau = (None, None) if per_stage else harness.wrench(y0)
            ends = np.array([int(r.n_steps) for r in reqs])
            stopped: dict = {}   # body -> (step, words)
            rollout = getattr(world, "rollout", None)
            y = None   # the packed states, once converted
            if getattr(world, "rollout_takes_all_forces", False) and n_max:
                # the world's compiled loop takes every force itself (the harness, called back from it)
                t0 = time.perf_counter()
                _rollout(world, n_max, harness, rec)
                engine_s += time.perf_counter() - t0
                y = _checked(engine, variant, reqs, world.packed(rec), B, "packed states")
                _check(engine, variant, reqs, world, rec, 1, n_max + 1, ends, stopped, y[1:])
            elif (world.rollout_forces or (not per_stage and constant and not harness.decays)) \
                    and rollout is not None and n_max:
                if not per_stage:
                    world.apply(f, tau)
                t0 = time.perf_counter()
                _rollout(world, n_max, harness, rec)
                engine_s += time.perf_counter() - t0
                y = _checked(engine, variant, reqs, world.packed(rec), B, "packed states")
                _check(engine, variant, reqs, world, rec, 1, n_max + 1, ends, stopped, y[1:])
            else:
                engine_s, y = _steps(engine, variant, reqs, world, harness, rec, n_max, f, tau, ends,
                                     stopped, per_stage)
            engine_s -= float(world.host_s)
            if y is None:
                y = _checked(engine, variant, reqs, world.packed(rec), B, "packed states")
            if world.exact_start:
                y[0] = y0
    finally:
        world.close()
    if engine.sign_continuity:
        y = _same_side(y)
    host_s = time.perf_counter() - t_all - engine_s
    runs = []
    per_body = np.ascontiguousarray(np.swapaxes(y, 0, 1))   # (B, n + 1, 13): each run's rows, one copy
    total = max(1, int(ends.sum()))
    for i, r in enumerate(reqs):
        n, dt = int(r.n_steps), dts[i]
        if i in stopped:
            n_bad, why = stopped[i]
            run_i = diverged(per_body[i, :n_bad], dt, f" ({why})")
        else:
            run_i = Run(dt * np.arange(n + 1), per_body[i, :n + 1])
        share = n / total
        run_i.engine_s, run_i.host_s = engine_s * share, host_s * share
        runs.append(run_i)
    return runs


def _steps(engine, variant, reqs, world, harness, rec, n_max, f, tau, ends, stopped, per_stage) -> tuple:
    """The per-step loop (module docstring) into ``rec``; returns the seconds inside ``world.step()`` and the
    packed states (n_max + 1, B, 13), each chunk's as its divergence check converted them (rows after the
    last chunk, which no run reaches, NaN). The
    world's methods are bound once; a chunk's reads are kept as the world returns them and written into
    ``rec`` at the chunk's end, in one conversion (``World.rows``; the next step's forces use the last read
    as it is: ``World.packed_row`` of it). Constant forces that the engine clears after each step are
    re-applied by one call the world makes once for them (``World.applier``), and a step with nothing to
    apply or evaluate is the engine's step, timed, and the read only."""
    engine_s = 0.0
    perf = time.perf_counter
    step, read, apply, decay, packed_row = world.step, world.read, world.apply, world.decay, world.packed_row
    rows_of = world.rows
    wrench = harness.wrench_rows if world.float_rows and harness.rows is None else harness.wrench
    state_dependent, decays = harness.state_dependent, harness.decays
    kept = engine.keeps_forces and not state_dependent
    if not per_stage and kept:
        apply(f, tau)
    forces_each_step = not per_stage and (state_dependent or decays or not kept)
    again = None   # constant forces the engine clears: re-applied by one call per step (None: nothing to)
    if forces_each_step and not state_dependent and not decays:
        forces_each_step = False
        again = world.applier(f, tau)
    last = None   # the last read (none yet at step 1: the forces of step 1 are the requested state's)
    start = 1
    y = np.empty((n_max + 1, len(reqs), 13))
    y[0] = _checked(engine, variant, reqs, world.packed(rec[0:1]), len(reqs), "first state")[0]
    collecting = gc.isenabled()
    while start <= n_max:
        stop = min(start + engine.chunk, n_max + 1)
        rows = []
        keep = rows.append
        # the steps make no reference cycles: no collector pass over a chunk's reads, collected after it
        gc.disable()
        try:
            if forces_each_step:
                for _ in range(start, stop):
                    if state_dependent and last is not None:
                        f, tau = wrench(packed_row(last))
                    if decays:
                        decay(harness.g_v, harness.g_w)
                    if not kept:
                        apply(f, tau)
                    t0 = perf()
                    step()
                    engine_s += perf() - t0
                    last = read()
                    keep(last)
            elif again is not None:
                for _ in range(start, stop):
                    again()
                    t0 = perf()
                    step()
                    engine_s += perf() - t0
                    keep(read())
            else:
                for _ in range(start, stop):
                    t0 = perf()
                    step()
                    engine_s += perf() - t0
                    keep(read())
            rec[start:stop] = rows_of(rows)
            del rows, keep
        finally:
            if collecting:
                gc.enable()
        y[start:stop] = _check(engine, variant, reqs, world, rec, start, stop, ends, stopped)
        if len(stopped) == len(reqs) or all(i in stopped or ends[i] < stop for i in range(len(reqs))):
            rec[stop:] = np.nan
            y[stop:] = np.nan
            break
        start = stop
    return engine_s, y


def _rollout(world, n_max: int, harness, rec) -> None:
    """``world.rollout``'s raw states of steps 1..n_max into ``rec[1:]``: written there by the world itself
    when it takes an ``out`` (``World.rollout_into``: no copy of the whole record), else copied."""
    if world.rollout_into:
        world.rollout(n_max, harness, out=rec[1:])
    else:
        rec[1:] = np.asarray(world.rollout(n_max, harness), dtype=float)


def _body_torque(world, harness, per_stage: bool) -> None:
    """Give a world that takes the body-axes torques itself (``WorldEngine.takes_body_torque``) its bodies'
    torques, once (it keeps them): scaled by the pre-step decay factor γ_ω as the harness's own torques are,
    unless its forces are evaluated at every stage (the decay is then a damping torque of the stages)."""
    tau_B = harness.body_torque_B
    if tau_B is not None:
        world.apply_body_torque(tau_B if per_stage else tau_B * harness.g_w[:, None])


def _check(engine, variant, reqs, world, rec, start: int, stop: int, ends, stopped: dict, y=None):
    """Bodies whose recorded states of steps ``start..stop-1`` (within their own runs) blew up, or whose
    engine warned there, into ``stopped`` as ``(first bad step, words)``: the words of everything found in
    the chunk (``World.first_cause_only``: of what was found at that step only). ``y``: those steps' packed
    states when already converted. Returns those packed states."""
    if y is None:
        y = _checked(engine, variant, reqs, world.packed(rec[start:stop]), len(reqs), "states")
    if not world.warnings and none_bad(y):   # the common case, in two passes over the chunk
        return y
    bad = bad_rows(y)
    warned: dict = {}
    for i, n, words in world.warnings:
        if start <= n < stop and i not in warned:
            warned[i] = (n, words)
    # each body's first bad row of the chunk (its row count where none), for all bodies at once
    first_bad = np.where(bad.any(axis=0), np.argmax(bad, axis=0), len(bad)).tolist()
    for i in range(len(reqs)):
        if i in stopped or ends[i] < start:
            continue
        last = min(stop, ends[i] + 1) - start
        candidates = []
        if first_bad[i] < last:
            k = first_bad[i]
            candidates.append((start + k, blowup_words(y[k, i])))
        if i in warned and warned[i][0] < start + last:
            candidates.append(warned[i])
        if candidates:
            first = min(c[0] for c in candidates)
            stopped[i] = (first, "; ".join(c[1] for c in sorted(candidates)
                                           if c[0] == first or not world.first_cause_only))
    return y


def _same_side(y) -> np.ndarray:
    """States (n + 1, B, 13) with each quaternion's sign on the previous recorded one's side
    (reference_sim.quaternion.same_side, step after step): the sign of row n is the product of the signs
    of the dot products of consecutive raw rows (a sign flip is exact)."""
    q = y[..., 6:10]
    with np.errstate(invalid="ignore", over="ignore"):
        dots = np.einsum("nbi,nbi->nb", q[1:], q[:-1])
    flips = np.where(dots < 0.0, -1.0, 1.0)
    sign = np.concatenate([np.ones((1, y.shape[1])), np.cumprod(flips, axis=0)])
    out = y.copy(order="K")   # in y's layout (a world may give it per run: packed_rows)
    out[..., 6:10] = q * sign[..., None]
    return out


def one_step(engine, scenario, variant: str, dt_s: float, y_start) -> np.ndarray:
    """One step of ``dt_s`` from exactly each row of ``y_start`` (..., 13): a world of one body per row, put
    at the row with its pre-step decay, the harness forces of the row applied, stepped once and read; a row
    whose step the engine reported failed (``World.warnings``) comes back non-finite."""
    base.check_variant(engine.name, engine.variants, variant)
    rows = np.asarray(y_start, dtype=float).reshape(-1, 13)
    if len(rows) == 0:
        return np.empty(np.shape(y_start))
    from cross_checks.engines.base import RunRequest
    reqs = [RunRequest(scenario, float(dt_s), 1)] * len(rows)
    harness = Harness([scenario] * len(rows), dt_s, engine.applies_gravity, engine.takes_body_torque)
    world = engine.build(reqs, variant, float(dt_s))
    try:
        with np.errstate(all="ignore"):
            per_stage = bool(world.per_stage)
            if getattr(world, "rollout_takes_all_forces", False):   # the decay and the forces: the world's
                world.set_state(rows)
                raw1 = np.asarray(world.rollout(1, harness), dtype=float)
            else:
                _body_torque(world, harness, per_stage)
                if per_stage:
                    world.set_state(rows)
                else:
                    y_dec = rows.copy()
                    y_dec[:, 3:6] *= harness.g_v[:, None]
                    y_dec[:, 10:13] *= harness.g_w[:, None]
                    world.set_state(y_dec)
                    world.apply(*harness.wrench(rows))
                world.step()
                raw1 = world.rows([world.read()])
            y1 = _checked(engine, variant, reqs, world.packed(raw1), len(rows), "states")[0]
            for i, _, _ in world.warnings:   # a step the engine reported failed has no state
                y1[i] = np.nan
    finally:
        world.close()
    if engine.sign_continuity:
        y1 = y1.copy()
        y1[:, 6:10] = same_side(y1[:, 6:10], rows[:, 6:10])
    return y1.reshape(np.shape(y_start))
