"""jaxsim (JAX) as an engine (``jaxsim:VARIANT``): a :class:`JaxsimWorld` stepped by the host loop
(cross_checks.engines.loop) through its compiled rollout. What jaxsim does, the defaults neutralised and what
was measured: docs/engine_conventions.md, "jaxsim 0.9".

Model: one ``JaxSimModel`` per body built from an SDF string (:func:`model_sdf`: one link, its inertial at the
link origin = COM, no collision, no joint: a floating base), its spatial inertia checked against the
scenario's. Precision: float64 (JAX started by runtimes.start_jax; importing jaxsim also turns
``jax_enable_x64`` on).

State at the boundary, in the Mixed velocity representation: ``base_position`` = x_W (m), ``base_quaternion``
= q_WB (w, x, y, z), ``base_velocity`` = [v_W (m/s, COM, world axes), ω_W (rad/s, world axes)] — the packed
state's own quantities. Every step starts from the packed state (``JaxSimModelData.build``).

Forces: ``link_forces`` = [f_W (N) at the COM minus the weight jaxsim applies, τ_W (N m)], the loop's harness
from the start-of-step state (state-dependent ones on the host through ``jax.pure_callback``); RK4 holds them
over its stages. Gravity (0, 0, −g) is jaxsim's scalar g; any other direction goes into the link force
(:func:`engine_gravity`). The decay is applied to v and ω before each step, inside the compiled step.

The world's rollout (it takes every force: ``World.rollout_takes_all_forces``) runs its bodies one after the
other through compiled ``lax.fori_loop`` chunks of CHUNK steps; the one-step mode vmaps its rows (padded to a
multiple of ROW_BLOCK). JAX is imported on first use only (never at import or in ``version()``): a sweep's
parent must not start it before forking.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import threading
import time
from pathlib import Path

import numpy as np

from cross_checks.core import tolerances as tol
from cross_checks.core.files import kernel_cache_dir
from cross_checks.engines import base, forces, install, runtimes
from cross_checks.engines.base import EngineError, Variant
from cross_checks.engines.world import World, WorldEngine
from reference_sim.simulate import bad_rows

__all__ = ["ENGINE", "VARIANTS", "INTEGRATORS", "CHUNK", "ROW_BLOCK", "EngineError", "version", "simulate",
           "simulate_many", "one_step", "build_model", "model_sdf", "engine_gravity", "jaxsim_frame",
           "turn_in", "turn_out", "repro_refuses", "body_spec", "timings", "xla_cache_dir", "JaxsimWorld",
           "JaxsimEngine", "JaxsimAdapter"]

ENGINE = "jaxsim"
HINT = "pip install 'rbcheck[jaxsim]'"
#: variant -> jaxsim's ``IntegratorType`` member.
INTEGRATORS = {"semi_implicit_euler": "SemiImplicitEuler", "rk4": "RungeKutta4"}
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

#: Steps of one compiled run call (``lax.fori_loop`` with a traced count: a shorter last call costs no more).
CHUNK = 1024
#: one_step pads its rows to a multiple of this (one compiled shape for the sweep's 64 local samples).
ROW_BLOCK = 64
#: Bodies per vmapped batch of a rollout at most (padded to a power of two, so that batch sizes share
#: executables): a thousand bodies in one call, as an engine's own vmapped loop runs them.
MAX_BATCH = 1024
MODEL_NAME = "rbcheck_body"

_LOCK = threading.RLock()
_TIMES = runtimes.Stats(compile_seconds=0.0, compiles=0, run_seconds=0.0, steps=0)
_CONTEXTS = runtimes.Registry()  # callback key -> (world, y -> link force (6 floats)) of one body's rollout


# --- availability without importing JAX (fork safety) --------------------------------------------------


def version() -> str:
    """The installed jaxsim distribution's version, from its metadata and import spec: nothing imported.
    EngineNotInstalled when it is absent; ImportError when it is installed but not importable."""
    import importlib.util

    ver = install.installed_version("jaxsim")
    if ver is None:
        raise install.EngineNotInstalled(f"jaxsim is not installed ({HINT})")
    try:
        spec = importlib.util.find_spec("jaxsim")
    except (ImportError, ValueError) as exc:
        spec, why = None, f"{type(exc).__name__}: {exc}"
    else:
        why = "no module named 'jaxsim' on sys.path"
    if spec is None:
        raise ImportError(f"jaxsim {ver} is installed but cannot be imported: {why}")
    return ver


def xla_cache_dir() -> Path:
    """Where the XLA persistent compilation cache of this adapter lives: core.files.kernel_cache_dir("jax")
    (shared with the other JAX engines: JAX keys its entries by the computation and the jaxlib)."""
    return kernel_cache_dir("jax")


@functools.lru_cache(maxsize=1)
def _jax():
    """(jax, jax.numpy, jaxsim.api): imported on first use (runtimes.start_jax: float64 on before jaxsim's
    import, checked after)."""
    jax, err = install.optional_import("jax")
    install.require(jax, err, "jax", hint=HINT)
    runtimes.start_jax()
    jaxsim, err = install.optional_import("jaxsim")
    install.require(jaxsim, err, "jaxsim", hint=HINT)
    import jax.numpy as jnp
    import jaxsim.api as js

    if not jax.config.jax_enable_x64:
        raise EngineError("jaxsim: jax_enable_x64 is off after importing jaxsim; rbcheck needs float64")
    return jax, jnp, js


def start_for_repro() -> None:
    """JAX started as the adapter starts it (float64, rbcheck's XLA cache) before ``rbcheck repro`` runs a
    reproducer in this process: the script's world imports jaxsim itself."""
    install.engine_or_error(_jax)


def _world():
    """:mod:`cross_checks.engines.worlds.jaxsim` (what ``rbcheck repro`` embeds), imported after :func:`_jax`
    started JAX rbcheck's way."""
    _jax()
    from cross_checks.engines.worlds import jaxsim as jsw
    return jsw


def _refuse_forked_jax() -> None:
    runtimes.refuse_forked_jax(
        "jaxsim cannot run in a process forked after JAX started in its parent (a running JAX backend "
        "does not survive fork: it would hang); run the sweep with --jobs 1 from there, or from a "
        "process that has not run JAX")


def timings() -> dict:
    """This process's jaxsim time: ``compile_seconds`` (tracing + XLA compilation of the run and one-step
    functions, persistent-cache loads included), ``compiles`` (how many), ``run_seconds`` and ``steps`` (the
    compiled runs' execution, force callbacks included; one_step's rows count as steps)."""
    return dict(_TIMES)


# --- the model -----------------------------------------------------------------------------------------


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
    r = jaxsim_frame(scenario)
    if r is None:
        return float(-g[2])
    return float(np.linalg.norm(g)) * (1.0 if g[2] <= 0.0 else -1.0)


def repro_refuses(scenario) -> str:
    """Why a reproducer (cross_checks.sweep.repro) cannot state ``scenario`` for jaxsim, "" when it can: a
    gravity off the z axis, which this adapter runs in a frame turned onto jaxsim's z axis
    (:func:`jaxsim_frame`) and the reproducer's world (worlds/jaxsim.py) does not."""
    if jaxsim_frame(scenario) is None:
        return ""
    return ("its gravity is off the z axis: jaxsim takes gravity along z only, and rbcheck's adapter runs "
            "such a scenario in a frame turned onto it, which a reproducer does not write yet")


def turn_in(r, y):
    """Packed states ``y`` (..., 13) of the scenario's frame in jaxsim's frame ``r`` (:func:`jaxsim_frame`):
    x, v, ω turned by R(r), q_WB → r ⊗ q_WB."""
    return _turned(r, y, inverse=False)


def turn_out(r, y):
    """Packed states ``y`` (..., 13) of jaxsim's frame ``r`` back in the scenario's frame (the inverse of
    :func:`turn_in`)."""
    return _turned(r, y, inverse=True)


def _turned(r, y, inverse: bool):
    from reference_sim.quaternion import matrix_from_quat, quat_conj, quat_mul
    r = np.asarray(r, dtype=float)
    if inverse:
        r = quat_conj(r)
    R = matrix_from_quat(r)
    y = np.array(y, dtype=float)
    for block in (slice(0, 3), slice(3, 6), slice(10, 13)):
        y[..., block] = y[..., block] @ R.T
    y[..., 6:10] = quat_mul(r, y[..., 6:10])
    return y


def model_sdf(mass_kg: float, inertia_B) -> str:
    """SDF 1.7 of one link (:func:`cross_checks.engines.worlds.jaxsim.model_sdf`)."""
    return _world().model_sdf(mass_kg, inertia_B)


def body_spec(body) -> tuple:
    """``(mass_kg, inertia_B (3, 3), None)``: jaxsim takes the full tensor (its SDF's ``<inertia>``)."""
    return float(body.mass_kg), np.asarray(body.inertia_B, dtype=float), None


def build_model(scenario, variant: str):
    """The scenario's jaxsim model for ``variant`` (EngineError with jaxsim's words when it refuses it)."""
    base.check_variant(ENGINE, VARIANTS, variant)
    body = scenario.problem.body
    inertia = np.asarray(body.inertia_B, dtype=float)
    return _model(float(body.mass_kg), tuple(inertia.reshape(-1).tolist()), engine_gravity(scenario), variant)


@functools.lru_cache(maxsize=64)
def _model(mass_kg: float, inertia: tuple, gravity: float, variant: str):
    jax, jnp, js = _jax()
    try:
        model = _world().build_model(mass_kg, np.reshape(inertia, (3, 3)), gravity, variant)
    except Exception as exc:  # noqa: BLE001 - jaxsim's parser and builder raise many types
        raise EngineError(f"jaxsim refused the model: {type(exc).__name__}: {exc}") from None
    if not model.floating_base() or model.number_of_links() != 1 or model.dofs() != 0:
        raise EngineError(
            "jaxsim did not build one free link from the SDF "
            f"(floating base {model.floating_base()}, {model.number_of_links()} links)"
        )
    if len(model.kin_dyn_parameters.contact_parameters.body):
        raise EngineError("jaxsim gave the link collidable points; rbcheck's free body must have none")
    M = np.asarray(js.model.link_spatial_inertia_matrices(model))[0]
    want = np.zeros((6, 6))
    want[:3, :3] = mass_kg * np.eye(3)
    want[3:, 3:] = np.reshape(inertia, (3, 3))
    if not np.all(np.abs(M - want) <= tol.ENGINE_MODEL_PARAMETER_REL * np.max(np.abs(want))):
        raise EngineError(
            f"jaxsim's spatial inertia of the link is not the scenario's mass and inertia tensor "
            f"about the link origin: {M.tolist()}"
        )
    return _world().compact(model)   # without its SDF text: one compilation for every scenario


# --- the compiled functions ----------------------------------------------------------------------------


def _host_forces(key, y):
    """The link forces (..., 6) [f_W − m g_jaxsim, τ_W] of the states ``y`` (..., 13) of the rollout ``key``:
    the loop's harness in plain floats (the jax.pure_callback target), its seconds the world's ``host_s``."""
    t0 = time.perf_counter()
    y = np.asarray(y, dtype=np.float64)
    keys = np.broadcast_to(np.asarray(key), y.shape[:-1]).reshape(-1)
    rows = y.reshape(-1, 13)
    out = np.empty((len(rows), 6))
    world = None
    for i, (k, row) in enumerate(zip(keys.tolist(), rows.tolist())):
        world, wrench = _CONTEXTS[k]
        out[i] = wrench(row)
    if world is not None:
        world.host_s += time.perf_counter() - t0
    return out.reshape(y.shape[:-1] + (6,))


#: The modes of a body's forces in the compiled loop: none but constant ones (``f6`` held), state-dependent
#: ones evaluated in the loop (cross_checks.engines.jax_forces), or called back from the host where the loop
#: cannot evaluate them bit for bit (:data:`HOST_FORCES_REASON`).
MODES = ("const", "state", "callback")
#: Why the forces of a scenario whose gravity is off the z axis are called back from the host at every step
#: rather than evaluated in the compiled loop.
HOST_FORCES_REASON = (
    "its gravity is off the z axis: the adapter runs it in a frame turned onto jaxsim's (jaxsim_frame), and "
    "the harness's forces are evaluated at the state turned back and turned in with NumPy's matrix products, "
    "whose rounding the compiled loop does not reproduce; they are called back from the host at every step")


def _step_fn(mode: str):
    """One jaxsim step of the packed state ``y`` (13,) (:func:`cross_checks.engines.worlds.jaxsim.step`):
    ``(model, y, f6, scale, key, fa, z) -> y``, the pre-step decay ``scale`` (13,), the link force the
    constant ``f6`` (6,) ("const"), the harness's at ``y`` (before the decay, as forces.harness_force_torque)
    evaluated in the loop from the body's arrays ``fa`` ("state": jax_forces.wrench, ``z`` its traced zero),
    or called back from the host ("callback", the rollout ``key``'s)."""
    from cross_checks.engines import jax_forces
    jax, jnp, js = _jax()
    world_step = _world().step

    def step(model, y, f6, scale, key, fa, z):
        if mode == "state":
            f6 = jax_forces.wrench_apart(fa, y[0:3], y[3:6], y[6:10], z)
        elif mode == "callback":
            f6 = jax.pure_callback(
                _host_forces, jax.ShapeDtypeStruct((6,), jnp.float64), key, y, vmap_method="broadcast_all"
            )
        return world_step(model, y, f6, scale)

    return step


def _with_dt(model, dt):
    """``model`` stepping at ``dt`` (s; traced: one compilation for every Δt)."""
    return dataclasses.replace(model, time_step=dt)


def _run_fn(mode: str, rows: int, vmapped: bool = True):
    """``run(models, dt, y0 (B, 13), count, f6 (B, 6), scale (B, 13), key (B,), fa, z)``: ``count`` (≤ rows,
    traced) steps of :func:`_step_fn` of B bodies vmapped (each its own model: runtimes.stack_trees) from
    ``y0`` at ``dt`` (s, traced), in one ``lax.fori_loop``; returns the last states (B, 13) and the recorded
    rows (B, rows, 13) (the first ``count`` are the states after each step). Not ``vmapped``: one body, each
    argument without its batch axis: the loop of worlds/jaxsim.py ``run_fn`` (what a reproducer runs)."""
    jax, jnp, js = _jax()
    step = _step_fn(mode)

    def one(model, dt, y0, count, f6, scale, key, fa, z):
        model = _with_dt(model, dt)

        def body(i, carry):
            y, out = carry
            y = step(model, y, f6, scale, key, fa, z)
            return y, out.at[i].set(y)

        return jax.lax.fori_loop(0, count, body, (y0, jnp.zeros((rows, 13))))

    return jax.vmap(one, in_axes=(0, None, 0, None, 0, 0, 0, 0, None)) if vmapped else one


def _one_fn(mode: str):
    jax, jnp, js = _jax()
    step = _step_fn(mode)

    def one(model, dt, ys, f6, scale, key, fa, z):
        model = _with_dt(model, dt)
        return jax.vmap(lambda y, a: step(model, y, f6, scale, key, a, z))(ys, fa)

    return one


_COMPILED: dict = {}


def _compiled(kind: str, mode: str, model, static: tuple, make, *args):
    """The ahead-of-time compiled ``make()`` for these arguments' shapes, the model's static fields (jaxsim's
    gravity and integrator) and ``static`` (what else decides the computation); compiled once per process,
    the time counted."""
    jax, jnp, js = _jax()
    key = (kind, mode, model.integrator, model.gravity, static,
           tuple(np.shape(a) for a in jax.tree_util.tree_leaves(args)))
    with _LOCK:
        fn = _COMPILED.get(key)
        if fn is None:
            try:
                with _TIMES.timing("compile_seconds"):
                    fn = jax.jit(make()).lower(model, *args).compile()
            except Exception as exc:  # noqa: BLE001 - jaxsim or XLA refusing the computation
                raise EngineError(
                    f"jaxsim/XLA could not compile the step: {type(exc).__name__}: {exc}"
                ) from None
            _TIMES["compiles"] += 1
            _COMPILED[key] = fn
    return fn


def _weight(scenario) -> tuple:
    """The weight jaxsim applies itself (N, the scenario's world axes): m g, the whole gravity (turned into
    jaxsim's frame, :func:`jaxsim_frame`, where it is off the z axis)."""
    if jaxsim_frame(scenario) is None:
        return (0.0, 0.0, -float(scenario.problem.body.mass_kg) * engine_gravity(scenario))
    return tuple(float(scenario.problem.body.mass_kg) * np.asarray(scenario.problem.forces.gravity_W, float))


def _turned_wrench(r, wrench):
    """``y -> link force`` in jaxsim's frame ``r`` of the scenario's ``wrench``: at the state turned back,
    its force and torque turned in."""
    from reference_sim.quaternion import matrix_from_quat
    R = matrix_from_quat(np.asarray(r, dtype=float))

    def turned(y):
        f = np.asarray(wrench([float(v) for v in turn_out(r, y)]), dtype=float)
        return tuple(float(v) for v in np.concatenate([R @ f[:3], R @ f[3:]]))
    return turned


def _inputs(scenario, harness, i: int):
    """(mode (:data:`MODES`), constant link force (6,), pre-step decay scale (13,), ``y -> link force`` (6
    floats)) of body ``i`` of ``harness`` (the loop's: its force evaluator and decay factors; jaxsim's own
    weight off), in jaxsim's frame (:func:`jaxsim_frame`): the link force of a state ``y`` of that frame."""
    ft, gv, gw = harness.ft[i], float(harness.g_v[i]), float(harness.g_w[i])

    def decayed(y):   # forces.harness_force_torque_floats, with the loop's evaluator
        fx, fy, fz, tx, ty, tz = ft(y)
        return gv * fx, gv * fy, gv * fz, gw * tx, gw * ty, gw * tz
    wrench = forces.minus_weight(decayed, _weight(scenario))
    r = jaxsim_frame(scenario)
    if r is not None:
        wrench = _turned_wrench(r, wrench)
    scale = np.ones(13)
    scale[3:6] = gv
    scale[10:13] = gw
    y0 = scenario.problem.initial_packed()
    if scenario.problem.forces.state_dependent:
        return ("callback" if r is not None else "state"), np.zeros(6), scale, wrench
    return "const", np.array(wrench([float(v) for v in (y0 if r is None else turn_in(r, y0))])), scale, wrench


class JaxsimWorld(World):
    """B bodies, each its own jaxsim model, stepped by the compiled functions above; raw rows are packed
    states. Its rollout takes every force (``rollout_takes_all_forces``): the harness's, constant,
    evaluated in the compiled loop (cross_checks.engines.jax_forces) or called back from it
    (:data:`HOST_FORCES_REASON`), and the decay; compilation and callbacks are counted in ``host_s``."""

    rollout_takes_all_forces = True

    def __init__(self, requests, variant: str, dt_s: float):
        super().__init__()
        _refuse_forked_jax()
        self.scenarios = [r.scenario for r in requests]
        self.models = [build_model(sc, variant) for sc in self.scenarios]
        self.frames = [jaxsim_frame(sc) for sc in self.scenarios]
        self.turned = any(r is not None for r in self.frames)
        #: a turned body's state read back is its requested one to round-off only: the loop records the latter
        self.exact_start = self.turned
        self.ends = [int(r.n_steps) for r in requests]
        self.dt = np.float64(dt_s)
        self.host_s = 0.0
        self.y = np.empty((len(requests), 13))

    def set_state(self, y):
        """Body i at the packed state ``y[i]`` of its scenario's frame (held in jaxsim's frame)."""
        self.y = np.array(y, dtype=float)
        for i, r in enumerate(self.frames):
            if r is not None:
                self.y[i] = turn_in(r, self.y[i])

    def read(self):
        return self.y

    def packed(self, raw) -> np.ndarray:
        """Raw rows (..., B, 13) of jaxsim's frames as packed states of each body's scenario frame."""
        y = np.asarray(raw, dtype=float)
        if self.turned:
            y = y.copy()
            for i, r in enumerate(self.frames):
                if r is not None:
                    y[..., i, :] = turn_out(r, y[..., i, :])
        return y

    def rollout(self, n_steps, harness):
        """The states (n_steps, B, 13) after each step: one step of every row in one vmapped call when the
        bodies are one scenario's (the one-step mode), else the bodies vmapped in compiled chunks, a batch
        per model structure and kind of forces (NaN after a body's last step; a batch stops at the first
        chunk after which every body has ended or blown up)."""
        from cross_checks.engines import jax_forces
        compiled = _TIMES["compile_seconds"]
        t0 = time.perf_counter()
        try:
            inputs = [_inputs(sc, harness, i) for i, sc in enumerate(self.scenarios)]
            fa = jax_forces.BodyForces(harness)
            fa.arrays["weight"] = np.array([_weight(sc) for sc in self.scenarios], dtype=float)
            self.host_s += time.perf_counter() - t0
            if n_steps == 1 and all(sc is self.scenarios[0] for sc in self.scenarios):
                return self._one(inputs, fa)[None]
            out = np.full((n_steps, len(self.y), 13), np.nan)
            groups: dict = {}
            for i, (mode, *_rest) in enumerate(inputs):
                groups.setdefault((mode, self.models[i].integrator, self.models[i].gravity), []).append(i)
            for (mode, *_), idx in groups.items():
                for s in range(0, len(idx), MAX_BATCH):
                    self._run(idx[s:s + MAX_BATCH], mode, n_steps, inputs, fa, out)
            return out
        finally:   # compiling is not stepping: counted apart, with the host's seconds
            self.host_s += _TIMES["compile_seconds"] - compiled

    def _run(self, idx, mode: str, n_max: int, inputs, fa, out) -> None:
        """The bodies ``idx`` (of one model structure and force mode) vmapped, padded to a power of two."""
        from cross_checks.engines import jax_forces
        t0, compiled = time.perf_counter(), _TIMES["compile_seconds"]
        # one body runs the reproducer's loop (worlds/jaxsim.py), not vmapped: its numbers to the bit; XLA
        # rounds a vmapped batch's (of any size) differently, by ~1e-14 relative
        B, M = len(idx), runtimes.power_of_two(len(idx))
        pad = list(idx) + [idx[0]] * (M - B)
        distinct = list(dict.fromkeys(id(self.models[i]) for i in idx))
        trees = {id(self.models[i]): self.models[i] for i in idx}
        models = runtimes.stack_trees([trees[k] for k in distinct],
                                      [distinct.index(id(self.models[i])) for i in pad])
        rows = runtimes.chunk_rows(M, CHUNK)
        f6 = np.array([inputs[i][1] for i in pad])
        scale = np.array([inputs[i][2] for i in pad])
        y = self.y[pad]
        ends = np.array([self.ends[i] for i in idx])
        with contextlib.ExitStack() as stack:
            hold = _CONTEXTS.holding
            keys = np.array([stack.enter_context(hold((self, inputs[i][3]))) if mode == "callback"
                             else np.int64(0) for i in pad], dtype=np.int64)
            args = (self.dt, y, np.int64(0), f6, scale, keys, fa.take(pad), jax_forces.zero())
            if M == 1:   # without the batch axis (see above)
                models = self.models[idx[0]]
                args = (self.dt, y[0], np.int64(0), f6[0], scale[0], keys[0], fa.take(pad[0]),
                        jax_forces.zero())
                y = y[0]
            fn = _compiled("run", mode, models, (rows, fa.key, M == 1),
                           lambda: _run_fn(mode, rows, vmapped=M > 1), *args)
            # stacking the models and the inputs (the compilation is added by rollout)
            self.host_s += time.perf_counter() - t0 - (_TIMES["compile_seconds"] - compiled)
            done, k = np.zeros(B, dtype=bool), 0
            while k < n_max and not done.all():
                count = min(rows, n_max - k)
                with _TIMES.timing("run_seconds"):
                    y, chunk = fn(models, self.dt, y, np.int64(count), *args[3:])
                    chunk = np.asarray(chunk).reshape(M, rows, 13)[:B, :count]
                _TIMES["steps"] += count * B
                out[k:k + count, idx] = chunk.transpose(1, 0, 2)
                done |= bad_rows(chunk).any(axis=1) | (ends <= k + count)
                k += count

    def _one(self, inputs, fa):
        from cross_checks.engines import jax_forces
        n = len(self.y)
        model, dt = self.models[0], self.dt
        mode, f6, scale, wrench = inputs[0]
        pad = -n % ROW_BLOCK
        padded = np.concatenate([self.y, np.repeat(self.y[:1], pad, axis=0)]) if pad else self.y
        rows = fa.take(np.r_[np.arange(n), np.zeros(pad, dtype=int)])
        with _CONTEXTS.holding((self, wrench)) as key:
            args = (dt, padded, f6, scale, key, rows, jax_forces.zero())
            fn = _compiled("one", mode, model, (fa.key,), lambda: _one_fn(mode), *args)
            with _TIMES.timing("run_seconds"):
                out = np.asarray(fn(model, *args))[:n]
            _TIMES["steps"] += n
        return out


class JaxsimEngine(WorldEngine):
    """``jaxsim:VARIANT`` — registered under the entry-point group ``rbcheck.engines``; optional
    (``pip install 'rbcheck[jaxsim]'``)."""

    name = ENGINE
    variants = VARIANTS
    distribution = module = extra = "jaxsim"

    def version(self) -> str:   # from metadata: JAX must not start in a sweep's parent
        return version()

    def build(self, requests, variant, dt_s):
        return JaxsimWorld(requests, variant, dt_s)

    def group_key(self, request) -> tuple:   # the bodies run one after the other: any runs share a world
        return (float(request.dt_s),)

    @property
    def compile_seconds(self) -> float:
        """Seconds this process spent compiling jaxsim's run and one-step functions (apart from stepping)."""
        return _TIMES["compile_seconds"]

    def timings(self) -> dict:
        return timings()

    def engine_files(self) -> list:
        """jaxsim's Python files (found without importing it: a changed jaxsim is a new engine)."""
        return install.package_files("jaxsim", pattern="**/*.py")


_ENGINE = JaxsimEngine()
#: The module's functions (tests and scripts call them): the engine's, through the host loop.
simulate, simulate_many, one_step = _ENGINE.simulate, _ENGINE.simulate_many, _ENGINE.one_step
JaxsimAdapter = JaxsimEngine
