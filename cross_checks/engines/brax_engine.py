"""Brax (JAX) as an engine adapter (``brax:VARIANT``), one variant per pipeline; the interface is
cross_checks.engines.base. What each pipeline does, the defaults neutralised (NEUTRAL_SYSTEM, NEUTRAL_DOF) and
what was measured: docs/engine_conventions.md, "Brax 0.14.2".

Model: the scenario's free body as MJCF (:func:`mjcf_text`) loaded by ``brax.io.mjcf.loads``; a model MuJoCo's
compiler rejects is an EngineError with its words. Precision: float64 (JAX started by runtimes.start_jax).

State at the boundary: ``pipeline.init(sys, q, qd)`` with ``q = [x_W, q_WB (w x y z)]``, ``qd = [v_W, ω_B]``
(ω in body axes); read back from ``state.x.pos``, ``state.x.rot`` (w x y z), ``state.xd.vel`` and
``state.xd.ang`` (world axes).

Forces: brax has no external-wrench input. The generalized pipeline gets them as
``act = [f − m g, R_WBᵀ τ_W]`` through six actuators on the free joint's DOFs (:func:`six_dof_actuator`; brax
applies gravity itself), from the start-of-step state (state-dependent ones evaluated inside the compiled
loop: cross_checks.engines.jax_forces, the loop's harness in JAX, bit for bit); the positional and spring
pipelines take gravity only (:func:`expressible`). The decay is applied to ``qd`` before each step.

A :class:`BraxWorld` holds one scenario's runs at any Δt (``WorldEngine.mixed_steps``) and takes every force
itself (``World.rollout_takes_all_forces``): its rollout vmaps the runs (their Δt ladder) through a compiled
``jax.lax.fori_loop`` that records every state (runtimes.chunk_rows steps a call, at most CHUNK), and one step
of many rows is one vmapped call. JAX is imported on
first use only (never at import or in ``version()``): a sweep's parent must not start it before forking.
"""
from __future__ import annotations

import contextlib
import functools
import io
import threading
import time
import warnings

import numpy as np

from cross_checks.engines import base, forces, install, runtimes
from cross_checks.engines.base import EngineError, Traits, Variant
from cross_checks.engines.world import HostRowsWorld, WorldEngine
from reference_sim.simulate import bad_rows

__all__ = ["ENGINE", "VARIANTS", "CHUNK", "ONE_STEP_MIN_BATCH",
           "EngineError", "version", "mjcf_text", "build_system", "simulate", "simulate_many", "one_step",
           "compile_seconds", "BraxWorld", "BraxEngine", "BraxAdapter", "expressible"]

ENGINE = "brax"
#: The positional pipeline's invariance finding (docs/engine_conventions.md, "Invariance").
POSITIONS_FAR_OUT_REASON = (
    "the engine's: the positional pipeline recomputes the velocity from the position change, "
    "v = (x' − x)/Δt (brax/positional/integrator.py project_xd), so the rounding of x' = x + vΔt, half "
    "an ulp of |x|, becomes a velocity error that the next step keeps; these roundings follow the smooth "
    "motion and do not average out. Measured on particle_body 1 km and 10 km out: 6.4e-7 and 1.06e-5 m by "
    "5 s, growing as t² (a steady acceleration error), about the same at Δt/2 (7.6e-7, 1.21e-5 m), 16× "
    "apart as the ulps of 1 km and 10 km are (1.1e-13, 1.8e-12 m); the rotation untouched (0 rad/s); a body "
    "at rest in translation (tennis_racket) keeps its position exactly")
#: The pipelines' integrators (read in brax 0.14.2's source): all first order.
VARIANTS = {
    # generalized/integrator.py: q̇ += Δt M⁻¹(τ − C) (C has ω_B × I ω_B), then q with the new q̇ (exp map)
    "generalized": Variant(1, "brax generalized pipeline: semi-implicit Euler in generalized coordinates, "
                              "explicit gyroscopic term (body axes), exponential-map rotation update with "
                              "the new ω",
                           traits=base.SYMPLECTIC_EULER_EXPLICIT_GYRO),
    # spring/pipeline.py + spring/integrator.py: ω_W += Δt I_W⁻¹ τ (no gyroscopic term), q += ½Δt ω_W ⊗ q
    "spring": Variant(1, "brax spring pipeline: semi-implicit Euler in maximal coordinates, NO gyroscopic "
                         "term, quaternion q += ½Δt ω ⊗ q renormalised; forces: gravity only",
                      traits=Traits(gyroscopic_term=False, translation_drift=0, rotation_drift="none",
                                    rotation_sign=0)),
    # positional/pipeline.py + integrator.py: as spring, then ω_W = 2 vec(Δq)/Δt (project_xd): |ω| shrinks
    "positional": Variant(1, "brax positional pipeline: the spring pipeline's step, then velocities "
                             "projected from the position change (ω shrinks by |ω|²Δt²/8 a step), NO "
                             "gyroscopic term; forces: gravity only",
                          traits=Traits(gyroscopic_term=False, translation_drift=0, rotation_drift="none",
                                        rotation_sign=-1, velocity_from_positions=True,
                                        invariance_findings=(base.InvarianceFinding(
                                            "translation", (("distance_m", 1e3, 1e4),),
                                            POSITIONS_FAR_OUT_REASON, ("position", "velocity")),))),
}


