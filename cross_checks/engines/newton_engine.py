"""Newton (``newton``, NVIDIA/Disney/DeepMind's physics engine on NVIDIA Warp) as an engine adapter
(``newton:VARIANT``); the interface is cross_checks.engines.base.

Precision: FLOAT32. Newton's state (``State.body_q``, ``body_qd``, ``joint_q``, ``joint_qd``), its model
(mass, inertia, gravity) and the step size it passes to its kernels are Warp ``float32``; every variant
declares ``Traits(precision="float32")`` (docs/verdicts.md §7). The device is Warp's CPU (``"cpu"``): the
kernels are compiled to native code by Warp's bundled LLVM/Clang, once per module, and cached in
``core.files.kernel_cache_dir("newton")`` (``wp.config.kernel_cache_dir``, set before Warp initialises).

Model (:func:`build_model`): a ``newton.ModelBuilder(gravity=(0, 0, 0))`` with ONE WORLD PER BODY
(``begin_world(gravity=g)``: each world its own gravity vector, so runs of different scenarios share one
model); each body has ``com = 0`` (body origin = centre of mass, so the recorded position and velocity are
the COM's), ``mass`` and ``inertia`` = the scenario's tensor about the COM in body axes (a full 3×3 taken as
given; what ``finalize`` stored is checked against it, to float32). No shape (nothing to collide with, no
ground), no particle, no spring.

* ``semi_implicit`` and ``xpbd`` (maximal coordinates: ``State.body_q``/``body_qd``): a body WITHOUT a joint
  (``ModelBuilder.add_link``). Newton's ``add_body`` adds a FREE joint, and with any joint
  ``SolverXPBD`` applies its (zero) joint corrections through ``apply_body_deltas``, which sets every linear
  or angular velocity below 1e-4 to exactly zero ("this improves gradient stability",
  newton/_src/solvers/xpbd/kernels.py) — a body released near rest, or whose ω passes through zero, would
  stop. A jointless body is free in both solvers (they integrate ``body_q`` whatever the joints). Pinned.
* ``featherstone`` (generalized coordinates: ``State.joint_q``/``joint_qd``): ``add_body`` (a FREE joint to
  the world, its own articulation); the state goes in and out through ``joint_q`` =
  ``[x_W, q_WB (x y z w)]`` and ``joint_qd`` = ``[v_COM (world), ω (world)]`` (Newton's public FREE joint
  convention), the solver converting them to its internal origin-based spatial velocity every step.

State mapping (docs/engine_conventions.md "Newton 1.8.0", pinned by
tests/cross_checks/engines/test_newton_engine.py): ``body_q`` = ``[p, q (x, y, z, w)]`` — Warp quaternions
are (x, y, z, w), converted at the boundary only; ``body_qd`` = ``[v, ω]`` — LINEAR FIRST, the COM's
velocity and ω both in WORLD axes; ``body_f`` = ``[f, τ]`` — a world force at the COM and a world torque
about the COM.
The recorded quaternion is made sign-continuous from the scenario's initial one.

The steps (each read in Newton 1.8.0's source; every one first order):

* ``SolverSemiImplicit`` (solvers/solver.py ``integrate_rigid_body``): ``v += Δt (f/m + g)``,
  ``x += Δt v⁺``; ``ω_B += Δt I⁻¹(τ_B − ω_B × I ω_B)`` in body axes at the start attitude
  (explicit gyroscopic term), ``q ← normalize(q + ½ Δt [ω⁺_W, 0] ⊗ q)``; then
  ``ω ← (1 − angular_damping Δt) ω``.
* ``SolverXPBD`` (solvers/xpbd/solver_xpbd.py ``step``): the same ``integrate_bodies`` kernel, then its
  constraint iterations — nothing to solve for a jointless body without contacts.
* ``SolverFeatherstone`` (solvers/featherstone/kernels.py ``jcalc_integrate``, FREE joint): the
  composite-rigid-body mass matrix and ``qdd = M⁻¹(τ − C)`` in world-origin spatial coordinates (the
  gyroscopic term in the bias force, explicit), then ``ω += Δt α``, ``v_COM += Δt a_COM``,
  ``q ← normalize(q + ½ Δt [ω⁺, 0] ⊗ q)``, ``x_COM += Δt v⁺_COM``.
* ``SolverMuJoCo(use_mujoco_cpu=True)`` (solvers/mujoco/solver_mujoco.py ``step``), variant ``mujoco_cpu``:
  Newton's float32 ``joint_q``/``joint_qd``/``body_f`` copied into MuJoCo C's MjData before every step,
  ``mj_step`` (float64) with Newton's default integrator implicitfast (implicit gyroscopic term), and back to
  float32. MuJoCo C takes one world: one body per model. Its autoreset is turned off (a blow-up would restart
  from rest) and its warnings go to a handler during runs (no MUJOCO_LOG.TXT). It needs ``mujoco_warp``
  installed (imported even on MuJoCo C; the extra pins it).

Forces (harness semantics of base.py): Newton applies gravity itself (per world); every step the harness's
world force at the COM minus the weight ``m g`` and the world torque go into ``State.body_f`` of the step's
input state, evaluated from the start-of-step state (state-dependent ones by the package's force model,
``step_floats.harness_fn``, on the host); velocity decay ``e^{−kΔt}`` is applied to the state's velocities
before the step (base.apply_decay_prestep), that step's force and torque scaled alike.

Defaults that are not the scenario's physics, each neutralised explicitly (SOLVER_SETTINGS, pinned): the
angular damping of SemiImplicit and Featherstone (0.05 by default) and XPBD (0), XPBD's restitution (its
velocity-from-position-deltas is off by default, deprecated, pinned), Featherstone's mass-matrix update
interval (1: every step); gravity (the builder's default is −9.81 along z); ``finalize``'s inertia validation
(``skip_validation_inertia=True``: by default it shifts the eigenvalues of a tensor with I1 + I2 < I3 or a
small I1 — another body); no shape, so no contact nor ground; the free joint's armature, friction, target and
limit gains are zero and its limits ±1e10 by default (pinned). Newton has no sleeping, no velocity clamp for
rigid bodies (``particle_max_velocity`` acts on particles only) and no substeps in these solvers.

Batching (:func:`simulate_many`): the runs of one call that share a Δt step together, one body (one world)
each, in one model — a ladder's rungs have different Δt and run one after another, the fuzz's cases at one
rung run together; :func:`one_step` steps its rows as that many bodies of one model. The Python loop calls
``solver.step`` once per step (Warp's CPU launches cannot be captured in a graph), reading and writing the
state through NumPy views of Warp's CPU arrays (no copy).

Compile time: Warp compiles (or loads from its cache) each kernel module on first launch. The first use of a
variant in a process builds a one-body model and takes one step outside any run, timed apart:
:func:`compile_stats`.

Divergence: Newton neither warns nor stops; the first recorded state that is non-finite or has a component
beyond BLOWUP_LIMIT ends the run as ``diverged at t = …``.
"""
from __future__ import annotations

