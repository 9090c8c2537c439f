"""MuJoCo XLA (``mujoco-mjx``, MuJoCo's physics in JAX) as an engine adapter (``mjx:VARIANT``); the
interface is cross_checks.engines.base. What MJX does, the defaults neutralised and what was measured:
docs/engine_conventions.md, "MJX 3.17.0".

Model: ``mujoco_engine.build_model``'s, put on the device by ``mjx.put_model``. Precision: float64 (JAX
started by base.start_jax: ``jax_enable_x64`` is process-global).

State at the boundary (MuJoCo's, converted by mujoco_engine's ``to_qpos_qvel``/``to_packed``):
``qpos = [x_W, q_WB (w x y z)]``, ``qvel = [v_W (COM, world axes), ω_B (body axes)]``.

Forces: the harness's world force at the COM minus the weight ``m g`` (MJX applies gravity) and its world
torque go into the body's row of ``xfrc_applied``, from the start-of-step state (state-dependent ones on the
host through ``jax.pure_callback``), the decay applied before the step; RK4 holds them over its stages (MJX
has no per-stage hook).

:func:`simulate_many` vmaps its runs through one compiled loop (CHUNK steps a call) per model structure, in
batches of at most MAX_BATCH; :func:`one_step` vmaps its rows. JAX is imported on first use only (never at
import or in ``version()``): a sweep's parent must not start it before forking.

Divergence: the first recorded state that is non-finite or beyond BLOWUP_LIMIT ends the run
(``diverged at t = …``).
"""
from __future__ import annotations

import contextlib
import functools
import io
import threading
from pathlib import Path

import numpy as np

from cross_checks.core.files import kernel_cache_dir
from cross_checks.engines import base
from cross_checks.engines.base import EngineError, ModuleAdapter, Traits, Variant, installed_version
from cross_checks.engines.step_floats import harness_fn
from reference_sim.simulate import Run, recorded_run

__all__ = ["ENGINE", "VARIANTS", "CHUNK", "ONE_STEP_BATCH", "MAX_BATCH", "EngineError", "version", "simulate",
           "simulate_many", "one_step", "device_model", "compile_stats", "reset_compiled", "jax_cache_dir",
           "MjxAdapter"]

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

#: Steps per call of the compiled loop (a run longer than this calls it again from its last state).
CHUNK = 2048
#: Rows of one one_step call (the sweep's local-error mode asks 64 at a time); more rows run in several calls.
ONE_STEP_BATCH = 64
#: Runs per compiled batch of simulate_many (padded to a power of two, so that batch sizes share executables).
MAX_BATCH = 64
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
    base.check_installed(_DIST, _HINT, version_of=installed_version)
    for mod in ("jax", "jaxlib"):
        if importlib.util.find_spec(mod) is None:
            raise ImportError(f"{_DIST} {installed_version(_DIST)} is installed but cannot be imported: "
                              f"{mod} is missing ({_HINT})")
    if importlib.util.find_spec("mujoco.mjx") is None:
        raise ImportError(f"{_DIST} {installed_version(_DIST)} is installed but mujoco.mjx cannot be found")


def version() -> str:
    """MJX's version and the JAX release it runs on, e.g. ``3.17.0 (jax 0.10.2)``, from package metadata
    (EngineNotInstalled when mujoco-mjx is absent)."""
    _check_installed()
    return base.release(_DIST, ("jax", "jax"))


@functools.lru_cache(maxsize=1)
def _engine():
    """``(jax, jax.numpy, mujoco.mjx)``, imported on first use (base.start_jax). ImportError (with JAX's or
    MJX's words) when the import fails."""
    _check_installed()
    # mujoco.mjx prints "Failed to import warp: ..." on stdout when the optional Warp backend is absent
    with base.first_import(_DIST, installed_version), contextlib.redirect_stdout(io.StringIO()):
        jax = base.start_jax()
        import jax.numpy as jnp
        from mujoco import mjx
    return jax, jnp, mjx


def _engine_or_error():
    """:func:`_engine`, an import failure as EngineError; EngineError too in a process forked after JAX
    started in its parent."""
    base.refuse_forked_jax("MJX cannot run in a process forked after JAX started in its parent (a running "
                           "JAX backend does not survive fork: its threads are gone and it would hang); run "
                           "the sweep with --jobs 1 from there, or from a process that has not run MJX")
    return base.engine_or_error(_engine)


# --- compile bookkeeping ----------------------------------------------------------------------------------

_COMPILED: dict = {}   # key -> compiled executable
_STATS = base.Stats(compilations=0, compile_seconds=0.0, step_seconds=0.0, body_steps=0)


def compile_stats() -> dict:
    """This process's compilations so far: ``compilations`` (count), ``compile_seconds`` (lowering + XLA
    compile, wall s), and the stepping apart from it: ``step_seconds`` (wall s inside compiled loops) and
    ``body_steps`` (steps × bodies they advanced)."""
    return dict(_STATS)


