"""The engine adapter interface (:class:`EngineAdapter`), the harness semantics adapters share, and the
plumbing of the optional engines (import on first use, JAX and Warp started once, fd 2 silenced).

An engine is an adapter class registered under the entry-point group ``rbcheck.engines``, or an engine file
(TOML, :mod:`cross_checks.engines.external`) turned into an adapter of the same interface; the registry
(:mod:`cross_checks.engines`) instantiates the class with no arguments. The contract and a worked example:
docs/engines.md, "Python engines: an adapter class and an entry point", and each method's docstring below.

Harness semantics (every built-in adapter; docs/semantics.md, "Forces are evaluated where each scheme's
equations say" and "Velocity decay"):

* Forces and torques are evaluated from the state at the start of each step and held over the step
  (zero-order hold), unless the engine evaluates them at every stage (:func:`stage_force_torque`).
* Velocity decay (the per-step factor γ at the scenario's dt) is damping at the rate ``k = −ln γ / dt``: a
  step Δt gets ``e^{−kΔt}`` (:func:`decay_factors`). A single-stage engine gets it BEFORE the step,
  ``v ← e^{−k_vΔt} v``, ``ω ← e^{−k_ωΔt} ω``, with that step's force and torque scaled alike: for a
  semi-implicit step exactly the course's ``v ← e^{−kΔt} (v + Δt f/m)``, and its rotation exactly where the
  gyroscopic torque vanishes (else a difference of order (1 − e^{−kΔt}) Δt: still first order). A multi-stage
  engine gets the damping in its right-hand side: a force ``−m k_v v`` at the COM, a torque ``−k_ω I_W ω``.
"""
from __future__ import annotations

import abc
import contextlib
import functools
import importlib
import inspect
import itertools
import math
import os
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cross_checks.core.files import kernel_cache_dir

__all__ = ["EngineAdapter", "Variant", "harness_force_torque", "stage_force_torque",
           "harness_force_torque_floats", "stage_force_torque_floats", "apply_decay_prestep",
           "decay_factors", "EngineError", "optional_import", "require", "EngineNotInstalled",
           "installed_version", "release", "library_files", "RunRequest", "Traits", "INVARIANTS",
           "SYMPLECTIC_EULER_EXPLICIT_GYRO", "SYMPLECTIC_EULER_IMPLICIT_GYRO", "WHOLE_STATE_EXPLICIT_EULER",
           "WHOLE_STATE_IMPLICIT_EULER", "HIGHER_ORDER", "DEFAULT_TRAITS", "ModuleAdapter", "package_files",
           "one_request", "check_variant", "run_in_groups", "check_installed", "quiet_fd2", "first_import",
           "engine_or_error", "start_jax", "refuse_forked_jax", "start_warp", "Stats", "Registry",
           "weight_W", "minus_weight", "power_of_two"]


class EngineError(RuntimeError):
    """The engine rejected the model or failed during a run; the message carries the engine's own words.
    A sweep records the run as `failed` with this message and goes on."""


class NotExpressible(EngineError):
    """The engine cannot take the scenario's physics as written (EngineAdapter.expressible said so): a limit
    of the engine, not a failure of the run. A sweep lists the pair under ``not_expressible`` and runs
    nothing for it."""


@contextlib.contextmanager
def quiet_fd2():
    """File descriptor 2 sent to /dev/null for the duration: what a native library prints there (PyBullet's
    build time at import, Warp's missing CUDA driver at ``wp.init``) would land in every CLI run's error
    output. Nothing is silenced where fd 2 cannot be duplicated."""
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError, AttributeError):   # pragma: no cover - no usable fd 2
        yield
        return
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 2)
    os.close(devnull)
    try:
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def optional_import(name: str, *, quiet_stderr: bool = False):
    """``(module, None)``, or ``(None, the ImportError)`` when ``name`` cannot be imported: an adapter
    module imports without its engine so that the registry can say why the engine is unavailable.
    ``quiet_stderr``: fd 2 silenced during the import (:func:`quiet_fd2`)."""
    with quiet_fd2() if quiet_stderr else contextlib.nullcontext():
        try:
            return importlib.import_module(name), None
        except ImportError as exc:  # pragma: no cover - exercised only where the engine is missing
            return None, exc


class EngineNotInstalled(ImportError):
    """The engine's distribution is not installed at all (as opposed to installed and failing to import)."""