import dataclasses
import functools
import os
import sys
import threading
import time
import warnings

import numpy as np

from cross_checks.core.files import kernel_cache_dir
from cross_checks.engines import base
from cross_checks.engines.base import EngineError, ModuleAdapter, Traits, Variant, installed_version
from cross_checks.engines.step_floats import harness_fn
from reference_sim.quaternion import sign_continuous
from reference_sim.simulate import Run, bad_rows, diverged, recorded_run

__all__ = ["ENGINE", "VARIANTS", "SOLVERS", "SOLVER_SETTINGS", "EngineError", "version", "simulate",
           "simulate_many", "one_step", "build_model", "make_solver", "compile_stats", "to_newton_rows",
           "from_newton_rows", "NewtonAdapter", "PIP_HINT"]

ENGINE = "newton"
_DIST = "newton"
PIP_HINT = "pip install 'rbcheck[newton]'"

#: Semi-implicit Euler with an explicit gyroscopic term in body axes before the attitude update (energy and
#: |L|² drift together, a phase error; the explicit term makes the energy grow), computed in float32.
_SYMPLECTIC_F32 = Traits(rotation_drift="body", rotation_sign=+1, precision="float32")
#: SemiImplicit's and XPBD's step (``integrate_rigid_body``) takes ω to body axes and back with Warp's
#: ``quat_rotate_inv``/``quat_rotate``, whose ``c = 2w² − 1`` is exact for a unit quaternion only: a vector
#: along the rotation axis comes back as ``(2|q|² − 1) v``, so every step scales ω by ≈ (1 + 2δ)²,
#: δ = |q|² − 1 as float32 ``normalize`` left it — not zero on average (measured +0.4 ε or −0.5 ε over a run,
#: depending on the motion). On spins about a principal axis, where the exact step keeps |ω|, measured: |ω|
#: moves by 0.4–1.8 ε per step on average, ALWAYS THE SAME WAY over a run (the floors' one-sided term allows
#: 1 ε), and by up to 18.8 u in one step (the one-step allowance: CHECK_ROUNDINGS_PER_STEP = 16 u). Two
#: ordinary steps' rounding covers both
#: (test_semi_implicit_rounds_omega_one_way_more_than_an_ordinary_step_and_within_its_factor); Featherstone
#: (ω stays in world axes) and MuJoCo C (float64 inside) stay within one.
_SYMPLECTIC_F32_BODY_AXES_ROUND_TRIP = dataclasses.replace(_SYMPLECTIC_F32, rounding_factor=2.0)

