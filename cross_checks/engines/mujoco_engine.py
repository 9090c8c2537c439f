"""MuJoCo as an engine adapter (``mujoco:VARIANT``, float64); the interface is cross_checks.engines.base.

State at the boundary: ``qpos = [x_W, q_WB (w x y z)]``, ``qvel = [v_W (COM), ω_B (BODY axes)]``, so the
packed state's ``ω_W = R(q) ω_B``; read from qpos/qvel only. Forces: the harness's world force at the COM
minus the weight ``m g`` (MuJoCo applies gravity) and world torque, written into ``xfrc_applied`` before
every step from the start-of-step state; ``mujoco:rk4`` with state-dependent forces or decay evaluates them
at every RK4 stage through MuJoCo's process-global control callback (:class:`Session`); the other
integrators get the decay before the step (base.apply_decay_prestep). :func:`simulate_many` runs the
requests through ``mujoco.rollout``. Divergence: the first bad state (reference_sim.simulate.bad_rows) or
MuJoCo warning ends the run as ``diverged at t = …``; no MUJOCO_LOG.TXT is written.
Conventions, defaults neutralised and what pins them: docs/engine_conventions.md, "MuJoCo 4.0.0".
"""
from __future__ import annotations

import threading

import numpy as np

from cross_checks.engines import base
from cross_checks.engines.base import (
    EngineError,
    ModuleAdapter,
    Variant,
    harness_force_torque,
    stage_force_torque_floats,
)
from cross_checks.engines.step_floats import harness_fn
from reference_sim.quaternion import quat_conj, quat_from_matrix, rotate
from reference_sim.simulate import Run, bad_rows, blowup_words, diverged

mujoco, _IMPORT_ERROR = base.optional_import("mujoco")

__all__ = ["ENGINE", "VARIANTS", "EngineError", "version", "simulate", "simulate_many", "one_step",
           "build_model", "packed_floats", "to_packed", "to_qpos_qvel"]

ENGINE = "mujoco"
#: The variants, named after MuJoCo's integrators (``mjtIntegrator.mjINT_<NAME>``).
VARIANTS = {
    "euler": Variant(1, "MuJoCo Euler: semi-implicit Euler, explicit gyroscopic term, quaternion by the "
                        "exponential map",
                     traits=base.SYMPLECTIC_EULER_EXPLICIT_GYRO),
    "rk4": Variant(4, "MuJoCo RK4: classical 4th-order Runge-Kutta; state-dependent forces evaluated at "
                      "every stage",
                   traits=base.HIGHER_ORDER),
    "implicit": Variant(1, "MuJoCo implicit: velocity-implicit Euler (gyroscopic/velocity derivatives in "
                           "the step)",
                        traits=base.SYMPLECTIC_EULER_IMPLICIT_GYRO),
    "implicitfast": Variant(1, "MuJoCo implicitfast: implicit Euler without the Coriolis/centrifugal "
                               "derivatives",
                            traits=base.SYMPLECTIC_EULER_IMPLICIT_GYRO),
    "discrete": Variant(1, "MuJoCo discrete: constraint solve and implicit velocity update in one, in the "
                           "metric M + hD + h²K (for a lone free body: implicitfast's step)",
                        traits=base.SYMPLECTIC_EULER_IMPLICIT_GYRO),
}

#: Steps between divergence checks of a free-running simulation (checked vectorised per chunk).
_CHUNK = 256
_BODY = 1  # body id of the free body (0 is the world)

_LOCK = threading.RLock()

#: Evaluate state-dependent forces at every RK4 stage (True) or hold the start-of-step value over the
#: step like the other variants (False: first order in the force; kept for the tests that show why).
_RK4_STAGE_FORCES = True


def _require():
    base.require(mujoco, _IMPORT_ERROR, "mujoco")


def version() -> str:
    _require()
    return mujoco.__version__