def package_root(module: str) -> Path | None:
    """The folder of the installed package ``module`` (dotted: its parent packages are imported, it is not),
    or None where it is not installed: how an adapter lists the engine's sources for the cache key without
    starting the engine (a sweep's parent must not start JAX or Warp before forking)."""
    import importlib.util
    try:
        spec = importlib.util.find_spec(module)
    except (ImportError, ValueError):
        return None
    if spec is None:
        return None
    if spec.submodule_search_locations:
        return Path(next(iter(spec.submodule_search_locations)))
    return Path(spec.origin).parent if spec.origin else None


def installed_version(dist: str) -> str | None:
    """The installed version of distribution ``dist`` from its metadata (None when it is not installed)."""
    from importlib.metadata import PackageNotFoundError
    from importlib.metadata import version as dist_version
    try:
        return dist_version(dist)
    except PackageNotFoundError:
        return None


@functools.cache
def release(dist: str, runs_on: tuple = ()) -> str:
    """Distribution ``dist``'s installed version ("unknown" without metadata), read once per process, and
    with ``runs_on = (label, distribution)`` the version of what it runs on: ``"4.0.0 (warp 1.19.0)"``."""
    ver = installed_version(dist) or "unknown"
    return f"{ver} ({runs_on[0]} {installed_version(runs_on[1])})" if runs_on else ver


def library_files(module) -> list:
    """The compiled files behind an engine's Python module, which its results depend on beyond a version
    string: the module itself when it is an extension (pybullet), else the shared libraries in its package
    folder and its ``lib/`` folder (libmujoco.so.X, pydrake/lib/libdrake.so). [] without the module."""
    if module is None or not getattr(module, "__file__", None):
        return []
    f = Path(module.__file__)
    if f.suffix == ".so" or ".so." in f.name:
        return [f]
    folder = f.parent
    return sorted(p for d in (folder, folder / "lib") if d.is_dir() for p in d.iterdir()
                  if p.is_file() and (p.suffix == ".so" or ".so." in p.name))


def require(module, import_error, name: str, dist: str | None = None, hint: str = "") -> None:
    """When :func:`optional_import` could not import the engine's module: :class:`EngineNotInstalled`
    if its distribution ``dist`` (default ``name``) is not installed, else an ImportError saying that it
    IS installed (with its version) and how the import failed: a broken install (e.g. a wheel built for
    another NumPy) must never read as an absent one. ``hint`` says how to install it."""
    if module is not None:
        return
    ver = installed_version(dist or name)
    if ver is None:
        raise EngineNotInstalled(f"{name} is not installed{f' ({hint})' if hint else ''}")
    why = " ".join(f"{type(import_error).__name__}: {import_error}".split())
    raise ImportError(f"{name} {ver} is installed but cannot be imported: {why}")


@functools.lru_cache(maxsize=64)
def float_forces(scenario):
    """The single-state force evaluator of this scenario (reference_sim.compiled.ForceEvaluator: the
    definition's force model, compiled), built once: ``.force_torque(y)`` -> 6 floats."""
    from reference_sim.compiled import ForceEvaluator
    return ForceEvaluator(scenario.problem)


def decay_factors(scenario, dt_s: float):
    """``(γ_v, γ_ω)``: the per-step decay factors ``e^{−kΔt}`` at step ``dt_s`` (exactly the scenario's
    own factors at its dt); what an engine that applies decay per step must use at that Δt."""
    return scenario.problem.forces.decay_factors(float(dt_s))


def harness_force_torque(scenario, y, dt_s: float):
    """World force (N, at the COM) and world torque (N m) to apply for the step of ``dt_s`` starting at
    ``y`` (13,), scaled by the pre-step decay factors (see the module docstring); evaluated by
    :func:`float_forces`."""
    fx, fy, fz, tx, ty, tz = harness_force_torque_floats(scenario, y, dt_s)
    return np.array([fx, fy, fz]), np.array([tx, ty, tz])


def harness_force_torque_floats(scenario, y, dt_s: float) -> tuple:
    """:func:`harness_force_torque` as 6 plain floats (fx, fy, fz, tx, ty, tz): the same numbers, for an
    adapter's per-step loop, where building two small arrays per step costs more than the engine's step."""
    fx, fy, fz, tx, ty, tz = float_forces(scenario).force_torque(y)
    gv, gw = decay_factors(scenario, dt_s)
    return gv * fx, gv * fy, gv * fz, gw * tx, gw * ty, gw * tz