#: Newton's solvers that step a free rigid body, their orders from Newton's documentation and source
#: (SolverSemiImplicit: "A semi-implicit integrator using symplectic Euler"; SolverXPBD integrates the bodies
#: with the same kernel before its position-based constraint iterations (Macklin et al. 2016, first order);
#: SolverFeatherstone's FREE joint: "symplectic Euler" in jcalc_integrate), and their traits (module
#: docstring).
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
    # SolverMuJoCo(use_mujoco_cpu=True) copies Newton's float32 state into MuJoCo's MjData before every step
    # and back after it (update_data_interval 1): MuJoCo C's float64 step on a float32 state. Newton's own
    # default integrator is implicitfast (MuJoCo's documentation: first order; an implicit gyroscopic term,
    # the traits of mujoco:implicitfast)
    "mujoco_cpu": Variant(1, "Newton SolverMuJoCo on MuJoCo C (use_mujoco_cpu): implicitfast, Newton's "
                             "default "
                             "integrator, the state copied from and back to Newton's float32 every step",
                          traits=Traits(rotation_drift="body", rotation_sign=-1, precision="float32")),
}

#: The solver class of each variant (``newton.solvers.<name>``).
SOLVERS = {"semi_implicit": "SolverSemiImplicit", "xpbd": "SolverXPBD", "featherstone": "SolverFeatherstone",
           "mujoco_cpu": "SolverMuJoCo"}

#: Constructor arguments of each solver: every default that is not the scenario's physics, set explicitly
#: (Newton 1.8.0's defaults in the comments; pinned by the tests).
SOLVER_SETTINGS = {
    # angular_damping 0.05 (ω ← (1 − 0.05 Δt) ω every step)
    "semi_implicit": {"angular_damping": 0.0},
    # angular_damping 0.0, iterations 2 (constraint iterations, not substeps: nothing to solve here),
    # enable_restitution False
    "xpbd": {"angular_damping": 0.0, "iterations": 2, "enable_restitution": False},
    # angular_damping 0.05 (stored, unused by 1.8.0's step), update_mass_matrix_interval 1
    "featherstone": {"angular_damping": 0.0, "update_mass_matrix_interval": 1},
    # MuJoCo C (not mujoco_warp), Newton's default integrator named, no contact (there is no geom either)
    # kinematic_switchable_roots True by default: an inactive weld equality per free root (so that it can be
    # made kinematic), off
    "mujoco_cpu": {"use_mujoco_cpu": True, "integrator": "implicitfast", "disable_contacts": True,
                   "kinematic_switchable_roots": False},
}
#: Solver attributes set after construction (none: XPBD's ``compute_body_velocity_from_position_delta`` is
#: False by default and deprecated since Newton 1.6 — setting it warns; its default is pinned instead).
SOLVER_ATTRIBUTES: dict = {}