def integrator_of(variant):
    _require()
    base.check_variant(ENGINE, VARIANTS, variant)
    return getattr(mujoco.mjtIntegrator, f"mjINT_{variant.upper()}")


def build_model(scenario, variant: str, dt_s: float):
    """Compile the scenario's free body for ``variant`` at step ``dt_s``; returns ``mujoco.MjModel``.

    Raises EngineError with MuJoCo's message when the compiler rejects the model (e.g. principal
    moments violating MuJoCo's own ``A + B >= C`` check).
    """
    integrator = integrator_of(variant)
    body = scenario.problem.body
    forces = scenario.problem.forces
    spec = mujoco.MjSpec()
    spec.modelname = f"rbcheck_{scenario.name}"
    spec.compiler.alignfree = False        # keep the joint (= qpos) on the body frame, not the inertial frame
    spec.compiler.inertiafromgeom = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_FALSE
    spec.compiler.balanceinertia = False   # never alter the scenario's inertia silently
    spec.compiler.boundmass = 0.0
    spec.compiler.boundinertia = 0.0
    spec.option.timestep = float(dt_s)
    spec.option.gravity = np.asarray(forces.gravity_W, dtype=float)
    spec.option.integrator = integrator
    spec.option.disableflags |= mujoco.mjtDisableBit.mjDSBL_AUTORESET
    b = spec.worldbody.add_body()
    b.name = "body"
    b.add_freejoint()
    b.explicitinertial = True
    b.ipos = [0.0, 0.0, 0.0]               # explicit: unset (NaN) would let geoms override the inertial
    b.mass = float(body.mass_kg)
    if body.is_diagonal():
        b.iquat = [1.0, 0.0, 0.0, 0.0]
        b.inertia = np.diag(body.inertia_B).copy()
    else:
        moments, R_BP = body.principal_axes()
        b.iquat = quat_from_matrix(R_BP)   # principal frame P in body coordinates (w x y z)
        b.inertia = moments
    try:
        with _LOCK:
            prev = _clear_force_callbacks()
            try:
                return spec.compile()
            finally:
                _restore_force_callbacks(prev)
    except ValueError as exc:
        raise EngineError(f"MuJoCo {mujoco.__version__} rejected the model of scenario "
                          f"{scenario.name!r}: {exc}") from None


# --- state conversion --------------------------------------------------------------------------------

def to_qpos_qvel(y):
    """Packed states (..., 13) -> qpos (..., 7), qvel (..., 6) with ω in BODY axes."""
    y = np.asarray(y, dtype=float)
    q = y[..., 6:10]
    qpos = np.concatenate([y[..., 0:3], q], axis=-1)
    qvel = np.concatenate([y[..., 3:6], rotate(quat_conj(q), y[..., 10:13])], axis=-1)
    return qpos, qvel


def to_packed(qpos, qvel):
    """qpos (..., 7), qvel (..., 6) -> packed states (..., 13) with ω in WORLD axes."""
    q = qpos[..., 3:7]
    return np.concatenate([qpos[..., 0:3], qvel[..., 0:3], q, rotate(q, qvel[..., 3:6])], axis=-1)


def _packed1(qpos, qvel) -> list:
    """One state: qpos (7,), qvel (6,) arrays -> :func:`packed_floats`."""
    return packed_floats(qpos.tolist(), qvel.tolist())


def packed_floats(qpos, qvel) -> list:
    """One state, qpos (7 floats) and qvel (6 floats, ω in body axes) -> the packed state (13 floats, ω in
    world axes): :func:`to_packed` of one row in plain floats, for the per-step loops."""
    x0, x1, x2, s, a, b, c = qpos
    v0, v1, v2, p0, p1, p2 = qvel
    # ω_W = R(q) ω_B = ω + s t + u × t with t = 2 u × ω, u = (a, b, c)
    t0, t1, t2 = 2.0 * (b * p2 - c * p1), 2.0 * (c * p0 - a * p2), 2.0 * (a * p1 - b * p0)
    return [x0, x1, x2, v0, v1, v2, s, a, b, c,
            p0 + s * t0 + (b * t2 - c * t1),
            p1 + s * t1 + (c * t0 - a * t2),
            p2 + s * t2 + (a * t1 - b * t0)]