def stage_force_torque(scenario, y):
    """World force and torque of the right-hand side at state ``y`` (13,), decay included as the
    damping force ``−m k_v v`` at the COM and the torque ``−k_ω I_W ω`` (so that ``ω̇`` gets ``−k_ω ω``):
    what a multi-stage engine must see at every stage."""
    fx, fy, fz, tx, ty, tz = stage_force_torque_floats(scenario, y)
    return np.array([fx, fy, fz]), np.array([tx, ty, tz])


def stage_force_torque_floats(scenario, y) -> tuple:
    """:func:`stage_force_torque` as 6 plain floats (for the per-stage callback)."""
    return float_forces(scenario).force_torque(y, stage=True)


def apply_decay_prestep(scenario, y, dt_s: float):
    """The state(s) ``y`` (..., 13) with the pre-step decay of a step of ``dt_s`` applied (a copy)."""
    gv, gw = decay_factors(scenario, dt_s)
    y = np.array(y, dtype=float)
    y[..., 3:6] *= gv
    y[..., 10:13] *= gw
    return y


@dataclass(frozen=True)
class RunRequest:
    """One free run asked of :meth:`EngineAdapter.simulate_many`: ``n_steps`` steps of ``dt_s`` (s) from
    ``scenario``'s initial state."""

    scenario: object
    dt_s: float
    n_steps: int


#: The kinds of Traits.rotation_drift.
ROTATION_DRIFTS = ("none", "body", "whole_state", "momentum")
#: What Traits.keeps may name: invariants of the torque-free body a step keeps by construction.
INVARIANTS = ("energy", "energy_bounded", "angular_momentum_norm", "angular_momentum")


@dataclass(frozen=True)
class Traits:
    """What a variant's step does besides its order (the order itself: :attr:`Variant.order`); the sweep
    derives a variant's expectations from them (cross_checks.analysis.expectations). What each trait means
    for the verdicts, and why: docs/verdicts.md, §3.

    gyroscopic_term : whether the rotation update has the gyroscopic torque −ω × (I ω).
    translation_drift : a first-order step's effect on the amplitude of a translational oscillation: 0 keeps
        it (symplectic Euler), +1 grows it (explicit), −1 damps it (implicit), None unknown (both considered).
    rotation_drift : a first-order step's effect on the rotation's energy and momentum (ROTATION_DRIFTS):
        "none" — no gyroscopic term (ω constant without torques); "body" — a body-frame Euler step of Euler's
        equations before the attitude update (energy and |L|² drift together: a phase error);
        "whole_state" — one step of the whole state in world axes (they drift independently: a neighbouring
        motion); "momentum" — an explicit body-frame gyroscopic step with |L| rescaled to its old magnitude
        (Jolt's MotionProperties::ApplyGyroscopicForceInternal, reference:jolt_gyro, Rapier, PhysX), judged
        as "body" with both signs.
    rotation_sign : +1 the rotational energy grows (an explicit gyroscopic term), −1 it decays (an
        implicit one), 0 none, None unknown (both are considered).
    rotation_order : the order of the attitude update where the body-axes ω turns within a step, when it is
        below the variant's order; None: the variant's order.
    velocity_from_positions : the step recomputes the velocity as the change of position over Δt (its
        round-off then grows as Δt shrinks: metrics.differencing_floor).
    precision : the floating-point format the engine's step computes in, "float64" or "float32"
        (core.tolerances.MACHINE_EPSILON; docs/verdicts.md §7).
    rounding_factor : how many times an ordinary step's rounding (CHECK_ROUNDINGS_PER_STEP roundings) the
        engine's step leaves, ≥ 1: every round-off floor and the one-step allowance scale with ε × this
        factor. Declared from the step's arithmetic and pinned by a measurement in its adapter's tests.
    keeps : the invariants of the torque-free body the step keeps BY CONSTRUCTION (a subset of INVARIANTS),
        judged on the long runs (cross_checks.analysis.judge.judge_long_run): "energy" and
        "angular_momentum_norm" (|L|) to round-off, "energy_bounded" (no secular drift: a symplectic step),
        "angular_momentum" (the world vector L) to round-off. "momentum" drift implies
        "angular_momentum_norm". () claims nothing: the long runs are reported, never judged.
    gyroscopic_clamp_N_m : the step cuts the gyroscopic torque |ω × I ω| to this length (N m) when it is
        longer (Bullet's ``m_maxGyroscopicForce``, reference:explicit_gyro_clamped); None: no clamp. Where
        the motion's gyroscopic torque exceeds it the variant is expected not to converge in rotation.
    forces_held : the engine holds the applied force and torque over all the stages of a step (no per-stage
        evaluation): a multi-stage scheme is then first order where the forces change within a step
        (state-dependent forces, velocity decay).
    lever_arms : the engine's arithmetic may hold lever arms measured from the world origin (MuJoCo's and
        Featherstone's spatial algebra: torques r × F with r known to ε |x| only, momenta about the origin),
        so its runs are given the round-off that grows with the distance from the origin
        (analysis.metrics.lever_floor). True, the cautious default, for any engine whose algebra is not
        known here; False for rbcheck's own schemes, which take torques about the COM and step ω itself
        (a floor they do not pay would hide their order: docs/fuzz.md §5).
    """

    gyroscopic_term: bool = True
    translation_drift: int | None = 0
    rotation_drift: str = "none"
    rotation_sign: int | None = 0
    forces_held: bool = False
    precision: str = "float64"
    velocity_from_positions: bool = False
    rotation_order: float | None = None
    rounding_factor: float = 1.0
    keeps: tuple = ()
    gyroscopic_clamp_N_m: float | None = None
    lever_arms: bool = True

    def __post_init__(self):
        bad = [k for k in self.keeps if k not in INVARIANTS]
        if bad or not isinstance(self.keeps, tuple):
            raise ValueError(f"keeps must be a tuple of {', '.join(INVARIANTS)}, not {self.keeps!r}")
        if not self.rounding_factor >= 1.0:
            raise ValueError(f"rounding_factor must be at least 1, not {self.rounding_factor!r}")
        if self.rotation_drift not in ROTATION_DRIFTS:
            raise ValueError(f"rotation_drift must be one of {', '.join(ROTATION_DRIFTS)}, "
                             f"not {self.rotation_drift!r}")
        if self.precision not in ("float64", "float32"):
            raise ValueError(f"precision must be 'float64' or 'float32', not {self.precision!r}")

