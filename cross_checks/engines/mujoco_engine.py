"""MuJoCo as an engine (``mujoco:VARIANT``, float64): a world of free bodies for rbcheck's loop
(cross_checks.engines.world, cross_checks.engines.loop).

State at the boundary: ``qpos = [x_W, q_WB (w x y z)]``, ``qvel = [v_W (COM), ω_B (BODY axes)]``, so the
packed state's ``ω_W = R(q) ω_B``; read from qpos/qvel only. Forces: the loop's world force at the COM (the
weight ``m g`` taken off: MuJoCo applies gravity) and world torque, written into ``xfrc_applied`` (kept by
MuJoCo between steps); ``mujoco:rk4`` with state-dependent forces or decay evaluates them at every RK4 stage
through MuJoCo's process-global control callback (:class:`Session`); the other integrators get the loop's
pre-step decay. With the forces held, the steps run in ``mujoco.rollout``. Divergence: the loop's, plus a
MuJoCo warning, which ends its body's run as ``diverged at t = …``; no MUJOCO_LOG.TXT is written.
Conventions, defaults neutralised and what pins them: docs/engine_conventions.md, "MuJoCo 4.0.0".
"""
from __future__ import annotations

import threading
import time

import numpy as np

from cross_checks.engines import base, forces, install
from cross_checks.engines.base import EngineError, Variant
from cross_checks.engines.forces import stage_force_torque_floats
from cross_checks.engines.loop import host_problem
from cross_checks.engines.packed_rows import qpos_qvel_packed
from cross_checks.engines.world import World, WorldEngine
from reference_sim.quaternion import quat_from_matrix

mujoco, _IMPORT_ERROR, mjw = install.optional_world("mujoco", "mujoco", "Bodies", "FormBodies")
if _IMPORT_ERROR is None:
    from cross_checks.engines.worlds.mujoco import to_packed, to_qpos_qvel

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

#: From this many bodies in a world on, a rollout steps with ``mj_step`` from Python and copies each step's
#: qpos and qvel (a few µs per step) instead of calling ``mujoco.rollout``, which records the full physics
#: state of every step: 0.2 µs more per body-step, measured (docs/speed.md); the same numbers, bit for bit.
STEP_LOOP_BODIES = 32

_LOCK = threading.RLock()

#: Evaluate state-dependent forces at every RK4 stage (True) or hold the start-of-step value over the
#: step like the other variants (False: first order in the force; kept for the tests that show why).
_RK4_STAGE_FORCES = True


def _require():
    install.require(mujoco, _IMPORT_ERROR, "mujoco")


def version() -> str:
    _require()
    return mujoco.__version__


def integrator_of(variant):
    _require()
    base.check_variant(ENGINE, VARIANTS, variant)
    return getattr(mujoco.mjtIntegrator, f"mjINT_{variant.upper()}")


def build_model(scenario, variant: str, dt_s: float, copies: int = 1):
    """Compile the scenario's free body (``copies`` of it, body k's qpos at 7k, qvel at 6k) for ``variant``
    at step ``dt_s``; returns ``mujoco.MjModel``. Raises EngineError with MuJoCo's message when the compiler
    rejects the model (e.g. principal moments violating MuJoCo's own ``A + B >= C`` check)."""
    return build_world_model([scenario] * copies, variant, dt_s)


def build_world_model(scenarios, variant: str, dt_s: float):
    """One model of the scenarios' free bodies (body k+1 is scenario k's; they share the first one's
    gravity): each body moves in it exactly, bit for bit, as alone in a model of its own (MuJoCo steps
    separate kinematic trees apart; tested). The MjSpec is :mod:`cross_checks.engines.worlds.mujoco`'s (what
    ``rbcheck repro`` embeds), of the bodies' :func:`body_spec`."""
    integrator_of(variant)
    forces = scenarios[0].problem.forces
    try:
        with _LOCK:
            prev = _clear_force_callbacks()
            try:
                return mjw.build_model([body_entry(sc) for sc in scenarios], forces.gravity_W,
                                       variant, dt_s, name=f"rbcheck_{scenarios[0].name}")
            finally:
                _restore_force_callbacks(prev)
    except ValueError as exc:
        names = ", ".join(dict.fromkeys(repr(sc.name) for sc in scenarios))
        raise EngineError(f"MuJoCo {mujoco.__version__} rejected the model of scenario {names}: "
                          f"{exc}") from None


def body_spec(body) -> tuple:
    """``(mass_kg, moments (3,), q_BP (w x y z))`` of an rbcheck RigidBody as MuJoCo takes it: a diagonal
    tensor as it is (no frame rotation), a full one as its principal moments (:func:`on_the_triangle`) and
    the principal frame P in body coordinates."""
    if body.is_diagonal():
        return float(body.mass_kg), np.diag(body.inertia_B).copy(), [1.0, 0.0, 0.0, 0.0]
    moments, R_BP = body.principal_axes()
    return float(body.mass_kg), on_the_triangle(moments), quat_from_matrix(R_BP)


