"""Running one engine variant on a whole batch of cases: free runs at the three rungs, and one-step runs.

Three paths, each giving what the engine's own adapter gives, case by case:

* ``reference:*`` — :class:`~cross_checks.fuzz.kernel.CaseKernel`: every case and rung of the batch in one
  NumPy-backend stepper (bit-identical to ``reference_sim.simulate``'s single-body path, tested);
* ``mujoco:*`` — ``mujoco.rollout`` over one model per case, built once by the adapter's own
  ``build_model`` and set to each variant's integrator and each rung's step in place (:func:`_model`):
  constant forces in one call per rung, state-dependent forces and the velocity decay
  one step per call with the adapter's harness (forces from the start-of-step state, decay before the
  step, the weight left to MuJoCo) evaluated for all cases at once. Bit-identical to
  ``MujocoAdapter.simulate`` (tested); ``mujoco:rk4`` with forces that change within a step needs its
  per-stage control callback and runs through the adapter, case by case (on the case's compiled model,
  ``mujoco_engine.models_from``). A run that blows up is re-run through the adapter, so its
  "diverged at t = …" is the adapter's own;
* ``pybullet:*`` — :mod:`~cross_checks.fuzz.pybullet_batch`: the adapter's runs, case by case, in a world of
  the process's own (a body per case and variant, kept for its runs, instead of a world reset per run;
  bit-identical, tested);
  a run that blows up or is rejected goes through the adapter;
* every other engine (engine files, Python adapters) — its adapter, case by case.

Runs are recorded whole (``(n + 1, B, 13)``, NaN after a divergence or for a failed run); the batch is
small enough (tens of cases, a few hundred steps) that measuring afterwards beats measuring on the fly.
"""
from __future__ import annotations

import contextlib
import math
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np

from cross_checks.core import tolerances as tol
from cross_checks.fuzz.kernel import CaseKernel, columns, rows, runs_compiled
from reference_sim.simulate import BLOWUP_LIMIT

__all__ = ["Runs", "RUNGS", "run_ladder", "one_step"]

#: Rungs of a case's free-running ladder: steps h, h/2, h/4.
RUNGS = 3


@dataclass
class Runs:
    """A variant's runs of every case of a batch at one step per case (``h_s``, (B,), s).

    y : (n + 1, B, 13) packed states [x_W, v_W, q_WB (w x y z), w_W], NaN from a divergence on, and for
        a failed run. status : per case "ok", "diverged" or "failed". diverged_at_s : (B,), NaN when not
        diverged. message : per case ("" when ok).
    """

    h_s: np.ndarray
    y: np.ndarray
    status: list
    diverged_at_s: np.ndarray
    message: list


def _empty_runs(h_s, n):
    B = len(h_s)
    return Runs(np.asarray(h_s, dtype=float), np.full((n + 1, B, 13), np.nan), ["ok"] * B, np.full(B, np.nan),
                [""] * B)


def _store_run(runs, i, run, n):
    """Put an adapter's Run (reference_sim.simulate.Run) into case ``i`` of ``runs``."""
    k = len(run.y)
    runs.y[:k, i] = run.y
    if run.diverged_at_s is not None:
        runs.status[i] = "diverged"
        runs.diverged_at_s[i] = float(run.diverged_at_s)
        runs.message[i] = run.message or f"diverged at t = {run.diverged_at_s:.6g} s"
    elif k != n + 1:
        runs.status[i] = "failed"
        runs.message[i] = f"the engine returned {k} states instead of {n + 1}"


def _fail(runs, i, message):
    runs.y[:, i] = np.nan
    runs.status[i] = "failed"
    runs.message[i] = message


def _adapter_run(variant, scenario, h, n, runs, i):
    """Case ``i`` through the engine's own adapter (time-limited like a sweep's run)."""
    from cross_checks.engines import get_adapter, split_variant
    from cross_checks.sweep.lifecycle import TimeLimitExceeded, time_limit
    engine, var = split_variant(variant)
    try:
        with time_limit(tol.RUN_TIME_LIMIT_S, "the run"):
            run = get_adapter(engine).simulate(scenario, var, float(h), int(n))
    except KeyboardInterrupt:
        raise
    except TimeLimitExceeded as exc:
        return _fail(runs, i, str(exc))
    except Exception as exc:  # noqa: BLE001 - an engine failure is a failed run, as in a sweep
        return _fail(runs, i, f"{type(exc).__name__}: {exc}".strip())
    _store_run(runs, i, run, n)


