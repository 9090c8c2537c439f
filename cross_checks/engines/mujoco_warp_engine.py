"""MuJoCo Warp (``mujoco-warp``: MuJoCo's physics as NVIDIA Warp kernels) as an engine
(``mujoco_warp:VARIANT``, float32 on Warp's CPU device): a world of rbcheck's loop on
cross_checks/engines/worlds/mujoco_warp.py (what ``rbcheck repro`` embeds: ``mujoco_engine.build_model``'s
model without ``mjDSBL_AUTORESET``, ``opt.timestep`` one per world, so that a scenario's Δt rungs are the
worlds of one batch, one step captured as a Warp graph and replayed; MuJoCo's state and ``xfrc_applied``).
RK4 with forces that change within a step evaluates them at every stage (:func:`stage_callback`). What
mujoco_warp does, the defaults neutralised and what was measured: docs/engine_conventions.md, "MuJoCo Warp".
"""
from __future__ import annotations

import dataclasses
import functools
import threading
import time

import numpy as np

from cross_checks.engines import base, install, runtimes
from cross_checks.engines.base import EngineError, Traits, Variant
from cross_checks.engines.world import World, WorldEngine

__all__ = ["ENGINE", "VARIANTS", "EngineError", "version", "simulate", "simulate_many", "one_step",
           "host_model", "device_model", "compile_stats", "WarpWorld", "MujocoWarpAdapter"]

ENGINE = "mujoco_warp"
_F32 = "float32"

#: mujoco_warp's integrators (``IntegratorType``), orders from MuJoCo's documentation, traits read in
#: mujoco_warp/_src/forward.py, all float32.
VARIANTS = {
    "euler": Variant(1, "MuJoCo Warp Euler (float32): semi-implicit Euler, explicit gyroscopic term, "
                        "quaternion by the exponential map (mujoco:euler's scheme)",
                     traits=dataclasses.replace(base.SYMPLECTIC_EULER_EXPLICIT_GYRO, precision=_F32)),
    "rk4": Variant(4, "MuJoCo Warp RK4 (float32): classical 4th-order Runge-Kutta, Munthe-Kaas attitude "
                      "update; state-dependent forces evaluated at every stage (control callback)",
                   traits=Traits(precision=_F32)),
    "implicit": Variant(1, "MuJoCo Warp implicit (float32): velocity-implicit Euler, the free body's "
                           "gyroscopic derivative in the solve",
                        traits=dataclasses.replace(base.SYMPLECTIC_EULER_IMPLICIT_GYRO, precision=_F32)),
    "implicitfast": Variant(1, "MuJoCo Warp implicitfast (float32): on a free body the same solve as "
                               "implicit (MuJoCo 4.0's free-body gyroscopic derivative)",
                            traits=dataclasses.replace(base.SYMPLECTIC_EULER_IMPLICIT_GYRO, precision=_F32)),
    "discrete": Variant(1, "MuJoCo Warp discrete (float32): qacc in the effective metric with the free "
                           "body's gyroscopic derivative (implicitfast's step for a lone body)",
                        traits=dataclasses.replace(base.SYMPLECTIC_EULER_IMPLICIT_GYRO, precision=_F32)),
}

_BODY = 1   # body id of the free body (0 is the world)
#: Worlds of one batch at most: a step's kernel launches cost about the same for 256 worlds as for 4096 on
#: the CPU device, so a batch is as large as MuJoCo Warp's own run of N worlds (``rbcheck bench``: N = 1000,
#: one batch); about 50 kB of Data a world (4096: ~200 MB). A sweep's batches are a scenario's ladder (5-10
#: rungs) or one_step's rows (64 at a time).
MAX_WORLDS = 4096

_LOCK = threading.RLock()


def _world():
    """:mod:`cross_checks.engines.worlds.mujoco_warp`, imported after :func:`_engine` started Warp."""
    _engine()
    from cross_checks.engines.worlds import mujoco_warp as mww
    return mww


#: This process's kernel work (:func:`compile_stats`): ``compilations`` (variants whose kernels were compiled
#: or loaded from the kernel cache), ``compile_seconds`` (wall s of their first, uncaptured step on a scratch
#: world), and apart from it ``step_seconds`` (wall s of the runs' steps), ``steps`` (engine steps, each
#: advancing every world of its batch), ``body_steps`` (steps × worlds) and ``captures`` (graphs recorded).
_STATS = runtimes.Stats(compilations=0, compile_seconds=0.0, step_seconds=0.0, steps=0, body_steps=0,
                        captures=0)


