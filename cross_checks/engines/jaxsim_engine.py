"""jaxsim (JAX) as an engine (``jaxsim:VARIANT``): a :class:`JaxsimWorld` whose compiled rollout takes every
force, the link force [f_W (N) at the COM less jaxsim's weight, τ_W (N m)] of the start-of-step state held
over RK4's stages. jaxsim, its defaults neutralised and its compile time: docs/engine_conventions.md, "jaxsim
0.9"; the model, the state (Mixed velocities: the packed state's quantities) and the step: worlds/jaxsim.py.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import time

import numpy as np
from scipy.linalg import block_diag

from cross_checks.core import tolerances as tol
from cross_checks.engines import base, forces, install, jax_forces, runtimes
from cross_checks.engines.base import EngineError, Variant
from cross_checks.engines.world import HostRowsWorld, body_spec  # the full tensor (the SDF's <inertia>)
from reference_sim.quaternion import matrix_from_quat, quat_conj, quat_mul

__all__ = ["ENGINE", "VARIANTS", "ROW_BLOCK", "EngineError", "version", "simulate", "simulate_many",
           "one_step", "timings", "build_model", "engine_gravity", "jaxsim_frame", "turned", "repro_refuses",
           "body_spec", "start_for_repro", "JaxsimWorld", "JaxsimEngine", "JaxsimAdapter"]

ENGINE = "jaxsim"
#: Schemes read in jaxsim/api/integrators.py (``semi_implicit_euler_integration``, ``rk4_integration``).
VARIANTS = {
    "semi_implicit_euler": Variant(
        1,
        "jaxsim SemiImplicitEuler: symplectic Euler in the inertial representation, "
        "explicit gyroscopic term, q += Δt q̇ then normalised",
        traits=base.SYMPLECTIC_EULER_EXPLICIT_GYRO,
    ),
    "rk4": Variant(
        4,
        "jaxsim RungeKutta4: classical 4th-order Runge-Kutta; the applied force and torque held over "
        "the step (first order where they change within it)",
        traits=dataclasses.replace(base.HIGHER_ORDER, forces_held=True),
    ),
}
#: The one-step mode pads its rows to a multiple of this (one compiled shape for the sweep's 64 samples).
ROW_BLOCK = 64

#: callback key -> (world, y -> link force (6 floats)) of a rollout whose forces are called back from it
_CONTEXTS = runtimes.Registry()


class JaxsimEngine(runtimes.JaxEngine):
    """``jaxsim:VARIANT`` (entry point ``rbcheck.engines``; optional: ``pip install 'rbcheck[jaxsim]'``)."""

    name, variants, distribution, module, extra = ENGINE, VARIANTS, "jaxsim", "jaxsim", "jaxsim"
    #: the latter: the SDF, the INTEGRATORS, the step and CHUNK (a compiled call's steps); what repro embeds
    imports = ("jaxsim.api", "cross_checks.engines.worlds.jaxsim")

    def build(self, requests, variant, dt_s):
        return JaxsimWorld(requests, variant, dt_s)

    def group_key(self, request) -> tuple:   # the bodies run one after the other: any runs share a world
        return (float(request.dt_s),)

    def engine_files(self) -> list:
        """jaxsim's Python files (found without importing it: a changed jaxsim is a new engine)."""
        return install.package_files("jaxsim", pattern="**/*.py")


def jaxsim_frame(scenario):
    """The unit quaternion r (w, x, y, z) of jaxsim's frame: jaxsim's vectors are the scenario's world vectors
    turned by R(r), the shortest rotation that puts the scenario's gravity on the z axis (onto −z, or onto +z
    when it points up more than down); None when the gravity is zero or already along z (no turn: the
    scenario's frame itself, bit for bit)."""
    g = np.asarray(scenario.problem.forces.gravity_W, dtype=float)
    if g[0] == 0.0 and g[1] == 0.0:
        return None
    a = g / np.linalg.norm(g)
    b = np.array([0.0, 0.0, -1.0 if a[2] <= 0.0 else 1.0])
    r = np.concatenate([[1.0 + float(a @ b)], np.cross(a, b)])   # 1 + a·b ≥ 1: well conditioned
    return r / np.linalg.norm(r)


def engine_gravity(scenario) -> float:
    """The scalar gravity (m/s², along −z of jaxsim's frame, :func:`jaxsim_frame`) given to jaxsim: g for a
    scenario gravity (0, 0, −g); for any other direction its length along the z axis it is turned onto."""
    g = np.asarray(scenario.problem.forces.gravity_W, dtype=float)
    if jaxsim_frame(scenario) is None:
        return float(-g[2])
    return float(np.linalg.norm(g)) * (1.0 if g[2] <= 0.0 else -1.0)