#: Steps of one call of the compiled loop at most (its count traced: a shorter call runs its own steps only; a
#: batch of many runs records fewer a call: runtimes.chunk_rows).
CHUNK = 2048
#: one_step batches are padded to at least this many rows (a power of two): one step of 64 bodies costs about
#: what one costs, and every small batch shares one executable.
ONE_STEP_MIN_BATCH = 64

_LOCK = threading.RLock()
_COMPILED: dict = {}         # key -> compiled executable
_COMPILE_S: dict = {}        # key -> seconds spent compiling it (lower + compile)


def version() -> str:
    """brax's version and the jax it runs on, from package metadata (no import: a sweep's parent must not
    start JAX before forking). EngineNotInstalled without brax; ImportError without jax/jaxlib."""
    ver = install.installed_version("brax")
    if ver is None:
        raise install.EngineNotInstalled("brax is not installed (pip install 'rbcheck[brax]')")
    jax_ver, jaxlib_ver = install.installed_version("jax"), install.installed_version("jaxlib")
    if jax_ver is None or jaxlib_ver is None:
        raise ImportError(f"brax {ver} is installed but jax or jaxlib is not (pip install 'rbcheck[brax]')")
    return f"{ver} (jax {jax_ver})"


@functools.lru_cache(maxsize=1)
def _lib():
    """brax and jax, imported on first use (runtimes.start_jax); mujoco.mjx's "Failed to import warp" on
    stdout and brax's warnings silenced."""
    version()
    with install.first_import("brax", install.installed_version), contextlib.redirect_stdout(io.StringIO()), \
            warnings.catch_warnings():
        warnings.simplefilter("ignore")
        jax = runtimes.start_jax()
        import jax.numpy as jp
        from brax.base import Actuator
        from brax.generalized import pipeline as generalized
        from brax.io import mjcf
        from brax.positional import pipeline as positional
        from brax.spring import pipeline as spring

        from cross_checks.engines.worlds import brax as world  # the model and step rbcheck repro embeds
    return {"jax": jax, "jp": jp, "mjcf": mjcf, "Actuator": Actuator, "world": world,
            "pipelines": {"generalized": generalized, "positional": positional, "spring": spring}}


