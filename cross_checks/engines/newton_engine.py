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

:class:`NewtonWorld`: the runs of one Δt as the bodies of models of at most MAX_BATCH bodies (one for
``mujoco_cpu``: MuJoCo C takes one world); the loop's forces (the weight taken off: Newton applies gravity per
world) go into ``State.body_f`` of each step's input state, the decay scales the float32 velocities before
the step. Warp and Newton are imported on first use only (never at import or in ``version()``).
"""
from __future__ import annotations

import dataclasses
import functools
import threading
import time
import warnings

import numpy as np

from cross_checks.engines import base, install, runtimes
from cross_checks.engines.base import EngineError, Traits, Variant
from cross_checks.engines.install import installed_version
from cross_checks.engines.world import World, WorldEngine

__all__ = ["ENGINE", "VARIANTS", "SOLVERS", "SOLVER_SETTINGS", "EngineError", "version", "simulate",
           "simulate_many", "one_step", "build_model", "make_solver", "compile_stats", "to_newton_rows",
           "from_newton_rows", "NewtonWorld", "NewtonAdapter", "PIP_HINT"]

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

#: The solver class of each variant (``newton.solvers.<name>``).
SOLVERS = {"semi_implicit": "SolverSemiImplicit", "xpbd": "SolverXPBD", "featherstone": "SolverFeatherstone",
           "mujoco_cpu": "SolverMuJoCo"}

#: Constructor arguments of each solver: every default that is not the scenario's physics, set explicitly
#: (Newton 1.8.0's defaults: docs/engine_conventions.md, "Newton 1.8.0").
SOLVER_SETTINGS = {
    "semi_implicit": {"angular_damping": 0.0},
    "xpbd": {"angular_damping": 0.0, "iterations": 2, "enable_restitution": False},
    "featherstone": {"angular_damping": 0.0, "update_mass_matrix_interval": 1},
    "mujoco_cpu": {"use_mujoco_cpu": True, "integrator": "implicitfast", "disable_contacts": True,
                   "kinematic_switchable_roots": False},
}

#: Variants whose state is Newton's generalized coordinates (``joint_q``/``joint_qd`` of a FREE joint).
_GENERALIZED = frozenset({"featherstone", "mujoco_cpu"})
#: Variants whose model takes one body only (SolverMuJoCo on MuJoCo C refuses a model of several worlds).
_ONE_BODY = frozenset({"mujoco_cpu"})

MAX_BATCH = 256   # bodies (runs or rows) per model: more run as several models

_LOCK = threading.RLock()


def _check_installed() -> None:   # install.check_installed for this engine and the Warp it runs on
    install.check_installed(_DIST, PIP_HINT, (("warp", "warp-lang"),), installed_version)


def version() -> str:
    """Newton's version and the Warp release it runs on, e.g. ``1.8.0 (warp 1.19.0)``, from package metadata
    (EngineNotInstalled when newton is absent)."""
    _check_installed()
    return install.release(_DIST, ("warp", "warp-lang"))


@functools.lru_cache(maxsize=1)
def _engine():
    """``(warp, newton)``, imported on first use (runtimes.start_warp: the kernel cache in
    ``kernel_cache_dir("newton")``, the device banner and module loads off). ImportError with the engine's
    words when the import fails."""
    _check_installed()
    with install.first_import(_DIST, installed_version):
        wp = runtimes.start_warp(ENGINE, "LOG_WARNING", quiet=True)
        import newton
    return wp, newton


_WARM: dict = {}    # variant -> seconds its first model build and step took (kernel compile or cache load)
_STATS = runtimes.Stats(compilations=0, compile_seconds=0.0, build_seconds=0.0, step_seconds=0.0,
                        body_steps=0)


def compile_stats() -> dict:
    """This process's Newton costs so far: ``compilations`` (variants warmed up: their kernel modules
    compiled by Warp, or loaded from its cache), ``compile_seconds`` (wall s of those warm-ups: a one-body
    model's finalize, the solver's construction and one step), ``per_variant`` (the same per variant), and
    apart from it ``build_seconds`` (model building of the runs), ``step_seconds`` (wall s of the worlds'
    steps) and ``body_steps`` (steps × bodies they advanced)."""
    return {**_STATS, "per_variant": dict(_WARM)}


def _warm(variant: str) -> None:
    """Compile (or load) every kernel module ``variant`` uses, once per process, timed apart from the runs."""
    if variant in _WARM:
        return
    wp, newton = install.engine_or_error(_engine)
    t0 = time.perf_counter()
    model = build_model(variant, [(1.0, np.eye(3), np.zeros(3))])
    solver = make_solver(variant, model)
    s0, s1 = model.state(), model.state()
    solver.step(s0, s1, None, None, 1e-3)
    wp.synchronize()
    _WARM[variant] = time.perf_counter() - t0
    _STATS["compilations"] += 1
    _STATS["compile_seconds"] += _WARM[variant]


def build_model(variant: str, bodies):
    """A finalized Newton model on the CPU with one world per body of ``bodies`` (``(mass, I_B (3, 3),
    gravity_W (3,))`` each): jointless links for the maximal-coordinate solvers, FREE-jointed bodies for
    Featherstone; com = 0, no shape. EngineError when ``finalize`` did not keep the mass or the inertia (its
    inertia validation corrects a tensor it finds non-physical)."""
    wp, newton = install.engine_or_error(_engine)
    builder = newton.ModelBuilder(gravity=(0.0, 0.0, 0.0))
    add = builder.add_body if variant in _GENERALIZED else builder.add_link
    for mass, inertia, gravity in bodies:
        builder.begin_world(gravity=tuple(float(g) for g in gravity))
        add(xform=wp.transform(wp.vec3(0.0, 0.0, 0.0), wp.quat_identity()), com=wp.vec3(0.0, 0.0, 0.0),
            mass=float(mass), inertia=wp.mat33(*(float(v) for v in np.asarray(inertia, dtype=float).ravel())))
        builder.end_world()
    try:
        # skip_validation_inertia: finalize would otherwise "correct" a tensor it finds non-physical (another
        # body); rbcheck's own body check has already refused a bad one
        with warnings.catch_warnings():
            warnings.simplefilter("error", category=UserWarning)
            model = builder.finalize(device="cpu", skip_validation_inertia=True)
    except Exception as exc:  # noqa: BLE001 - Newton refuses the model: its own words
        raise EngineError(f"Newton {version()} refused the model: {type(exc).__name__}: {exc}") from None
    want_m = np.array([b[0] for b in bodies], dtype=np.float32)
    want_i = np.array([np.asarray(b[1], dtype=float) for b in bodies], dtype=np.float32)
    if not (np.array_equal(model.body_mass.numpy(), want_m)
            and np.array_equal(model.body_inertia.numpy(), want_i)):
        raise EngineError(f"Newton {version()} changed the body's mass or inertia when finalizing the model")
    return model


def make_solver(variant: str, model):
    """The variant's Newton solver for ``model``, every setting of SOLVER_SETTINGS applied."""
    _, newton = install.engine_or_error(_engine)
    base.check_variant(ENGINE, VARIANTS, variant)
    with warnings.catch_warnings():
        # SolverMuJoCo warns that MuJoCo 4.0.0 is not the ~=3.17.0 Newton declares (rbcheck pins 4.0.0)
        warnings.filterwarnings("ignore", message="MuJoCo dependency version mismatch")
        try:
            solver = getattr(newton.solvers, SOLVERS[variant])(model, **SOLVER_SETTINGS[variant])
        except (ImportError, ValueError) as exc:   # a missing backend, a model it refuses: its own words
            hint = f" ({PIP_HINT} installs mujoco-warp)" if isinstance(exc, ImportError) else ""
            raise EngineError(f"Newton {version()}'s {SOLVERS[variant]} refused the model: "
                              f"{type(exc).__name__}: {exc}{hint}") from None
    if variant == "mujoco_cpu":
        # MuJoCo resets a run whose acceleration is non-finite or huge to the model's initial state
        # (autoreset, with a warning): a blow-up would continue from rest; off: divergence is seen
        import mujoco
        solver.mj_model.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_AUTORESET)
    return solver