#: Variants whose state is Newton's generalized coordinates (``joint_q``/``joint_qd`` of a FREE joint).
_GENERALIZED = frozenset({"featherstone", "mujoco_cpu"})
#: Variants whose model takes one body only (SolverMuJoCo on MuJoCo C refuses a model of several worlds).
_ONE_BODY = frozenset({"mujoco_cpu"})

#: Bodies (runs or rows) per model: more run as several models.
MAX_BATCH = 256

_LOCK = threading.RLock()


# --- the engine, imported lazily (never at module import, never in version()) -----------------------------

def _check_installed() -> None:
    """base.check_installed for this engine and the Warp it runs on."""
    base.check_installed(_DIST, PIP_HINT, (("warp", "warp-lang"),), installed_version)


def version() -> str:
    """Newton's version and the Warp release it runs on, e.g. ``1.8.0 (warp 1.19.0)``, from package metadata
    (EngineNotInstalled when newton is absent)."""
    _check_installed()
    return _dist_version()


@functools.lru_cache(maxsize=1)
def _dist_version() -> str:
    return f"{installed_version(_DIST)} (warp {installed_version('warp-lang')})"


@functools.lru_cache(maxsize=1)
def _engine():
    """``(warp, newton)``, imported on first use, Warp's kernel cache in ``kernel_cache_dir("newton")`` and
    its
    messages (device banner, module loads) off. ImportError with the engine's words when the import fails."""
    _check_installed()
    try:
        import warp as wp
        folder = kernel_cache_dir(ENGINE)
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError:   # pragma: no cover - Warp then falls back to its own cache directory
            pass
        wp.config.kernel_cache_dir = str(folder)
        wp.config.quiet = True
        wp.config.log_level = wp.LOG_WARNING
        import newton
        # Warp's native library warns on stderr that no CUDA driver exists (CPU only here)
        with _quiet_fd2():
            wp.init()
    except Exception as exc:  # noqa: BLE001 - a broken install: the engine's own words
        raise ImportError(f"newton {installed_version(_DIST)} is installed but cannot be imported: "
                          f"{type(exc).__name__}: {exc}") from exc
    return wp, newton


class _quiet_fd2:
    """File descriptor 2 sent to /dev/null for the duration (what a native library prints there)."""

    def __enter__(self):
        try:
            sys.stderr.flush()
            self.saved = os.dup(2)
        except (OSError, ValueError, AttributeError):   # pragma: no cover - no usable fd 2
            self.saved = None
            return self
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, 2)
        os.close(devnull)
        return self

    def __exit__(self, *exc):
        if self.saved is not None:
            os.dup2(self.saved, 2)
            os.close(self.saved)
        return False


def _engine_or_error():
    try:
        return _engine()
    except ImportError as exc:
        raise EngineError(str(exc)) from None


# --- compile bookkeeping ----------------------------------------------------------------------------------

_WARM: dict = {}    # variant -> seconds its first model build and step took (kernel compile or cache load)
_STATS = {"compilations": 0, "compile_seconds": 0.0, "build_seconds": 0.0, "step_seconds": 0.0,
          "body_steps": 0}


def compile_stats() -> dict:
    """This process's Newton costs so far: ``compilations`` (variants warmed up: their kernel modules
    compiled by Warp, or loaded from its cache), ``compile_seconds`` (wall s of those warm-ups: a one-body
    model's finalize, the solver's construction and one step), ``per_variant`` (the same per variant), and
    apart from it ``build_seconds`` (model building of the runs), ``step_seconds`` (wall s in the step loops)
    and ``body_steps`` (steps × bodies they advanced)."""
    return {**_STATS, "per_variant": dict(_WARM)}