#: A body-frame step of Euler's equations with an explicit gyroscopic term, then the attitude (MuJoCo Euler).
SYMPLECTIC_EULER_EXPLICIT_GYRO = Traits(rotation_drift="body", rotation_sign=+1)
#: The same with an implicit gyroscopic term (MuJoCo implicit, PyBullet maximal).
SYMPLECTIC_EULER_IMPLICIT_GYRO = Traits(rotation_drift="body", rotation_sign=-1)
#: Whole-state Euler in world axes: an oscillator's amplitude grows (explicit) or damps (implicit), the
#: rotational energy does the opposite (explicit Euler loses 2E and |L|², implicit gains them).
WHOLE_STATE_EXPLICIT_EULER = Traits(translation_drift=+1, rotation_drift="whole_state", rotation_sign=-1)
WHOLE_STATE_IMPLICIT_EULER = Traits(translation_drift=-1, rotation_drift="whole_state", rotation_sign=+1)
#: A variant that declares no traits (e.g. a user engine with only its declared order): assumed to
#: have the gyroscopic term (a correct engine; if it lacks it, the sweep says so), and, if it is first
#: order, to drift in either direction in both translation and rotation, whole-state style — the most
#: cautious choice: no order is claimed wherever any first-order scheme could be pre-asymptotic.
DEFAULT_TRAITS = Traits(gyroscopic_term=True, translation_drift=None, rotation_drift="whole_state",
                        rotation_sign=None)
#: Order ≥ 2: the amplitude error of an order-p scheme is of order p + 1 (|R(iωΔt)|² = 1 + O((ωΔt)^{p+2})); a
#: symplectic scheme keeps it: no amplitude rule applies.
HIGHER_ORDER = Traits()


