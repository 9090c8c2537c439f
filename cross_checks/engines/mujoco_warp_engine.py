"""MuJoCo Warp (``mujoco-warp``, MuJoCo's physics as NVIDIA Warp kernels) as an engine adapter
(``mujoco_warp:VARIANT``); the interface is cross_checks.engines.base. What mujoco_warp does, the defaults
neutralised and what was measured: docs/engine_conventions.md, "MuJoCo Warp 4.0.0".

Precision: float32 on Warp's CPU device (every Model and Data array is ``wp.float32``): each variant declares
``Traits(precision="float32")``.

Model: ``mujoco_engine.build_model``'s with ``mjDSBL_AUTORESET`` cleared (``mjw.put_model`` refuses it), put
on the CPU device; ``opt.timestep`` is per world, so a scenario's Δt rungs run as the worlds of one batch.

State at the boundary (MuJoCo's, converted in float64 by mujoco_engine's ``to_qpos_qvel``/``to_packed``):
``qpos = [x_W, q_WB (w x y z)]``, ``qvel = [v_W (COM, world axes), ω_B (body axes)]``; the recorded quaternion
kept sign-continuous from the scenario's.

Forces: the harness's world force at the COM minus the weight ``m g`` (mujoco_warp applies gravity) and its
world torque go into the body's row of ``Data.xfrc_applied``, from the start-of-step state, the decay applied
to qvel before the step — except RK4 with forces that change within a step, which evaluates them at every
stage through ``Model.callback.control`` (:func:`stage_callback`, the decay as damping).

:func:`simulate_many` runs one scenario's requests as the worlds of one batch (at most MAX_WORLDS), one step
captured as a Warp graph and replayed; :func:`one_step` runs its rows as worlds. Warp is imported on first use
only (never at import or in ``version()``); its kernels are compiled into ``kernel_cache_dir("mujoco_warp")``.

Divergence: the first recorded state that is non-finite or beyond BLOWUP_LIMIT ends the run
(``diverged at t = …``).
"""
from __future__ import annotations

import functools
import threading

import numpy as np

from cross_checks.engines import base
from cross_checks.engines.base import EngineError, ModuleAdapter, Traits, Variant, installed_version
from cross_checks.engines.step_floats import harness_fn
from reference_sim.quaternion import same_side, sign_continuous
from reference_sim.simulate import Run, recorded_run

__all__ = ["ENGINE", "VARIANTS", "EngineError", "version", "simulate", "simulate_many", "one_step",
           "host_model", "device_model", "compile_stats", "reset_stats", "MujocoWarpAdapter"]

ENGINE = "mujoco_warp"
_DIST = "mujoco-warp"
_HINT = "pip install 'rbcheck[mujoco_warp]'"
_F32 = "float32"


def _traits(base: Traits) -> Traits:
    import dataclasses
    return dataclasses.replace(base, precision=_F32)


#: mujoco_warp's integrators (``IntegratorType``), orders from MuJoCo's documentation, traits read in
#: mujoco_warp/_src/forward.py, all float32.
VARIANTS = {
    "euler": Variant(1, "MuJoCo Warp Euler (float32): semi-implicit Euler, explicit gyroscopic term, "
                        "quaternion by the exponential map (mujoco:euler's scheme)",
                     traits=_traits(base.SYMPLECTIC_EULER_EXPLICIT_GYRO)),
    "rk4": Variant(4, "MuJoCo Warp RK4 (float32): classical 4th-order Runge-Kutta, Munthe-Kaas attitude "
                      "update; state-dependent forces evaluated at every stage (control callback)",
                   traits=Traits(precision=_F32)),
    "implicit": Variant(1, "MuJoCo Warp implicit (float32): velocity-implicit Euler, the free body's "
                           "gyroscopic derivative in the solve",
                        traits=_traits(base.SYMPLECTIC_EULER_IMPLICIT_GYRO)),
    "implicitfast": Variant(1, "MuJoCo Warp implicitfast (float32): on a free body the same solve as "
                               "implicit (MuJoCo 4.0's free-body gyroscopic derivative)",
                            traits=_traits(base.SYMPLECTIC_EULER_IMPLICIT_GYRO)),
    "discrete": Variant(1, "MuJoCo Warp discrete (float32): qacc in the effective metric with the free "
                           "body's gyroscopic derivative (implicitfast's step for a lone body)",
                        traits=_traits(base.SYMPLECTIC_EULER_IMPLICIT_GYRO)),
}