def _warm(variant: str) -> None:
    """Compile (or load) every kernel module ``variant`` uses, once per process, timed apart from the runs."""
    if variant in _WARM:
        return
    wp, newton = _engine_or_error()
    t0 = time.perf_counter()
    model = build_model(variant, [(1.0, np.eye(3), np.zeros(3))])
    solver = make_solver(variant, model)
    s0, s1 = model.state(), model.state()
    solver.step(s0, s1, None, None, 1e-3)
    wp.synchronize()
    _WARM[variant] = time.perf_counter() - t0
    _STATS["compilations"] += 1
    _STATS["compile_seconds"] += _WARM[variant]


# --- model, solver, state -----------------------------------------------------------------------------------

def build_model(variant: str, bodies):
    """A finalized Newton model on the CPU with one world per body of ``bodies`` (``(mass, I_B (3, 3),
    gravity_W (3,))`` each): jointless links for the maximal-coordinate solvers, FREE-jointed bodies for
    Featherstone; com = 0, no shape. EngineError when ``finalize`` did not keep the mass or the inertia (its
    inertia validation corrects a tensor it finds non-physical)."""
    wp, newton = _engine_or_error()
    builder = newton.ModelBuilder(gravity=(0.0, 0.0, 0.0))
    add = builder.add_body if variant in _GENERALIZED else builder.add_link
    for mass, inertia, gravity in bodies:
        builder.begin_world(gravity=tuple(float(g) for g in gravity))
        add(xform=wp.transform(wp.vec3(0.0, 0.0, 0.0), wp.quat_identity()), com=wp.vec3(0.0, 0.0, 0.0),
            mass=float(mass), inertia=wp.mat33(*(float(v) for v in np.asarray(inertia, dtype=float).ravel())))
        builder.end_world()
    try:
        # skip_validation_inertia: finalize would otherwise "correct" a tensor it finds non-physical (shift
        # its eigenvalues to satisfy I1 + I2 >= I3 with balance_inertia, or a relative floor on the smallest
        # one) — a body other than the scenario's; rbcheck's own body check has already refused a bad one
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
    """The variant's Newton solver for ``model``, every setting of SOLVER_SETTINGS and SOLVER_ATTRIBUTES
    applied."""
    _, newton = _engine_or_error()
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
    for attr, value in SOLVER_ATTRIBUTES.get(variant, {}).items():
        setattr(solver, attr, value)
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



class _Views:
    """NumPy views (no copy: Warp's CPU arrays share their memory) of one State's pose, velocity and force
    arrays, shaped (N, 7), (N, 6), (N, 6)."""

    def __init__(self, state, generalized: bool):
        n = state.body_count
        if generalized:
            self.q = state.joint_q.numpy().reshape(n, 7)
            self.qd = state.joint_qd.numpy().reshape(n, 6)
        else:
            self.q = state.body_q.numpy()
            self.qd = state.body_qd.numpy()
        self.f = state.body_f.numpy()


class _Batch:
    """Bodies of one variant stepping together at one Δt: a model, its solver, two states (swapped each step)
    and their views."""

    def __init__(self, variant: str, bodies):
        self.variant = variant
        t0 = time.perf_counter()
        self.model = build_model(variant, bodies)
        self.solver = make_solver(variant, self.model)
        gen = variant in _GENERALIZED
        self.states = [self.model.state(), self.model.state()]
        self.views = [_Views(s, gen) for s in self.states]
        self.weights = np.array([np.asarray(g, dtype=float) * m for m, _, g in bodies])
        _STATS["build_seconds"] += time.perf_counter() - t0

    def set_state(self, y) -> None:
        """Put body i at packed state ``y[i]`` in the current input state (float32)."""
        q, qd = to_newton_rows(y)
        v = self.views[0]
        v.q[:] = q
        v.qd[:] = qd

    def step(self, dt_s: float, ft) -> None:
        """One step of every body: ``ft`` (N, 6) the harness force (at the COM, weight included) and torque,
        world axes; Newton gets the force without the weight (it applies gravity itself)."""
        vin = self.views[0]
        vin.f[:, 0:3] = ft[:, 0:3] - self.weights
        vin.f[:, 3:6] = ft[:, 3:6]
        self.solver.step(self.states[0], self.states[1], None, None, dt_s)
        self.states.reverse()
        self.views.reverse()

    def read(self) -> np.ndarray:
        """The current state of every body, packed (N, 13) float64."""
        v = self.views[0]
        return from_newton_rows(v.q, v.qd)