# --- the reference: the N-case kernel --------------------------------------------------------------------

def _mark_divergence(runs, i, k, h):
    t = k * h
    runs.status[i] = "diverged"
    runs.diverged_at_s[i] = t
    runs.message[i] = f"diverged at t = {t:.6g} s"
    runs.y[k:, i] = np.nan


def _reference_ladder(var, scenarios, h0s, n0):
    """All cases and rungs in one kernel, members dropped as their rung ends."""
    B = len(scenarios)
    members = [(r, i) for r in range(RUNGS) for i in range(B)]
    hs = [h0s[i] / 2 ** r for r, i in members]
    out = [_empty_runs(np.asarray(h0s) / 2 ** r, n0 * 2 ** r) for r in range(RUNGS)]
    y0 = np.array([_initial(scenarios[i].problem) for _, i in members])
    problems = [scenarios[i].problem for _, i in members]
    each = runs_compiled(var, problems, hs, y0, [n0 * 2 ** r for r, _ in members])
    if each is not None:   # member by member, compiled (bit-identical to each member's float stepper)
        for (r, i), h, (y, k) in zip(members, hs, each):
            out[r].y[:, i] = y
            if k is not None:
                _mark_divergence(out[r], i, k, h)
        return out
    kern = CaseKernel.stack(problems, var, hs)
    for r in range(RUNGS):
        out[r].y[0] = y0[r * B:(r + 1) * B]
    y = columns(y0)
    rung = np.array([r for r, _ in members], dtype=int)
    case = np.array([i for _, i in members], dtype=int)
    last = n0 * 2 ** rung                    # each member's final step
    alive = np.ones(len(members), dtype=bool)
    active = np.arange(len(members))         # member numbers currently in the kernel
    with np.errstate(all="ignore"):
        for k in range(1, n0 * 2 ** (RUNGS - 1) + 1):
            y = kern.step(y)
            Y = rows(y)
            bad = ~np.all(np.isfinite(Y), axis=1) | (np.max(np.abs(Y), axis=1) > BLOWUP_LIMIT)
            live = alive[active]
            for j in np.flatnonzero(live & bad):
                mnum = int(active[j])
                alive[mnum] = False
                _mark_divergence(out[rung[mnum]], int(case[mnum]), k, hs[mnum])
            ok = live & ~bad
            for r in range(RUNGS):
                sel = ok & (rung[active] == r)
                if sel.any():
                    out[r].y[k, case[active[sel]]] = Y[sel]
            ended = last[active] == k
            if ended.any():
                keep = np.flatnonzero(~ended)
                if not len(keep):
                    break
                kern = kern.take(keep)
                y = [c[keep] for c in y]
                active = active[keep]
    return out


# --- MuJoCo: rollout over one model per (case, rung) ---------------------------------------------------

#: The adapter's Session records the time of a warning from its MjData; rollouts have many, so a
#: warning's time is not kept (a run that warned is re-run through the adapter, which keeps it).
_NO_DATA = SimpleNamespace(time=math.nan)

#: Compiled models of the batch's scenarios, ONE per scenario whatever the variant and step:
#: {(id(scenario), build_model): (scenario, model or the adapter's EngineError message)}. The scenario is
#: kept so that its id cannot be reused while cached; ``build_model`` is in the key so that a model built
#: before it was patched is never served after.
_MODELS: dict = {}
_MODELS_MAX = 512   # a batch holds 64 cases


def _model(sc, var, h):
    """``build_model(sc, var, h)``: compiled once per scenario, then set to ``var``'s integrator and step
    ``h`` in place (``opt.integrator`` and ``opt.timestep`` are all a variant and a step change in a
    compiled model: runs bit-identical to the adapter's, tested for every variant on the same models).
    The model is shared: a rollout call must hold each scenario at one (variant, step) only, and set it
    right before the call (:func:`_set`). Raises the adapter's EngineError for a model MuJoCo rejects."""
    from cross_checks.engines import mujoco_engine as me
    from cross_checks.engines.base import EngineError
    key = (id(sc), me.build_model)
    hit = _MODELS.get(key)
    if hit is None or hit[0] is not sc:
        if len(_MODELS) >= _MODELS_MAX:
            _MODELS.clear()
        try:
            hit = (sc, me.build_model(sc, var, h))
        except EngineError as exc:
            hit = (sc, str(exc))
        _MODELS[key] = hit
    if isinstance(hit[1], str):
        raise EngineError(hit[1])
    return _set(hit[1], var, h)


