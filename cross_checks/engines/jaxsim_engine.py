"""jaxsim (JAX, float64) as an engine adapter (``jaxsim:VARIANT``); the interface: cross_checks.engines.base.

Model: one ``JaxSimModel`` per scenario built from an SDF string
(``JaxSimModel.build_from_model_description(sdf, is_urdf=False, gravity=…, integrator=…)``; a URDF would need
Gazebo's ``gz``): one link, its ``<inertial>`` at the link origin with the scenario's mass and the FULL
inertia tensor about the COM in link axes (ixx … iyz), so the link frame is the scenario's body frame and
link origin = COM (checked after the build: jaxsim's spatial inertia must hold exactly that mass and tensor,
else EngineError). A model without joints is floating-base (a 6-DOF ``world_to_base`` joint).

State mapping (docs/engine_conventions.md "jaxsim 0.9", pinned by tests/cross_checks/engines/
test_jaxsim_engine.py): the data are built in the MIXED velocity representation (``VelRepr.Mixed``):
``base_position`` = x_W (m), ``base_quaternion`` = q_WB in (w, x, y, z) order (jaxsim's own order: no
conversion), ``base_velocity`` = [v_W (m/s, the link origin = COM, world axes), ω_W (rad/s, world axes)]:
the packed state's own quantities. jaxsim stores the velocity internally in the INERTIAL representation
(v_in = ẋ − ω × x, the velocity of the body point passing through the world origin) and converts at
``build``/``base_velocity``: a round off of ε·|ω||x| per step, nothing else.

Every step starts from the packed state: ``JaxSimModelData.build`` from it, ``js.model.step``, the packed
state read back — so a free run and :func:`one_step` from any recorded state take the same step.

The step (jaxsim/api/model.py ``step`` → jaxsim/api/integrators.py): the link forces are converted to the
inertial representation ONCE, at the start state, then

* ``semi_implicit_euler`` (``semi_implicit_euler_integration``): the ABA acceleration in the inertial
  representation (gravity added as the inertial acceleration [0, 0, −g, 0, 0, 0]; ω̇_W = I_W⁻¹(τ − ω × I_W ω),
  the explicit gyroscopic term), ``ν_in += Δt ν̇_in``, then ``x += Δt (v_in⁺ + ω⁺ × x)`` and
  ``q += Δt · ½ [0, ω⁺] ⊗ q`` (``Quaternion.derivative``, Baumgarte K = 0.1 on |q| − 1 = 0), normalised:
  symplectic Euler with an explicit gyroscopic term and the course's quaternion update, the rotation of
  reference:course_gyro exactly. Its translation is that of the INERTIAL velocity: where the body spins
  (ω ≠ 0) away from the world origin it differs from the course's ``v += Δt f/m`` by O(Δt) terms in ω × ẋ
  (first order still; tumbling_box at 1e-3 s: 35 m of position error against MuJoCo Euler's 0.05 m).
* ``rk4`` (``rk4_integration``): classical RK4 on (x, q, v_in, ω) with ``system_dynamics``, each stage's
  quaternion normalised (``data.replace``); 4th order. Its four stages take the SAME link forces
  (``link_forces`` is an argument of the integrator, converted once per step): jaxsim has no per-stage force
  hook (no control callback; the contact model is the only per-stage force and needs collision points), so
  the applied force and torque are held over the step (Traits.forces_held): first order where they change
  within a step (state-dependent forces, velocity decay). The held wrench is the INERTIAL one (the force and
  its moment about the world origin): the force keeps its line of action in space over the stages, so even a
  constant force at the COM gives a moving body a spurious torque (x0 − x_stage) × f — first order in
  rotation (pinned; no catalog scenario has such a force besides gravity, which jaxsim applies as an
  acceleration).
* ``RungeKutta4Fast`` is not offered: with no collidable point its ``rk4fast_integration`` reads
  ``W_f_L_terrain`` before assigning it (UnboundLocalError in jaxsim 0.9.0, pinned by a test).

Forces (harness semantics of base.py): ``link_forces`` (1, 6) in the Mixed representation — [f_W (N) at the
link origin = COM, τ_W (N m) about it, world axes] — exactly base.harness_force_torque's force and torque,
minus the weight m g that jaxsim applies itself, given afresh to every step (``step`` keeps nothing).
Gravity: jaxsim's is a scalar along −z (a static field of the model): a scenario gravity (0, 0, −g) is
jaxsim's gravity g; any other direction is given to jaxsim as gravity 0 with the weight in the link force.
Forces that depend on the state are evaluated by the package's force model (step_floats.harness_fn:
reference_sim.compiled.ForceEvaluator) from the start-of-step state through ``jax.pure_callback`` inside the
compiled loop; constant ones are evaluated once and passed in. Velocity decay: the pre-step factors
(base.decay_factors) multiply v and ω before the step (base.apply_decay_prestep's arithmetic), that step's
force and torque scaled alike (by the harness).

Defaults that are not the scenario's physics, each neutralised and pinned by a test: contact — jaxsim's
default SoftContacts with a flat terrain at z = 0 act only on collidable points, and the link has no
``<collision>``, so there is none (a body below z = 0 moves as one above); no joint (so no joint friction,
damping, limits or actuation model terms); no kinematic constraint; one integrator call per step (no
substeps); float64 — importing jaxsim switches ``jax_enable_x64`` on PROCESS-WIDE (jaxsim/__init__.py),
which this adapter also sets before the import and checks after (every JAX engine in the same process then
computes in float64). jaxsim has no velocity clamp, sleeping or damping to switch off.

Compilation: two functions per (variant, force path, jaxsim gravity value) — a run of up to CHUNK steps
(``lax.fori_loop``) and one step of ROW_BLOCK·k rows (``jax.vmap``) — compiled ahead of time once per process
(the model, Δt, forces and states are arguments), timed apart from stepping (:func:`timings`,
``JaxsimAdapter.compile_seconds``). The XLA persistent compilation cache is kept in
``core.files.kernel_cache_dir("jax")`` (shared with the other JAX engines); JAX does not persist an
executable holding a host callback, so the state-dependent path compiles in every process.

Fork safety: importing jaxsim initialises a JAX backend (it calls ``jax.devices()``), after which a fork can
deadlock; the sweep forks its workers. So this module never imports JAX at module level, and ``version()``
reads the distribution's metadata and checks that jaxsim is importable with ``importlib.util.find_spec``
(no import): a parent process that lists, schedules or sweeps never starts JAX (every run of a sweep, its
refinements included, is a worker's).

Divergence: JAX never stops on a non-finite value, so every chunk of states is checked
(reference_sim.simulate.bad_rows): the first state that is non-finite or beyond BLOWUP_LIMIT ends the run as
``diverged at t = …``.
"""

