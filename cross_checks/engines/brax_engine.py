"""Brax (JAX) as an engine (``brax:VARIANT``), one variant per pipeline: a :class:`BraxWorld` of the host loop
whose compiled rollout takes every force. What each pipeline does, the defaults neutralised and what was
measured: docs/engine_conventions.md, "Brax 0.14.2".

Model: the scenario's free body as MJCF (:func:`mjcf_text`) loaded by ``brax.io.mjcf.loads``; a model MuJoCo's
compiler rejects is an EngineError with its words. State: ``pipeline.init(sys, q, qd)`` with ``q = [x_W, q_WB
(w x y z)]``, ``qd = [v_W, ω_B]`` (ω in body axes); read back from ``state.x.pos``, ``state.x.rot`` (w x y z),
``state.xd.vel`` and ``state.xd.ang`` (world axes). Forces: brax has no external-wrench input; the generalized
pipeline gets ``act = [f − m g, R_WBᵀ τ_W]`` through six actuators on the free joint's DOFs (brax applies
gravity) from the start-of-step state; the positional and spring pipelines take gravity only
(:func:`expressible`). The decay on ``qd`` before each step.
"""
from __future__ import annotations

import functools
import warnings

import numpy as np

from cross_checks.engines import base, forces, install, jax_forces, runtimes
from cross_checks.engines.base import EngineError, Traits, Variant
from cross_checks.engines.world import HostRowsWorld, body_spec  # the full tensor (MJCF ``fullinertia``)

__all__ = ["ENGINE", "VARIANTS", "CHUNK", "ONE_STEP_MIN_BATCH", "EngineError", "version", "timings",
           "mjcf_text", "build_system", "simulate", "simulate_many", "one_step", "BraxWorld", "BraxEngine",
           "BraxAdapter", "expressible", "body_spec"]

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


#: Steps of one call of the compiled loop at most (fewer for a batch of many runs: runtimes.chunk_rows).
CHUNK = 2048
#: one_step batches are padded to at least this many rows (a power of two): one step of 64 bodies costs about
#: what one costs, and every small batch shares one executable.
ONE_STEP_MIN_BATCH = 64


class BraxEngine(runtimes.JaxEngine):
    """``brax:VARIANT`` (entry point ``rbcheck.engines``; optional: ``pip install 'rbcheck[brax]'``)."""

    name, variants, distribution, module, extra = ENGINE, VARIANTS, "brax", "brax", "brax"
    runs_on = ("jax", "jax")
    imports = ("brax.io.mjcf", "cross_checks.engines.worlds.brax")   # the latter what rbcheck repro embeds
    quiet_warnings = True
    mixed_steps = True     # a scenario's Δt ladder in one batch

    def build(self, requests, variant, dt_s):
        return BraxWorld(requests, variant)

    def group_key(self, request) -> tuple:   # one System per world: one scenario
        return (id(request.scenario),)

    def engine_files(self) -> list:
        """brax's pipeline sources (found without importing brax)."""
        return install.package_files("brax", *(f"{d}/{f}" for d in ("generalized", "positional", "spring")
                                          for f in ("pipeline.py", "integrator.py")))

    def expressible(self, scenario, variant: str, dt_s: float | None = None) -> str:
        """"" when ``variant`` can take the scenario's forces at step ``dt_s`` (default the scenario's: a
        constant force is the same at every Δt), else why not (positional and spring: gravity only)."""
        if variant == "generalized":
            return ""
        fm, dt_s = scenario.problem.forces, scenario.dt_s if dt_s is None else dt_s
        why = (f"brax's {variant} pipeline takes no applied force but gravity ({variant}/joints.py gives a "
               "free joint zero actuator force and the pipeline has no other force input); this scenario "
               "has ")
        if fm.state_dependent:
            return why + "forces that depend on the state"
        f, tau = forces.harness_force_torque(scenario, scenario.problem.initial_packed(), dt_s)
        weight = forces.weight_W(scenario)
        if np.any(tau != 0.0) or not np.allclose(f, weight, rtol=1e-15, atol=0.0):
            return why + f"a force {np.round(f - weight, 6).tolist()} N besides the weight and a torque " \
                         f"{np.round(tau, 6).tolist()} N m"
        return ""