def to_newton_rows(y):
    """Packed states (N, 13) ``[x_W, v_W, q_WB (w x y z), ω_W]`` -> ``(q (N, 7) [x, qx, qy, qz, qw],
    qd (N, 6) [v_COM, ω], both world axes)``, float64 (the caller casts)."""
    y = np.asarray(y, dtype=float).reshape(-1, 13)
    q = np.concatenate([y[:, 0:3], y[:, 7:10], y[:, 6:7]], axis=1)
    qd = np.concatenate([y[:, 3:6], y[:, 10:13]], axis=1)
    return q, qd


def from_newton_rows(q, qd):
    """Newton's ``(q (..., 7) [x, qx, qy, qz, qw], qd (..., 6) [v, ω])`` -> packed (..., 13), float64."""
    q = np.asarray(q, dtype=float)
    qd = np.asarray(qd, dtype=float)
    return np.concatenate([q[..., 0:3], qd[..., 0:3], q[..., 6:7], q[..., 3:6], qd[..., 3:6]], axis=-1)


class _Batch:
    """Bodies stepping together in one model: its solver, two states (swapped each step) and their zero-copy
    NumPy views of the pose (N, 7), velocity (N, 6) and applied wrench (N, 6) (float32)."""

    def __init__(self, variant: str, bodies):
        with _STATS.timing("build_seconds"):
            self.model = build_model(variant, bodies)
            self.solver = make_solver(variant, self.model)
            self.states = [self.model.state(), self.model.state()]
        q, qd = ("joint_q", "joint_qd") if variant in _GENERALIZED else ("body_q", "body_qd")
        self.views = [(getattr(s, q).numpy().reshape(-1, 7), getattr(s, qd).numpy().reshape(-1, 6),
                       s.body_f.numpy()) for s in self.states]   # (q, qd, f) of each state

    def step(self, dt_s: float) -> None:
        self.solver.step(self.states[0], self.states[1], None, None, dt_s)
        self.states.reverse()
        self.views.reverse()