from __future__ import annotations

import dataclasses
import functools
import itertools
import threading
import time
from pathlib import Path

import numpy as np

from cross_checks.core import tolerances as tol
from cross_checks.core.files import kernel_cache_dir
from cross_checks.engines import base
from cross_checks.engines.base import EngineError, ModuleAdapter, Variant, installed_version
from cross_checks.engines.step_floats import harness_fn
from reference_sim.simulate import Run, bad_rows, blowup_words, diverged

__all__ = [
    "ENGINE",
    "VARIANTS",
    "INTEGRATORS",
    "CHUNK",
    "ROW_BLOCK",
    "EngineError",
    "version",
    "simulate",
    "simulate_many",
    "one_step",
    "build_model",
    "model_sdf",
    "engine_gravity",
    "timings",
    "xla_cache_dir",
    "JaxsimAdapter",
]

ENGINE = "jaxsim"
HINT = "pip install 'rbcheck[jaxsim]'"
#: variant -> jaxsim's ``IntegratorType`` member.
INTEGRATORS = {"semi_implicit_euler": "SemiImplicitEuler", "rk4": "RungeKutta4"}
VARIANTS = {
    # jaxsim/api/integrators.py semi_implicit_euler_integration: ω_W += Δt I_W⁻¹(τ − ω × I_W ω), then
    # q += Δt ½ [0, ω⁺] ⊗ q, normalised, and x with the new velocity: a body-frame symplectic Euler step
    # with an explicit gyroscopic term (MuJoCo Euler's and reference:course_gyro's velocity update)
    "semi_implicit_euler": Variant(
        1,
        "jaxsim SemiImplicitEuler: symplectic Euler in the inertial representation, "
        "explicit gyroscopic term, q += Δt q̇ then normalised",
        traits=base.SYMPLECTIC_EULER_EXPLICIT_GYRO,
    ),
    # jaxsim/api/integrators.py rk4_integration: classical RK4, the step's link forces (an inertial wrench)
    # held over its 4 stages
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
MODEL_NAME = "rbcheck_body"

_LOCK = threading.RLock()
_TIMES = {"compile_seconds": 0.0, "compiles": 0, "run_seconds": 0.0, "steps": 0}
_CONTEXTS: dict = {}  # callback key -> (harness, weight floats): the forces of one run / one_step call
_KEYS = itertools.count(1)


# --- availability without importing JAX (fork safety) --------------------------------------------------


def version() -> str:
    """The installed jaxsim distribution's version, from its metadata: no import (see the module docstring).
    EngineNotInstalled when it is absent; ImportError when it is installed but not importable."""
    import importlib.util

    ver = installed_version("jaxsim")
    if ver is None:
        raise base.EngineNotInstalled(f"jaxsim is not installed ({HINT})")
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
    """(jax, jax.numpy, jaxsim.api): imported on first use (never in a process that only lists engines),
    float64 switched on before jaxsim's import and checked after, the persistent cache in rbcheck's
    directory."""
    jax, err = base.optional_import("jax")
    base.require(jax, err, "jax", hint=HINT)
    jax.config.update("jax_enable_x64", True)
    try:
        path = xla_cache_dir()
        path.mkdir(parents=True, exist_ok=True)
        jax.config.update("jax_compilation_cache_dir", str(path))
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)
    except OSError:  # no writable cache directory: compile every time
        pass
    jaxsim, err = base.optional_import("jaxsim")
    base.require(jaxsim, err, "jaxsim", hint=HINT)
    import jax.numpy as jnp
    import jaxsim.api as js

    if not jax.config.jax_enable_x64:
        raise EngineError("jaxsim: jax_enable_x64 is off after importing jaxsim; rbcheck needs float64")
    return jax, jnp, js