def body_entry(scenario) -> tuple:
    """The scenario's body as :func:`cross_checks.engines.worlds.mujoco.build_model` takes it: its
    :func:`body_spec`; a body whose frame origin is off its COM (scenario.body_com_B_m) also with that COM
    (its inertial frame there) and its welded parts (scenario.body_parts; none: no fifth item), each
    ``(*body_spec, com)``: the first the jointed body's inertial, the others child bodies without a joint,
    each with its own inertial frame (MuJoCo #3553's form). ``rbcheck repro`` writes the same entry into a
    script."""
    from reference_sim.body import RigidBody
    com = getattr(scenario, "body_com_B_m", None)
    spec = body_spec(scenario.problem.body)
    if com is None:
        return spec
    parts = [(*body_spec(RigidBody(float(q.mass_kg), q.inertia_B)), [float(v) for v in q.com_B_m])
             for q in getattr(scenario, "body_parts", ())]
    return (*spec, [float(v) for v in com], *([parts] if parts else []))


def on_the_triangle(moments_kg_m2) -> np.ndarray:
    """Principal moments (3,) with the largest set to the sum of the other two where it exceeds it by
    round-off only (≤ 8 ε of it): a body on the boundary A + B = C (a flat body: tennis_racket's 1, 2, 3
    kg m²) comes back from an eigen-decomposition 1e-15 beyond it, which MuJoCo's compiler refuses
    (balanceinertia off)."""
    m = np.array(moments_kg_m2, dtype=float)
    k = int(np.argmax(m))
    i, j = (x for x in range(3) if x != k)
    rest = float(m[i] + m[j])
    if rest < m[k] <= rest + 8 * np.finfo(float).eps * m[k]:
        m[k] = rest
    return m


# --- state conversion --------------------------------------------------------------------------------

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
    """Installs the warning handler (and, when given, the control callback) for one world.

    MuJoCo's callbacks and warning handler are process-global: the session holds a module lock,
    clears any control/passive callback (a user's would add forces to this body), stores the previous
    handlers and restores them on exit. The lock serialises this adapter's own runs only: another
    thread calling MuJoCo meanwhile would see these handlers. The callback acts only on this run's
    MjData; an exception inside it is kept and re-raised (as EngineError) after the step.
    """

    def __init__(self, data, control=None):
        self.data = data
        self.control = control
        self.warnings: list[str] = []   # MuJoCo's messages, in order
        self.callback_error: BaseException | None = None

    def _on_warning(self, msg):
        self.warnings.append(str(msg))

    def _control_hook(self):
        """The function installed as MuJoCo's control callback: ``control``, skipped after a failure (a
        closure: it runs at every RK4 stage)."""
        control = self.control

        def on_control(m, d):
            if self.callback_error is not None:
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
    """RK4 with forces that change within a step (state-dependent forces or velocity decay; a torque fixed in
    body axes is MuJoCo's own, in qfrc_applied): evaluated at every stage through the control callback."""
    fm = host_problem(scenario.problem, MujocoEngine.takes_body_torque).forces
    return variant == "rk4" and (fm.state_dependent or fm.has_decay) and _RK4_STAGE_FORCES


def _stage_force_writer(scenario, qpos, qvel, xfrc, weight, form=None):
    """Control callback body for one body, whose (stage) state is in the views ``qpos`` (7) and ``qvel`` (6)
    of the world's MjData: its forces into its row ``xfrc`` of xfrc_applied, the weight taken off (MuJoCo
    applies gravity), in plain floats (it runs at every RK4 stage). The torques fixed in body axes are not
    among them: MuJoCo holds them in qfrc_applied (MujocoEngine.takes_body_torque)."""
    import dataclasses
    w0, w1, w2 = (float(c) for c in weight)
    host = host_problem(scenario.problem, MujocoEngine.takes_body_torque)
    if host is not scenario.problem:
        scenario = dataclasses.replace(scenario, problem=host)
    if form is not None:   # a body off its COM or of parts (worlds.mujoco.Form): the COM's state, shared
        def control_form(_m, _d):
            y = form.com_rows(np.concatenate((qpos, qvel))[None])[0]
            f = np.array(stage_force_torque_floats(scenario, y.tolist()))
            form.write(xfrc, (f[0:3] - weight)[None], f[3:6][None])
        return control_form

    def control(_m, _d):
        fx, fy, fz, tx, ty, tz = stage_force_torque_floats(scenario, _packed1(qpos, qvel))
        xfrc[:] = (fx - w0, fy - w1, fz - w2, tx, ty, tz)
    return control