def reset_compiled() -> None:
    """Forget the compiled executables and zero :func:`compile_stats` (the next run compiles again; JAX's
    persistent cache may make that faster)."""
    _COMPILED.clear()
    _STATS.reset()


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


# --- the host side of the force callback -------------------------------------------------------------------

_HOST: dict = {}   # callback id -> base.minus_weight's y -> 6 floats: set for the duration of a run


def _host_forces(qpos, qvel, ids):
    """xfrc_applied rows (..., 6) for the states ``qpos`` (..., 7), ``qvel`` (..., 6) of the runs ``ids``:
    each run's harness force (minus its weight) and torque, from the package's force model."""
    from cross_checks.engines.mujoco_engine import to_packed
    qpos, qvel, ids = np.asarray(qpos), np.asarray(qvel), np.asarray(ids)
    shape = ids.shape
    with np.errstate(all="ignore"):
        y = to_packed(qpos.reshape(-1, 7), qvel.reshape(-1, 6))
    out = np.empty((len(y), 6))
    for k, (row, i) in enumerate(zip(y.tolist(), ids.reshape(-1).tolist())):
        out[k] = _HOST[i](row)
    return out.reshape(*shape, 6)


# --- the compiled functions ---------------------------------------------------------------------------------

def _chunk_fn(d0, callback: bool):
    """``run(models, qpos (B, 7), qvel (B, 6), gains (B, 6), xfrc (B, 6), ids (B,), n)`` -> states (B, CHUNK,
    13) ``[qpos, qvel]`` after each of the first ``n`` steps (the rest zeros): the chunk of a free run,
    vmapped over B runs. ``gains``: the pre-step decay factors on qvel; ``xfrc``: the constant applied
    row, or with ``callback`` the host force model's at every step."""
    jax, jnp, mjx = _engine()
    f64 = jax.ShapeDtypeStruct((6,), jnp.float64)

    def member(m, qpos, qvel, gain, xfrc, cb_id, n):
        d = d0.replace(qpos=qpos, qvel=qvel)

        def body(i, carry):
            d, out = carry
            if callback:
                f = jax.pure_callback(_host_forces, f64, d.qpos, d.qvel, cb_id, vmap_method="broadcast_all")
            else:
                f = xfrc
            d = d.replace(qvel=d.qvel * gain, xfrc_applied=d.xfrc_applied.at[_BODY].set(f))
            d = mjx.step(m, d)
            return d, out.at[i].set(jnp.concatenate([d.qpos, d.qvel]))

        _, out = jax.lax.fori_loop(0, n, body, (d, jnp.zeros((CHUNK, 13))))
        return out

    def run(models, qpos, qvel, gains, xfrc, ids, n):
        return jax.vmap(member, in_axes=(0, 0, 0, 0, 0, 0, None))(models, qpos, qvel, gains, xfrc, ids, n)
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


# --- adapter entry points ---------------------------------------------------------------------------------

def simulate(scenario, variant: str, dt_s: float, n_steps: int) -> Run:
    """Free run of ``n_steps`` steps of ``dt_s`` from the scenario's initial state, every step recorded (one
    request of :func:`simulate_many`)."""
    return base.one_request(simulate_many, scenario, variant, dt_s, n_steps)


def simulate_many(variant: str, requests) -> list:
    """The runs of ``requests`` (``base.RunRequest``), each a Run (or its EngineError): grouped by model
    structure and force callback, each group vmapped through the compiled chunk loop in batches of at most
    MAX_BATCH runs."""
    base.check_variant(ENGINE, VARIANTS, variant)
    out: list = [None] * len(requests)
    try:
        _engine_or_error()
    except EngineError as exc:
        return [exc] * len(requests)
    groups: dict = {}
    with _LOCK:
        for j, r in enumerate(requests):
            try:
                key, xm = device_model(r.scenario, variant, r.dt_s)
            except EngineError as exc:
                out[j] = exc
                continue
            callback = bool(r.scenario.problem.forces.state_dependent)
            groups.setdefault((key, callback), []).append((j, xm))
        for (key, callback), members in groups.items():
            for start in range(0, len(members), MAX_BATCH):
                batch = members[start:start + MAX_BATCH]
                runs = _run_batch(key, callback, [requests[j] for j, _ in batch], [xm for _, xm in batch])
                for (j, _), run in zip(batch, runs):
                    out[j] = run
    return out