def timings() -> dict:
    """This process's jaxsim time: ``compile_seconds`` (tracing + XLA compilation of the run and one-step
    functions, persistent-cache loads included), ``compiles`` (how many), ``run_seconds`` and ``steps`` (the
    compiled runs' execution, force callbacks included; one_step's rows count as steps)."""
    return dict(_TIMES)


# --- the model -----------------------------------------------------------------------------------------


def engine_gravity(scenario) -> float:
    """The scalar gravity (m/s², along −z) given to jaxsim: g for a scenario gravity (0, 0, −g), else 0 (the
    weight then goes into the link force)."""
    g = np.asarray(scenario.problem.forces.gravity_W, dtype=float)
    return float(-g[2]) if g[0] == 0.0 and g[1] == 0.0 else 0.0


def model_sdf(mass_kg: float, inertia_B) -> str:
    """SDF 1.7 of one link named ``body``: an ``<inertial>`` at the link origin with ``mass_kg`` and the full
    tensor ``inertia_B`` (kg m², about the COM, link axes), no ``<collision>``, no joint; every number with
    Python's shortest round-trip repr (exactly the double)."""
    inertia = np.asarray(inertia_B, dtype=float)
    names = (("ixx", 0, 0), ("ixy", 0, 1), ("ixz", 0, 2), ("iyy", 1, 1), ("iyz", 1, 2), ("izz", 2, 2))
    moments = "".join(f"<{n}>{float(inertia[i, j])!r}</{n}>" for n, i, j in names)
    return (
        '<?xml version="1.0"?>\n<sdf version="1.7"><model name="' + MODEL_NAME + '"><link name="body">'
        f"<inertial><pose>0 0 0 0 0 0</pose><mass>{float(mass_kg)!r}</mass><inertia>{moments}</inertia>"
        "</inertial></link></model></sdf>"
    )


def build_model(scenario, variant: str):
    """The scenario's jaxsim model for ``variant`` (EngineError with jaxsim's words when it refuses it)."""
    base.check_variant(ENGINE, VARIANTS, variant)
    body = scenario.problem.body
    inertia = np.asarray(body.inertia_B, dtype=float)
    return _model(float(body.mass_kg), tuple(inertia.reshape(-1).tolist()), engine_gravity(scenario), variant)


@functools.lru_cache(maxsize=64)
def _model(mass_kg: float, inertia: tuple, gravity: float, variant: str):
    jax, jnp, js = _jax()
    sdf = model_sdf(mass_kg, np.reshape(inertia, (3, 3)))
    try:
        model = js.model.JaxSimModel.build_from_model_description(
            sdf,
            model_name=MODEL_NAME,
            is_urdf=False,
            time_step=0.001,
            gravity=gravity,
            integrator=getattr(js.model.IntegratorType, INTEGRATORS[variant]),
        )
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
    # the SDF text (a static field) would make every scenario's model a new pytree structure: one compilation
    # per scenario; the model's numbers are all in its arrays
    return dataclasses.replace(model, built_from=MODEL_NAME)


# --- the compiled functions ----------------------------------------------------------------------------