# --- adapter entry points ---------------------------------------------------------------------------------

def simulate(scenario, variant: str, dt_s: float, n_steps: int) -> Run:
    """Free run of ``n_steps`` steps of ``dt_s`` from the scenario's initial state, every step recorded (one
    request of :func:`simulate_many`)."""
    return base.one_request(simulate_many, scenario, variant, dt_s, n_steps)


def _body(scenario):
    b = scenario.problem.body
    g = np.asarray(scenario.problem.forces.gravity_W, dtype=float)
    return float(b.mass_kg), np.asarray(b.inertia_B, dtype=float), g


def simulate_many(variant: str, requests) -> list:
    """The runs of ``requests`` (``base.RunRequest``), each a Run (or its EngineError): those of one Δt step
    together as the bodies of one model (at most MAX_BATCH per model)."""
    base.check_variant(ENGINE, VARIANTS, variant)
    try:
        with _LOCK:
            _warm(variant)
    except EngineError as exc:
        return [exc] * len(requests)
    with _LOCK, _mujoco_warnings(variant):
        return base.run_in_groups(requests, lambda r: float(r.dt_s),
                             lambda reqs: _run_batch(variant, float(reqs[0].dt_s), reqs),
                             1 if variant in _ONE_BODY else MAX_BATCH)


class _mujoco_warnings:
    """For the MuJoCo C variant: MuJoCo's warnings ("Nan, Inf or huge value in QACC") go to a handler for the
    duration (else MuJoCo prints them and writes MUJOCO_LOG.TXT into the working directory); the state they
    announce is non-finite or huge and ends the run as divergence. The previous handler is restored."""

    def __init__(self, variant: str):
        self.active = variant == "mujoco_cpu"

    def __enter__(self):
        if self.active:
            import mujoco
            self.prev = mujoco.get_mju_user_warning()
            mujoco.set_mju_user_warning(lambda msg: None)
        return self

    def __exit__(self, *exc):
        if self.active:
            import mujoco
            mujoco.set_mju_user_warning(self.prev)
        return False


