"""Newton (``newton``, the physics engine on NVIDIA Warp) as an engine (``newton:VARIANT``): a world of
bodies for rbcheck's loop (cross_checks.engines.world, cross_checks.engines.loop). What each solver does, the
defaults neutralised (SOLVER_SETTINGS) and what was measured: docs/engine_conventions.md, "Newton 1.8.0".

Float32 on Warp's CPU device (state, model and Δt are ``wp.float32``: every variant's ``Traits``); kernels
compiled into ``core.files.kernel_cache_dir("newton")``. Model (:func:`build_model`): one world per body, each
with its own gravity; ``com = 0`` (body origin = COM), the scenario's mass and full inertia tensor (about the
COM, body axes), checked after ``finalize``; no shape. ``semi_implicit`` and ``xpbd`` step jointless links
(``State.body_q``/``body_qd``), ``featherstone`` and ``mujoco_cpu`` a FREE joint (``joint_q``/``joint_qd``).
State at the boundary (:func:`to_newton_rows`, :func:`from_newton_rows`): ``[x_W, q_WB (x, y, z, w)]`` (Warp
quaternions are xyzw) and ``[v_W (COM), ω_W]``, linear first, both world axes.

The model, solvers, views and conversions are cross_checks/engines/worlds/newton.py's (NumPy, Warp and Newton
only: what ``rbcheck repro`` embeds). :class:`NewtonWorld`: the runs of one Δt as the bodies of models of at
most MAX_BATCH bodies (one for ``mujoco_cpu``: MuJoCo C takes one world); the loop's forces (the weight taken
off: Newton applies gravity per world) go into ``State.body_f`` of each step's input state, the decay scales
the float32 velocities before the step. Warp and Newton are imported on first use only (never at import or in
``version()``).
"""
from __future__ import annotations

import dataclasses
import threading
import time

import numpy as np

from cross_checks.engines import base, install, runtimes
from cross_checks.engines.base import EngineError, Traits, Variant
from cross_checks.engines.world import World, body_spec  # Newton takes the full tensor (add_body's inertia)
from cross_checks.engines.worlds import newton as nw  # numpy only at import: Warp and Newton on first use

__all__ = ["ENGINE", "VARIANTS", "SOLVERS", "SOLVER_SETTINGS", "EngineError", "version", "simulate",
           "simulate_many", "one_step", "build_model", "make_solver", "compile_stats", "to_newton_rows",
           "from_newton_rows", "body_spec", "start_for_repro", "NewtonWorld", "NewtonAdapter", "PIP_HINT"]

ENGINE = "newton"
_DIST = "newton"
PIP_HINT = "pip install 'rbcheck[newton]'"

#: Semi-implicit Euler with an explicit gyroscopic term in body axes before the attitude update, in float32.
_SYMPLECTIC_F32 = Traits(rotation_drift="body", rotation_sign=+1, precision="float32")
#: SemiImplicit's and XPBD's step takes ω to body axes and back with Warp's ``quat_rotate_inv`` and
#: ``quat_rotate``, exact for a unit quaternion only: it rounds ω one way over a run, within two ordinary
#: steps' rounding.
_SYMPLECTIC_F32_BODY_AXES_ROUND_TRIP = dataclasses.replace(_SYMPLECTIC_F32, rounding_factor=2.0)

#: Newton's solvers that step a free rigid body, all first order (symplectic Euler; XPBD integrates the bodies
#: with the same kernel before its constraint iterations, Macklin et al. 2016).
VARIANTS = {
    "semi_implicit": Variant(1, "Newton SolverSemiImplicit: symplectic Euler, explicit gyroscopic term in "
                                "body axes, quaternion q + ½Δt ω⊗q normalised (float32)",
                             traits=_SYMPLECTIC_F32_BODY_AXES_ROUND_TRIP),
    "xpbd": Variant(1, "Newton SolverXPBD: the same symplectic Euler body integration, then position-based "
                       "constraint iterations (none for a free body without contact) (float32)",
                    traits=_SYMPLECTIC_F32_BODY_AXES_ROUND_TRIP),
    "featherstone": Variant(1, "Newton SolverFeatherstone: articulated dynamics in world-origin spatial "
                               "coordinates on a FREE joint, symplectic Euler, quaternion q + ½Δt ω⊗q "
                               "normalised (float32)",
                            traits=_SYMPLECTIC_F32),
    # MuJoCo C's float64 implicitfast step (Newton's default integrator) on Newton's float32 state, copied in
    # and out every step: mujoco:implicitfast's traits
    "mujoco_cpu": Variant(1, "Newton SolverMuJoCo on MuJoCo C (use_mujoco_cpu): implicitfast, Newton's "
                             "default integrator, the state copied from and back to Newton's float32 every "
                             "step",
                          traits=Traits(rotation_drift="body", rotation_sign=-1, precision="float32")),
}

#: The solver class and the settings of each variant, and the state conversions: the world's (what ``rbcheck
#: repro`` embeds, cross_checks/engines/worlds/newton.py).
SOLVERS, SOLVER_SETTINGS = nw.SOLVERS, nw.SOLVER_SETTINGS
to_newton_rows, from_newton_rows = nw.to_newton_rows, nw.from_newton_rows

MAX_BATCH = 256   # bodies (runs or rows) per model: more run as several models

_LOCK = threading.RLock()


#: This process's Newton costs (:func:`compile_stats`, with ``per_variant``: the seconds of each variant's
#: warm-up): ``compilations`` (variants warmed up: their kernel modules compiled by Warp, or loaded from its
#: cache), ``compile_seconds`` (wall s of those warm-ups: a one-body model's finalize, the solver's
#: construction and one step), and apart from it ``build_seconds`` (model building of the runs),
#: ``step_seconds`` (wall s of the worlds' steps) and ``body_steps`` (steps × bodies they advanced).
_STATS = runtimes.Stats(compilations=0, compile_seconds=0.0, build_seconds=0.0, step_seconds=0.0,
                        body_steps=0)