_BODY = 1   # body id of the free body (0 is the world)
#: Worlds of one batch at most (a scenario's ladder is 5-10 rungs; one_step's rows are 64 at a time).
MAX_WORLDS = 256

_LOCK = threading.RLock()


# --- the engine, imported lazily (never at module import, never in version()) -----------------------------

def _check_installed() -> None:
    """base.check_installed for this engine and the Warp it runs on."""
    base.check_installed(_DIST, _HINT, (("warp", "warp-lang"),), installed_version)


def version() -> str:
    """mujoco_warp's version and the Warp release it runs on, e.g. ``4.0.0 (warp 1.19.0)``, from package
    metadata (EngineNotInstalled when mujoco-warp is absent)."""
    _check_installed()
    return base.release(_DIST, ("warp", "warp-lang"))


@functools.lru_cache(maxsize=1)
def _engine():
    """``(warp, mujoco_warp, mujoco)``, imported on first use (base.start_warp: the kernel cache in
    ``kernel_cache_dir("mujoco_warp")``). ImportError with the engine's words when the import fails."""
    _check_installed()
    with base.first_import(_DIST, installed_version), base.quiet_fd2():
        wp = base.start_warp(ENGINE, "LOG_ERROR")
        import mujoco
        import mujoco_warp as mjw
    return wp, mjw, mujoco


# --- bookkeeping: compile time apart from stepping ------------------------------------------------

_STATS = base.Stats(compilations=0, compile_seconds=0.0, step_seconds=0.0, steps=0, body_steps=0, captures=0)
_WARM: set = set()   # (variant, callback) whose kernels this process has loaded


def compile_stats() -> dict:
    """This process's kernel work so far: ``compilations`` (variants whose kernels were compiled or loaded
    from the kernel cache) and ``compile_seconds`` (wall s of their first, uncaptured step on a scratch
    world), and the stepping apart from it: ``step_seconds`` (wall s of the steps of runs), ``steps`` (engine
    steps, each advancing every world of its batch), ``body_steps`` (steps × worlds) and ``captures``
    (graphs recorded)."""
    return dict(_STATS)


def reset_stats() -> None:
    """Zero :func:`compile_stats` (Warp keeps its loaded modules: a variant is not recompiled)."""
    _STATS.reset()


def _warm_up(variant: str, m_host, callback=None) -> None:
    """Load (compile on first use ever, else read from the kernel cache) every kernel a step of ``variant``
    launches (with the stage-force ``callback``, if any), by one uncaptured step of a scratch world of
    ``m_host``; its wall time is the compile time."""
    key = (variant, callback is not None)
    if key in _WARM:
        return
    wp, mjw, mujoco = _engine()
    with _STATS.timing("compile_seconds"):
        wm = mjw.put_model(m_host)
        wd = mjw.put_data(m_host, mujoco.MjData(m_host), nworld=1)
        if callback is not None:
            wm.callback.control = callback
        with wp.ScopedDevice("cpu"):
            mjw.step(wm, wd)
        wp.synchronize()
    _STATS["compilations"] += 1
    _WARM.add(key)


# --- models ---------------------------------------------------------------------------------------

def host_model(scenario, variant: str, dt_s: float):
    """The scenario's MjModel for ``variant`` at ``dt_s``: mujoco_engine's ``build_model`` with
    ``mjDSBL_AUTORESET`` cleared (mujoco_warp refuses it; it never resets a world). EngineError with MuJoCo's
    words."""
    from cross_checks.engines import mujoco_engine
    base.check_variant(ENGINE, VARIANTS, variant)
    _, _, mujoco = base.engine_or_error(_engine)
    m = mujoco_engine.build_model(scenario, variant, dt_s)
    m.opt.disableflags &= ~int(mujoco.mjtDisableBit.mjDSBL_AUTORESET)
    return m


def device_model(m_host, dts):
    """``mjw.put_model(m_host)`` on the CPU device with ``opt.timestep`` one per world (``dts``). EngineError
    with mujoco_warp's words when it refuses the model."""
    wp, mjw, _ = _engine()
    try:
        with wp.ScopedDevice("cpu"):
            wm = mjw.put_model(m_host)
            wm.opt.timestep = wp.array(np.asarray(dts, dtype=np.float32), dtype=wp.float32)
    except Exception as exc:  # noqa: BLE001 - mujoco_warp refuses a model feature: its own words
        raise EngineError(f"mujoco_warp {version()} refused the model: {type(exc).__name__}: {exc}") from None
    return wm


