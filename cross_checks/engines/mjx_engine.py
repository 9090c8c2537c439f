"""MuJoCo XLA (``mujoco-mjx``, MuJoCo's physics in JAX) as an engine adapter (``mjx:VARIANT``); the
interface is cross_checks.engines.base. What MJX does, the defaults neutralised and what was measured:
docs/engine_conventions.md, "MJX 3.17.0".

Model: ``mujoco_engine.build_model``'s, put on the device by ``mjx.put_model``. Precision: float64 (JAX
started by runtimes.start_jax: ``jax_enable_x64`` is process-global).

State at the boundary (MuJoCo's, converted by mujoco_engine's ``to_qpos_qvel``/``to_packed``):
``qpos = [x_W, q_WB (w x y z)]``, ``qvel = [v_W (COM, world axes), ω_B (body axes)]``.

Forces: the harness's world force at the COM minus the weight ``m g`` (MJX applies gravity) and its world
torque go into the body's row of ``xfrc_applied``, from the start-of-step state (state-dependent ones
evaluated inside the compiled loop by cross_checks.engines.jax_forces: the loop's harness in JAX, bit for
bit), the decay applied before the step; RK4 holds them over its stages (MJX has no per-stage hook).

A world of rbcheck's loop (cross_checks.engines.world, cross_checks.engines.loop): :class:`MjxWorld`, the
requests of one model structure whatever their Δt, vmapped through one compiled loop per structure in
batches of at most MAX_BATCH, its ``rollout``, which takes every force itself and records every state in the
compiled loop (runtimes.chunk_rows steps a call, at most CHUNK); the loop's one-step mode vmaps the rows.
JAX is imported on first use only (never at import or in ``version()``): a sweep's parent must not start it
before forking. Divergence is the loop's.
"""
from __future__ import annotations

import contextlib
import functools
import io
import threading
import time
from pathlib import Path

import numpy as np

from cross_checks.core.files import kernel_cache_dir
from cross_checks.engines import base, install, runtimes
from cross_checks.engines.base import EngineError, Traits, Variant
from cross_checks.engines.world import World, WorldEngine

__all__ = ["ENGINE", "VARIANTS", "CHUNK", "ONE_STEP_BATCH", "MAX_BATCH", "EngineError", "version", "simulate",
           "simulate_many", "one_step", "device_model", "compile_stats", "jax_cache_dir",
           "MjxWorld", "MjxAdapter"]

ENGINE = "mjx"
#: MJX's integrators (``IntegratorType``), orders from MuJoCo's documentation, traits read in
#: mujoco/mjx/_src/forward.py and derivative.py.
VARIANTS = {
    "euler": Variant(1, "MJX Euler: semi-implicit Euler, explicit gyroscopic term, quaternion by the "
                        "exponential map (mujoco:euler's scheme, in JAX)",
                     traits=base.SYMPLECTIC_EULER_EXPLICIT_GYRO),
    # rungekutta4 advances q by ONE exponential of the stages' weighted body-axes ω (a vector sum)
    "rk4": Variant(4, "MJX RK4: classical 4th-order Runge-Kutta; the applied force and torque held over "
                      "the four stages (no per-stage hook in MJX); the attitude advanced by one exponential "
                      "of the stages' weighted ω: second order where the body-axes ω turns",
                   traits=Traits(forces_held=True, rotation_order=2.0)),
    "implicitfast": Variant(1, "MJX implicitfast: velocity-implicit in the actuator and damping derivatives "
                               "only (no RNE derivative in MJX): Euler's step on a lone free body",
                            traits=base.SYMPLECTIC_EULER_EXPLICIT_GYRO),
}

#: Steps per call of the compiled loop at most (a run longer than this calls it again from its last state;
#: a batch of many bodies records fewer a call: runtimes.chunk_rows).
CHUNK = 2048
#: Rows of one one_step call (the sweep's local-error mode asks 64 at a time); more rows run in several calls.
ONE_STEP_BATCH = 64
#: Runs per compiled batch of simulate_many (padded to a power of two, so that batch sizes share executables):
#: a thousand bodies in one call, as an engine's own vmapped loop runs them.
MAX_BATCH = 1024
_BODY = 1   # body id of the free body (0 is the world)
_DIST = "mujoco-mjx"
_HINT = "pip install 'rbcheck[mjx]'"

_LOCK = threading.RLock()