@dataclass(frozen=True)
class Variant:
    """A variant an engine offers: its declared global order (the error at a fixed final time shrinks like
    Δt^order; verdicts check it), a one-line description for ``rbcheck list`` and the report, and ``traits``:
    what the step does besides its order (:class:`Traits`; None: the cautious default of
    cross_checks.analysis.expectations), and ``imitates``: the ``ENGINE:VARIANT`` whose scheme this one claims
    to compute ("" for none), whose traits it then gets — so that it is judged exactly as that scheme."""

    order: float
    description: str = ""
    imitates: str = ""
    traits: Traits | None = None

    def __post_init__(self):
        o = self.order
        if isinstance(o, bool) or not isinstance(o, (int, float)) or not math.isfinite(o) or not 0 < o <= 20:
            raise ValueError(f"order must be a number in (0, 20], got {o!r}")
        if not isinstance(self.description, str):
            raise ValueError(f"description must be a string, got {self.description!r}")
        if self.traits is not None and not isinstance(self.traits, Traits):
            raise ValueError(f"traits must be a Traits or None, got {self.traits!r}")
        if not isinstance(self.imitates, str):
            raise ValueError(f"imitates must be a string (ENGINE:VARIANT or empty), got {self.imitates!r}")
        object.__setattr__(self, "order", float(o))


def check_installed(dist: str, hint: str, needs: tuple = (), version_of=None) -> None:
    """From package metadata and import specs only (nothing imported): :class:`EngineNotInstalled` when the
    distribution ``dist`` is not installed; ImportError when it is but one of ``needs`` — (module,
    distribution) pairs it runs on — is missing. ``hint`` says how to install it; ``version_of`` (default
    :func:`installed_version`) reads a distribution's installed version."""
    import importlib.util
    version_of = version_of or installed_version
    if version_of(dist) is None:
        raise EngineNotInstalled(f"{dist} is not installed ({hint})")
    for module, needed in needs:
        if importlib.util.find_spec(module) is None or version_of(needed) is None:
            raise ImportError(f"{dist} {version_of(dist)} is installed but cannot be imported: "
                              f"{needed} is missing ({hint})")


@contextlib.contextmanager
def first_import(dist: str, version_of=None):
    """Around an engine's import on first use: any exception in the block is raised as ImportError "DIST VER
    is installed but cannot be imported: TYPE: words" (a broken install, never read as an absent one);
    ``version_of`` (default :func:`installed_version`) reads the installed version."""
    try:
        yield
    except Exception as exc:  # noqa: BLE001 - a broken install: the engine's own words
        ver = (version_of or installed_version)(dist)
        raise ImportError(f"{dist} {ver} is installed but cannot be imported: {type(exc).__name__}: {exc}") \
            from exc


def engine_or_error(engine):
    """``engine()`` (an adapter's import on first use) with its ImportError raised as :class:`EngineError`."""
    try:
        return engine()
    except ImportError as exc:
        raise EngineError(str(exc)) from None


@functools.lru_cache(maxsize=1)
def start_jax():
    """``jax`` with float64 on (``jax_enable_x64``: process-global, so every JAX engine of the process
    computes in float64) and its persistent compilation cache in ``core.files.kernel_cache_dir("jax")``,
    shared by the JAX engines. Called on first use only: a sweep's parent must not start JAX (it forks)."""
    import jax
    jax.config.update("jax_enable_x64", True)
    try:
        folder = kernel_cache_dir("jax")
        folder.mkdir(parents=True, exist_ok=True)
        jax.config.update("jax_compilation_cache_dir", str(folder))
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)
    except OSError:   # pragma: no cover - an unwritable cache directory only costs compile time
        pass
    return jax


#: True in a process forked after JAX's backend had started in its parent (set in the child at fork).
_FORKED_AFTER_JAX = [False]


def _after_fork_in_child() -> None:
    if "jax" in sys.modules:
        from jax._src import xla_bridge
        _FORKED_AFTER_JAX[0] = bool(xla_bridge.backends_are_initialized())


os.register_at_fork(after_in_child=_after_fork_in_child)


def refuse_forked_jax(words: str) -> None:
    """:class:`EngineError` with ``words`` in a process forked after JAX started in its parent: a running JAX
    backend does not survive fork (its threads are gone) and its first computation would hang."""
    if _FORKED_AFTER_JAX[0]:
        raise EngineError(words)