@functools.lru_cache(maxsize=1)
def _lib():
    """``jax``, ``jp`` (jax.numpy), ``mjcf``, ``world`` (cross_checks.engines.worlds.brax) and its
    ``pipelines``, imported on first use (:meth:`JaxEngine.modules`)."""
    jax, jp, mjcf, world = _ENGINE.modules()
    return {"jax": jax, "jp": jp, "mjcf": mjcf, "world": world, "pipelines": world.PIPELINES}


def __getattr__(name):
    """cross_checks.engines.worlds.brax's ``NEUTRAL_SYSTEM``, ``NEUTRAL_DOF``, ``neutralise``,
    ``six_dof_actuator``, ``to_q_qd`` and ``packed`` (brax imported then)."""
    if name in ("NEUTRAL_SYSTEM", "NEUTRAL_DOF", "neutralise", "six_dof_actuator", "to_q_qd", "packed"):
        return getattr(_lib()["world"], name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


# --- the model --------------------------------------------------------------------------------------------

def mjcf_text(scenario, dt_s: float, *, actuators: bool) -> str:
    """The scenario's free body as MJCF for ``brax.io.mjcf.loads`` (full-precision numbers):
    cross_checks.engines.worlds.brax's."""
    p = scenario.problem
    return _lib()["world"].mjcf_text(p.body.mass_kg, p.body.inertia_B, p.forces.gravity_W, dt_s, actuators)


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


# --- the compiled step ------------------------------------------------------------------------------------

def _step_fn(variant: str, mode: str):
    """One step of one body: ``(sys, state, consts, fa, zero, decay) -> state``. ``mode``: "none" (no applied
    force), "const" (consts = [f_W − m g, τ_W, γ_v, γ_ω, decay]), "state" (consts = [−m g, 0, γ_v, γ_ω,
    decay]; the forces jax_forces' of the body's arrays ``fa``, ``zero`` its traced integer zero, at the
    state after the decay, where the host callback it replaces evaluated them: the harness's definition is
    the state before it). With decay (1, unbatched: under vmap a batched predicate would make the
    ``lax.cond`` a select running both branches) the state is re-initialised from the decayed ``q, qd``."""
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


def _executable(kind: str, variant: str, mode: str, batch: int, rows: int, args):
    """The compiled ``run`` (a chunk of runs, ``rows`` steps recorded at most, the count traced) or
    ``one_step`` for these arguments."""
    lib = _lib()
    jax, W = lib["jax"], lib["world"]

    def with_dt(sys, dt):
        return sys.replace(opt=sys.opt.replace(timestep=dt))

    def make():
        step, P = _step_fn(variant, mode), lib["pipelines"][variant]
        if kind == "run":
            def run(sys, state, dt, consts, fa, z, decay, n):
                s = with_dt(sys, dt)
                loop = runtimes.recorded(lambda st: step(s, st, consts, fa, z, decay), W.packed, rows)
                return loop(state, n)
            return jax.vmap(run, in_axes=(None, 0, 0, 0, 0, None, None, None))

        def one(sys, q, qd, dt, consts, fa, z, decay):
            s = with_dt(sys, dt)
            return W.packed(step(s, P.init(s, q, qd), consts, fa, z, decay))
        return jax.vmap(one, in_axes=(None, 0, 0, 0, 0, 0, None, None))

    key = (kind, variant, mode, batch, rows, jax.tree_util.tree_structure(args))
    return _ENGINE.compiled(key, make, *args, name=f"{kind}:{variant}:{mode}:{batch}")


def _mode_and_consts(scenario, variant: str, dt_s: float):
    """``(mode, consts (9,))`` of the scenario's forces at step ``dt_s`` (see :func:`_step_fn`)."""
    why = _ENGINE.expressible(scenario, variant, dt_s)
    if why:
        raise EngineError(why)
    p, fm = scenario.problem, scenario.problem.forces
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


class BraxWorld(runtimes.JaxWorld, HostRowsWorld):
    """One scenario's runs (any Δt each) in one brax batch; raw rows are packed states. Its rollout takes
    every force (:func:`_mode_and_consts`) and the decay: the runs (their Δt ladder) vmapped through the
    compiled chunk loop, padded to a power of two (NaN after a run's last step or its first chunk with a
    blown-up state); one step of one Δt from each row (the one-step mode) in one vmapped call."""

    engine = BraxEngine

    def __init__(self, requests, variant: str):
        super().__init__(requests)
        _ENGINE.usable()
        self.lib = _lib()
        self.scenario, self.variant = requests[0].scenario, variant
        self.sys = _system_of(self.scenario, variant)
        self.dts = [float(r.dt_s) for r in requests]
        self.modes = [_mode_and_consts(self.scenario, variant, dt) for dt in self.dts]

    def run(self, n_steps, harness):
        fa = jax_forces.BodyForces(harness)
        if n_steps == 1 and len(set(self.dts)) == 1:
            return self._one(fa)[None]
        return self._run(n_steps, fa)

    def _run(self, n_max: int, fa):
        jp, n = self.lib["jp"], len(self.dts)
        mode = self.modes[0][0]
        B = runtimes.power_of_two(n)
        rows = runtimes.chunk_rows(B, CHUNK)
        pad = list(range(n)) + [0] * (B - n)
        dts = np.array([self.dts[i] for i in pad], dtype=float)
        consts = np.stack([self.modes[i][1] for i in pad])
        q0, qd0 = self.lib["world"].to_q_qd(self.y[0])    # every run starts at its scenario's state
        state = [_initial(self.variant, B)(self.sys, jp.asarray(q0), jp.asarray(qd0))]
        out = np.full((n_max, n, 13), np.nan)
        fargs = fa.take(pad) if mode == "state" else {}
        args = (self.sys, state[0], jp.asarray(dts), jp.asarray(consts), fargs, jax_forces.zero(),
                jp.asarray(consts[0, 8]), np.int32(0))
        exe = _executable("run", self.variant, mode, B, rows, args)

        def call(m):
            state[0], ys = exe(self.sys, state[0], *args[2:7], np.int32(m))
            return ys
        self.chunks(call, n_max, rows, list(range(n)), out)
        return out

    def _one(self, fa):
        jp, T = self.lib["jp"], len(self.y)
        mode, consts = self.modes[0]
        B = runtimes.power_of_two(max(T, ONE_STEP_MIN_BATCH))
        pad = np.concatenate([self.y, np.broadcast_to(self.scenario.problem.initial_packed(), (B - T, 13))])
        q, qd = self.lib["world"].to_q_qd(pad)
        args = (self.sys, jp.asarray(q), jp.asarray(qd), jp.full(B, self.dts[0]),
                jp.asarray(np.tile(consts, (B, 1))),
                fa.take(np.r_[np.arange(T), np.zeros(B - T, dtype=int)]) if mode == "state" else {},
                jax_forces.zero(), jp.asarray(consts[8]))
        exe = _executable("one_step", self.variant, mode, B, 1, args)
        with _ENGINE.stats.timing("step_seconds"):
            out = np.array(exe(*args))[:T]
        _ENGINE.stats["body_steps"] += T
        return out


_ENGINE = BraxEngine()
#: The module's functions (tests and scripts call them): the engine's, through the host loop.
simulate, simulate_many, one_step = _ENGINE.simulate, _ENGINE.simulate_many, _ENGINE.one_step
version, timings, expressible = _ENGINE.version, _ENGINE.timings, _ENGINE.expressible
BraxAdapter = BraxEngine