def compile_stats() -> dict:
    return {**_STATS, "per_variant": dict(NewtonEngine.warmed)}


def _warm(variant: str) -> None:
    """Compile (or load) every kernel module ``variant`` uses, once per process, timed apart from the runs."""
    wp, newton = install.engine_or_error(_engine)

    def load():
        model = build_model(variant, [(1.0, np.eye(3), np.zeros(3))])
        solver, s0, s1 = make_solver(variant, model), model.state(), model.state()
        solver.step(s0, s1, None, None, 1e-3)
        wp.synchronize()
    _ENGINE.warm(variant, load)


def build_model(variant: str, bodies):
    """A finalized Newton model on the CPU with one world per body of ``bodies`` (``(mass, I_B (3, 3),
    gravity_W (3,))`` each): the world's (:func:`cross_checks.engines.worlds.newton.build_model`); EngineError
    when ``finalize`` failed or did not keep the mass or the inertia (its inertia validation corrects a
    tensor it finds non-physical)."""
    install.engine_or_error(_engine)
    try:
        return nw.build_model(variant, bodies)
    except nw.Refused as exc:
        raise _refused(exc) from None


def make_solver(variant: str, model):
    """The variant's Newton solver for ``model``, every setting of SOLVER_SETTINGS applied (the world's)."""
    install.engine_or_error(_engine)
    base.check_variant(ENGINE, VARIANTS, variant)
    try:
        return nw.make_solver(variant, model)
    except nw.Refused as exc:
        raise _refused(exc) from None


def _refused(exc) -> EngineError:
    """The world's refusal as the engine's error: Newton's version (``'s`` solver) and its words, and what
    to install when a backend is missing."""
    hint = f" ({PIP_HINT} installs mujoco-warp)" if exc.backend else ""
    whose = "'s" if exc.solver else ""
    return EngineError(f"Newton {version()}{whose} {exc}{hint}")


class NewtonWorld(nw.Bodies, World):
    """The bodies of ``requests`` (one Δt) as the world's models of at most MAX_BATCH bodies
    (:class:`cross_checks.engines.worlds.newton.Bodies`, what ``rbcheck repro`` embeds), under the module's
    lock (held by the caller, released by close). Raw rows: ``[q (x, q_xyzw), qd (v, ω)]`` (13 float32
    values), world axes."""

    exact_start = True   # the float32 round trip of the scenario's state is not the state

    def __init__(self, requests, variant: str, dt_s: float):
        World.__init__(self)
        bodies = [(float(r.scenario.problem.body.mass_kg), np.asarray(r.scenario.problem.body.inertia_B),
                   np.asarray(r.scenario.problem.forces.gravity_W, dtype=float)) for r in requests]
        try:
            with _STATS.timing("build_seconds"):
                nw.Bodies.__init__(self, variant, bodies, dt_s, MAX_BATCH)
        except nw.Refused as exc:
            raise _refused(exc) from None
        self.mujoco = None
        if variant == "mujoco_cpu":
            # MuJoCo's warnings ("Nan, Inf or huge value in QACC": the loop's divergence) to a handler until
            # close(), else MuJoCo prints them and writes MUJOCO_LOG.TXT in the working directory
            import mujoco
            self.mujoco, self.prev = mujoco, mujoco.get_mju_user_warning()
            mujoco.set_mju_user_warning(lambda msg: None)

    def step(self):
        t0 = time.perf_counter()
        nw.Bodies.step(self)
        _STATS["step_seconds"] += time.perf_counter() - t0
        _STATS["body_steps"] += sum(len(b.views[0][0]) for _, b in self.parts)

    def close(self):
        if self.mujoco is not None:
            self.mujoco.set_mju_user_warning(self.prev)
        _LOCK.release()


class NewtonEngine(runtimes.WarpEngine):
    """``newton:VARIANT`` — registered under the entry-point group ``rbcheck.engines``; optional
    (``pip install 'rbcheck[newton]'``)."""

    name, variants, distribution, extra = ENGINE, VARIANTS, _DIST, "newton"
    imports, warp_quiet, stats = ("newton",), True, _STATS   # Warp's device banner and module loads off
    sign_continuity = True   # the recorded quaternion kept on the previous one's side

    def build(self, requests, variant, dt_s):
        _LOCK.acquire()
        try:
            _warm(variant)
            return NewtonWorld(requests, variant, dt_s)
        except BaseException:
            _LOCK.release()
            raise

    def group_key(self, request) -> tuple:
        """One world per Δt, runs of any length (the bodies of a model are independent worlds)."""
        return (float(request.dt_s),)

    def engine_files(self) -> list:
        """Newton's solver sources (found without importing Newton or Warp)."""
        return install.package_files("newton", *(f"_src/{p}" for p in (
            "solvers/solver.py", "solvers/semi_implicit", "solvers/xpbd", "solvers/featherstone",
            "solvers/mujoco", "sim/builder.py", "sim/model.py", "sim/state.py")))


_ENGINE = NewtonEngine()
#: The module's functions (tests and scripts call them): the engine's (``_engine()``: ``(warp, newton)``).
simulate, simulate_many, one_step = _ENGINE.simulate, _ENGINE.simulate_many, _ENGINE.one_step
version, _engine, start_for_repro = _ENGINE.version, _ENGINE.modules, _ENGINE.start_for_repro
NewtonAdapter = NewtonEngine
