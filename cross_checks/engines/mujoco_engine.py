"""MuJoCo as an engine (``mujoco:VARIANT``, float64): a world of free bodies for rbcheck's loop on
cross_checks/engines/worlds/mujoco.py (the MjSpec model and state conversions ``rbcheck repro`` embeds:
``qpos = [x_W, q_WB (w x y z)]``, ``qvel = [v_W (COM), ω_B (BODY axes)]``, forces in ``xfrc_applied``, a
torque fixed in body axes in ``qfrc_applied``, both kept by MuJoCo). ``mujoco:rk4`` evaluates forces that
change within a step at every stage; a MuJoCo warning ends its body's run as ``diverged at t = …``.
Conventions, defaults neutralised and what pins them: docs/engine_conventions.md, "MuJoCo 4.0.0".
"""
from __future__ import annotations

import dataclasses
import re
import threading
import time

import numpy as np

from cross_checks.engines import base, forces, install
from cross_checks.engines.base import EngineError, Variant
from cross_checks.engines.forces import stage_force_torque_floats
from cross_checks.engines.loop import host_problem
from cross_checks.engines.packed_rows import qpos_qvel_packed
from cross_checks.engines.world import MANY_BODIES, World, WorldEngine
from reference_sim.body import RigidBody
from reference_sim.quaternion import quat_from_matrix

mujoco, _IMPORT_ERROR, mjw = install.optional_world("mujoco", "mujoco", "Bodies", "FormBodies", "to_packed",
                                                    "to_qpos_qvel")
to_packed, to_qpos_qvel = mjw.to_packed, mjw.to_qpos_qvel   # packed states <-> qpos, qvel: the world's

__all__ = ["ENGINE", "VARIANTS", "EngineError", "version", "simulate", "simulate_many", "one_step",
           "build_model", "packed_floats", "to_packed", "to_qpos_qvel"]

ENGINE = "mujoco"
#: The variants, named after MuJoCo's integrators (``mjtIntegrator.mjINT_<NAME>``).
VARIANTS = {
    "euler": Variant(1, "MuJoCo Euler: semi-implicit Euler, explicit gyroscopic term, quaternion by the "
                        "exponential map", traits=base.SYMPLECTIC_EULER_EXPLICIT_GYRO),
    "rk4": Variant(4, "MuJoCo RK4: classical 4th-order Runge-Kutta; state-dependent forces evaluated at "
                      "every stage", traits=base.HIGHER_ORDER),
    "implicit": Variant(1, "MuJoCo implicit: velocity-implicit Euler (gyroscopic/velocity derivatives in "
                           "the step)", traits=base.SYMPLECTIC_EULER_IMPLICIT_GYRO),
    "implicitfast": Variant(1, "MuJoCo implicitfast: implicit Euler without the Coriolis/centrifugal "
                               "derivatives", traits=base.SYMPLECTIC_EULER_IMPLICIT_GYRO),
    "discrete": Variant(1, "MuJoCo discrete: constraint solve and implicit velocity update in one, in the "
                           "metric M + hD + h²K (for a lone free body: implicitfast's step)",
                        traits=base.SYMPLECTIC_EULER_IMPLICIT_GYRO),
}

#: From this many bodies in a world on, a rollout steps with ``mj_step`` from Python, copying each step's qpos
#: and qvel (a few µs per step), instead of calling ``mujoco.rollout``, which records the full physics state
#: of every step: 0.2 µs more per body-step, measured (docs/speed.md); the same numbers, bit for bit.
STEP_LOOP_BODIES = 32

#: MuJoCo's callbacks and warning handler are process-global: this adapter's compiles and worlds hold them
#: under this lock (another thread calling MuJoCo meanwhile would see a world's handlers).
_LOCK = threading.RLock()

#: RK4's changing forces at every stage (False: held over the step, first order; for the tests that show why).
_RK4_STAGE_FORCES = True


def build_model(scenarios, variant: str, dt_s: float):
    """The ``mujoco.MjModel`` of a scenario's free body for ``variant`` at step ``dt_s``, or of a list's
    (body k+1 scenario k's, the first one's gravity; each bit for bit as alone: the world's MjSpec of their
    :func:`body_entry`). EngineError with MuJoCo's words when its compiler rejects the model."""
    scenarios = scenarios if isinstance(scenarios, list) else [scenarios]
    version()
    base.check_variant(ENGINE, VARIANTS, variant)
    try:
        with _LOCK:
            prev = _set_force_callbacks()
            try:
                return mjw.build_model([body_entry(sc) for sc in scenarios],
                                       scenarios[0].problem.forces.gravity_W, variant, dt_s,
                                       name=f"rbcheck_{scenarios[0].name}")
            finally:
                _set_force_callbacks(*prev)
    except ValueError as exc:
        names = ", ".join(dict.fromkeys(repr(sc.name) for sc in scenarios))
        raise EngineError(f"MuJoCo {mujoco.__version__} rejected the model of scenario {names}: "
                          f"{exc}") from None