# --- the engine, imported lazily (never at module import, never in version()) -----------------------------

def jax_cache_dir() -> Path:
    """Where JAX's persistent compilation cache is kept: core.files.kernel_cache_dir("jax")."""
    return kernel_cache_dir("jax")


def _check_installed() -> None:
    """EngineNotInstalled when mujoco-mjx is not installed; ImportError when it is but MJX or JAX cannot be
    found — from package metadata and import specs only (nothing imported, no JAX backend started)."""
    import importlib.util
    install.check_installed(_DIST, _HINT, needs=(("jax", "jax"), ("jaxlib", "jaxlib")))
    if importlib.util.find_spec("mujoco.mjx") is None:
        raise ImportError(f"{_DIST} {install.installed_version(_DIST)} is installed but mujoco.mjx cannot be "
                          "found")


def version() -> str:
    """MJX's version and the JAX release it runs on, e.g. ``3.17.0 (jax 0.10.2)``, from package metadata
    (EngineNotInstalled when mujoco-mjx is absent)."""
    _check_installed()
    return install.release(_DIST, ("jax", "jax"))


@functools.lru_cache(maxsize=1)
def _engine():
    """``(jax, jax.numpy, mujoco.mjx)``, imported on first use (runtimes.start_jax). ImportError (with JAX's
    or MJX's words) when the import fails."""
    _check_installed()
    # mujoco.mjx prints "Failed to import warp: ..." on stdout when the optional Warp backend is absent
    with install.first_import(_DIST), contextlib.redirect_stdout(io.StringIO()):
        jax = runtimes.start_jax()
        import jax.numpy as jnp
        from mujoco import mjx
    return jax, jnp, mjx


def _engine_or_error():
    """:func:`_engine`, an import failure as EngineError; EngineError too in a process forked after JAX
    started in its parent."""
    runtimes.refuse_forked_jax(
        "MJX cannot run in a process forked after JAX started in its parent (a running JAX backend does "
        "not survive fork: its threads are gone and it would hang); run the sweep with --jobs 1 from "
        "there, or from a process that has not run MJX")
    return install.engine_or_error(_engine)


# --- compile bookkeeping ----------------------------------------------------------------------------------

_COMPILED: dict = {}   # key -> compiled executable
_STATS = runtimes.Stats(compilations=0, compile_seconds=0.0, step_seconds=0.0, body_steps=0)


def compile_stats() -> dict:
    """This process's compilations so far: ``compilations`` (count), ``compile_seconds`` (lowering + XLA
    compile, wall s), and the stepping apart from it: ``step_seconds`` (wall s inside compiled loops) and
    ``body_steps`` (steps × bodies they advanced)."""
    return dict(_STATS)


def _executable(key, fn, *args):
    """The compiled ``fn`` for ``args`` (ahead-of-time: ``jax.jit(fn).lower(*args).compile()``), once per
    ``key``; its compile time counted in :func:`compile_stats`."""
    exe = _COMPILED.get(key)
    if exe is None:
        jax, _, _ = _engine()
        with _STATS.timing("compile_seconds"):
            exe = jax.jit(fn).lower(*args).compile()
        _STATS["compilations"] += 1
        _COMPILED[key] = exe
    return exe


# --- models: one compiled MuJoCo model per scenario, on the device, stacked per structure -------------------

def _meta_key(obj, prefix="") -> tuple:
    """The static (non-array) fields of an MJX Model, recursively, except the name tables — what decides
    whether two models share one compiled executable (the scenario's name is in the names; Δt, mass and
    inertia are array leaves)."""
    import dataclasses
    jax, _, _ = _engine()
    out = []
    for f in dataclasses.fields(obj):
        v = getattr(obj, f.name)
        if f.name.startswith("name") or f.name == "signature":
            continue
        if dataclasses.is_dataclass(v):
            out.extend(_meta_key(v, f"{prefix}{f.name}."))
        elif not isinstance(v, jax.Array):
            if isinstance(v, np.ndarray):
                v = (v.dtype.str, v.shape, v.tobytes())
            elif isinstance(v, tuple):
                v = tuple((a.dtype.str, a.shape, a.tobytes()) if isinstance(a, np.ndarray) else a for a in v)
            out.append((prefix + f.name, v))
    return tuple(out)


_TEMPLATES: dict = {}   # structure key -> (template MJX Model, its MjModel)
_NUMBERS: dict = {}     # structure key -> a small number (a world's key)