def start_warp(cache: str, log_level: str, quiet: bool = False):
    """``warp``, initialised on first use with its kernel cache in ``core.files.kernel_cache_dir(cache)`` (set
    before ``wp.init``), ``wp.config.log_level = wp.<log_level>`` and ``wp.config.quiet``; fd 2 silenced
    meanwhile (Warp's runtime prints there that no CUDA driver exists).

    A cache is a cache (docs/hardening.md): a folder where nothing can be written is replaced by a private
    one for the run; a module whose cached files cannot be loaded (an object cut in half: "Failed to load CPU
    module", a damaged metadata file) has its folder removed, said once, and is compiled again."""
    from cross_checks.core.files import usable_cache_dir
    folder = usable_cache_dir(kernel_cache_dir(cache), f"{cache}'s kernel")   # read-only, full: skipped, said
    with quiet_fd2():
        import warp as wp
        wp.config.kernel_cache_dir = str(folder)
        wp.config.quiet = quiet
        wp.config.log_level = getattr(wp, log_level)
        wp.init()
    module_class = getattr(getattr(getattr(wp, "_src", None), "context", None), "Module", None)
    load = getattr(module_class, "load", None)
    if load is not None and not getattr(load, "rbcheck_recompiles_damaged", False):
        import json
        import shutil
        import sys

        def load_or_recompile(self, device, block_dim=None, binary_path=None, output_arch=None,
                              meta_path=None):
            try:
                return load(self, device, block_dim, binary_path, output_arch, meta_path)
            except Exception as exc:
                damaged = (isinstance(exc, json.JSONDecodeError) or "Failed to load" in str(exc)
                           or "metadata file" in str(exc))   # not a build error of the kernel's own
                if binary_path is not None or not damaged:   # (binary_path: the caller's, not the cache)
                    raise
                try:
                    where = os.path.join(wp.config.kernel_cache_dir, self.get_module_identifier(
                        block_dim if block_dim is not None else self.options["block_dim"]))
                except Exception:  # noqa: BLE001 - Warp's internals changed: its own error stands
                    raise exc from None
                if not os.path.isdir(where):
                    raise
                print(f"rbcheck: {cache}'s kernel cache entry {where} could not be loaded ({exc}); removed, "
                      "compiling it again", file=sys.stderr, flush=True)
                shutil.rmtree(where, ignore_errors=True)
                return load(self, device, block_dim, binary_path, output_arch, meta_path)
        load_or_recompile.rbcheck_recompiles_damaged = True
        module_class.load = load_or_recompile
    return wp


class Stats(dict):
    """An adapter's counters in this process (compilations, wall seconds, steps), zeroed by :meth:`reset`."""

    def __init__(self, **zeros):
        super().__init__(zeros)
        self.zeros = zeros

    def reset(self) -> None:
        self.update(self.zeros)

    @contextlib.contextmanager
    def timing(self, key: str):
        """Adds the block's wall seconds to ``self[key]`` (nothing when it raises)."""
        t0 = time.perf_counter()
        yield
        self[key] += time.perf_counter() - t0


class Registry(dict):
    """Values held under fresh integer keys for the duration of a block: what a host callback inside compiled
    code (``jax.pure_callback``) looks up by the key it was given."""

    def __init__(self):
        super().__init__()
        self._keys = itertools.count(1)
        self._lock = threading.Lock()

    @contextlib.contextmanager
    def holding(self, value):
        """``np.int64(key)`` of ``value`` for the block; the entry is dropped after it."""
        with self._lock:
            key = next(self._keys)
            self[key] = value
        try:
            yield np.int64(key)
        finally:
            self.pop(key, None)


def weight_W(scenario) -> np.ndarray:
    """The body's weight ``m g`` (N, world axes): what an engine that applies gravity itself must not get
    again in its applied force."""
    return scenario.problem.body.mass_kg * np.asarray(scenario.problem.forces.gravity_W, dtype=float)


def minus_weight(harness, weight_W):
    """``y -> (fx, fy, fz, tx, ty, tz)``: the plain-float ``harness(y)`` (step_floats.harness_fn) with the
    weight ``weight_W`` (N, world axes) taken off its force: what an engine that applies gravity gets."""
    w0, w1, w2 = (float(w) for w in weight_W)

    def wrench(y):
        fx, fy, fz, tx, ty, tz = harness(y)
        return fx - w0, fy - w1, fz - w2, tx, ty, tz
    return wrench


def power_of_two(n: int) -> int:
    """The batch size ``n`` (≥ 1) runs or rows are padded to: the next power of two, so that a handful of
    compiled executables serve every batch size."""
    return 1 << (int(n) - 1).bit_length()