def __getattr__(name):
    """``NEUTRAL_SYSTEM`` and ``NEUTRAL_DOF``: cross_checks.engines.worlds.brax's (brax imported then)."""
    if name in ("NEUTRAL_SYSTEM", "NEUTRAL_DOF"):
        return getattr(_lib()["world"], name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _usable():
    """The brax/jax modules, or EngineError in a process forked after its parent had run JAX (instead of a
    hang)."""
    lib = _lib()
    runtimes.refuse_forked_jax("JAX cannot run in this process: it was forked after JAX had started in its "
                               "parent (run brax in a fresh process, e.g. the rbcheck CLI, or with one job)")
    return lib


def compile_seconds() -> dict:
    """Seconds spent compiling (lowering + XLA compile) each executable this process built, by
    ``"kind:variant:mode:batch"`` (kind ``run`` = the chunk loop, ``one_step``); apart from stepping
    time."""
    with _LOCK:
        return dict(_COMPILE_S)


# --- the model --------------------------------------------------------------------------------------------

def mjcf_text(scenario, dt_s: float, *, actuators: bool) -> str:
    """The scenario's free body as MJCF for ``brax.io.mjcf.loads`` (full-precision numbers):
    cross_checks.engines.worlds.brax's."""
    p = scenario.problem
    return _lib()["world"].mjcf_text(p.body.mass_kg, p.body.inertia_B, p.forces.gravity_W, dt_s, actuators)


def neutralise(sys):
    """``sys`` with every NEUTRAL_SYSTEM and NEUTRAL_DOF field set (whatever it was)."""
    return _lib()["world"].neutralise(sys)


def six_dof_actuator(sys):
    """``sys`` with one motor per DOF of the free joint, gear 1: ``act`` is the generalized force
    ``[f_W, τ_B]`` (cross_checks.engines.worlds.brax's)."""
    return _lib()["world"].six_dof_actuator(sys)


def body_spec(body) -> tuple:
    """``(mass_kg, inertia_B (3, 3), None)``: brax takes the full tensor (MJCF ``fullinertia``)."""
    return float(body.mass_kg), np.asarray(body.inertia_B, dtype=float), None


def expressible(scenario, variant: str, dt_s: float) -> str:
    """"" when ``variant`` can take the scenario's forces, else why not (positional and spring: gravity
    only)."""
    if variant == "generalized":
        return ""
    fm = scenario.problem.forces
    why = (f"brax's {variant} pipeline takes no applied force but gravity ({variant}/joints.py gives a free "
           "joint zero actuator force and the pipeline has no other force input); this scenario has ")
    if fm.state_dependent:
        return why + "forces that depend on the state"
    f, tau = forces.harness_force_torque(scenario, scenario.problem.initial_packed(), dt_s)
    weight = forces.weight_W(scenario)
    if np.any(tau != 0.0) or not np.allclose(f, weight, rtol=1e-15, atol=0.0):
        return why + f"a force {np.round(f - weight, 6).tolist()} N besides the weight and a torque " \
                     f"{np.round(tau, 6).tolist()} N m"
    return ""


@functools.lru_cache(maxsize=32)
def _system_of(scenario, variant: str):
    """The neutralised brax System of the scenario's body for ``variant`` (Δt is set per run)."""
    lib = _lib()
    base.check_variant(ENGINE, VARIANTS, variant)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")     # brax's "not actively being maintained", on every load
            mass, inertia, _ = body_spec(scenario.problem.body)
            sys = lib["world"].system(mass, inertia, scenario.problem.forces.gravity_W, variant)
        lib["mjcf"].validate_model(sys.mj_model)
    except (ValueError, NotImplementedError, RuntimeError) as exc:
        raise EngineError(f"brax {install.installed_version('brax')} (MuJoCo's compiler) rejected the model "
                          f"of scenario {scenario.name!r}: {' '.join(str(exc).split())}") from None
    # mj_model is a static field: left in, every scenario would compile its own executable (validated above)
    return sys.replace(mj_model=None)


def build_system(scenario, variant: str, dt_s: float):
    """The brax System the adapter steps: the scenario's body, neutralised, at step ``dt_s``."""
    sys = _system_of(scenario, variant)
    return sys.replace(opt=sys.opt.replace(timestep=_lib()["jp"].asarray(float(dt_s))))


# --- state conversion (the boundary) ----------------------------------------------------------------------

def to_q_qd(y):
    """Packed states (..., 13) -> brax ``q = [x_W, q_WB (w x y z)]`` (..., 7), ``qd = [v_W, ω_B]``
    (..., 6) (cross_checks.engines.worlds.brax's)."""
    return _lib()["world"].to_q_qd(y)


def _packed(state):
    """A brax state (one body) -> packed (13,): x.pos, xd.vel, x.rot (w x y z), xd.ang — all world axes."""
    return _lib()["world"].packed(state)


# --- the compiled step ------------------------------------------------------------------------------------

def _step_fn(variant: str, mode: str):
    """One step of one body: ``(sys, state, consts, fa, zero, decay) -> state``. ``mode``: "none" (no applied
    force), "const" (consts = [f_W − m g, τ_W, γ_v, γ_ω, decay]), "state" (consts = [−m g, 0, γ_v, γ_ω,
    decay]; the forces evaluated in the loop: cross_checks.engines.jax_forces of the body's arrays ``fa``,
    ``zero`` its traced integer zero, at the state after the decay: where the host callback evaluated them
    before, so the numbers are the same; the harness's definition is the state before it, which differs
    where a force depends on the velocity and the velocity decays). With decay (1, passed unbatched: under
    vmap a batched predicate would turn the cond into a select that runs both branches) the state is
    re-initialised from the decayed ``q, qd`` (a ``lax.cond``: one executable serves runs with and without
    decay; without it the state is carried as is)."""
    from cross_checks.engines import jax_forces
    lib = _lib()
    jax, jp = lib["jax"], lib["jp"]
    P, W = lib["pipelines"][variant], lib["world"]

    def step(sys, state, consts, fa, z, decay):
        factors = jp.concatenate([jp.full(3, consts[6]), jp.full(3, consts[7])])
        state = jax.lax.cond(decay > 0.0, lambda s: P.init(sys, s.q, s.qd * factors), lambda s: s, state)
        if mode == "none":
            f = tau = None
        elif mode == "const":
            f, tau = consts[0:3], consts[3:6]
        else:   # at the state after the decay, where the host callback evaluated them before (bit for bit)
            ft = jax_forces.wrench_apart(fa, state.x.pos[0], state.xd.vel[0], state.x.rot[0], z)
            f, tau = ft[0:3], ft[3:6]
        return P.step(sys, state, W.act(sys, state, f, tau, variant))   # the act rbcheck repro embeds
    return step


def _compiled(kind: str, variant: str, mode: str, batch: int, rows: int, args):
    """The ahead-of-time compiled executable for these arguments (cached; compile time recorded): ``run``, a
    chunk of a run (``rows`` steps recorded at most, the count traced), or ``one_step``."""
    lib = _lib()
    jax, jp = lib["jax"], lib["jp"]
    key = (kind, variant, mode, batch, rows, jax.tree_util.tree_structure(args),
           tuple(np.shape(a) for a in jax.tree_util.tree_leaves(args)))
    with _LOCK:
        hit = _COMPILED.get(key)
    if hit is not None:
        return hit
    step = _step_fn(variant, mode)
    P = lib["pipelines"][variant]

    def with_dt(sys, dt):
        return sys.replace(opt=sys.opt.replace(timestep=dt))

    if kind == "run":
        def one(sys, state, dt, consts, fa, z, decay, n):
            s = with_dt(sys, dt)

            def body(i, carry):
                st, out = carry
                st = step(s, st, consts, fa, z, decay)
                return st, out.at[i].set(_packed(st))
            return jax.lax.fori_loop(0, n, body, (state, jp.zeros((rows, 13))))
        fn = jax.vmap(one, in_axes=(None, 0, 0, 0, 0, None, None, None))
    else:
        def one(sys, q, qd, dt, consts, fa, z, decay):
            s = with_dt(sys, dt)
            return _packed(step(s, P.init(s, q, qd), consts, fa, z, decay))
        fn = jax.vmap(one, in_axes=(None, 0, 0, 0, 0, 0, None, None))
    t0 = time.perf_counter()
    exe = jax.jit(fn).lower(*args).compile()
    seconds = time.perf_counter() - t0
    with _LOCK:
        _COMPILED[key] = exe
        name = f"{kind}:{variant}:{mode}:{batch}"
        _COMPILE_S[name] = _COMPILE_S.get(name, 0.0) + seconds
    return exe


def _mode_and_consts(scenario, variant: str, dt_s: float):
    """``(mode, consts (9,))`` of the scenario's forces at step ``dt_s`` (see :func:`_step_fn`)."""
    why = expressible(scenario, variant, dt_s)
    if why:
        raise EngineError(why)
    p = scenario.problem
    fm = p.forces
    weight = forces.weight_W(scenario)
    gv, gw = (float(g) for g in forces.decay_factors(scenario, dt_s))
    decay = 1.0 if fm.has_decay else 0.0
    if variant != "generalized":
        return "none", np.r_[np.zeros(6), gv, gw, decay]
    if fm.state_dependent:
        return "state", np.r_[-weight, np.zeros(3), gv, gw, decay]
    f, tau = forces.harness_force_torque(scenario, p.initial_packed(), dt_s)
    return "const", np.r_[f - weight, tau, gv, gw, decay]


@functools.lru_cache(maxsize=64)
def _initial(variant: str, batch: int):
    """``(sys, q, qd) -> state``: ``pipeline.init`` broadcast to ``batch`` members, jitted (eagerly it is
    many small operations per run)."""
    lib = _lib()
    jax, jp = lib["jax"], lib["jp"]
    P = lib["pipelines"][variant]

    def init(sys, q, qd):
        return jax.tree.map(lambda a: jp.broadcast_to(a, (batch, *jp.shape(a))), P.init(sys, q, qd))
    return jax.jit(init)


class BraxWorld(HostRowsWorld):
    """One scenario's runs (any Δt each) in one brax batch; raw rows are packed states. Its rollout takes
    every force (:func:`_mode_and_consts`; state-dependent ones evaluated inside the compiled loop:
    cross_checks.engines.jax_forces) and the decay; compilation is counted in ``host_s``."""

    def __init__(self, requests, variant: str):
        super().__init__(requests)
        self.lib = _usable()
        self.scenario, self.variant = requests[0].scenario, variant
        self.sys = _system_of(self.scenario, variant)
        self.dts = [float(r.dt_s) for r in requests]
        self.modes = [_mode_and_consts(self.scenario, variant, dt) for dt in self.dts]

    def rollout(self, n_steps, harness):
        """The states (n_steps, B, 13) after each step (NaN after a run's last step or its first chunk with
        a blown-up state); one step of one Δt from each row (the one-step mode) in one vmapped call."""
        from cross_checks.engines import jax_forces
        seconds = sum(_COMPILE_S.values())
        t0 = time.perf_counter()
        fa = jax_forces.BodyForces(harness)
        self.host_s += time.perf_counter() - t0
        try:
            if n_steps == 1 and len(set(self.dts)) == 1:
                return self._one(fa)[None]
            return self._run(n_steps, fa)
        finally:   # compiling is not stepping: counted apart, with the host's seconds
            self.host_s += sum(_COMPILE_S.values()) - seconds

    def _run(self, n_max: int, fa):
        from cross_checks.engines import jax_forces
        jp, n = self.lib["jp"], len(self.dts)
        mode = self.modes[0][0]
        B = runtimes.power_of_two(n)
        rows = runtimes.chunk_rows(B, CHUNK)
        pad = list(range(n)) + [0] * (B - n)
        dts = np.array([self.dts[i] for i in pad], dtype=float)
        consts = np.stack([self.modes[i][1] for i in pad])
        q0, qd0 = to_q_qd(self.y[0])    # every run starts at its scenario's state
        state = _initial(self.variant, B)(self.sys, jp.asarray(q0), jp.asarray(qd0))
        out = np.full((n_max, n, 13), np.nan)
        done = np.zeros(n, dtype=bool)
        args = (self.sys, state, jp.asarray(dts), jp.asarray(consts), fa.take(pad) if mode == "state" else {},
                jax_forces.zero(),
                jp.asarray(consts[0, 8]), np.int32(0))
        exe = _compiled("run", self.variant, mode, B, rows, args)
        k = 0
        while k < n_max and not done.all():
            m = min(rows, n_max - k)
            state, ys = exe(self.sys, state, *args[2:7], np.int32(m))
            ys = np.asarray(ys)
            out[k:k + m] = ys[:n, :m].transpose(1, 0, 2)
            bad = bad_rows(ys[:n, :m])
            done |= bad.any(axis=1) | (k + m >= np.array(self.ends))
            k += m
        return out

    def _one(self, fa):
        from cross_checks.engines import jax_forces
        jp, T = self.lib["jp"], len(self.y)
        mode, consts = self.modes[0]
        B = runtimes.power_of_two(max(T, ONE_STEP_MIN_BATCH))
        pad = np.concatenate([self.y, np.broadcast_to(self.scenario.problem.initial_packed(), (B - T, 13))])
        q, qd = to_q_qd(pad)
        args = (self.sys, jp.asarray(q), jp.asarray(qd), jp.full(B, self.dts[0]),
                jp.asarray(np.tile(consts, (B, 1))),
                fa.take(np.r_[np.arange(T), np.zeros(B - T, dtype=int)]) if mode == "state" else {},
                jax_forces.zero(), jp.asarray(consts[8]))
        exe = _compiled("one_step", self.variant, mode, B, 1, args)
        return np.array(exe(*args))[:T]


class BraxEngine(WorldEngine):
    """``brax:VARIANT`` — registered under the entry-point group ``rbcheck.engines``; optional
    (``pip install 'rbcheck[brax]'``)."""

    name = ENGINE
    variants = VARIANTS
    distribution = module = extra = "brax"
    mixed_steps = True     # a scenario's Δt ladder in one batch

    def version(self) -> str:   # from metadata: JAX must not start in a sweep's parent
        return version()

    def build(self, requests, variant, dt_s):
        return BraxWorld(requests, variant)

    def group_key(self, request) -> tuple:   # one System per world: one scenario
        return (id(request.scenario),)

    def engine_files(self) -> list:
        """brax's pipeline sources (found without importing brax)."""
        return install.package_files("brax", *(f"{d}/{f}" for d in ("generalized", "positional", "spring")
                                          for f in ("pipeline.py", "integrator.py")))

    @property
    def compile_seconds(self) -> dict:
        """Seconds spent compiling each executable in this process (see :func:`compile_seconds`)."""
        return compile_seconds()

    def expressible(self, scenario, variant: str) -> str:
        """Positional and spring take no force but gravity (:func:`expressible`); the harness's forces at the
        scenario's Δt decide (a constant force is the same at every Δt)."""
        return expressible(scenario, variant, scenario.dt_s)


_ENGINE = BraxEngine()
#: The module's functions (tests and scripts call them): the engine's, through the host loop.
simulate, simulate_many, one_step = _ENGINE.simulate, _ENGINE.simulate_many, _ENGINE.one_step
BraxAdapter = BraxEngine