def host_model(scenario, variant: str, dt_s: float):
    """The scenario's MjModel for ``variant`` at ``dt_s``: mujoco_engine's ``build_model`` with
    ``mjDSBL_AUTORESET`` cleared (the world's ``host_model``: mujoco_warp refuses it). EngineError with
    MuJoCo's words."""
    from cross_checks.engines import mujoco_engine
    base.check_variant(ENGINE, VARIANTS, variant)
    install.engine_or_error(_engine)
    return _world().host_model(mujoco_engine.build_model(scenario, variant, dt_s))


def device_model(m_host, dts):
    """``mjw.put_model(m_host)`` on the CPU device with ``opt.timestep`` one per world (``dts``). EngineError
    with mujoco_warp's words when it refuses the model."""
    try:
        return _world().device_model(m_host, dts)
    except Exception as exc:  # noqa: BLE001 - mujoco_warp refuses a model feature: its own words
        raise EngineError(f"mujoco_warp {version()} refused the model: {type(exc).__name__}: {exc}") from None


def _worlds(scenario, variant: str, dts, qpos0, qvel0, callback=None):
    """``N`` worlds of one scenario's model, world ``k`` stepping at ``dts[k]`` (the world's ``Worlds``: its
    zero-copy float32 views ``qpos``, ``qvel``, ``xfrc``, its captured step), put at ``qpos0``, ``qvel0``, no
    force applied."""
    install.engine_or_error(_engine)
    m = host_model(scenario, variant, float(dts[0]))   # the kernels loaded by a scratch world's step:
    _ENGINE.warm((variant, callback is not None), lambda: _world().warm_up(m, callback))   # compile time
    W = _world().Worlds(device_model(m, dts), m, callback)
    if not W.shared:
        raise EngineError("Warp's CPU arrays are not shared with NumPy here: the adapter cannot run")
    W.qpos[:], W.qvel[:] = qpos0, qvel0
    W.xfrc[:] = 0.0
    return W


@functools.lru_cache(maxsize=1)
def _stage_kernel():
    """The Warp kernel of RK4's per-stage forces (``forces.stage_force_torque`` in float32, the decay as
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


class WarpWorld(World):
    """The bodies of one scenario's requests as the worlds of :func:`_worlds` batches (MAX_WORLDS at most),
    world k stepping at its request's Δt. Raw rows: ``[qpos (7), qvel (6)]`` per body (float32 values, ω in
    BODY axes). :meth:`rollout` captures one step as a Warp graph and replays it, taking every force itself
    (``rollout_forces``): the loop's Harness at every step from the float32 state, the decay on qvel before
    the step, or RK4's stage callback; :meth:`step` (the one-step mode) steps uncaptured."""

    exact_start = True
    rollout_forces = True

    def __init__(self, requests, variant: str):
        super().__init__()
        sc = requests[0].scenario
        self.per_stage = _ENGINE.per_stage(sc, variant)
        self.B, self.host_s = len(requests), 0.0
        self.parts = []   # (slice of the bodies, its worlds: _worlds)
        for s in range(0, self.B, MAX_WORLDS):
            part = slice(s, min(s + MAX_WORLDS, self.B))
            dts = [float(r.dt_s) for r in requests[part]]
            zeros = np.zeros((len(dts), 7)), np.zeros((len(dts), 6))
            self.parts.append((part, _worlds(sc, variant, dts, *zeros,
                                             stage_callback(sc) if self.per_stage else None)))

    def set_state(self, y):
        from cross_checks.engines.mujoco_engine import to_qpos_qvel
        qpos, qvel = to_qpos_qvel(y)
        for part, W in self.parts:
            W.qpos[:], W.qvel[:] = qpos[part], qvel[part]

    def apply(self, f_W, tau_W):
        for part, W in self.parts:
            W.xfrc[:, _BODY, 0:3], W.xfrc[:, _BODY, 3:6] = f_W[part], tau_W[part]

    def decay(self, g_v, g_w):
        for part, W in self.parts:
            W.qvel[:, 0:3] *= g_v[part, None]
            W.qvel[:, 3:6] *= g_w[part, None]

    def step(self):
        for _, W in self.parts:
            W.step()
            _STATS["steps"] += 1
            _STATS["body_steps"] += len(W.qpos)

    def read(self):
        return np.concatenate([np.concatenate((W.qpos, W.qvel), axis=1) for _, W in self.parts]).astype(float)

    def packed(self, raw):
        from cross_checks.engines.mujoco_engine import to_packed
        from cross_checks.engines.packed_rows import qpos_qvel_packed
        # a whole record: in each run's own layout, to_packed's numbers (packed_rows)
        return qpos_qvel_packed(raw, lambda r: to_packed(r[..., 0:7], r[..., 7:13]))

    def rollout(self, n_steps, harness):
        """``n_steps`` steps of every world, batch by batch, the step captured once and replayed; a batch
        whose worlds have all blown up stops there (its later rows NaN). The seconds outside the engine's
        steps (forces, decay, recording, the capture) go to ``host_s``."""
        out = np.empty((n_steps, self.B, 13))
        with _LOCK:
            for part, W in self.parts:
                out[:, part] = self._run(W, part, n_steps, harness)
        return out

    def _run(self, W, bodies: slice, n_max, harness):
        t_all, t_steps = time.perf_counter(), 0.0
        per_step = harness.state_dependent and not self.per_stage
        decay = harness.decays and not self.per_stage
        W.capture()
        _STATS["captures"] += 1
        N = len(W.qpos)
        qpos_out = np.empty((n_max, N, 7), dtype=np.float32)
        qvel_out = np.empty((n_max, N, 6), dtype=np.float32)
        qpos, qvel, xfrc = W.qpos, W.qvel, W.xfrc
        gv, gw = harness.g_v[bodies, None], harness.g_w[bodies, None]
        alive = np.ones(N, dtype=bool)
        perf = time.perf_counter
        with _STATS.timing("step_seconds"), np.errstate(all="ignore"):
            for n in range(1, n_max + 1):
                if per_step:   # the packed states of every world at once (packed_rows: to_packed's numbers)
                    y = self.packed(np.concatenate((qpos, qvel), axis=1)[None].astype(float))[0]
                    xfrc[:, _BODY, 0:3], xfrc[:, _BODY, 3:6] = harness.wrench(y, bodies)
                if decay:
                    qvel[:, 0:3] *= gv
                    qvel[:, 3:6] *= gw
                t0 = perf()
                W.step()
                t_steps += perf() - t0
                qpos_out[n - 1], qvel_out[n - 1] = qpos, qvel
                if n % 256 == 0:   # stop early once every world has blown up
                    alive &= np.isfinite(qvel).all(axis=1) & np.isfinite(qpos).all(axis=1)
                    if not alive.any():
                        qpos_out[n:], qvel_out[n:] = np.nan, np.nan
                        break
        _STATS["steps"] += n
        _STATS["body_steps"] += n * N
        self.host_s += time.perf_counter() - t_all - t_steps
        return np.concatenate((qpos_out, qvel_out), axis=2).astype(float)