def repro_refuses(scenario) -> str:
    """Why a reproducer (cross_checks.sweep.repro) cannot state ``scenario`` for jaxsim, "" when it can: a
    gravity off the z axis, which this adapter runs in a turned frame and worlds/jaxsim.py does not."""
    if jaxsim_frame(scenario) is None:
        return ""
    return ("its gravity is off the z axis: jaxsim takes gravity along z only, and rbcheck's adapter runs "
            "such a scenario in a frame turned onto it, which a reproducer does not write yet")


def turned(r, y, back: bool = False):
    """Packed states ``y`` (..., 13) of the scenario's frame in jaxsim's frame ``r`` (:func:`jaxsim_frame`):
    x, v, ω turned by R(r), q_WB → r ⊗ q_WB; ``back``: the inverse, from jaxsim's frame."""
    r = quat_conj(np.asarray(r, dtype=float)) if back else np.asarray(r, dtype=float)
    R = matrix_from_quat(r)
    y = np.array(y, dtype=float)
    for block in (slice(0, 3), slice(3, 6), slice(10, 13)):
        y[..., block] = y[..., block] @ R.T
    y[..., 6:10] = quat_mul(r, y[..., 6:10])
    return y


def build_model(scenario, variant: str):
    """The scenario's jaxsim model for ``variant`` (EngineError with jaxsim's words when it refuses it)."""
    base.check_variant(ENGINE, VARIANTS, variant)
    mass, inertia, _ = body_spec(scenario.problem.body)
    return _model(mass, tuple(inertia.reshape(-1).tolist()), engine_gravity(scenario), variant)


@functools.lru_cache(maxsize=64)
def _model(mass_kg: float, inertia: tuple, gravity: float, variant: str):
    jax, jnp, js, jsw = _ENGINE.modules()
    try:
        model = jsw.build_model(mass_kg, np.reshape(inertia, (3, 3)), gravity, variant)
    except Exception as exc:  # noqa: BLE001 - jaxsim's parser and builder raise many types
        raise EngineError(f"jaxsim refused the model: {type(exc).__name__}: {exc}") from None
    if not model.floating_base() or model.number_of_links() != 1 or model.dofs() != 0:
        raise EngineError("jaxsim did not build one free link from the SDF "
                          f"(floating base {model.floating_base()}, {model.number_of_links()} links)")
    if len(model.kin_dyn_parameters.contact_parameters.body):
        raise EngineError("jaxsim gave the link collidable points; rbcheck's free body must have none")
    M = np.asarray(js.model.link_spatial_inertia_matrices(model))[0]
    want = block_diag(mass_kg * np.eye(3), np.reshape(inertia, (3, 3)))
    if not np.all(np.abs(M - want) <= tol.ENGINE_MODEL_PARAMETER_REL * np.max(np.abs(want))):
        raise EngineError("jaxsim's spatial inertia of the link is not the scenario's mass and inertia "
                          f"tensor about the link origin: {M.tolist()}")
    return jsw.compact(model)   # without its SDF text: one compilation for every scenario


def _host_forces(key, y):
    """The link forces (..., 6) [f_W − m g_jaxsim, τ_W] of the states ``y`` (..., 13) of the rollout ``key``:
    the loop's harness in plain floats (the jax.pure_callback target), its seconds the world's ``host_s``."""
    t0 = time.perf_counter()
    y = np.asarray(y, dtype=np.float64)
    held = [_CONTEXTS[k] for k in np.broadcast_to(np.asarray(key), y.shape[:-1]).reshape(-1).tolist()]
    out = np.array([wrench(row) for (_, wrench), row in zip(held, y.reshape(-1, 13).tolist())], dtype=float)
    held[0][0].host_s += time.perf_counter() - t0
    return out.reshape(y.shape[:-1] + (6,))


def _step_fn(mode: str):
    """``(model, y, f6, scale, key, fa, z) -> y``: one step of the packed state ``y`` (13,) (worlds/jaxsim.py
    ``step``) after the decay ``scale`` (13,), the link force the constant ``f6`` (6,) ("const"), the
    harness's at ``y`` evaluated in the loop (jax_forces of the body's arrays ``fa``, ``z`` its traced zero:
    "state"), or called back from the host ("callback": a gravity off the z axis, whose forces NumPy turns
    with matrix products the compiled loop does not reproduce bit for bit)."""
    jax, jnp, js, jsw = _ENGINE.modules()

    def step(model, y, f6, scale, key, fa, z):
        if mode == "state":
            f6 = jax_forces.wrench_apart(fa, y[0:3], y[3:6], y[6:10], z)
        elif mode == "callback":
            f6 = jax.pure_callback(
                _host_forces, jax.ShapeDtypeStruct((6,), jnp.float64), key, y, vmap_method="broadcast_all"
            )
        return jsw.step(model, y, f6, scale)

    return step