def _set(model, var, h):
    """``model`` set to ``var``'s integrator and step ``h`` (in place)."""
    from cross_checks.engines import mujoco_engine as me
    model.opt.integrator = me.integrator_of(var)
    model.opt.timestep = float(h)
    return model


#: Initial states of the batch's problems: {id(problem): (problem, packed (13,))}, read-only.
_INITIAL: dict = {}


def _initial(problem) -> np.ndarray:
    """``problem.initial_packed()``, once per problem (every variant's runs start there; not to be written
    into)."""
    hit = _INITIAL.get(id(problem))
    if hit is None or hit[0] is not problem:
        if len(_INITIAL) >= _MODELS_MAX:
            _INITIAL.clear()
        hit = _INITIAL[id(problem)] = (problem, problem.initial_packed())
        hit[1].flags.writeable = False
    return hit[1]


def clear_cache() -> None:
    """Forget the batch's compiled models, initial states and shared steppers, and remove the PyBullet world's
    body (the end of a batch)."""
    import sys

    from cross_checks.fuzz import kernel
    _MODELS.clear()
    _INITIAL.clear()
    _STRUCTURES.clear()
    kernel.clear_cache()
    if "cross_checks.fuzz.pybullet_batch" in sys.modules:
        sys.modules["cross_checks.fuzz.pybullet_batch"].release()


def _mujoco_state(me, y):
    """Packed states (M, 13) -> MuJoCo full-physics states (M, 14): [time 0, qpos, qvel (ω in BODY axes)]."""
    qpos, qvel = me.to_qpos_qvel(y)
    return np.concatenate([np.zeros((len(y), 1)), qpos, qvel], axis=1)


def _packed1_cols(qpos, qvel):
    """MujocoAdapter's ``_packed1`` on columns: the state its harness evaluates the forces at."""
    x0, x1, x2, s, a, b, c = qpos.T
    v0, v1, v2, p0, p1, p2 = qvel.T
    t0, t1, t2 = 2.0 * (b * p2 - c * p1), 2.0 * (c * p0 - a * p2), 2.0 * (a * p1 - b * p0)
    return [x0, x1, x2, v0, v1, v2, s, a, b, c,
            p0 + s * t0 + (b * t2 - c * t1), p1 + s * t1 + (c * t0 - a * t2), p2 + s * t2 + (a * t1 - b * t0)]


class _Harness:
    """The MuJoCo adapter's harness for N (case, step) members: world force minus the weight and world
    torque (``base.harness_force_torque``: the plain-float force kernel, scaled by the pre-step decay
    factors), evaluated for all members at once from columns of states."""

    def __init__(self, scenarios, hs):
        from cross_checks.engines.base import decay_factors
        self.forces = CaseKernel.stack([sc.problem for sc in scenarios], "course", [sc.dt_s for sc in scenarios])
        g = np.array([decay_factors(sc, h) for sc, h in zip(scenarios, hs)], dtype=float)
        self.gv, self.gw = g[:, 0], g[:, 1]
        self.weight = np.array([sc.problem.body.mass_kg * np.asarray(sc.problem.forces.gravity_W, dtype=float)
                                for sc in scenarios])

    def xfrc(self, y_cols):
        """(M, 12) xfrc_applied rows of [world body (zeros), the free body: f − m g, τ]."""
        fx, fy, fz, tx, ty, tz = self.forces.force_torque_cols(y_cols)
        out = np.zeros((len(self.gv), 12))
        f = np.stack([self.gv * fx, self.gv * fy, self.gv * fz], axis=1)
        out[:, 6:9] = f - self.weight
        out[:, 9:12] = np.stack([self.gw * tx, self.gw * ty, self.gw * tz], axis=1)
        return out


def _needs_per_step(sc):
    fm = sc.problem.forces
    return fm.state_dependent or fm.has_decay