def per_stage(scenario, variant: str) -> bool:
    """RK4 with forces that change within a step (state-dependent forces or velocity decay): evaluated at
    every stage through ``Model.callback.control`` (like mujoco:rk4)."""
    fm = scenario.problem.forces
    return variant == "rk4" and bool(fm.state_dependent or fm.has_decay)


class _Worlds:
    """``N`` worlds of one scenario's model on the CPU device, world ``k`` stepping at ``dts[k]``, with
    zero-copy NumPy views of their qpos, qvel and xfrc_applied (float32)."""

    def __init__(self, scenario, variant: str, dts, qpos0, qvel0, callback=None):
        wp, mjw, mujoco = base.engine_or_error(_engine)
        m = host_model(scenario, variant, float(dts[0]))
        _warm_up(variant, m, callback)
        self.wp, self.mjw = wp, mjw
        with wp.ScopedDevice("cpu"):
            self.m = device_model(m, dts)
            self.d = mjw.put_data(m, mujoco.MjData(m), nworld=len(dts))
        self.qpos, self.qvel = self.d.qpos.numpy(), self.d.qvel.numpy()
        self.xfrc = self.d.xfrc_applied.numpy()
        if not (np.shares_memory(self.qpos, self.d.qpos.numpy()) and np.shares_memory(self.xfrc,
                                                                                         self.d.xfrc_applied.numpy())):
            raise EngineError("Warp's CPU arrays are not shared with NumPy here: the adapter cannot run")
        self.qpos[:], self.qvel[:] = qpos0, qvel0
        self.xfrc[:] = 0.0
        self.graph = None
        if callback is not None:
            self.m.callback.control = callback

    def capture(self) -> None:
        """Record one step as a graph (replayed by :meth:`step`); the state is not advanced by recording
        (tested)."""
        wp = self.wp
        saved = self.qpos.copy(), self.qvel.copy()
        with wp.ScopedDevice("cpu"), wp.ScopedCapture() as cap:
            self.mjw.step(self.m, self.d)
        self.qpos[:], self.qvel[:] = saved
        self.graph = cap.graph
        _STATS["captures"] += 1

    def step(self) -> None:
        if self.graph is not None:
            self.wp.capture_launch(self.graph)
        else:
            with self.wp.ScopedDevice("cpu"):
                self.mjw.step(self.m, self.d)


# --- adapter entry points ----------------------------------------------------------------------------------

def simulate(scenario, variant: str, dt_s: float, n_steps: int) -> Run:
    """Free run of ``n_steps`` steps of ``dt_s`` from the scenario's initial state, every step recorded (one
    request of :func:`simulate_many`)."""
    return base.one_request(simulate_many, scenario, variant, dt_s, n_steps)


def simulate_many(variant: str, requests) -> list:
    """The runs of ``requests`` (``base.RunRequest``), each a Run (or its EngineError): the requests of one
    scenario run as the worlds of one batch (one world per Δt, in batches of at most MAX_WORLDS)."""
    base.check_variant(ENGINE, VARIANTS, variant)
    try:
        base.engine_or_error(_engine)
    except EngineError as exc:
        return [exc] * len(requests)
    with _LOCK:
        return base.run_in_groups(requests, lambda r: id(r.scenario), lambda reqs: _run_batch(variant, reqs),
                             MAX_WORLDS)