class NewtonWorld(World):
    """The bodies of ``requests`` (one Δt) as :class:`_Batch` models, under the module's lock (held by the
    caller, released by close). Raw rows: ``[q (x, q_xyzw), qd (v, ω)]`` (13 float32 values), world axes."""

    exact_start = True   # the float32 round trip of the scenario's state is not the state

    def __init__(self, requests, variant: str, dt_s: float):
        super().__init__()
        self.dt_s, size = float(dt_s), 1 if variant in _ONE_BODY else MAX_BATCH
        bodies = [(float(r.scenario.problem.body.mass_kg), np.asarray(r.scenario.problem.body.inertia_B),
                   np.asarray(r.scenario.problem.forces.gravity_W, dtype=float)) for r in requests]
        self.parts = [(slice(s, s + size), _Batch(variant, bodies[s:s + size]))
                      for s in range(0, len(bodies), size)]
        self.mujoco = None
        if variant == "mujoco_cpu":
            # MuJoCo's warnings ("Nan, Inf or huge value in QACC": the loop's divergence) to a handler until
            # close(), else MuJoCo prints them and writes MUJOCO_LOG.TXT in the working directory
            import mujoco
            self.mujoco, self.prev = mujoco, mujoco.get_mju_user_warning()
            mujoco.set_mju_user_warning(lambda msg: None)

    def set_state(self, y):
        q, qd = to_newton_rows(y)
        for part, b in self.parts:
            b.views[0][0][:], b.views[0][1][:] = q[part], qd[part]

    def apply(self, f_W, tau_W):   # into the input state's body_f (float32), for the next step
        for part, b in self.parts:
            f = b.views[0][2]
            f[:, 0:3], f[:, 3:6] = f_W[part], tau_W[part]

    def decay(self, g_v, g_w):   # the float32 velocities scaled in float64, rounded to float32
        for part, b in self.parts:
            qd = b.views[0][1]
            qd[:, 0:3] *= g_v[part, None]
            qd[:, 3:6] *= g_w[part, None]

    def step(self):
        t0 = time.perf_counter()
        for _, b in self.parts:
            b.step(self.dt_s)
        _STATS["step_seconds"] += time.perf_counter() - t0
        _STATS["body_steps"] += sum(len(b.views[0][0]) for _, b in self.parts)

    def read(self):
        return np.concatenate([np.concatenate(b.views[0][0:2], axis=1) for _, b in self.parts]).astype(float)

    def packed(self, raw):
        raw = np.asarray(raw, dtype=float)
        return from_newton_rows(raw[..., 0:7], raw[..., 7:13])

    def close(self):
        if self.mujoco is not None:
            self.mujoco.set_mju_user_warning(self.prev)
        _LOCK.release()


class NewtonEngine(WorldEngine):
    """``newton:VARIANT`` — registered under the entry-point group ``rbcheck.engines``; optional
    (``pip install 'rbcheck[newton]'``)."""

    name, variants, distribution, extra = ENGINE, VARIANTS, _DIST, "newton"
    sign_continuity = True   # the recorded quaternion kept on the previous one's side

    version = staticmethod(version)   # the module's: from package metadata, Warp not started

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
#: The module's functions (tests and scripts call them): the engine's, through the host loop.
simulate, simulate_many, one_step = _ENGINE.simulate, _ENGINE.simulate_many, _ENGINE.one_step
NewtonAdapter = NewtonEngine