def _structure(model) -> tuple:
    """What an MjData built for ``model`` depends on besides sizes: a free body whose inertial frame is the
    body frame is "simple" (diagonal mass-matrix storage, nC = 6), a rotated one is not (nC = 21). One
    MjData serves every model of the same structure; across structures rollout silently produces
    garbage (measured: the non-simple models blow up in their first step). Read once per model (a batch
    groups its models by structure at every rung and one-step round)."""
    hit = _STRUCTURES.get(id(model))
    if hit is None or hit[0] is not model:
        if len(_STRUCTURES) >= _MODELS_MAX:
            _STRUCTURES.clear()
        hit = _STRUCTURES[id(model)] = (model, (tuple(int(v) for v in model.body_simple),
                                                tuple(int(v) for v in model.dof_simplenum)))
    return hit[1]


#: {id(model): (model, its _structure)}: the model kept so that its id cannot be reused while cached.
_STRUCTURES: dict = {}


def _by_structure(models, idx):
    groups: dict = {}
    for j in idx:
        groups.setdefault(_structure(models[j]), []).append(j)
    return list(groups.values())


def _rollout_free(mods, state0, xfrc, harness, per_step, n_max, threads, session):
    """qpos (n_max + 1, M, 7), qvel (n_max + 1, M, 6) of members sharing one model structure."""
    import mujoco
    from mujoco import rollout
    spec = mujoco.mjtState.mjSTATE_XFRC_APPLIED
    datas = [mujoco.MjData(mods[0]) for _ in range(max(1, threads))]
    M = len(mods)
    qpos = np.empty((n_max + 1, M, 7))
    qvel = np.empty((n_max + 1, M, 6))
    qpos[0], qvel[0] = state0[:, 1:8], state0[:, 8:14]
    if not per_step.any() and np.all(harness.gv == 1.0) and np.all(harness.gw == 1.0):
        out, _ = rollout.rollout(mods, datas, state0, xfrc[:, None, :], control_spec=spec, nstep=n_max)
        qpos[1:], qvel[1:] = np.moveaxis(out[:, :, 1:8], 1, 0), np.moveaxis(out[:, :, 8:14], 1, 0)
        return qpos, qvel
    runner = rollout.Rollout(nthread=threads if threads > 1 else 0)
    # one step per call: the arrays rollout's wrapper would check and allocate every call, given once (in
    # the shapes and dtype it makes them: (M, nstate) start states, (M, 1, ·) controls, states, sensordata)
    state = np.ascontiguousarray(state0, dtype=float)
    ctrl = np.empty((M, 1, xfrc.shape[1]))
    out = np.empty((M, 1, state.shape[1]))
    sensors = np.empty((M, 1, mods[0].nsensordata))
    per_step_any = bool(per_step.any())
    try:
        for n in range(1, n_max + 1):
            if per_step_any:
                fresh = harness.xfrc(_packed1_cols(qpos[n - 1], qvel[n - 1]))
                xfrc[per_step] = fresh[per_step]
            st = state.copy()
            st[:, 8:11] *= harness.gv[:, None]
            st[:, 11:14] *= harness.gw[:, None]
            ctrl[:, 0, :] = xfrc
            runner.rollout(mods, datas, st, ctrl, control_spec=spec, nstep=1, state=out, sensordata=sensors,
                           skip_checks=True)
            state = out[:, 0, :].copy()
            qpos[n], qvel[n] = state[:, 1:8], state[:, 8:14]
    finally:
        runner.close()
    return qpos, qvel