# --- the global-state guard -----------------------------------------------------------------------

def _clear_force_callbacks():
    """Remove the process-global control and passive callbacks (returned for _restore_force_callbacks).

    Any Python callback installed there breaks ``MjSpec.compile`` ("engine error: Python exception
    raised": the compiler's internal mj_forward has no Python wrappers to pass it), and a user's
    callback would add forces to the adapter's free body.
    """
    prev = (mujoco.get_mjcb_control(), mujoco.get_mjcb_passive())
    mujoco.set_mjcb_control(None)
    mujoco.set_mjcb_passive(None)
    return prev


def _restore_force_callbacks(prev):
    mujoco.set_mjcb_control(prev[0])
    mujoco.set_mjcb_passive(prev[1])


class Session:
    """Installs the warning handler (and, when given, the control callback) for one run.

    MuJoCo's callbacks and warning handler are process-global: the session holds a module lock,
    clears any control/passive callback (a user's would add forces to this body), stores the previous
    handlers and restores them on exit. The lock serialises this adapter's own runs only: another
    thread calling MuJoCo meanwhile would see these handlers. The callback acts only on this run's
    MjData; an exception inside it is kept and re-raised (as EngineError) after the step.
    """

    def __init__(self, data, control=None):
        self.data = data
        self.control = control
        self.warnings: list[tuple[float, str]] = []   # (d.time when raised, message)
        self.callback_error: BaseException | None = None

    def _on_warning(self, msg):
        self.warnings.append((float(self.data.time), str(msg)))

    def _control_hook(self):
        """The function installed as MuJoCo's control callback: ``control`` for this run's MjData only,
        skipped after a failure (a closure: it runs at every RK4 stage)."""
        data, control = self.data, self.control

        def on_control(m, d):
            if d is not data or self.callback_error is not None:
                return
            try:
                control(m, d)
            except BaseException as exc:  # noqa: BLE001 - re-raised after the step
                self.callback_error = exc
        return on_control

    def __enter__(self):
        _LOCK.acquire()
        try:
            self._prev = _clear_force_callbacks()
            self._prev_warn = mujoco.get_mju_user_warning()
            mujoco.set_mju_user_warning(self._on_warning)
            if self.control is not None:
                mujoco.set_mjcb_control(self._control_hook())
        except BaseException:
            _LOCK.release()
            raise
        return self

    def __exit__(self, *exc):
        try:
            mujoco.set_mju_user_warning(self._prev_warn)
            _restore_force_callbacks(self._prev)
        finally:
            _LOCK.release()
        return False

    def raise_callback_error(self):
        if self.callback_error is not None:
            exc, self.callback_error = self.callback_error, None
            raise EngineError(f"force evaluation inside MuJoCo's control callback failed: {exc!r}") from exc


def forces_per_stage(scenario, variant) -> bool:
    """RK4 with forces that change within a step (state-dependent forces or velocity decay): evaluated
    at every stage through the control callback."""
    fm = scenario.problem.forces
    return variant == "rk4" and (fm.state_dependent or fm.has_decay) and _RK4_STAGE_FORCES


def _apply(xfrc, f, tau, weight):
    """World force ``f`` at the COM minus the weight (MuJoCo applies gravity itself) and world torque
    ``tau`` into the body's row of xfrc_applied (MuJoCo never clears it)."""
    xfrc[0:3] = f - weight
    xfrc[3:6] = tau