def body_spec(body) -> tuple:
    """``(mass_kg, moments (3,), q_BP (w x y z))`` of an rbcheck RigidBody as MuJoCo takes it: a diagonal
    tensor as it is, a full one as its principal moments (:func:`on_the_triangle`) and principal frame P."""
    if body.is_diagonal():
        return float(body.mass_kg), np.diag(body.inertia_B).copy(), [1.0, 0.0, 0.0, 0.0]
    moments, R_BP = body.principal_axes()
    return float(body.mass_kg), on_the_triangle(moments), quat_from_matrix(R_BP)


def body_entry(scenario) -> tuple:
    """The scenario's body as the world's ``build_model`` takes it (and ``rbcheck repro`` writes it): its
    :func:`body_spec`, and for a frame origin off the COM (``body_com_B_m``) that COM, then its welded parts
    (``body_parts``), each ``(*body_spec, com)``, the first the jointed body's inertial (MuJoCo #3553)."""
    com = getattr(scenario, "body_com_B_m", None)
    spec = body_spec(scenario.problem.body)
    if com is None:
        return spec
    parts = [(*body_spec(RigidBody(float(q.mass_kg), q.inertia_B)), [float(v) for v in q.com_B_m])
             for q in getattr(scenario, "body_parts", ())]
    return (*spec, [float(v) for v in com], *([parts] if parts else []))


def on_the_triangle(moments_kg_m2) -> np.ndarray:
    """Principal moments (3,) with the largest set to the sum of the other two where it exceeds it by
    round-off only (≤ 8 ε of it): a flat body (tennis_racket's 1, 2, 3 kg m²) comes back from an
    eigen-decomposition 1e-15 beyond A + B = C, which MuJoCo's compiler refuses (balanceinertia off)."""
    m = np.array(moments_kg_m2, dtype=float)
    k = int(np.argmax(m))
    i, j = (x for x in range(3) if x != k)
    rest = float(m[i] + m[j])
    if rest < m[k] <= rest + 8 * np.finfo(float).eps * m[k]:
        m[k] = rest
    return m


def packed_floats(qpos, qvel) -> list:
    """One state, qpos (7 floats) and qvel (6 floats, ω in body axes) -> the packed state (13 floats, ω in
    world axes): :func:`to_packed`'s numbers in plain floats, for the per-step and per-stage loops."""
    x0, x1, x2, s, a, b, c = qpos
    v0, v1, v2, p0, p1, p2 = qvel
    # ω_W = R(q) ω_B = ω + s t + u × t with t = 2 u × ω, u = (a, b, c)
    t0, t1, t2 = 2.0 * (b * p2 - c * p1), 2.0 * (c * p0 - a * p2), 2.0 * (a * p1 - b * p0)
    return [x0, x1, x2, v0, v1, v2, s, a, b, c,
            p0 + s * t0 + (b * t2 - c * t1),
            p1 + s * t1 + (c * t0 - a * t2),
            p2 + s * t2 + (a * t1 - b * t0)]


def _set_force_callbacks(control=None, passive=None):
    """Set MuJoCo's process-global control and passive callbacks, returning the previous pair: cleared around
    a compile (a Python callback there breaks ``MjSpec.compile``) and in a world (a user's adds forces)."""
    prev = (mujoco.get_mjcb_control(), mujoco.get_mjcb_passive())
    mujoco.set_mjcb_control(control)
    mujoco.set_mjcb_passive(passive)
    return prev


#: Each thread's last few compiled world models, ``(scenarios, model)`` (matched by identity): a world of the
#: same scenarios takes that model with its integrator and step set in place (a fresh compile's numbers).
_LAST = threading.local()


def _model(scenarios, variant, dt_s):
    """``build_model(scenarios, variant, dt_s)``, or the thread's model of those scenarios set to them."""
    scenarios = list(scenarios) if isinstance(scenarios, (list, tuple)) else [scenarios]
    kept = _LAST.__dict__.setdefault("models", [])
    for scs, m in kept:
        if len(scs) == len(scenarios) and all(a is b for a, b in zip(scs, scenarios)):
            m.opt.integrator, m.opt.timestep = getattr(mujoco.mjtIntegrator, f"mjINT_{variant.upper()}"), dt_s
            return m
    kept.append((scenarios, build_model(scenarios, variant, dt_s)))
    del kept[:-8]
    return kept[-1][1]