@functools.lru_cache(maxsize=1)
def _stage_kernel():
    """The Warp kernel of RK4's per-stage forces (``base.stage_force_torque`` in float32, the decay as
    damping), one thread per world: the scenario's forces minus its weight from the stage state in qpos/qvel
    into the body's row of xfrc_applied. Launched from ``Model.callback.control``, which ``_forward`` calls at
    every stage, so the whole RK4 step, stages and forces, is captured and replayed."""
    wp, _, _ = _engine()

    @wp.kernel(module="unique", enable_backward=False)
    def stage_forces(qpos: wp.array2d(dtype=float), qvel: wp.array2d(dtype=float), f0: wp.vec3, t0: wp.vec3,
                     tB: wp.vec3, drag: float, m_kv: float, k_w: float, inertia: wp.mat33,
                     springs: wp.array2d(dtype=float), wpts: wp.array2d(dtype=float),
                     bpts: wp.array2d(dtype=float), body: int,
                     xfrc: wp.array2d(dtype=wp.spatial_vector)):
        k = wp.tid()
        x = wp.vec3(qpos[k, 0], qpos[k, 1], qpos[k, 2])
        n = wp.sqrt(qpos[k, 3] * qpos[k, 3] + qpos[k, 4] * qpos[k, 4] + qpos[k, 5] * qpos[k, 5]
                    + qpos[k, 6] * qpos[k, 6])
        qw = qpos[k, 3] / n
        qx = qpos[k, 4] / n
        qy = qpos[k, 5] / n
        qz = qpos[k, 6] / n
        R = wp.mat33(1.0 - 2.0 * (qy * qy + qz * qz), 2.0 * (qx * qy - qw * qz), 2.0 * (qx * qz + qw * qy),
                     2.0 * (qx * qy + qw * qz), 1.0 - 2.0 * (qx * qx + qz * qz), 2.0 * (qy * qz - qw * qx),
                     2.0 * (qx * qz - qw * qy), 2.0 * (qy * qz + qw * qx), 1.0 - 2.0 * (qx * qx + qy * qy))
        v = wp.vec3(qvel[k, 0], qvel[k, 1], qvel[k, 2])
        w_B = wp.vec3(qvel[k, 3], qvel[k, 4], qvel[k, 5])
        f = f0 - (drag + m_kv) * v
        tau = t0 + R @ tB - k_w * (R @ (inertia @ w_B))
        for j in range(springs.shape[0]):
            r = R @ wp.vec3(springs[j, 3], springs[j, 4], springs[j, 5])
            d = x + r - wp.vec3(springs[j, 0], springs[j, 1], springs[j, 2])
            L = wp.length(d)
            fs = wp.vec3(0.0)
            if L > 0.0:
                fs = (-springs[j, 6] * (L - springs[j, 7]) / L) * d
            f = f + fs
            tau = tau + wp.cross(r, fs)
        for j in range(wpts.shape[0]):
            g = wp.vec3(wpts[j, 0], wpts[j, 1], wpts[j, 2])
            f = f + g
            tau = tau + wp.cross(R @ wp.vec3(wpts[j, 3], wpts[j, 4], wpts[j, 5]), g)
        for j in range(bpts.shape[0]):
            g = R @ wp.vec3(bpts[j, 0], bpts[j, 1], bpts[j, 2])
            f = f + g
            tau = tau + wp.cross(R @ wp.vec3(bpts[j, 3], bpts[j, 4], bpts[j, 5]), g)
        xfrc[k, body] = wp.spatial_vector(f[0], f[1], f[2], tau[0], tau[1], tau[2])

    return stage_forces


def stage_callback(scenario):
    """``Model.callback.control`` for RK4's stages: :func:`_stage_kernel` launched over every world of the
    Data it is given, with the scenario's force parameters (reference_sim.forces.Members)."""
    wp, _, _ = _engine()
    kernel = _stage_kernel()
    mb = scenario.problem.members

    def rows(a, width):
        a = np.asarray(a, dtype=np.float32).reshape(-1, width)
        return wp.array(a if len(a) else np.zeros((1, width), dtype=np.float32), dtype=float, device="cpu")

    k_v, k_w = (float(c) for c in np.asarray(mb.decay_rates).reshape(-1)[:2])
    m = float(np.asarray(mb.mass_kg).reshape(-1)[0])
    args = [wp.vec3(*np.asarray(mb.force_W, dtype=float).reshape(3)),
            wp.vec3(*np.asarray(mb.torque_W, dtype=float).reshape(3)),
            wp.vec3(*np.asarray(mb.torque_B, dtype=float).reshape(3)),
            float(np.asarray(mb.drag).reshape(-1)[0]), m * k_v, k_w,
            wp.mat33(*np.asarray(mb.inertia_B, dtype=float).reshape(9)),
            rows(mb.springs, 8), rows(mb.world_points, 6), rows(mb.body_points, 6), _BODY]

    def control(_m, d):
        wp.launch(kernel, dim=d.nworld, inputs=[d.qpos, d.qvel, *args], outputs=[d.xfrc_applied],
                  device="cpu")
    return control