def _stage_force_writer(scenario, d, xfrc, weight):
    """Control callback body for MjData ``d`` (the only one Session passes it): forces from the (stage)
    state in its qpos/qvel into xfrc_applied, as :func:`_apply` writes them, in plain floats (it runs at
    every RK4 stage)."""
    w0, w1, w2 = (float(c) for c in weight)
    qpos, qvel = d.qpos, d.qvel   # views of d's arrays, bound once

    def control(_m, _d):
        fx, fy, fz, tx, ty, tz = stage_force_torque_floats(scenario, _packed1(qpos, qvel))
        xfrc[:] = (fx - w0, fy - w1, fz - w2, tx, ty, tz)
    return control


def _divergence(y_rows, first: int, warn_steps: tuple, session, dt_s: float):
    """``(step, words)`` of the first divergence among recorded states ``y_rows`` (step ``first`` onwards):
    a bad row (:func:`reference_sim.simulate.bad_rows`) or a MuJoCo warning, which counts in the step
    begun when it was raised (clamped to ``warn_steps`` = (first, last) step of the chunk); None if none."""
    candidates = []
    bad = bad_rows(y_rows)
    if bad.any():
        k = int(np.argmax(bad))
        candidates.append((first + k, blowup_words(y_rows[k])))
    if session.warnings:
        t_warn, msg = session.warnings[0]
        lo, hi = warn_steps
        candidates.append((min(max(int(round(t_warn / dt_s)) + 1, lo), hi), f"MuJoCo: {msg}"))
    if not candidates:
        return None
    return min(c[0] for c in candidates), "; ".join(c[1] for c in sorted(candidates))


#: Each thread's last compiled model and its MjData: ``(scenario, build_model, model, data)`` (the scenario
#: matched by identity). The next run of the same scenario takes that model, its integrator and step set in
#: place (the same numbers as a fresh compile, tested for every variant), and its MjData reset.
_LAST = threading.local()


def _set_variant(m, variant, dt_s):
    """Compiled model ``m`` set to ``variant``'s integrator and step ``dt_s`` (in place)."""
    m.opt.integrator = integrator_of(variant)
    m.opt.timestep = float(dt_s)
    return m


def _compiled(scenario, variant, dt_s):
    """``build_model(scenario, variant, dt_s)`` and a fresh (or reset) MjData of it."""
    last = getattr(_LAST, "run", None)
    if last is not None and last[0] is scenario and last[1] is build_model:
        mujoco.mj_resetData(last[2], last[3])
        return _set_variant(last[2], variant, dt_s), last[3]
    m = build_model(scenario, variant, dt_s)
    d = mujoco.MjData(m)
    _LAST.run = (scenario, build_model, m, d)
    return m, d


def _model_and_data(scenario, variant, dt_s):
    """``(MjModel, MjData, its xfrc_applied row, weight m g)`` of one run of the scenario's body."""
    m, d = _compiled(scenario, variant, dt_s)
    weight = scenario.problem.body.mass_kg * np.asarray(scenario.problem.forces.gravity_W, dtype=float)
    return m, d, d.xfrc_applied[_BODY], weight


# --- adapter entry points ----------------------------------------------------------------------------

def simulate(scenario, variant: str, dt_s: float, n_steps: int) -> Run:
    """Free run of ``n_steps`` steps of ``dt_s`` from the scenario's initial state, every step recorded: a
    loop of ``mj_step`` (:func:`simulate_many` records runs with ``mujoco.rollout``, the same numbers)."""
    m, d, xfrc, weight = _model_and_data(scenario, variant, dt_s)
    forces = scenario.problem.forces
    y0 = scenario.problem.initial_packed()
    d.qpos[:], d.qvel[:] = to_qpos_qvel(y0)
    per_stage = forces_per_stage(scenario, variant)
    decay = forces.has_decay and not per_stage       # pre-step decay (Euler-type integrators)
    per_step = forces.state_dependent and not per_stage
    if not forces.state_dependent:
        _apply(xfrc, *harness_force_torque(scenario, y0, dt_s), weight)   # constant (decay scaling included)
    control = _stage_force_writer(scenario, d, xfrc, weight) if per_stage else None
    return _simulate_loop(scenario, m, d, dt_s, n_steps, control, per_step, decay, xfrc, weight)