#: The last models put on the device: ``(id(scenario), variant) -> (scenario, key, MJX Model)`` (the scenario
#: held, so that its id stays its own); a scenario's other steps reuse its model with ``opt.timestep``
#: replaced (``mjx.put_model`` is slow; the step is all a Δt changes).
_PUT: dict = {}
_PUT_MAX = 256


def device_model(scenario, variant: str, dt_s: float):
    """``(structure key, MJX Model)`` of the scenario's body for ``variant`` at ``dt_s``: mujoco_engine's
    ``build_model``, then ``mjx.put_model``; the name tables replaced by those of the first model of the same
    structure (so that its executables serve it). EngineError with MuJoCo's or MJX's words."""
    from cross_checks.engines import mujoco_engine
    _, jnp, mjx = _engine_or_error()
    held = _PUT.get((id(scenario), variant))
    if held is not None and held[0] is scenario:
        _, key, xm = held
        return key, xm.replace(opt=xm.opt.replace(timestep=jnp.asarray(float(dt_s), dtype=jnp.float64)))
    m = mujoco_engine.build_model(scenario, variant, dt_s)
    try:
        xm = mjx.put_model(m)
    except Exception as exc:  # noqa: BLE001 - MJX refuses a model feature: its own words
        raise EngineError(f"MJX {version()} refused the model of scenario {scenario.name!r}: "
                          f"{type(exc).__name__}: {exc}") from None
    key = (variant, _meta_key(xm))
    tpl = _TEMPLATES.get(key)
    if tpl is None:
        _TEMPLATES[key] = tpl = (xm, m)
    else:
        import dataclasses
        xm = xm.replace(**{f.name: getattr(tpl[0], f.name) for f in dataclasses.fields(xm)
                           if f.name.startswith("name") or f.name == "signature"})
    if len(_PUT) >= _PUT_MAX:
        _PUT.pop(next(iter(_PUT)))
    _PUT[(id(scenario), variant)] = (scenario, key, xm)
    return key, xm


def _stack(models):
    """The models' leaves stacked along a new first axis, on the host (one transfer per leaf when the
    executable is called, instead of a ``jnp.stack`` dispatch per leaf)."""
    jax, _, _ = _engine()
    return jax.tree.map(lambda *xs: np.stack([np.asarray(x) for x in xs]), *models)


# --- the compiled functions ---------------------------------------------------------------------------------

def _chunk_fn(d0, forces_in_loop: bool, rows: int):
    """``run(models, qpos (B, 7), qvel (B, 6), gains (B, 6), xfrc (B, 6), fa, zero, n)`` -> states (B,
    rows, 13) ``[qpos, qvel]`` after each of the first ``n`` steps (the rest zeros): the chunk of a free run,
    vmapped over B runs (each its own model: runtimes.stack_trees). ``gains``: the pre-step decay factors on
    qvel; ``xfrc``: the constant applied row, or with ``forces_in_loop`` the harness's at the start of every
    step, evaluated in the loop (jax_forces.wrench of the arrays ``fa``, each body's row; ``zero`` its traced
    integer zero)."""
    jax, jnp, mjx = _engine()

    from cross_checks.engines import jax_forces
    from cross_checks.engines.worlds.mjx import step_one  # the step rbcheck repro embeds

    def member(m, qpos, qvel, gain, xfrc, fa, z, n):
        d = d0.replace(qpos=qpos, qvel=qvel)

        def body(i, carry):
            d, out = carry
            if forces_in_loop:   # the start-of-step state, before the decay (as the loop's harness)
                f = jax_forces.wrench_apart(fa, d.qpos[0:3], d.qvel[0:3], d.qpos[3:7], z)
            else:
                f = xfrc
            d = step_one(m, d, gain, f)
            return d, out.at[i].set(jnp.concatenate([d.qpos, d.qvel]))

        _, out = jax.lax.fori_loop(0, n, body, (d, jnp.zeros((rows, 13))))
        return out

    def run(models, qpos, qvel, gains, xfrc, fa, z, n):
        vmapped = jax.vmap(member, in_axes=(0, 0, 0, 0, 0, 0, None, None))
        return vmapped(models, qpos, qvel, gains, xfrc, fa, z, n)
    return run