def _compiled(kind: str, mode: str, model, static: tuple, *args):
    """The compiled ``run(models, dt (s), y0 (B, 13), count, f6 (B, 6), scale (B, 13), key (B,), fa, z)`` ->
    (last states, rows (B, static[0], 13)): ``count`` steps of :func:`_step_fn` of B bodies vmapped (each its
    own model; ``static[2]``: one body unbatched, worlds/jaxsim.py ``run_fn``'s loop); or ``one(model, dt,
    ys, ...)``: one step of each row of ``ys``. Keyed by ``static`` and the model's gravity and integrator."""
    jax = _ENGINE.modules()[0]

    def make():
        step = _step_fn(mode)

        def run(model, dt, y0, count, f6, scale, key, fa, z):
            model = dataclasses.replace(model, time_step=dt)
            loop = runtimes.recorded(lambda y: step(model, y, f6, scale, key, fa, z), lambda y: y, static[0])
            return loop(y0, count)

        def one(model, dt, ys, f6, scale, key, fa, z):
            model = dataclasses.replace(model, time_step=dt)
            return jax.vmap(lambda y, a: step(model, y, f6, scale, key, a, z))(ys, fa)
        if kind == "one":
            return one
        return run if static[2] else jax.vmap(run, in_axes=(0, None, 0, None, 0, 0, 0, 0, None))
    key = (kind, mode, model.integrator, model.gravity, static)
    return _ENGINE.compiled(key, make, model, *args, name=f"{kind}:{mode}:{model.integrator}")


def _weight(scenario) -> tuple:
    """The weight jaxsim applies itself (N, the scenario's world axes): m g, the whole gravity (turned into
    jaxsim's frame, :func:`jaxsim_frame`, where it is off the z axis)."""
    if jaxsim_frame(scenario) is None:
        return (0.0, 0.0, -float(scenario.problem.body.mass_kg) * engine_gravity(scenario))
    return tuple(float(scenario.problem.body.mass_kg) * np.asarray(scenario.problem.forces.gravity_W, float))


def _inputs(scenario, harness, i: int):
    """(mode (:func:`_step_fn`), constant link force (6,), decay scale (13,), ``y -> link force`` (6 floats))
    of body ``i`` of the loop's ``harness``, jaxsim's own weight off, for states ``y`` of jaxsim's frame."""
    ft, gv, gw = harness.ft[i], float(harness.g_v[i]), float(harness.g_w[i])

    def decayed(y):   # forces.harness_force_torque_floats, with the loop's evaluator
        fx, fy, fz, tx, ty, tz = ft(y)
        return gv * fx, gv * fy, gv * fz, gw * tx, gw * ty, gw * tz
    wrench = forces.minus_weight(decayed, _weight(scenario))
    r = jaxsim_frame(scenario)
    if r is not None:   # at the state turned back, the force and torque turned in
        R, in_world = matrix_from_quat(np.asarray(r, dtype=float)), wrench

        def wrench(y):
            f = np.asarray(in_world([float(v) for v in turned(r, y, back=True)]), dtype=float)
            return tuple(float(v) for v in np.concatenate([R @ f[:3], R @ f[3:]]))
    scale = np.r_[np.ones(3), np.full(3, gv), np.ones(4), np.full(3, gw)]
    y0 = scenario.problem.initial_packed()
    if scenario.problem.forces.state_dependent:
        return ("callback" if r is not None else "state"), np.zeros(6), scale, wrench
    return "const", np.array(wrench([float(v) for v in (y0 if r is None else turned(r, y0))])), scale, wrench