def _simulate_loop(scenario, m, d, dt_s, n_steps, control, per_step, decay, xfrc, weight) -> Run:
    """The run as a Python loop of mj_step: forces written before each step (``per_step``), the pre-step
    decay applied to qvel (``decay``), the RK4 stage callback (``control``); divergence checked per chunk.
    Per step in plain floats (one read of qpos/qvel, one write of xfrc_applied and of qvel): the numbers of
    :func:`_apply` and ``base.harness_force_torque``, bit for bit (tested)."""
    gv, gw = (float(g) for g in base.decay_factors(scenario, dt_s))
    harness = harness_fn(scenario, dt_s) if per_step else None
    w0, w1, w2 = (float(c) for c in weight)
    qpos, qvel = d.qpos, d.qvel   # views of d's arrays, bound once
    qpos_out = np.empty((n_steps + 1, 7))
    qvel_out = np.empty((n_steps + 1, 6))
    qpos_out[0], qvel_out[0] = qpos, qvel
    y = np.empty((n_steps + 1, 13))
    with np.errstate(all="ignore"):
        y[0:1] = to_packed(qpos_out[0:1], qvel_out[0:1])
    step = mujoco.mj_step
    reads = per_step or decay
    with Session(d, control) as session, np.errstate(all="ignore"):
        for start in range(1, n_steps + 1, _CHUNK):
            stop = min(start + _CHUNK, n_steps + 1)
            for n in range(start, stop):
                if reads:
                    qp, qv = qpos.tolist(), qvel.tolist()
                    if per_step:
                        fx, fy, fz, tx, ty, tz = harness(packed_floats(qp, qv))
                        xfrc[:] = (fx - w0, fy - w1, fz - w2, tx, ty, tz)
                    if decay:
                        qvel[:] = (qv[0] * gv, qv[1] * gv, qv[2] * gv, qv[3] * gw, qv[4] * gw, qv[5] * gw)
                step(m, d)
                if session.callback_error is not None:
                    session.raise_callback_error()
                qpos_out[n] = qpos
                qvel_out[n] = qvel
            # row by row: each chunk once
            y[start:stop] = to_packed(qpos_out[start:stop], qvel_out[start:stop])
            bad = _divergence(y[start:stop], start, (start, stop - 1), session, dt_s)
            if bad is not None:
                n_bad, what = bad
                return diverged(y[:n_bad].copy(), dt_s, f" ({what})")
    return Run(dt_s * np.arange(n_steps + 1), y)


@base.on_rows
def one_step(scenario, variant: str, dt_s: float, y_start) -> np.ndarray:
    """One step of ``dt_s`` from each row of ``y_start`` (T, 13); rows the engine blows up come back as
    whatever MuJoCo produced (possibly non-finite)."""
    m, d, xfrc, weight = _model_and_data(scenario, variant, dt_s)
    per_stage = forces_per_stage(scenario, variant)
    control = _stage_force_writer(scenario, d, xfrc, weight) if per_stage else None
    y_dec = y_start if per_stage else base.apply_decay_prestep(scenario, y_start, dt_s)
    qpos_in, qvel_in = to_qpos_qvel(y_dec)
    qpos_out = np.empty((len(y_start), 7))
    qvel_out = np.empty((len(y_start), 6))
    qpos, qvel, step = d.qpos, d.qvel, mujoco.mj_step   # views of d's arrays, bound once
    with Session(d, control) as session, np.errstate(all="ignore"):
        for i in range(len(y_start)):
            if not per_stage:
                _apply(xfrc, *harness_force_torque(scenario, y_start[i], dt_s), weight)
            d.time = 0.0
            qpos[:] = qpos_in[i]
            qvel[:] = qvel_in[i]
            step(m, d)
            session.raise_callback_error()
            qpos_out[i] = qpos
            qvel_out[i] = qvel
            session.warnings.clear()
    with np.errstate(all="ignore"):
        return to_packed(qpos_out, qvel_out)