def _run_batch(variant: str, dt_s: float, reqs) -> list:
    """The Runs of ``reqs`` (one Δt), stepped together."""
    B = len(reqs)
    batch = _Batch(variant, [_body(r.scenario) for r in reqs])
    y0 = np.array([r.scenario.problem.initial_packed() for r in reqs])
    batch.set_state(y0)
    n_max = max(r.n_steps for r in reqs)
    harness = [harness_fn(r.scenario, dt_s) for r in reqs]
    varying = [k for k, r in enumerate(reqs) if r.scenario.problem.forces.state_dependent]
    gains = np.array([[float(g) for g in base.decay_factors(r.scenario, dt_s)] for r in reqs])   # (B, 2)
    decay = [k for k, r in enumerate(reqs) if r.scenario.problem.forces.has_decay]
    gv = np.repeat(gains[:, 0:1], 3, axis=1)
    gw = np.repeat(gains[:, 1:2], 3, axis=1)
    ft = np.array([harness[k](y0[k].tolist()) for k in range(B)], dtype=float)
    hist_q = np.empty((n_max, B, 7), dtype=np.float32)
    hist_qd = np.empty((n_max, B, 6), dtype=np.float32)
    done = np.zeros(B, dtype=bool)
    t0 = time.perf_counter()
    steps = 0
    with np.errstate(all="ignore"):
        for i in range(n_max):
            if i and varying:
                v = batch.views[0]
                rows = from_newton_rows(v.q[varying], v.qd[varying])
                for k, row in zip(varying, rows.tolist()):
                    ft[k] = harness[k](row)
            if decay:
                qd = batch.views[0].qd
                qd[decay, 0:3] *= gv[decay]
                qd[decay, 3:6] *= gw[decay]
            batch.step(dt_s, ft)
            v = batch.views[0]
            hist_q[i] = v.q
            hist_qd[i] = v.qd
            steps += 1
            if (i & 255) == 255 or i == n_max - 1:
                done |= bad_rows(from_newton_rows(v.q, v.qd))
                if done.all():
                    break
    _STATS["step_seconds"] += time.perf_counter() - t0
    _STATS["body_steps"] += steps * B
    runs = []
    with np.errstate(all="ignore"):
        for k, r in enumerate(reqs):
            n = min(r.n_steps, steps)
            y = np.empty((n + 1, 13))
            y[0] = y0[k]
            y[1:] = from_newton_rows(hist_q[:n, k], hist_qd[:n, k])
            y[1:, 6:10] = sign_continuous(y[1:, 6:10], first=y0[k, 6:10])
            run = recorded_run(y, r.dt_s)
            if run.diverged_at_s is None and n < r.n_steps:  # pragma: no cover - only when every run diverged
                run = diverged(y, r.dt_s, "")
            runs.append(run)
    return runs


@base.on_rows
def one_step(scenario, variant: str, dt_s: float, y_start) -> np.ndarray:
    """One step of ``dt_s`` from each row of ``y_start`` (T, 13), the rows stepped together as the bodies of
    one model: the forces from the row, the pre-step decay. Rows the engine blows up come back as Newton left
    them."""
    base.check_variant(ENGINE, VARIANTS, variant)
    T = len(y_start)
    out = np.empty((T, 13))
    harness = harness_fn(scenario, dt_s)
    gv, gw = (float(g) for g in base.decay_factors(scenario, dt_s))
    with _LOCK, _mujoco_warnings(variant):
        _warm(variant)
        size = 1 if variant in _ONE_BODY else MAX_BATCH
        for s in range(0, T, size):
            rows = y_start[s:s + size]
            batch = _Batch(variant, [_body(scenario)] * len(rows))
            ft = np.array([harness(r) for r in rows.tolist()], dtype=float)
            y_dec = rows.copy()
            y_dec[:, 3:6] *= gv
            y_dec[:, 10:13] *= gw
            batch.set_state(y_dec)
            t0 = time.perf_counter()
            with np.errstate(all="ignore"):
                batch.step(float(dt_s), ft)
            _STATS["step_seconds"] += time.perf_counter() - t0
            _STATS["body_steps"] += len(rows)
            out[s:s + len(rows)] = batch.read()
    # each quaternion on the side of its start state's (one step turns it by less than π)
    with np.errstate(all="ignore"):
        sign = np.where(np.einsum("ij,ij->i", out[:, 6:10], y_start[:, 6:10]) < 0.0, -1.0, 1.0)
    out[:, 6:10] *= sign[:, None]
    return out


class NewtonAdapter(ModuleAdapter):
    """``newton:VARIANT`` — registered under the entry-point group ``rbcheck.engines``; optional
    (``pip install 'rbcheck[newton]'``). Every variant is first order (semi-implicit Euler) and float32.
    :func:`simulate_many` steps the requests of one Δt together in one model."""

    name = ENGINE
    variants = VARIANTS
    harness = ("cross_checks.engines.step_floats",)

    def engine_files(self) -> list:
        """Newton's solver sources (found without importing Newton or Warp)."""
        return base.package_files("newton", *(f"_src/{p}" for p in (
            "solvers/solver.py", "solvers/semi_implicit", "solvers/xpbd", "solvers/featherstone",
            "solvers/mujoco", "sim/builder.py", "sim/model.py", "sim/state.py")))