#: Each thread's compiled world models: ``(scenarios, build_world_model, model)`` (the scenarios matched by
#: identity), the last few kept. A world of the same scenarios takes that model with its integrator and step
#: set in place (the same numbers as a fresh compile, tested for every variant).
_LAST = threading.local()


def _model(scenarios, variant, dt_s):
    """``build_world_model(scenarios, variant, dt_s)``, or the thread's model of those scenarios set to them
    (``scenarios``: one scenario, or a list)."""
    scenarios = list(scenarios) if isinstance(scenarios, (list, tuple)) else [scenarios]
    kept = getattr(_LAST, "models", None)
    if kept is None:
        kept = _LAST.models = []
    for scs, builder, m in kept:
        if builder is build_world_model and len(scs) == len(scenarios) and all(
                a is b for a, b in zip(scs, scenarios)):
            m.opt.integrator, m.opt.timestep = integrator_of(variant), float(dt_s)   # in place
            return m
    m = build_world_model(scenarios, variant, dt_s)
    kept.append((scenarios, build_world_model, m))
    del kept[:-8]
    return m


def _body_of_warning(msg: str, n_bodies: int):
    """``(body, message as a lone body's)`` of a MuJoCo warning that names a DOF ("... in QACC at DOF 9"; a
    qpos index for QPOS): the body it belongs to and the message with the DOF counted in that body (what the
    body alone in its model would say); ``(None, msg)`` when it names none."""
    import re
    m = re.search(r"(QPOS|QVEL|QACC)? at DOF (\d+)", msg)
    if m is None or n_bodies == 0:
        return None, msg
    width = 7 if m.group(1) == "QPOS" else 6
    i = int(m.group(2))
    return min(i // width, n_bodies - 1), msg[:m.start(2)] + str(i % width) + msg[m.end(2):]


class MujocoWorld(mjw.FormBodies, World):
    """B free bodies in one MjModel (one kinematic tree each) and one MjData, stepped by ``mj_step`` or, with
    the forces held, by ``mujoco.rollout``. Raw rows: ``[qpos (7), qvel (6)]`` per body, ω in BODY axes. The
    warning handler (and RK4's stage-force callback) are installed for the world's lifetime
    (:class:`Session`); a warning is attributed to the body whose DOF it names."""

    def __init__(self, requests, variant, dt_s):
        World.__init__(self)
        mjw.Bodies.__init__(self, _model([r.scenario for r in requests], variant, dt_s))
        d = self.data
        scs = [r.scenario for r in requests]
        entries = [body_entry(sc) for sc in scs]
        self.form = mjw.Form(entries) if any(len(e) > 3 for e in entries) else None
        self.per_stage = forces_per_stage(requests[0].scenario, variant)
        self.n = 0
        self.host_s = 0.0
        control = None
        if self.per_stage:
            writers = [_stage_force_writer(r.scenario, self.qpos[k], self.qvel[k], self.xfrc[k],
                                           forces.weight_W(r.scenario)) if self.form is None else
                       _stage_force_writer(r.scenario, self.qpos[k], self.qvel[k],
                                           self.xfrc[self.form.span(k)], forces.weight_W(r.scenario),
                                           mjw.Form([body_entry(r.scenario)]))
                       for k, r in enumerate(requests)]
            perf = time.perf_counter

            def control(m_, d_):
                t0 = perf()
                for w in writers:
                    w(m_, d_)
                self.host_s += perf() - t0
        self.session = Session(d, control).__enter__()

    def set_state(self, y):
        # MuJoCo's state is the body frame origin's (worlds.mujoco.FormBodies, what a reproducer runs)
        (mjw.Bodies if self.form is None else mjw.FormBodies).set_state(self, y)
        self.n = 0

    def apply(self, f_W, tau_W):
        (mjw.Bodies if self.form is None else mjw.FormBodies).apply(self, f_W, tau_W)

    def decay(self, g_v, g_w):
        if self.form is None:
            mjw.Bodies.decay(self, g_v, g_w)
            return
        y = self.form.com_rows(self.read())   # the COM's v and ω decay: the origin's velocity is v − ω × R c
        y[:, 3:6] *= g_v[:, None]
        y[:, 10:13] *= g_w[:, None]
        self.qpos[:], self.qvel[:] = self.form.origin_rows(y)

    def packed(self, raw):
        if self.form is None:   # a whole record: in each run's own layout, the same numbers (packed_rows)
            return qpos_qvel_packed(raw, lambda r: mjw.Bodies.packed(self, r))
        return mjw.FormBodies.packed(self, raw)

    def step(self):
        self.n += 1
        session = self.session
        seen = len(session.warnings)
        mjw.Bodies.step(self)
        if session.callback_error is not None:
            session.raise_callback_error()
        for msg in session.warnings[seen:]:
            body, words = _body_of_warning(msg, self.B)
            for k in range(self.B) if body is None else (body,):
                self.warnings.append((k, self.n, f"MuJoCo: {words}"))

    def packed_row(self, raw):
        # many bodies (or bodies off their COM): the vectorised conversion, the same numbers (tested)
        if self.B > 4 or self.form is not None:
            return self.packed(np.asarray(raw, dtype=float)[None])[0]
        return [packed_floats(r[0:7], r[7:13]) for r in np.asarray(raw).tolist()]

    rollout_into = True

    def rollout(self, n_steps, harness=None, out=None):
        """``n_steps`` steps in ``mujoco.rollout`` with the applied forces (xfrc_applied, and the body-axes
        torques in qfrc_applied) held, their rows (n_steps, B, 13) written into ``out`` (a new array when
        None) and returned; if MuJoCo warned, the steps again one by one (:meth:`step`), which attribute the
        warning to its body."""
        if out is None:
            out = np.empty((n_steps, self.B, 13))
        if self.B >= STEP_LOOP_BODIES:
            return self._stepped(n_steps, out)
        from mujoco import rollout
        t_all = time.perf_counter()
        m, d = self.model, self.data
        start = self.read()
        state = np.concatenate([[0.0], d.qpos, d.qvel])[None]    # [time, qpos, qvel]
        spec = mujoco.mjtState.mjSTATE_QFRC_APPLIED | mujoco.mjtState.mjSTATE_XFRC_APPLIED
        control = np.empty(mujoco.mj_stateSize(m, spec))
        mujoco.mj_getState(m, d, control, spec)                  # in MuJoCo's own order of the two
        seen = len(self.session.warnings)
        datas = [mujoco.MjData(m)]
        t0 = time.perf_counter()
        states, _ = rollout.rollout(m, datas, state, control[None, None], control_spec=spec, nstep=n_steps)
        t1 = time.perf_counter()
        out[..., 0:7] = states[0, :, 1:1 + m.nq].reshape(n_steps, self.B, 7)
        out[..., 7:13] = states[0, :, 1 + m.nq:].reshape(n_steps, self.B, 6)
        # the engine's own time is the rollout call's; the set-up and the rows' layout are rbcheck's
        self.host_s += time.perf_counter() - t_all - (t1 - t0)
        if len(self.session.warnings) == seen:
            return out
        self.qpos[:], self.qvel[:] = start[:, 0:7], start[:, 7:13]
        self.data.time, self.n = 0.0, 0
        for k in range(n_steps):
            self.step()
            out[k] = self.read()
        return out

    def _stepped(self, n_steps, out):
        """:meth:`rollout` of many bodies: ``n_steps`` of :meth:`step` (``mj_step``, each warning attributed
        to its body) with the applied forces held, every step's qpos and qvel copied into ``out``'s rows
        (n_steps, B, 13); the copies are rbcheck's time (``host_s``), the steps the engine's."""
        perf = time.perf_counter
        t_all, inside = perf(), 0.0
        qpos, qvel, step = self.qpos, self.qvel, self.step
        for k in range(n_steps):
            t0 = perf()
            step()
            inside += perf() - t0
            out[k, :, 0:7] = qpos
            out[k, :, 7:13] = qvel
        self.host_s += perf() - t_all - inside
        return out

    def close(self):
        self.session.__exit__(None, None, None)


class MujocoEngine(WorldEngine):
    """``mujoco:VARIANT`` — registered under the entry-point group ``rbcheck.engines``."""

    name = ENGINE
    variants = VARIANTS
    distribution = "mujoco"
    keeps_forces = True     # xfrc_applied is never cleared by MuJoCo
    takes_body_torque = True   # a free joint's rotational DOFs are body axes: qfrc_applied holds τ_B itself
    body_forms = frozenset({"com_offset", "welded_parts"})   # inertial frame off the body's; welded children
    chunk = 256

    def version(self) -> str:
        _require()
        return mujoco.__version__

    def build(self, requests, variant, dt_s):
        _require()
        return MujocoWorld(requests, variant, dt_s)

    def group_key(self, request) -> tuple:
        """One world per step and gravity (a model has one of each): the bodies of a call's scenarios step
        together, each exactly as alone."""
        return (float(request.dt_s), tuple(float(g) for g in request.scenario.problem.forces.gravity_W))

    def per_stage(self, scenario, variant):
        return forces_per_stage(scenario, variant)

    def source_files(self) -> list:
        from cross_checks.engines import packed_rows
        return [*super().source_files(), *packed_rows.source_files()]


_ENGINE = MujocoEngine()
# the module's functions are the engine's (the host loop's runs: cross_checks.engines.loop)
simulate, simulate_many, one_step = _ENGINE.simulate, _ENGINE.simulate_many, _ENGINE.one_step


MujocoAdapter = MujocoEngine