def _mujoco_group(var, scenarios, hs, ns, threads):
    """Free runs of members (scenario, h, n) through mujoco.rollout: (y (n_max + 1, M, 13), built, warned)
    with ``built[j]`` the adapter's EngineError message for a model it rejects ("" otherwise) and
    ``warned`` whether MuJoCo raised a warning (an instability) during the rollouts."""
    from cross_checks.engines import mujoco_engine as me
    from cross_checks.engines.base import EngineError
    M = len(scenarios)
    models, built = [], []
    for sc, h in zip(scenarios, hs):
        try:
            models.append(_model(sc, var, h))
            built.append("")
        except EngineError as exc:
            models.append(None)
            built.append(str(exc))
    n_max = max(ns) if ns else 0
    Y = np.full((n_max + 1, M, 13), np.nan)
    warned = False
    for grp in _by_structure(models, [j for j in range(M) if models[j] is not None]):
        sub = [scenarios[j] for j in grp]
        y0 = np.array([_initial(sc.problem) for sc in sub])
        harness = _Harness(sub, [hs[j] for j in grp])
        xfrc = harness.xfrc(columns(y0))
        per_step = np.array([sc.problem.forces.state_dependent for sc in sub])
        with me.Session(_NO_DATA) as session, np.errstate(all="ignore"):
            qpos, qvel = _rollout_free([models[j] for j in grp], _mujoco_state(me, y0), xfrc, harness, per_step,
                                       n_max, threads, session)
            warned = warned or bool(session.warnings)
        Y[:, grp] = me.to_packed(qpos, qvel)
    return Y, built, warned


def _mujoco_ladder(var, scenarios, h0s, n0, threads):
    from cross_checks.engines import mujoco_engine as me
    B = len(scenarios)
    out = []
    for r in range(RUNGS):
        h = np.asarray(h0s) / 2 ** r
        n = n0 * 2 ** r
        runs = _empty_runs(h, n)
        batched = [i for i in range(B) if not me.forces_per_stage(scenarios[i], var)]
        staged = [i for i in range(B) if me.forces_per_stage(scenarios[i], var)]
        if batched:
            Y, built, warned = _mujoco_group(var, [scenarios[i] for i in batched], [h[i] for i in batched],
                                             [n] * len(batched), threads)
            for j, i in enumerate(batched):
                bad = ~np.all(np.isfinite(Y[:, j]), axis=1) | (np.max(np.abs(Y[:, j]), axis=1) > BLOWUP_LIMIT)
                if built[j]:
                    _fail(runs, i, f"EngineError: {built[j]}")
                elif bad.any() or warned:
                    staged.append(i)   # the adapter's own divergence time and message
                else:
                    runs.y[:, i] = Y[:, j]
        with me.models_from(_model):   # the adapter's runs on the batch's compiled models
            for i in staged:
                _adapter_run(f"mujoco:{var}", scenarios[i], h[i], n, runs, i)
        out.append(runs)
    return out


# --- entry points ---------------------------------------------------------------------------------------

def run_ladder(variant: str, scenarios, h0s, n0: int, *, threads: int = 1) -> list:
    """The free runs of ``variant`` on every case at h0, h0/2, h0/4 (``n0``, 2 n0, 4 n0 steps): [Runs] × 3."""
    engine, var = variant.split(":", 1)
    if engine == "reference":
        return _reference_ladder(var, scenarios, h0s, n0)
    if engine == "mujoco":
        return _mujoco_ladder(var, scenarios, h0s, n0, threads)
    out = [_empty_runs(np.asarray(h0s) / 2 ** r, n0 * 2 ** r) for r in range(RUNGS)]
    for i, sc in enumerate(scenarios):   # case by case: PyBullet keeps a case's body for its rungs
        for r, runs in enumerate(out):
            h, n = float(runs.h_s[i]), n0 * 2 ** r
            if engine != "pybullet" or not _pybullet_run(var, sc, h, n, runs, i):
                _adapter_run(variant, sc, h, n, runs, i)
    return out


def _pybullet_run(var, scenario, h, n, runs, i) -> bool:
    """Case ``i`` through :mod:`~cross_checks.fuzz.pybullet_batch` (the adapter's run, cheaper); False when
    the run must go through the adapter instead (it blew up, or PyBullet rejected the body)."""
    from cross_checks.fuzz import pybullet_batch
    try:
        y = pybullet_batch.simulate(scenario, var, float(h), int(n))
    except KeyboardInterrupt:
        raise
    except Exception:  # noqa: BLE001 - the adapter reproduces the failure with its own message
        return False
    if y is None:
        return False
    runs.y[:, i] = y
    return True


def _rounds(scenarios, hs) -> list:
    """Member indices in rounds that hold each scenario at one step only (the models are shared per
    scenario, :func:`_model`): round k holds every scenario's k-th distinct step."""
    seen: dict = {}
    rounds: list = []
    for j, (sc, h) in enumerate(zip(scenarios, hs)):
        steps = seen.setdefault(id(sc), [])
        if float(h) not in steps:
            steps.append(float(h))
        k = steps.index(float(h))
        while len(rounds) <= k:
            rounds.append([])
        rounds[k].append(j)
    return rounds