def on_rows(one_step):
    """An adapter's ``one_step(scenario, variant, dt_s, y_start)`` for ``y_start`` of any shape (..., 13):
    ``one_step`` sees the states as float rows (T, 13) and its (T, 13) answer comes back in ``y_start``'s
    shape."""
    @functools.wraps(one_step)
    def on_any_shape(scenario, variant: str, dt_s: float, y_start) -> np.ndarray:
        rows = np.asarray(y_start, dtype=float).reshape(-1, 13)
        return np.asarray(one_step(scenario, variant, dt_s, rows)).reshape(np.shape(y_start))
    return on_any_shape


def check_variant(engine: str, variants, variant: str) -> None:
    """ValueError naming ``engine``'s variants when ``variant`` is not one of them."""
    if variant not in variants:
        raise ValueError(f"unknown {engine} variant {variant!r}; variants: {', '.join(variants)}")


def run_in_groups(requests, key, run_group, max_size: int | None = None) -> list:
    """``simulate_many`` of an engine that steps requests together: the requests grouped by ``key(request)``
    (in order, at most ``max_size`` per group), each group's runs from ``run_group(list of requests)``; an
    :class:`EngineError` a group raises is the run of each of its requests."""
    out: list = [None] * len(requests)
    groups: dict = {}
    for j, r in enumerate(requests):
        groups.setdefault(key(r), []).append(j)
    for idx in groups.values():
        size = max_size or len(idx)
        for part in (idx[s:s + size] for s in range(0, len(idx), size)):
            try:
                runs = run_group([requests[j] for j in part])
            except EngineError as exc:
                runs = [exc] * len(part)
            for j, run in zip(part, runs):
                out[j] = run
    return out


def one_request(simulate_many, scenario, variant: str, dt_s: float, n_steps: int):
    """``simulate`` of an engine that batches: the run of the one request (scenario, ``dt_s``, ``n_steps``)
    through its ``simulate_many``, whose :class:`EngineError` is raised."""
    run = simulate_many(variant, [RunRequest(scenario, float(dt_s), int(n_steps))])[0]
    if isinstance(run, EngineError):
        raise run
    return run


class EngineAdapter(abc.ABC):
    """Base class of every engine adapter (see the module docstring for the contract).

    Subclass it, set ``name`` and ``variants``, implement ``version`` and ``simulate`` (and
    ``one_step`` if the engine can restart a step from any state), and register the class::

        # pyproject.toml of your package
        [project.entry-points."rbcheck.engines"]
        mysim = "mysim_rbcheck:MySimAdapter"

    The class is instantiated once per process with no arguments. Results are cached by scenario,
    variant, Δt, ``version()`` and a hash of :meth:`source_files`: bump the version (or run with
    ``--no-cache``) when the engine changes outside those files.
    """

    #: Engine name in ``ENGINE:VARIANT`` ([a-z0-9_]+); must equal the entry point's name.
    name: str = ""
    #: variant name -> Variant(order, description).
    variants: dict = {}

    @abc.abstractmethod
    def version(self) -> str:
        """The engine's version; raise ImportError (or any exception) when it cannot run here."""

    @abc.abstractmethod
    def simulate(self, scenario, variant: str, dt_s: float, n_steps: int):
        """``n_steps`` steps of ``dt_s`` from the scenario's initial state -> reference_sim.simulate.Run."""

    def simulate_many(self, variant: str, requests) -> list:
        """The runs of ``requests`` (a sequence of :class:`RunRequest`) with ``variant``, in order: each a
        Run as :meth:`simulate` gives it, or the :class:`EngineError` that run raised (one failing run
        does not fail the others). Engines that batch override this; the default runs them one by one."""
        out: list = []
        for r in requests:
            try:
                out.append(self.simulate(r.scenario, variant, r.dt_s, r.n_steps))
            except EngineError as exc:
                out.append(exc)
        return out

    def expressible(self, scenario, variant: str) -> str:
        """"" when ``variant`` can run the scenario's physics as written; otherwise one sentence saying what
        of it the engine cannot take (e.g. "brax's spring pipeline takes no applied force but gravity"). The
        sweep then records the scenario's rows as ``not_expressible`` with that sentence instead of running
        them: a limit of the engine, said, not a failure. Override it when an engine cannot express part of
        the scenario schema; by default every scenario is expressible."""
        return ""

    def one_step(self, scenario, variant: str, dt_s: float, y_start) -> np.ndarray:
        """One step of ``dt_s`` from exactly each row of ``y_start`` (T, 13) -> (T, 13): the local-error mode.
        Optional (see :attr:`has_one_step`): an adapter that cannot restart its engine from an arbitrary state
        leaves this one, which refuses (the local-error columns then stay empty)."""
        raise EngineError(f"{self.name or type(self).__name__} has no one-step mode")

    @property
    def has_one_step(self) -> bool:
        """True when the class implements :meth:`one_step` (the local-error mode of a sweep)."""
        return type(self).one_step is not EngineAdapter.one_step

    def cache_token(self) -> str:
        """What identifies this adapter's code for the result cache: by default a SHA-256 of the
        contents of :meth:`source_files` (a file over 32 MiB, such as libdrake.so, by its size and
        modification time: a reinstall changes them, and reading it on every sweep would cost seconds)."""
        import hashlib
        h = hashlib.sha256()
        for f in self.source_files():
            h.update(str(f).encode())
            try:
                st = Path(f).stat()
                h.update(f"{st.st_size}:{st.st_mtime_ns}".encode() if st.st_size > 32 * 2 ** 20
                         else Path(f).read_bytes())
            except OSError:
                h.update(b"<missing>")
        return h.hexdigest()

    def source_files(self) -> list:
        """Files whose content determines this adapter's results (hashed into the cache key):
        by default the module that defines the class."""
        try:
            return [Path(inspect.getsourcefile(type(self)))]
        except (TypeError, OSError):
            return []


