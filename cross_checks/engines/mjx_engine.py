"""MuJoCo XLA (``mujoco-mjx``, MuJoCo's physics in JAX) as an engine (``mjx:VARIANT``): an
:class:`MjxWorld` of the host loop whose compiled rollout takes every force. What MJX does, the defaults
neutralised and what was measured: docs/engine_conventions.md, "MJX 3.17.0".

Model: ``mujoco_engine.build_model``'s, put on the device by ``mjx.put_model``. State (MuJoCo's, converted by
mujoco_engine's ``to_qpos_qvel``/``to_packed``): ``qpos = [x_W, q_WB (w x y z)]``, ``qvel = [v_W (COM, world
axes), ω_B (body axes)]``. Forces: the harness's world force at the COM minus the weight ``m g`` (MJX applies
gravity) and its world torque in the body's row of ``xfrc_applied``, from the start-of-step state, the decay
before the step; RK4 holds them over its stages (MJX has no per-stage hook).
"""
from __future__ import annotations

import dataclasses

import numpy as np

from cross_checks.engines import base, install, jax_forces, runtimes
from cross_checks.engines.base import EngineError, Traits, Variant

__all__ = ["ENGINE", "VARIANTS", "CHUNK", "ONE_STEP_BATCH", "EngineError", "version", "simulate",
           "simulate_many", "one_step", "timings", "device_model", "MjxWorld", "MjxEngine", "MjxAdapter"]

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
_BODY = 1   # body id of the free body (0 is the world)


class MjxEngine(runtimes.JaxEngine):
    """``mjx:VARIANT`` (entry point ``rbcheck.engines``; optional: ``pip install 'rbcheck[mjx]'``)."""

    name, variants, distribution, module, extra = ENGINE, VARIANTS, "mujoco-mjx", "mujoco.mjx", "mjx"
    runs_on, imports = ("jax", "jax"), ("mujoco.mjx",)
    harness = (*runtimes.JaxEngine.harness, "cross_checks.engines.mujoco_engine")

    def build(self, requests, variant, dt_s):
        self.usable()
        return MjxWorld(requests, variant)

    def world_key(self, request, variant):
        """One world per model structure and kind of forces, whatever the steps (each body's model carries
        its Δt); a request whose model is refused in a world of its scenario, whose build then says why."""
        try:
            with self.lock:
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


# --- models: one compiled MuJoCo model per scenario, on the device, stacked per structure -------------------

def _meta_key(obj, prefix="") -> tuple:
    """The static (non-array) fields of an MJX Model, recursively, except the name tables — what decides
    whether two models share one compiled executable (the scenario's name is in the names; Δt, mass and
    inertia are array leaves)."""
    jax = _ENGINE.modules()[0]
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
    _, jnp, mjx = _ENGINE.usable()
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
            xm = xm.replace(**{f.name: getattr(tpl[0], f.name) for f in dataclasses.fields(xm)
                           if f.name.startswith("name") or f.name == "signature"})
    if len(_PUT) >= _PUT_MAX:
        _PUT.pop(next(iter(_PUT)))
    _PUT[(id(scenario), variant)] = (scenario, key, xm)
    return key, xm


def _chunk_fn(d0, forces_in_loop: bool, rows: int):
    """``run(models, qpos (B, 7), qvel (B, 6), gains (B, 6), xfrc (B, 6), fa, zero, n)`` -> states (B,
    rows, 13) ``[qpos, qvel]`` after each of the first ``n`` steps (the rest zeros): the chunk of a free run,
    vmapped over B runs (each its own model: runtimes.stack_trees). ``gains``: the pre-step decay factors on
    qvel; ``xfrc``: the constant applied row, or with ``forces_in_loop`` the harness's at the start of every
    step, evaluated in the loop (jax_forces.wrench of the arrays ``fa``, each body's row; ``zero`` its traced
    integer zero)."""
    jax, jnp, mjx = _ENGINE.modules()
    from cross_checks.engines.worlds.mjx import step_one  # the step rbcheck repro embeds

    def member(m, qpos, qvel, gain, xfrc, fa, z, n):
        def step(d):   # the forces at the start-of-step state, before the decay (as the loop's harness)
            if not forces_in_loop:
                return step_one(m, d, gain, xfrc)
            return step_one(m, d, gain, jax_forces.wrench_apart(fa, d.qpos[0:3], d.qvel[0:3], d.qpos[3:7], z))

        def read(d):
            return jnp.concatenate([d.qpos, d.qvel])
        return runtimes.recorded(step, read, rows)(d0.replace(qpos=qpos, qvel=qvel), n)[1]

    def run(models, qpos, qvel, gains, xfrc, fa, z, n):
        vmapped = jax.vmap(member, in_axes=(0, 0, 0, 0, 0, 0, None, None))
        return vmapped(models, qpos, qvel, gains, xfrc, fa, z, n)
    return run