def _mujoco_one_step(var, scenarios, hs, y_start, threads):
    """One step per member through rollout (nstep 1): the adapter's one_step, member by member (NaN for a
    member whose model MuJoCo rejects)."""
    from cross_checks.engines import mujoco_engine as me
    from cross_checks.engines.base import EngineError
    M = len(scenarios)
    out = np.full((M, 13), np.nan)
    for rnd in _rounds(scenarios, hs):
        models = [None] * M
        for j in rnd:
            try:
                models[j] = _model(scenarios[j], var, hs[j])
            except EngineError:
                pass
        for grp in _by_structure(models, [j for j in rnd if models[j] is not None]):
            out[grp] = _mujoco_one_step_group(me, [scenarios[j] for j in grp], [models[j] for j in grp], hs[grp],
                                              y_start[grp], threads)
    return out


def _mujoco_one_step_group(me, sub, mods, hs, y_start, threads):
    """One step of members sharing one model structure, each scenario at one step: (M, 13)."""
    import mujoco
    from mujoco import rollout

    from cross_checks.engines.base import apply_decay_prestep
    harness = _Harness(sub, hs)
    xfrc = harness.xfrc(columns(y_start))
    y_dec = np.array([apply_decay_prestep(sc, y, h) for sc, y, h in zip(sub, y_start, hs)])
    datas = [mujoco.MjData(mods[0]) for _ in range(max(1, threads))]
    with me.Session(_NO_DATA), np.errstate(all="ignore"):
        res, _ = rollout.rollout(mods, datas, _mujoco_state(me, y_dec), xfrc[:, None, :],
                                 control_spec=mujoco.mjtState.mjSTATE_XFRC_APPLIED, nstep=1)
    return me.to_packed(res[:, 0, 1:8], res[:, 0, 8:14])


def one_step(variant: str, scenarios, hs, y_start, *, threads: int = 1):
    """One step of ``hs[j]`` from ``y_start[j]`` (M, 13) for members of ``scenarios[j]``: (M, 13), NaN
    where the engine failed; None when the engine has no one-step mode."""
    from cross_checks.engines import get_adapter, has_one_step
    engine, var = variant.split(":", 1)
    y_start = np.asarray(y_start, dtype=float)
    hs = np.asarray(hs, dtype=float)
    if not has_one_step(variant):
        return None
    if engine == "reference":
        kern = CaseKernel.stack([sc.problem for sc in scenarios], var, hs)
        with np.errstate(all="ignore"):
            return rows(kern.step(columns(y_start)))
    out = np.full((len(scenarios), 13), np.nan)
    rest = list(range(len(scenarios)))
    if engine == "mujoco":
        from cross_checks.engines import mujoco_engine as me
        plain = [j for j in rest if not me.forces_per_stage(scenarios[j], var)]
        rest = [j for j in rest if me.forces_per_stage(scenarios[j], var)]
        if plain:
            out[plain] = _mujoco_one_step(var, [scenarios[j] for j in plain], hs[plain], y_start[plain], threads)
    adapter = get_adapter(engine)
    if engine == "pybullet":   # the adapter's one_step in this process's own world (pybullet_batch)
        from cross_checks.fuzz import pybullet_batch
        adapter = SimpleNamespace(one_step=pybullet_batch.one_step)
    groups: dict = {}
    for j in rest:
        groups.setdefault((id(scenarios[j]), float(hs[j])), []).append(j)
    with _models_lent(engine):
        for idx in groups.values():
            try:
                with np.errstate(all="ignore"):
                    out[idx] = np.asarray(adapter.one_step(scenarios[idx[0]], var, float(hs[idx[0]]), y_start[idx]),
                                          dtype=float)
            except KeyboardInterrupt:
                raise
            except Exception:  # noqa: BLE001 - a failed one-step run leaves NaN: the property says so
                pass
    return out


def _models_lent(engine):
    """MuJoCo's adapter running on the batch's compiled models (:func:`_model`); nothing for other engines."""
    if engine != "mujoco":
        return contextlib.nullcontext()
    from cross_checks.engines import mujoco_engine as me
    return me.models_from(_model)