class MujocoWarpEngine(runtimes.WarpEngine):
    """``mujoco_warp:VARIANT`` — registered under the entry-point group ``rbcheck.engines``; optional
    (``pip install 'rbcheck[mujoco_warp]'``)."""

    name, variants, distribution, extra = ENGINE, VARIANTS, "mujoco-warp", "mujoco_warp"
    imports, warp_log, stats = ("mujoco_warp", "mujoco"), "LOG_ERROR", _STATS
    harness = (*WorldEngine.harness, "cross_checks.engines.mujoco_engine", "cross_checks.engines.packed_rows")
    sign_continuity = True   # the recorded quaternion kept on the previous one's side

    def build(self, requests, variant, dt_s):
        install.engine_or_error(_engine)
        with _LOCK:
            return WarpWorld(requests, variant)

    def world_key(self, request, variant):
        """One world per scenario, whatever the steps (``opt.timestep`` is per world)."""
        return (id(request.scenario), self.per_stage(request.scenario, variant))

    def per_stage(self, scenario, variant: str) -> bool:
        """RK4 with forces that change within a step (state-dependent forces or velocity decay): evaluated at
        every stage through ``Model.callback.control`` (like mujoco:rk4)."""
        fm = scenario.problem.forces
        return variant == "rk4" and bool(fm.state_dependent or fm.has_decay)

    def engine_files(self) -> list:
        """mujoco_warp's Python sources (found without importing them: Warp not started)."""
        return install.package_files("mujoco_warp", "_src")


_ENGINE = MujocoWarpEngine()
#: The module's functions (tests and scripts call them): the engine's, through the host loop.
version, simulate, simulate_many, one_step = _ENGINE.version, _ENGINE.simulate, _ENGINE.simulate_many, \
    _ENGINE.one_step
_engine, start_for_repro = _ENGINE.modules, _ENGINE.start_for_repro   # (warp, mujoco_warp, mujoco)
compile_stats = _ENGINE.stats.copy
MujocoWarpAdapter = MujocoWarpEngine