class JaxsimWorld(runtimes.JaxWorld, HostRowsWorld):
    """B bodies, each its own jaxsim model in its scenario's jaxsim frame; raw rows packed states of those
    frames. Its rollout takes every force and the decay (:func:`_inputs`): the bodies vmapped in compiled
    chunks (a batch per model structure and kind of forces), one body alone unvmapped (the reproducer's loop:
    XLA rounds a vmapped batch ~1e-14 relative differently); the one-step mode in one vmapped call."""

    engine = JaxsimEngine

    def __init__(self, requests, variant: str, dt_s: float):
        super().__init__(requests)
        _ENGINE.usable()
        self.scenarios = [r.scenario for r in requests]
        self.models = [build_model(sc, variant) for sc in self.scenarios]
        self.frames = [jaxsim_frame(sc) for sc in self.scenarios]
        self.turned = any(r is not None for r in self.frames)
        #: a turned body's state read back is its requested one to round-off only: the loop records the latter
        self.exact_start = self.turned
        self.dt = np.float64(dt_s)

    def _turned(self, y, back: bool) -> np.ndarray:
        """Rows (..., B, 13) of each body's scenario frame in its jaxsim frame (``back``: the inverse)."""
        y = np.array(y, dtype=float)
        for i, r in enumerate(self.frames):
            if r is not None:
                y[..., i, :] = turned(r, y[..., i, :], back)
        return y

    def set_state(self, y):
        self.y = self._turned(y, back=False)

    def packed(self, raw) -> np.ndarray:
        return self._turned(raw, back=True) if self.turned else np.asarray(raw, dtype=float)

    def run(self, n_steps, harness):
        inputs = [_inputs(sc, harness, i) for i, sc in enumerate(self.scenarios)]
        fa = jax_forces.BodyForces(harness)
        fa.arrays["weight"] = np.array([_weight(sc) for sc in self.scenarios], dtype=float)
        if n_steps == 1 and all(sc is self.scenarios[0] for sc in self.scenarios):
            return self._one(inputs, fa)[None]
        out = np.full((n_steps, len(self.y), 13), np.nan)
        groups: dict = {}
        for i, (mode, *_rest) in enumerate(inputs):
            groups.setdefault((mode, self.models[i].integrator, self.models[i].gravity), []).append(i)
        for (mode, *_), idx in groups.items():
            for s in range(0, len(idx), self.engine.max_batch):
                self._run(idx[s:s + self.engine.max_batch], mode, n_steps, inputs, fa, out)
        return out

    def _run(self, idx, mode: str, n_max: int, inputs, fa, out) -> None:
        """The bodies ``idx`` (of one model structure and force mode) vmapped, padded to a power of two."""
        M = runtimes.power_of_two(len(idx))
        pad = list(idx) + [idx[0]] * (M - len(idx))
        trees = {id(self.models[i]): self.models[i] for i in idx}   # each distinct model's leaves read once
        at = {key: k for k, key in enumerate(trees)}
        models = runtimes.stack_trees(list(trees.values()), [at[id(self.models[i])] for i in pad])
        rows = runtimes.chunk_rows(M, _ENGINE.modules()[3].CHUNK)
        f6 = np.array([inputs[i][1] for i in pad])
        scale = np.array([inputs[i][2] for i in pad])
        y = self.y[pad]
        with contextlib.ExitStack() as stack:
            hold = _CONTEXTS.holding
            keys = np.array([stack.enter_context(hold((self, inputs[i][3]))) if mode == "callback"
                             else np.int64(0) for i in pad], dtype=np.int64)
            args = (self.dt, y, np.int64(0), f6, scale, keys, fa.take(pad), jax_forces.zero())
            if M == 1:   # one body: without the batch axis
                models = self.models[idx[0]]
                args = (self.dt, y[0], np.int64(0), f6[0], scale[0], keys[0], fa.take(pad[0]),
                        jax_forces.zero())
            fn = _compiled("run", mode, models, (rows, fa.key, M == 1), *args)
            state = [args[1]]

            def call(count):
                state[0], chunk = fn(models, self.dt, state[0], np.int64(count), *args[3:])
                return np.asarray(chunk).reshape(M, rows, 13)
            self.chunks(call, n_max, rows, idx, out)

    def _one(self, inputs, fa):
        n, model = len(self.y), self.models[0]
        mode, f6, scale, wrench = inputs[0]
        pad = np.r_[np.arange(n), np.zeros(-n % ROW_BLOCK, dtype=int)]   # rows of the first row after them
        with _CONTEXTS.holding((self, wrench)) as key:
            args = (self.dt, self.y[pad], f6, scale, key, fa.take(pad), jax_forces.zero())
            fn = _compiled("one", mode, model, (fa.key,), *args)
            with _ENGINE.stats.timing("step_seconds"):
                out = np.asarray(fn(model, *args))[:n]
            _ENGINE.stats["body_steps"] += n
        return out


_ENGINE = JaxsimEngine()
#: The module's functions (tests and scripts call them): the engine's, through the host loop.
simulate, simulate_many, one_step = _ENGINE.simulate, _ENGINE.simulate_many, _ENGINE.one_step
version, timings = _ENGINE.version, _ENGINE.timings
start_for_repro = _ENGINE.usable   # JAX started as the adapter starts it, before rbcheck repro runs a script
JaxsimAdapter = JaxsimEngine