# --- many runs in one call: mujoco.rollout, one compiled model per scenario -----------------------------

class _NoData:
    """The MjData stand-in of a rollout's Session: the time of a warning is not kept (a member of a rollout
    that warned is run again through :func:`simulate`, which keeps it)."""

    time = float("nan")


def simulate_many(variant: str, requests) -> list:
    """The runs of ``requests`` (``base.RunRequest``) through ``mujoco.rollout``: each element
    :func:`simulate`'s Run bit for bit (tested), or its EngineError.

    One model is compiled per scenario and set to each request's step in place (:func:`_set_variant`), so a
    scenario's requests at different steps run in successive rounds (:func:`_rounds`), grouped by model
    structure (:func:`_structure`); the harness is :func:`simulate`'s. RK4 with per-stage forces, and every
    member of a group that blew up or made MuJoCo warn, run through :func:`simulate` itself (its divergence
    time and message)."""
    out: list = [None] * len(requests)
    models: dict = {}   # id(scenario) -> its compiled model or EngineError (the requests hold the scenarios)
    alone = []
    for j, r in enumerate(requests):
        if forces_per_stage(r.scenario, variant):
            alone.append(j)
            continue
        if id(r.scenario) not in models:
            try:
                models[id(r.scenario)] = build_model(r.scenario, variant, r.dt_s)
            except EngineError as exc:
                models[id(r.scenario)] = exc
        if isinstance(models[id(r.scenario)], EngineError):
            out[j] = models[id(r.scenario)]
    batched = [j for j in range(len(requests)) if out[j] is None and j not in set(alone)]
    for rnd in _rounds(requests, batched):
        groups: dict = {}
        for j in rnd:
            m = _set_variant(models[id(requests[j].scenario)], variant, requests[j].dt_s)
            groups.setdefault(_structure(m), []).append(j)
        for grp in groups.values():
            reqs = [requests[j] for j in grp]
            y, warned = _rollout_group(reqs, [models[id(r.scenario)] for r in reqs])
            for k, (j, r) in enumerate(zip(grp, reqs)):
                yj = y[:r.n_steps + 1, k]
                if warned or bad_rows(yj).any():
                    alone.append(j)
                else:
                    out[j] = Run(r.dt_s * np.arange(r.n_steps + 1), yj.copy())
    first = {}   # a scenario's runs one after the other: each takes the model compiled for the previous
    for j in alone:
        first.setdefault(id(requests[j].scenario), j)
    for j in sorted(alone, key=lambda j: (first[id(requests[j].scenario)], j)):
        r = requests[j]
        try:
            out[j] = simulate(r.scenario, variant, r.dt_s, r.n_steps)
        except EngineError as exc:
            out[j] = exc
    return out


def _rounds(requests, idx) -> list:
    """The request numbers ``idx`` in rounds that hold each scenario at one step only (its compiled model is
    shared): round k holds every scenario's k-th distinct step."""
    steps: dict = {}
    rounds: list = []
    for j in idx:
        seen = steps.setdefault(id(requests[j].scenario), [])
        h = float(requests[j].dt_s)
        if h not in seen:
            seen.append(h)
        k = seen.index(h)
        while len(rounds) <= k:
            rounds.append([])
        rounds[k].append(j)
    return rounds


def _structure(m) -> tuple:
    """What one MjData needs of the models it serves in a rollout besides their sizes: a free body whose
    inertial frame is the body frame is "simple" (diagonal mass-matrix storage), a rotated one is not.
    Across structures rollout silently produces wrong states."""
    return tuple(int(v) for v in m.body_simple), tuple(int(v) for v in m.dof_simplenum)