def _run_batch(variant: str, reqs) -> list:
    """The Runs of ``reqs`` (one scenario, any Δt and step counts) as the worlds of one batch."""
    from cross_checks.engines.mujoco_engine import packed_floats, to_packed, to_qpos_qvel
    sc = reqs[0].scenario
    forces = sc.problem.forces
    N = len(reqs)
    dts = [float(r.dt_s) for r in reqs]
    y0 = np.asarray(sc.problem.initial_packed(), dtype=float)
    qpos0, qvel0 = to_qpos_qvel(np.repeat(y0[None], N, axis=0))
    stage = per_stage(sc, variant)
    W = _Worlds(sc, variant, dts, qpos0, qvel0, stage_callback(sc) if stage else None)
    g = np.array([[float(v) for v in base.decay_factors(sc, h)] for h in dts])   # (N, 2)
    decay = forces.has_decay and not stage
    per_step = forces.state_dependent and not stage
    wrench = [base.minus_weight(harness_fn(sc, h), base.weight_W(sc)) for h in dts]
    if not stage and not per_step:   # constant (decay scaling included), written once
        for k in range(N):
            W.xfrc[k, _BODY] = wrench[k](y0.tolist())
    W.capture()
    n_max = max(r.n_steps for r in reqs)
    qpos_out = np.empty((n_max + 1, N, 7), dtype=np.float32)
    qvel_out = np.empty((n_max + 1, N, 6), dtype=np.float32)
    qpos_out[0], qvel_out[0] = W.qpos, W.qvel
    qpos, qvel, xfrc = W.qpos, W.qvel, W.xfrc
    gv, gw = g[:, 0:1], g[:, 1:2]
    alive = np.ones(N, dtype=bool)
    with _STATS.timing("step_seconds"), np.errstate(all="ignore"):
        for n in range(1, n_max + 1):
            if per_step:
                qp, qv = qpos.tolist(), qvel.tolist()
                xfrc[:, _BODY] = [wrench[k](packed_floats(qp[k], qv[k])) for k in range(N)]
            if decay:
                qvel[:, 0:3] *= gv
                qvel[:, 3:6] *= gw
            W.step()
            qpos_out[n], qvel_out[n] = qpos, qvel
            if n % 256 == 0:   # stop early once every world has blown up
                alive &= np.isfinite(qvel).all(axis=1) & np.isfinite(qpos).all(axis=1)
                if not alive.any():
                    qpos_out[n + 1:], qvel_out[n + 1:] = np.nan, np.nan
                    break
    _STATS["steps"] += n
    _STATS["body_steps"] += n * N
    runs = []
    with np.errstate(all="ignore"):
        for k, r in enumerate(reqs):
            rows = slice(0, r.n_steps + 1)
            y = to_packed(qpos_out[rows, k].astype(float), qvel_out[rows, k].astype(float))
            y[0] = y0
            y[:, 6:10] = sign_continuous(y[:, 6:10])
            runs.append(recorded_run(y, r.dt_s))
    return runs


@base.on_rows
def one_step(scenario, variant: str, dt_s: float, y_start) -> np.ndarray:
    """One step of ``dt_s`` from each row of ``y_start`` (T, 13), the rows as the worlds of one batch
    (MAX_WORLDS at a time): the forces from the row, the pre-step decay (RK4 with forces that change within a
    step: both per stage). Rows the engine blows up come back as it left them."""
    from cross_checks.engines.mujoco_engine import to_packed, to_qpos_qvel
    base.check_variant(ENGINE, VARIANTS, variant)
    T = len(y_start)
    out = np.empty((T, 13))
    stage = per_stage(scenario, variant)
    wrench = base.minus_weight(harness_fn(scenario, dt_s), base.weight_W(scenario))
    with _LOCK:
        for s in range(0, T, MAX_WORLDS):
            rows = y_start[s:s + MAX_WORLDS]
            n = len(rows)
            with np.errstate(all="ignore"):
                qpos0, qvel0 = to_qpos_qvel(rows if stage else base.apply_decay_prestep(scenario, rows, dt_s))
            W = _Worlds(scenario, variant, [float(dt_s)] * n, qpos0, qvel0,
                        stage_callback(scenario) if stage else None)
            if not stage:
                for k, row in enumerate(rows.tolist()):
                    W.xfrc[k, _BODY] = wrench(row)
            with _STATS.timing("step_seconds"):
                W.step()
            _STATS["steps"] += 1
            _STATS["body_steps"] += n
            with np.errstate(all="ignore"):
                y = to_packed(W.qpos.astype(float), W.qvel.astype(float))
            y[:, 6:10] = same_side(y[:, 6:10], rows[:, 6:10])
            out[s:s + n] = y
    return out


class MujocoWarpAdapter(ModuleAdapter):
    """``mujoco_warp:VARIANT`` — registered under the entry-point group ``rbcheck.engines``; optional
    (``pip install 'rbcheck[mujoco_warp]'``)."""

    harness = ("cross_checks.engines.step_floats", "cross_checks.engines.mujoco_engine")

    def engine_files(self) -> list:
        """mujoco_warp's Python sources (found without importing them: the parent of a sweep must not start
        Warp)."""
        return base.package_files("mujoco_warp", "_src")