def _run_batch(key, callback: bool, reqs, models) -> list:
    """The Runs of ``reqs`` (one structure; ``models`` their MJX models), vmapped chunk by chunk."""
    from cross_checks.engines.mujoco_engine import to_packed, to_qpos_qvel
    jax, jnp, _ = _engine()
    B, M = len(reqs), base.power_of_two(len(reqs))
    pad = list(range(B)) + [0] * (M - B)
    y0 = np.array([r.scenario.problem.initial_packed() for r in reqs])
    qpos0, qvel0 = to_qpos_qvel(y0)
    gains = np.empty((B, 6))
    xfrc = np.zeros((B, 6))
    ids = np.arange(B)
    for k, r in enumerate(reqs):
        gv, gw = (float(g) for g in base.decay_factors(r.scenario, r.dt_s))
        gains[k] = (gv, gv, gv, gw, gw, gw)
        if callback:
            _HOST[k] = base.minus_weight(harness_fn(r.scenario, r.dt_s), base.weight_W(r.scenario))
        else:
            f, tau = base.harness_force_torque(r.scenario, y0[k], r.dt_s)
            xfrc[k] = np.r_[f - base.weight_W(r.scenario), tau]
    stacked = _stack([models[k] for k in pad])
    n_max = max(r.n_steps for r in reqs)
    states = np.empty((B, n_max + 1, 13))
    states[:, 0, 0:7], states[:, 0, 7:13] = qpos0, qvel0
    qpos, qvel = jnp.asarray(qpos0[pad]), jnp.asarray(qvel0[pad])
    args = (stacked, qpos, qvel, jnp.asarray(gains[pad]), jnp.asarray(xfrc[pad]), jnp.asarray(ids[pad]),
            jnp.asarray(0, dtype=jnp.int32))
    exe = _executable(("chunk", key, callback, M), _chunk_fn(_data0(key), callback), *args)
    done = np.zeros(B, dtype=bool)   # diverged (the rest of its run is not needed)
    try:
        for s in range(0, n_max, CHUNK):
            n = min(CHUNK, n_max - s)
            with _STATS.timing("step_seconds"):
                chunk = np.asarray(exe(stacked, qpos, qvel, *args[3:6], jnp.asarray(n, dtype=jnp.int32)))
            _STATS["body_steps"] += n * M
            states[:, s + 1:s + n + 1] = chunk[:B, :n]
            with np.errstate(all="ignore"):
                done |= ~np.all(np.isfinite(chunk[:B, n - 1]), axis=-1)
            if done.all():
                break
            qpos, qvel = jnp.asarray(chunk[:, n - 1, 0:7]), jnp.asarray(chunk[:, n - 1, 7:13])
    finally:
        if callback:
            _HOST.clear()
    runs = []
    with np.errstate(all="ignore"):
        for k, r in enumerate(reqs):
            s = states[k, :r.n_steps + 1]
            y = to_packed(s[:, 0:7], s[:, 7:13])
            runs.append(recorded_run(y, r.dt_s))
    return runs


@base.on_rows
def one_step(scenario, variant: str, dt_s: float, y_start) -> np.ndarray:
    """One step of ``dt_s`` from each row of ``y_start`` (T, 13), all rows vmapped (ONE_STEP_BATCH per call):
    the forces from the row (host), the pre-step decay. Rows the engine blows up come back as MJX left
    them."""
    from cross_checks.engines.mujoco_engine import to_packed, to_qpos_qvel
    base.check_variant(ENGINE, VARIANTS, variant)
    jax, _, _ = _engine_or_error()
    T = len(y_start)
    with _LOCK:
        key, xm = device_model(scenario, variant, dt_s)
        host_model = jax.tree.map(np.asarray, xm)   # one argument signature, whichever way the model was made
        wrench = base.minus_weight(harness_fn(scenario, dt_s), base.weight_W(scenario))
        xfrc = np.empty((T, 6))
        for i, row in enumerate(y_start.tolist()):
            xfrc[i] = wrench(row)
        with np.errstate(all="ignore"):
            qpos_in, qvel_in = to_qpos_qvel(base.apply_decay_prestep(scenario, y_start, dt_s))
        out = np.empty((T, 13))
        fn = None
        for s in range(0, T, ONE_STEP_BATCH):
            rows = np.arange(s, min(s + ONE_STEP_BATCH, T))
            take = np.r_[rows, np.full(ONE_STEP_BATCH - len(rows), rows[0])]
            args = (host_model, qpos_in[take], qvel_in[take], xfrc[take])
            if fn is None:
                fn = _executable(("one_step", key, ONE_STEP_BATCH), _one_step_fn(_data0(key)), *args)
            with _STATS.timing("step_seconds"):
                out[rows] = np.asarray(fn(*args))[:len(rows)]
            _STATS["body_steps"] += ONE_STEP_BATCH
    with np.errstate(all="ignore"):
        return to_packed(out[:, 0:7], out[:, 7:13])


class MjxAdapter(ModuleAdapter):
    """``mjx:VARIANT`` — registered under the entry-point group ``rbcheck.engines``; optional
    (``pip install 'rbcheck[mjx]'``)."""

    harness = ("cross_checks.engines.step_floats", "cross_checks.engines.mujoco_engine")

    def engine_files(self) -> list:
        """MJX's Python sources (found without importing them: the parent of a sweep must not start JAX)."""
        return base.package_files("mujoco.mjx", "_src")
