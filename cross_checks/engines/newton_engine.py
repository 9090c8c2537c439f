"""Newton (``newton``, the physics engine on NVIDIA Warp) as an engine adapter (``newton:VARIANT``); the
interface is cross_checks.engines.base. What each solver does, the defaults neutralised (SOLVER_SETTINGS) and
what was measured: docs/engine_conventions.md, "Newton 1.8.0".

Precision: float32 on Warp's CPU device (state, model and Δt are ``wp.float32``): each variant declares
``Traits(precision="float32")``. Kernels are compiled into ``core.files.kernel_cache_dir("newton")``.

Model (:func:`build_model`): one world per body, each with its own gravity; ``com = 0`` (body origin = COM),
the scenario's mass and full inertia tensor (about the COM, body axes), checked after ``finalize``; no shape.
``semi_implicit`` and ``xpbd`` step jointless links (``State.body_q``/``body_qd``), ``featherstone`` and
``mujoco_cpu`` a FREE joint (``State.joint_q``/``joint_qd``).

State at the boundary (:func:`to_newton_rows`, :func:`from_newton_rows`): ``[x_W, q_WB (x, y, z, w)]`` — Warp
quaternions are xyzw — and ``[v_W (COM), ω_W]``, linear first, both world axes; the recorded quaternion kept
sign-continuous from the scenario's.

Forces: the harness's world force at the COM minus the weight ``m g`` (Newton applies gravity per world) and
its world torque go into ``State.body_f`` of the step's input state, from the start-of-step state; the decay
is applied to the velocities before the step.

:func:`simulate_many` steps the runs that share a Δt as the bodies of one model (at most MAX_BATCH; one for
``mujoco_cpu``, whose MuJoCo C takes one world); :func:`one_step` steps its rows as bodies. Warp and Newton
are imported on first use only (never at import or in ``version()``).

Divergence: the first recorded state that is non-finite or beyond BLOWUP_LIMIT ends the run
(``diverged at t = …``).
"""
from __future__ import annotations

import dataclasses
import functools
import threading
import time
import warnings

import numpy as np

from cross_checks.engines import base, forces, install, runtimes
from cross_checks.engines.base import EngineError, ModuleAdapter, Traits, Variant
from cross_checks.engines.install import installed_version
from cross_checks.engines.step_floats import harness_fn
from reference_sim.quaternion import same_side, sign_continuous
from reference_sim.simulate import Run, bad_rows, diverged, recorded_run

__all__ = ["ENGINE", "VARIANTS", "SOLVERS", "SOLVER_SETTINGS", "EngineError", "version", "simulate",
           "simulate_many", "one_step", "build_model", "make_solver", "compile_stats", "to_newton_rows",
           "from_newton_rows", "NewtonAdapter", "PIP_HINT"]

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
                             "default "
                             "integrator, the state copied from and back to Newton's float32 every step",
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

#: Bodies (runs or rows) per model: more run as several models.
MAX_BATCH = 256

_LOCK = threading.RLock()


# --- the engine, imported lazily (never at module import, never in version()) -----------------------------

def _check_installed() -> None:
    """install.check_installed for this engine and the Warp it runs on."""
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


# --- compile bookkeeping ----------------------------------------------------------------------------------

_WARM: dict = {}    # variant -> seconds its first model build and step took (kernel compile or cache load)
_STATS = runtimes.Stats(compilations=0, compile_seconds=0.0, build_seconds=0.0, step_seconds=0.0,
                        body_steps=0)


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


# --- model, solver, state -----------------------------------------------------------------------------------

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
        with _STATS.timing("build_seconds"):
            self.model = build_model(variant, bodies)
            self.solver = make_solver(variant, self.model)
            gen = variant in _GENERALIZED
            self.states = [self.model.state(), self.model.state()]
            self.views = [_Views(s, gen) for s in self.states]
            self.weights = np.array([np.asarray(g, dtype=float) * m for m, _, g in bodies])

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
    gains = np.array([[float(g) for g in forces.decay_factors(r.scenario, dt_s)] for r in reqs])   # (B, 2)
    decay = [k for k, r in enumerate(reqs) if r.scenario.problem.forces.has_decay]
    gv = np.repeat(gains[:, 0:1], 3, axis=1)
    gw = np.repeat(gains[:, 1:2], 3, axis=1)
    ft = np.array([harness[k](y0[k].tolist()) for k in range(B)], dtype=float)
    hist_q = np.empty((n_max, B, 7), dtype=np.float32)
    hist_qd = np.empty((n_max, B, 6), dtype=np.float32)
    done = np.zeros(B, dtype=bool)
    steps = 0
    with _STATS.timing("step_seconds"), np.errstate(all="ignore"):
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
    gv, gw = (float(g) for g in forces.decay_factors(scenario, dt_s))
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
            with _STATS.timing("step_seconds"), np.errstate(all="ignore"):
                batch.step(float(dt_s), ft)
            _STATS["body_steps"] += len(rows)
            out[s:s + len(rows)] = batch.read()
    out[:, 6:10] = same_side(out[:, 6:10], y_start[:, 6:10])
    return out


class NewtonAdapter(ModuleAdapter):
    """``newton:VARIANT`` — registered under the entry-point group ``rbcheck.engines``; optional
    (``pip install 'rbcheck[newton]'``)."""

    def engine_files(self) -> list:
        """Newton's solver sources (found without importing Newton or Warp)."""
        return install.package_files("newton", *(f"_src/{p}" for p in (
            "solvers/solver.py", "solvers/semi_implicit", "solvers/xpbd", "solvers/featherstone",
            "solvers/mujoco", "sim/builder.py", "sim/model.py", "sim/state.py")))