def package_files(module: str, *parts: str, pattern: str = "*.py") -> list:
    """The files matching ``pattern`` in the folders ``parts`` (paths relative to the installed package
    ``module``, found by :func:`package_root` without importing it; a part naming a file is taken as it is;
    ``*_test.py`` left out), sorted; [] where the package is not installed. With no ``parts``: the package
    folder itself."""
    root = package_root(module)
    if root is None:
        return []
    files: list = []
    for part in parts or ("",):
        p = root / part
        found = sorted(p.glob(pattern)) if p.is_dir() else [p] if p.is_file() else []
        files += [f for f in found if not f.name.endswith("_test.py")]
    return files


class ModuleAdapter(EngineAdapter):
    """An adapter whose engine is the functions of the module defining the class — ``version()``,
    ``simulate(scenario, variant, dt_s, n_steps)``, ``one_step(scenario, variant, dt_s, y_start)`` and,
    where the engine batches, ``simulate_many(variant, requests)`` — as every built-in adapter is written.
    The methods look the functions up when called.

    ``name`` and ``variants`` default to the module's ``ENGINE`` and ``VARIANTS``. :meth:`source_files` is the
    module, the modules of ``harness`` (dotted names of the code its loops run besides its own), and
    :meth:`engine_files` (the engine's own files: override it).
    """

    #: Dotted names of the modules besides the adapter's own whose code decides its results (default: the
    #: plain-float harness that evaluates the forces between an engine's steps).
    harness: tuple = ("cross_checks.engines.step_floats",)

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        module = sys.modules[cls.__module__]
        for attr, default in (("name", "ENGINE"), ("variants", "VARIANTS")):
            if attr not in cls.__dict__ and hasattr(module, default):
                setattr(cls, attr, getattr(module, default))

    def _engine(self):
        return sys.modules[type(self).__module__]

    def version(self) -> str:
        return self._engine().version()

    def simulate(self, scenario, variant: str, dt_s: float, n_steps: int):
        return self._engine().simulate(scenario, variant, dt_s, n_steps)

    def simulate_many(self, variant: str, requests) -> list:
        batched = getattr(self._engine(), "simulate_many", None)
        return super().simulate_many(variant, requests) if batched is None else batched(variant, requests)

    def one_step(self, scenario, variant: str, dt_s: float, y_start) -> np.ndarray:
        return self._engine().one_step(scenario, variant, dt_s, y_start)

    def engine_files(self) -> list:
        """The engine's files (sources or compiled libraries) whose content decides its results; [] here."""
        return []

    def source_files(self) -> list:
        harness = [Path(importlib.import_module(m).__file__ or "") for m in self.harness]
        return [*super().source_files(), *harness, *self.engine_files()]