def _rollout_group(reqs, mods):
    """Packed states (n_max + 1, M, 13) of requests whose models share one structure, each set to its
    request's variant and step, and whether MuJoCo warned during the rollouts."""
    from mujoco import rollout
    M, n_max = len(reqs), max(r.n_steps for r in reqs)
    y0 = np.array([r.scenario.problem.initial_packed() for r in reqs])
    qpos0, qvel0 = to_qpos_qvel(y0)
    state = np.concatenate([np.zeros((M, 1)), qpos0, qvel0], axis=1)   # [time, qpos, qvel]
    xfrc = np.zeros((M, 1, 12))   # xfrc_applied rows: the world body's (zeros), the free body's
    weights = [r.scenario.problem.body.mass_kg * np.asarray(r.scenario.problem.forces.gravity_W, dtype=float)
               for r in reqs]
    per_step = [k for k, r in enumerate(reqs) if r.scenario.problem.forces.state_dependent]
    for k, r in enumerate(reqs):
        if k not in per_step:
            _apply(xfrc[k, 0, 6:12], *harness_force_torque(r.scenario, y0[k], r.dt_s), weights[k])
    g = np.array([[float(v) for v in base.decay_factors(r.scenario, r.dt_s)] for r in reqs])
    decay = any(r.scenario.problem.forces.has_decay for r in reqs)
    qpos = np.empty((n_max + 1, M, 7))
    qvel = np.empty((n_max + 1, M, 6))
    qpos[0], qvel[0] = qpos0, qvel0
    datas = [mujoco.MjData(mods[0])]
    spec = mujoco.mjtState.mjSTATE_XFRC_APPLIED
    with Session(_NoData()) as session, np.errstate(all="ignore"):
        if n_max and not per_step and not decay:
            states, _ = rollout.rollout(mods, datas, state, xfrc, control_spec=spec, nstep=n_max)
            qpos[1:], qvel[1:] = np.moveaxis(states[:, :, 1:8], 1, 0), np.moveaxis(states[:, :, 8:14], 1, 0)
        elif n_max:
            _rollout_steps(reqs, mods, datas, state, xfrc, per_step, g, weights, qpos, qvel)
        warned = bool(session.warnings)
    with np.errstate(all="ignore"):
        return to_packed(qpos, qvel), warned


def _rollout_steps(reqs, mods, datas, state, xfrc, per_step, g, weights, qpos, qvel) -> None:
    """The rollout one step per call (into ``qpos``, ``qvel``): state-dependent forces of members
    ``per_step`` from each start-of-step state, the pre-step decay factors ``g`` (M, 2) on the velocities.
    The arrays rollout's wrapper would check and allocate every call are given once, in its shapes."""
    from mujoco import rollout
    harness = {k: harness_fn(reqs[k].scenario, reqs[k].dt_s) for k in per_step}
    M = len(reqs)
    out = np.empty((M, 1, state.shape[1]))
    sensors = np.empty((M, 1, mods[0].nsensordata))
    runner = rollout.Rollout(nthread=0)
    try:
        for n in range(1, len(qpos)):
            for k in per_step:
                fx, fy, fz, tx, ty, tz = harness[k](packed_floats(qpos[n - 1, k].tolist(),
                                                                  qvel[n - 1, k].tolist()))
                w0, w1, w2 = (float(c) for c in weights[k])
                xfrc[k, 0, 6:12] = (fx - w0, fy - w1, fz - w2, tx, ty, tz)
            st = state.copy()
            st[:, 8:11] *= g[:, 0:1]
            st[:, 11:14] *= g[:, 1:2]
            runner.rollout(mods, datas, st, xfrc, control_spec=mujoco.mjtState.mjSTATE_XFRC_APPLIED, nstep=1,
                           state=out, sensordata=sensors, skip_checks=True)
            state = out[:, 0, :].copy()
            qpos[n], qvel[n] = state[:, 1:8], state[:, 8:14]
    finally:
        runner.close()


class MujocoAdapter(ModuleAdapter):
    """``mujoco:VARIANT`` — registered under the entry-point group ``rbcheck.engines``."""

    def engine_files(self) -> list:
        """MuJoCo's shared library."""
        return base.library_files(mujoco)