def _one_step_fn(d0):
    """``step(model, qpos (R, 7), qvel (R, 6), xfrc (R, 6))`` -> (R, 13) ``[qpos, qvel]`` one step later."""
    jax, jnp, mjx = _engine()

    def member(m, qpos, qvel, xfrc):
        d = d0.replace(qpos=qpos, qvel=qvel, xfrc_applied=d0.xfrc_applied.at[_BODY].set(xfrc))
        d = mjx.step(m, d)
        return jnp.concatenate([d.qpos, d.qvel])

    def step(m, qpos, qvel, xfrc):
        return jax.vmap(member, in_axes=(None, 0, 0, 0))(m, qpos, qvel, xfrc)
    return step


def _data0(key):
    """A fresh MJX Data of the structure ``key`` (its template's MjModel)."""
    import mujoco
    _, _, mjx = _engine()
    m = _TEMPLATES[key][1]
    return mjx.put_data(m, mujoco.MjData(m))


# --- the world ----------------------------------------------------------------------------------------------

class MjxWorld(World):
    """B free bodies of one model structure (:func:`device_model`, each at its request's Δt). Raw rows:
    ``[qpos (7), qvel (6)]`` per body, ω in BODY axes. :meth:`rollout` vmaps the bodies through the compiled
    chunk loop in batches of at most MAX_BATCH, padded to a power of two, taking every force itself
    (constant: the applied rows; state-dependent: the loop's harness evaluated inside the compiled loop,
    cross_checks.engines.jax_forces, bit for bit the host's; the decay as gains on qvel before each step);
    :meth:`step` (the one-step mode) vmaps the bodies of one model through the one-step executable,
    ONE_STEP_BATCH at a time."""

    rollout_forces = True

    def __init__(self, requests, variant: str):
        super().__init__()
        with _LOCK:
            held: dict = {}   # (scenario, Δt) -> its MJX model, put once per world
            for r in requests:
                k = (id(r.scenario), float(r.dt_s))
                if k not in held:
                    held[k] = device_model(r.scenario, variant, r.dt_s)
        self.models = [xm for _, xm in held.values()]   # the distinct models
        self.same = [list(held).index((id(r.scenario), float(r.dt_s))) for r in requests]
        self.key = held[id(requests[0].scenario), float(requests[0].dt_s)][0]
        self.state_dependent = bool(requests[0].scenario.problem.forces.state_dependent)
        self.ends = [int(r.n_steps) for r in requests]
        B = self.B = len(requests)
        self.qpos, self.qvel, self.xfrc = np.zeros((B, 7)), np.zeros((B, 6)), np.zeros((B, 6))
        self.host_s = 0.0

    def set_state(self, y):
        from cross_checks.engines.mujoco_engine import to_qpos_qvel
        self.qpos, self.qvel = to_qpos_qvel(y)

    def apply(self, f_W, tau_W):
        self.xfrc = np.concatenate([f_W, tau_W], axis=1)

    def read(self):
        return np.concatenate((self.qpos, self.qvel), axis=1)

    def packed(self, raw):
        from cross_checks.engines.mujoco_engine import to_packed
        raw = np.asarray(raw, dtype=float)
        return to_packed(raw[..., 0:7], raw[..., 7:13])

    def step(self):
        """One step of every body, the bodies of one model (scenario and Δt) vmapped together."""
        jax, _, _ = _engine_or_error()
        out = np.empty((self.B, 13))
        same = np.asarray(self.same)
        with _LOCK:
            for model in dict.fromkeys(self.same):
                idx = np.flatnonzero(same == model)
                host_model = jax.tree.map(np.asarray, self.models[model])
                fn = None
                for s in range(0, len(idx), ONE_STEP_BATCH):
                    rows = idx[s:s + ONE_STEP_BATCH]
                    take = np.r_[rows, np.full(ONE_STEP_BATCH - len(rows), rows[0])]
                    args = (host_model, self.qpos[take], self.qvel[take], self.xfrc[take])
                    if fn is None:
                        fn = _executable(("one_step", self.key, ONE_STEP_BATCH),
                                         _one_step_fn(_data0(self.key)), *args)
                    with _STATS.timing("step_seconds"):
                        out[rows] = np.asarray(fn(*args))[:len(rows)]
                    _STATS["body_steps"] += ONE_STEP_BATCH
        self.qpos, self.qvel = out[:, 0:7], out[:, 7:13]

    def rollout(self, n_steps, harness):
        """``n_steps`` steps of every body in the compiled chunk loop, batch by batch; a batch whose bodies
        all ended (non-finite, or at their run's last step) stops there (its later rows NaN)."""
        from cross_checks.engines import jax_forces
        _engine_or_error()
        gains = np.concatenate([np.repeat(harness.g_v[:, None], 3, 1), np.repeat(harness.g_w[:, None], 3, 1)],
                               axis=1)
        out = np.full((n_steps, self.B, 13), np.nan)
        t0 = time.perf_counter()
        fa = jax_forces.BodyForces(harness) if self.state_dependent else None
        self.host_s += time.perf_counter() - t0
        with _LOCK:
            for s in range(0, self.B, MAX_BATCH):
                self._batch(list(range(s, min(s + MAX_BATCH, self.B))), n_steps, gains, fa, out)
        return out

    def _batch(self, idx, n_max, gains, fa, out):
        from cross_checks.engines import jax_forces
        _, jnp, _ = _engine()
        B, M = len(idx), runtimes.power_of_two(len(idx))
        pad = idx + [idx[0]] * (M - B)
        t0 = time.perf_counter()
        models = runtimes.stack_trees(self.models, [self.same[k] for k in pad])
        rows = runtimes.chunk_rows(M, CHUNK)
        fargs = {} if fa is None else fa.take(pad)
        args = (models, jnp.asarray(self.qpos[pad]), jnp.asarray(self.qvel[pad]), jnp.asarray(gains[pad]),
                jnp.asarray(self.xfrc[pad]), fargs, jax_forces.zero(), jnp.asarray(0, dtype=jnp.int32))
        exe = _executable(("chunk", self.key, fa is not None and fa.key, M, rows),
                          _chunk_fn(_data0(self.key), fa is not None, rows), *args)
        self.host_s += time.perf_counter() - t0   # stacking the models, compiling: not stepping
        qpos, qvel = args[1], args[2]
        ends = np.array([self.ends[k] for k in idx])
        done = np.zeros(B, dtype=bool)   # diverged or at its end (the rest of its run is not needed)
        for s in range(0, n_max, rows):
            n = min(rows, n_max - s)
            with _STATS.timing("step_seconds"):
                chunk = np.asarray(exe(models, qpos, qvel, *args[3:7], jnp.asarray(n, dtype=jnp.int32)))
            _STATS["body_steps"] += n * M
            out[s:s + n, idx] = chunk[:B, :n].transpose(1, 0, 2)
            with np.errstate(all="ignore"):
                done |= ~np.all(np.isfinite(chunk[:B, n - 1]), axis=-1) | (ends <= s + n)
            if done.all():
                break
            qpos, qvel = jnp.asarray(chunk[:, n - 1, 0:7]), jnp.asarray(chunk[:, n - 1, 7:13])