def _one_step_fn(d0):
    """``step(model, qpos (R, 7), qvel (R, 6), xfrc (R, 6))`` -> (R, 13) ``[qpos, qvel]`` one step later."""
    jax, jnp, mjx = _ENGINE.modules()

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
    _, _, mjx = _ENGINE.modules()
    m = _TEMPLATES[key][1]
    return mjx.put_data(m, mujoco.MjData(m))


# --- the world ----------------------------------------------------------------------------------------------

class MjxWorld(runtimes.JaxWorld):
    """B free bodies of one model structure (:func:`device_model`, each at its request's Δt). Raw rows:
    ``[qpos (7), qvel (6)]`` per body, ω in BODY axes. Its rollout vmaps the bodies through the compiled
    chunk loop in batches of at most ``max_batch``, padded to a power of two, taking every force itself
    (constant: the applied rows; state-dependent: evaluated inside the compiled loop by jax_forces; the decay
    as gains on qvel before each step); :meth:`step` (the one-step mode) vmaps the bodies of one model
    through the one-step executable, ONE_STEP_BATCH at a time."""

    engine = MjxEngine
    rollout_forces = True

    def __init__(self, requests, variant: str):
        super().__init__()
        with _ENGINE.lock:
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
        jax, _, _ = _ENGINE.usable()
        out = np.empty((self.B, 13))
        same = np.asarray(self.same)
        with _ENGINE.lock:
            for model in dict.fromkeys(self.same):
                idx = np.flatnonzero(same == model)
                host_model = jax.tree.map(np.asarray, self.models[model])
                for s in range(0, len(idx), ONE_STEP_BATCH):
                    rows = idx[s:s + ONE_STEP_BATCH]
                    take = np.r_[rows, np.full(ONE_STEP_BATCH - len(rows), rows[0])]
                    args = (host_model, self.qpos[take], self.qvel[take], self.xfrc[take])
                    fn = _ENGINE.compiled(("one_step", self.key, ONE_STEP_BATCH),
                                          lambda: _one_step_fn(_data0(self.key)), *args,
                                          name=f"one_step:{self.key[0]}:{ONE_STEP_BATCH}")
                    with _ENGINE.stats.timing("step_seconds"):
                        out[rows] = np.asarray(fn(*args))[:len(rows)]
                    _ENGINE.stats["body_steps"] += len(rows)
        self.qpos, self.qvel = out[:, 0:7], out[:, 7:13]

    def run(self, n_steps, harness):
        """``n_steps`` steps of every body in the compiled chunk loop, batch by batch; a batch whose bodies
        all ended (non-finite, or at their run's last step) stops there (its later rows NaN)."""
        _ENGINE.usable()
        gains = np.concatenate([np.repeat(harness.g_v[:, None], 3, 1), np.repeat(harness.g_w[:, None], 3, 1)],
                               axis=1)
        out = np.full((n_steps, self.B, 13), np.nan)
        fa = jax_forces.BodyForces(harness) if self.state_dependent else None
        with _ENGINE.lock:
            for s in range(0, self.B, self.engine.max_batch):
                self._batch(list(range(s, min(s + self.engine.max_batch, self.B))), n_steps, gains, fa, out)
        return out

    def _batch(self, idx, n_max, gains, fa, out):
        _, jnp, _ = _ENGINE.modules()
        B, M = len(idx), runtimes.power_of_two(len(idx))
        pad = idx + [idx[0]] * (M - B)
        models = runtimes.stack_trees(self.models, [self.same[k] for k in pad])
        rows = runtimes.chunk_rows(M, CHUNK)
        fargs = {} if fa is None else fa.take(pad)
        args = (models, jnp.asarray(self.qpos[pad]), jnp.asarray(self.qvel[pad]), jnp.asarray(gains[pad]),
                jnp.asarray(self.xfrc[pad]), fargs, jax_forces.zero(), jnp.asarray(0, dtype=jnp.int32))
        exe = _ENGINE.compiled(("chunk", self.key, fa is not None and fa.key, M, rows),
                               lambda: _chunk_fn(_data0(self.key), fa is not None, rows), *args,
                               name=f"chunk:{self.key[0]}:{M}")
        state = list(args[1:3])   # qpos, qvel: each chunk continues from the last one's last state

        def call(n):
            chunk = np.asarray(exe(models, *state, *args[3:7], jnp.asarray(n, dtype=jnp.int32)))
            state[:] = jnp.asarray(chunk[:, n - 1, 0:7]), jnp.asarray(chunk[:, n - 1, 7:13])
            return chunk
        self.chunks(call, n_max, rows, idx, out, finite_only=True)


_ENGINE = MjxEngine()
#: The module's functions (tests and scripts call them): the engine's, through the host loop.
simulate, simulate_many, one_step = _ENGINE.simulate, _ENGINE.simulate_many, _ENGINE.one_step
version, timings = _ENGINE.version, _ENGINE.timings
MjxAdapter = MjxEngine