def _host_forces(key, y):
    """The link forces (..., 6) [f_W − m g_jaxsim, τ_W] of the states ``y`` (..., 13) of the call ``key``:
    the package's harness (step_floats.harness_fn) in plain floats (the jax.pure_callback target)."""
    y = np.asarray(y, dtype=np.float64)
    keys = np.broadcast_to(np.asarray(key), y.shape[:-1]).reshape(-1)
    rows = y.reshape(-1, 13)
    out = np.empty((len(rows), 6))
    for i, (k, row) in enumerate(zip(keys.tolist(), rows.tolist())):
        harness, (wx, wy, wz) = _CONTEXTS[k]
        fx, fy, fz, tx, ty, tz = harness(row)
        out[i] = (fx - wx, fy - wy, fz - wz, tx, ty, tz)
    return out.reshape(y.shape[:-1] + (6,))


def _step_fn(callback: bool):
    """One jaxsim step of the packed state ``y`` (13,): pre-step decay ``scale`` (13,), link force ``f6`` (6,)
    or, with ``callback``, the harness's at ``y`` (before the decay, as base.harness_force_torque)."""
    jax, jnp, js = _jax()
    from jaxsim import VelRepr

    def step(model, y, f6, scale, key):
        if callback:
            f6 = jax.pure_callback(
                _host_forces, jax.ShapeDtypeStruct((6,), jnp.float64), key, y, vmap_method="broadcast_all"
            )
        y = y * scale
        data = js.data.JaxSimModelData.build(
            model=model,
            base_position=y[0:3],
            base_quaternion=y[6:10],
            base_linear_velocity=y[3:6],
            base_angular_velocity=y[10:13],
            velocity_representation=VelRepr.Mixed,
        )
        data = js.model.step(model, data, link_forces=f6[None, :])
        v = data.base_velocity
        return jnp.concatenate([data.base_position, v[0:3], data.base_quaternion, v[3:6]])

    return step


def _with_dt(model, dt):
    """``model`` stepping at ``dt`` (s; traced: one compilation for every Δt)."""
    return dataclasses.replace(model, time_step=dt)


def _run_fn(callback: bool):
    jax, jnp, js = _jax()
    step = _step_fn(callback)

    def run(model, dt, y0, count, f6, scale, key):
        model = _with_dt(model, dt)

        def body(i, carry):
            y, rows = carry
            y = step(model, y, f6, scale, key)
            return y, rows.at[i].set(y)

        return jax.lax.fori_loop(0, count, body, (y0, jnp.zeros((CHUNK, 13))))

    return run


def _one_fn(callback: bool):
    jax, jnp, js = _jax()
    step = _step_fn(callback)

    def one(model, dt, ys, f6, scale, key):
        model = _with_dt(model, dt)
        return jax.vmap(lambda y: step(model, y, f6, scale, key))(ys)

    return one


_COMPILED: dict = {}


def _compiled(kind: str, callback: bool, model, *args):
    """The ahead-of-time compiled ``kind`` ("run" or "one") function for these arguments' shapes and the
    model's static fields (jaxsim's gravity and integrator); compiled once per process, the time counted."""
    jax, jnp, js = _jax()
    key = (kind, callback, model.integrator, model.gravity, tuple(np.shape(a) for a in args))
    with _LOCK:
        fn = _COMPILED.get(key)
        if fn is None:
            t0 = time.perf_counter()
            make = _run_fn if kind == "run" else _one_fn
            try:
                fn = jax.jit(make(callback)).lower(model, *args).compile()
            except Exception as exc:  # noqa: BLE001 - jaxsim or XLA refusing the computation
                raise EngineError(
                    f"jaxsim/XLA could not compile the step: {type(exc).__name__}: {exc}"
                ) from None
            _TIMES["compile_seconds"] += time.perf_counter() - t0
            _TIMES["compiles"] += 1
            _COMPILED[key] = fn
    return fn


def _weight(scenario) -> tuple:
    """The weight jaxsim applies itself (N, world): m (0, 0, −g_jaxsim)."""
    return (0.0, 0.0, -float(scenario.problem.body.mass_kg) * engine_gravity(scenario))


def _inputs(scenario, dt_s: float):
    """(callback?, constant link force (6,), pre-step decay scale (13,), harness) of a run at ``dt_s``."""
    forces = scenario.problem.forces
    harness = harness_fn(scenario, dt_s)
    wx, wy, wz = _weight(scenario)
    gv, gw = (float(g) for g in base.decay_factors(scenario, dt_s))
    scale = np.ones(13)
    scale[3:6] = gv
    scale[10:13] = gw
    if forces.state_dependent:
        return True, np.zeros(6), scale, harness
    fx, fy, fz, tx, ty, tz = harness([float(v) for v in scenario.problem.initial_packed()])
    return False, np.array([fx - wx, fy - wy, fz - wz, tx, ty, tz]), scale, harness