class MjxEngine(WorldEngine):
    """``mjx:VARIANT`` — registered under the entry-point group ``rbcheck.engines``; optional
    (``pip install 'rbcheck[mjx]'``)."""

    name, variants, distribution, module, extra = ENGINE, VARIANTS, _DIST, "mujoco.mjx", "mjx"
    harness = (*WorldEngine.harness, "cross_checks.engines.mujoco_engine")

    version = staticmethod(version)   # the module's: from package metadata, JAX not started

    def build(self, requests, variant, dt_s):
        _engine_or_error()
        return MjxWorld(requests, variant)

    def world_key(self, request, variant):
        """One world per model structure and kind of forces, whatever the steps (each body's model carries
        its Δt); a request whose model is refused in a world of its scenario, whose build then says why."""
        try:
            with _LOCK:
                key, _ = device_model(request.scenario, variant, request.dt_s)
        except EngineError:
            return ("refused", id(request.scenario))
        # the structure's number, not its key (a tuple of every static field: hashing it once per request
        # cost ~50 µs, 50 ms of a thousand-run batch)
        number = _NUMBERS.setdefault(key, len(_NUMBERS))
        return (number, bool(request.scenario.problem.forces.state_dependent))

    def engine_files(self) -> list:
        """MJX's Python sources (found without importing them: the parent of a sweep must not start JAX)."""
        return install.package_files("mujoco.mjx", "_src")


_ENGINE = MjxEngine()
#: The module's functions (tests and scripts call them): the engine's, through the host loop.
simulate, simulate_many, one_step = _ENGINE.simulate, _ENGINE.simulate_many, _ENGINE.one_step
MjxAdapter = MjxEngine