class MujocoWorld(mjw.FormBodies, World):
    """B free bodies in one MjModel (a kinematic tree each) and MjData: the world's Bodies, or FormBodies
    where a body is off its COM or of parts; raw rows ``[qpos (7), qvel (6)]``. From its build to
    :meth:`close` it holds ``_LOCK`` and MuJoCo's process-global handlers (then restored; a user's callbacks
    cleared): a warning handler (a warning is the body's whose DOF it names) and :meth:`_control`."""

    def __init__(self, requests, variant, dt_s):
        World.__init__(self)
        mjw.Bodies.__init__(self, _model([r.scenario for r in requests], variant, dt_s))
        entries = [body_entry(r.scenario) for r in requests]
        self.form = mjw.Form(entries) if any(len(e) > 3 for e in entries) else None
        self.per_stage = forces_per_stage(requests[0].scenario, variant)
        self.n, self.host_s, self.said, self.failed = 0, 0.0, [], None
        control = self._control(requests, entries) if self.per_stage else None
        _LOCK.acquire()
        try:
            self.prev = (*_set_force_callbacks(control), mujoco.get_mju_user_warning())
            mujoco.set_mju_user_warning(lambda msg: self.said.append(str(msg)))
        except BaseException:
            _LOCK.release()
            raise

    def _control(self, requests, entries):
        """The per-stage control callback (RK4): each body's forces but its body-axes torques, minus its
        weight, from its stage qpos/qvel into its xfrc_applied rows (a Form's: from its COM's state, shared
        among its parts); rbcheck's time (``host_s``); after an exception, which :meth:`step` raises, off."""
        bodies = []
        for k, r in enumerate(requests):
            host = host_problem(r.scenario.problem, MujocoEngine.takes_body_torque)
            sc = r.scenario if host is r.scenario.problem else dataclasses.replace(r.scenario, problem=host)
            form = None if self.form is None else mjw.Form([entries[k]])
            bodies.append((sc, tuple(map(float, forces.weight_W(r.scenario))), self.qpos[k], self.qvel[k],
                           form, self.xfrc[k] if form is None else self.xfrc[self.form.span(k)]))
        perf = time.perf_counter

        def on_control(_m, _d):
            if self.failed is not None:
                return
            t0 = perf()
            try:
                for sc, (w0, w1, w2), qpos, qvel, form, xfrc in bodies:
                    if form is None:
                        fx, fy, fz, tx, ty, tz = stage_force_torque_floats(sc, packed_floats(qpos.tolist(),
                                                                                             qvel.tolist()))
                        xfrc[:] = (fx - w0, fy - w1, fz - w2, tx, ty, tz)
                        continue
                    y = form.com_rows(np.concatenate((qpos, qvel))[None])[0]
                    f = np.array(stage_force_torque_floats(sc, y.tolist()))
                    form.write(xfrc, (f[0:3] - (w0, w1, w2))[None], f[3:6][None])
            except BaseException as exc:  # noqa: BLE001 - re-raised after the step
                self.failed = exc
            self.host_s += perf() - t0
        return on_control

    def set_state(self, y):
        (mjw.Bodies if self.form is None else mjw.FormBodies).set_state(self, y)   # the frame origin's
        self.n = 0

    def apply(self, f_W, tau_W):
        (mjw.Bodies if self.form is None else mjw.FormBodies).apply(self, f_W, tau_W)

    def decay(self, g_v, g_w):
        n, t = self.n, self.data.time   # a Form's: the COM's v and ω decay (World's), the origin's follow
        (mjw.Bodies if self.form is None else World).decay(self, g_v, g_w)
        self.n, self.data.time = n, t

    def packed(self, raw):
        if self.form is None:   # a whole record: in each run's own layout, the same numbers (packed_rows)
            return qpos_qvel_packed(raw, lambda r: mjw.Bodies.packed(self, r))
        return mjw.FormBodies.packed(self, raw)

    def packed_row(self, raw):   # a few bodies: packed_floats (the same numbers, 2 µs faster per step)
        if self.B > MANY_BODIES or self.form is not None:
            return self.packed(np.asarray(raw, dtype=float)[None])[0]
        return [packed_floats(r[0:7], r[7:13]) for r in np.asarray(raw).tolist()]

    def step(self):
        self.n += 1
        seen = len(self.said)
        mjw.Bodies.step(self)
        if self.failed is not None:
            exc, self.failed = self.failed, None
            raise EngineError(f"force evaluation inside MuJoCo's control callback failed: {exc!r}") from exc
        for msg in self.said[seen:]:   # one that names a DOF ("in QACC at DOF 9"; QPOS: a qpos index) is its
            m = re.search(r"(QPOS|QVEL|QACC)? at DOF (\d+)", msg)   # body's, the DOF counted in that body
            if m is None:
                self.warnings += [(k, self.n, f"MuJoCo: {msg}") for k in range(self.B)]
                continue
            i, width = int(m.group(2)), 7 if m.group(1) == "QPOS" else 6
            words = msg[:m.start(2)] + str(i % width) + msg[m.end(2):]
            self.warnings.append((min(i // width, self.B - 1), self.n, f"MuJoCo: {words}"))

    rollout_into = True

    def rollout(self, n_steps, harness, out):
        """``n_steps`` steps with the applied forces (xfrc_applied, qfrc_applied) held, their raw rows
        (n_steps, B, 13) into ``out``: one ``mujoco.rollout`` call, or for STEP_LOOP_BODIES bodies or more,
        and again where MuJoCo warned, ``mj_step`` from Python (:meth:`step`, which names the warned body);
        the set-up and the rows' copies are rbcheck's time (``host_s``)."""
        perf = time.perf_counter
        t_all, inside, start, seen = perf(), 0.0, self.read(), len(self.said)
        if self.B < STEP_LOOP_BODIES:
            from mujoco import rollout
            m, d = self.model, self.data
            state = np.concatenate([[0.0], d.qpos, d.qvel])[None]    # [time, qpos, qvel]
            spec = mujoco.mjtState.mjSTATE_QFRC_APPLIED | mujoco.mjtState.mjSTATE_XFRC_APPLIED
            control = np.empty(mujoco.mj_stateSize(m, spec))
            mujoco.mj_getState(m, d, control, spec)                  # in MuJoCo's own order of the two
            t0 = perf()
            states, _ = rollout.rollout(m, [mujoco.MjData(m)], state, control[None, None], control_spec=spec,
                                        nstep=n_steps)
            inside = perf() - t0
            out[..., 0:7] = states[0, :, 1:1 + m.nq].reshape(n_steps, self.B, 7)
            out[..., 7:13] = states[0, :, 1 + m.nq:].reshape(n_steps, self.B, 6)
            if len(self.said) == seen:
                self.host_s += perf() - t_all - inside
                return out
            self.qpos[:], self.qvel[:] = start[:, 0:7], start[:, 7:13]
            self.data.time, self.n = 0.0, 0
        for k in range(n_steps):
            t0 = perf()
            self.step()
            inside += perf() - t0
            out[k, :, 0:7], out[k, :, 7:13] = self.qpos, self.qvel
        self.host_s += perf() - t_all - inside
        return out

    def close(self):
        try:
            mujoco.set_mju_user_warning(self.prev[2])
            _set_force_callbacks(*self.prev[:2])
        finally:
            _LOCK.release()


class MujocoEngine(WorldEngine):
    """``mujoco:VARIANT`` — registered under the entry-point group ``rbcheck.engines``."""

    name, variants, distribution = ENGINE, VARIANTS, "mujoco"
    keeps_forces = True     # xfrc_applied is never cleared by MuJoCo
    takes_body_torque = True   # a free joint's rotational DOFs are body axes: qfrc_applied holds τ_B itself
    body_forms = frozenset({"com_offset", "welded_parts"})   # inertial frame off the body's; welded children
    chunk = 256
    harness = (*WorldEngine.harness, "cross_checks.engines.packed_rows")

    def build(self, requests, variant, dt_s):
        return MujocoWorld(requests, variant, dt_s)   # build_model checks the install (version())

    def group_key(self, request) -> tuple:   # one world per step and gravity (a model has one of each)
        return (float(request.dt_s), tuple(float(g) for g in request.scenario.problem.forces.gravity_W))

    def per_stage(self, scenario, variant):
        """RK4 with forces that change within a step (state-dependent forces or velocity decay; a torque
        fixed in body axes is MuJoCo's own): evaluated at every stage through the control callback."""
        fm = host_problem(scenario.problem, self.takes_body_torque).forces
        return variant == "rk4" and bool(fm.state_dependent or fm.has_decay) and _RK4_STAGE_FORCES


_ENGINE = MujocoEngine()
version, forces_per_stage = _ENGINE.version, _ENGINE.per_stage
simulate, simulate_many, one_step = _ENGINE.simulate, _ENGINE.simulate_many, _ENGINE.one_step
MujocoAdapter = MujocoEngine