class _Context:
    """The callback key of one run or one_step call, registered for its duration."""

    def __init__(self, scenario, harness):
        self.key = next(_KEYS)
        self.value = (harness, _weight(scenario))

    def __enter__(self):
        _CONTEXTS[self.key] = self.value
        return np.asarray(self.key, dtype=np.int64)

    def __exit__(self, *exc):
        _CONTEXTS.pop(self.key, None)


def simulate(scenario, variant: str, dt_s: float, n_steps: int) -> Run:
    """Free run of ``n_steps`` steps of ``dt_s`` from the scenario's initial state, every step recorded."""
    model = build_model(scenario, variant)
    callback, f6, scale, harness = _inputs(scenario, dt_s)
    y0 = np.asarray(scenario.problem.initial_packed(), dtype=float)
    dt = np.float64(dt_s)
    rows = [y0[None]]
    y = y0
    done = 0
    with _Context(scenario, harness) as key:
        fn = _compiled("run", callback, model, dt, y0, np.int64(0), f6, scale, key)
        while done < n_steps:
            count = min(CHUNK, n_steps - done)
            t0 = time.perf_counter()
            y, chunk = fn(model, dt, y, np.int64(count), f6, scale, key)
            chunk = np.asarray(chunk)[:count]
            _TIMES["run_seconds"] += time.perf_counter() - t0
            _TIMES["steps"] += count
            bad = bad_rows(chunk)
            if bad.any():
                k = int(np.argmax(bad))
                return diverged(
                    np.concatenate(rows + [chunk[:k]]), float(dt_s), f" ({blowup_words(chunk[k])})"
                )
            rows.append(chunk)
            done += count
    return Run(float(dt_s) * np.arange(n_steps + 1), np.concatenate(rows))


def simulate_many(variant: str, requests) -> list:
    """The runs of ``requests`` (base.RunRequest), one after the other through the same compiled run function
    (one compilation for a whole Δt ladder): each equal to :func:`simulate`'s. A ladder is not vmapped: its
    runs differ in length (a batch steps all lanes to the longest) and each batch size is another compilation
    (docs/engine_conventions.md, "jaxsim 0.9": measured no gain)."""
    out: list = []
    for r in requests:
        try:
            out.append(simulate(r.scenario, variant, r.dt_s, r.n_steps))
        except EngineError as exc:
            out.append(exc)
    return out


@base.on_rows
def one_step(scenario, variant: str, dt_s: float, y_start) -> np.ndarray:
    """One step of ``dt_s`` from each row of ``y_start`` (T, 13), all rows in one vmapped call (padded to a
    multiple of ROW_BLOCK rows): the forces from each row, the pre-step decay — the free run's step."""
    n = len(y_start)
    if n == 0:
        return np.empty((0, 13))
    model = build_model(scenario, variant)
    callback, f6, scale, harness = _inputs(scenario, dt_s)
    pad = -n % ROW_BLOCK
    padded = np.concatenate([y_start, np.repeat(y_start[:1], pad, axis=0)]) if pad else y_start
    dt = np.float64(dt_s)
    with _Context(scenario, harness) as key:
        fn = _compiled("one", callback, model, dt, padded, f6, scale, key)
        t0 = time.perf_counter()
        out = np.asarray(fn(model, dt, padded, f6, scale, key))[:n]
        _TIMES["run_seconds"] += time.perf_counter() - t0
        _TIMES["steps"] += n
    return out


class JaxsimAdapter(ModuleAdapter):
    """``jaxsim:VARIANT`` — registered under the entry-point group ``rbcheck.engines``; optional
    (``pip install 'rbcheck[jaxsim]'``). Declared orders: semi-implicit Euler 1, RK4 4 (its forces held)."""

    name = ENGINE
    variants = VARIANTS
    harness = ("cross_checks.engines.step_floats",)

    @property
    def compile_seconds(self) -> float:
        """Seconds this process spent compiling jaxsim's run and one-step functions (apart from stepping)."""
        return _TIMES["compile_seconds"]

    def timings(self) -> dict:
        return timings()

    def engine_files(self) -> list:
        """jaxsim's Python files (found without importing it: a changed jaxsim is a new engine)."""
        return base.package_files("jaxsim", pattern="**/*.py")
