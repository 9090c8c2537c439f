"""The engine adapter interface: what an engine declares (:class:`Variant`, its :class:`Traits`) and what it
does (:class:`EngineAdapter`: ``version``, ``simulate``, ``simulate_many``, ``one_step``, ``expressible``,
the files its results depend on), the requests it gets (:class:`RunRequest`) and the errors it raises
(:class:`EngineError`, :class:`NotExpressible`).

An engine is an adapter class registered under the entry-point group ``rbcheck.engines``, or an engine file
(TOML, :mod:`cross_checks.engines.external`) turned into an adapter of the same interface; the registry
(:mod:`cross_checks.engines`) instantiates the class with no arguments. The contract and a worked example:
docs/engines.md, "Python engines: an adapter class and an entry point", and each method's docstring below.

Beside it: the forces every engine gets (:mod:`cross_checks.engines.forces`), the engine that supplies a
world to rbcheck's one loop (:mod:`cross_checks.engines.world`, :mod:`cross_checks.engines.loop`), the
optional engines' install checks (:mod:`cross_checks.engines.install`) and the JAX and Warp runtimes
(:mod:`cross_checks.engines.runtimes`).
"""
from __future__ import annotations

import abc
import importlib
import inspect
import math
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["EngineAdapter", "Variant", "EngineError", "NotExpressible", "RunRequest", "Traits", "INVARIANTS",
           "SYMPLECTIC_EULER_EXPLICIT_GYRO", "SYMPLECTIC_EULER_IMPLICIT_GYRO", "WHOLE_STATE_EXPLICIT_EULER",
           "WHOLE_STATE_IMPLICIT_EULER", "HIGHER_ORDER", "DEFAULT_TRAITS", "ModuleAdapter", "one_request",
           "check_variant", "InvarianceFinding"]


class EngineError(RuntimeError):
    """The engine rejected the model or failed during a run; the message carries the engine's own words.
    A sweep records the run as `failed` with this message and goes on."""


class NotExpressible(EngineError):
    """The engine cannot take the scenario's physics as written (EngineAdapter.expressible said so): a limit
    of the engine, not a failure of the run. A sweep lists the pair under ``not_expressible`` and runs
    nothing for it."""


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
class InvarianceFinding:
    """An invariance check a variant is known to break, declared beside its reason
    (Traits.invariance_findings; an engine file's ``[[variants.NAME.invariance_findings]]``), the way the
    traits declare a convergence
    finding: the checks (sweep, assert_engine, fuzz: cross_checks.sweep.invariance) report a matching broken
    check as a ``known finding``, with its number and this reason, instead of failing; a matching check that
    no longer breaks is said ("no longer broken"). Narrow by construction (docs/invariance.md, "Declared
    findings"):

    transform : the kind of transform (scenario.transforms.TRANSFORM_KINDS).
    within : ``((parameter, low, high), ...)``, at least one: a size of that kind
        (scenario.transforms.TRANSFORM_PARAMETERS: translation ``distance_m``, rotation and body_frame
        ``angle_deg``, scale ``k`` and ``mu``, com_offset ``gyration_radii``, welded_split ``child_mass``) and
        the closed range where the finding was measured; a transform outside any of them is judged as usual.
    reason : the sentence saying what the engine does and why, with what was measured.
    quantities : the quantities (core.quantities.QUANTITIES) the finding moves; a deviation beyond the
        allowance in any other keeps the check ``broken``.
    """

    transform: str
    within: tuple
    reason: str
    quantities: tuple = ("position", "orientation", "velocity", "angular_velocity")

    def __post_init__(self):
        from cross_checks.core.quantities import QUANTITIES
        from cross_checks.scenario.transforms import TRANSFORM_PARAMETERS
        if self.transform not in TRANSFORM_PARAMETERS:
            raise ValueError(f"transform must be one of {', '.join(TRANSFORM_PARAMETERS)}, "
                             f"not {self.transform!r}")
        names = TRANSFORM_PARAMETERS[self.transform]
        if not isinstance(self.within, tuple) or not self.within:
            raise ValueError(f"within must name at least one of {self.transform}'s sizes "
                             f"({', '.join(names)}) with its range (never the whole transform), "
                             f"not {self.within!r}")
        for item in self.within:
            ok = isinstance(item, tuple) and len(item) == 3 and item[0] in names
            if not ok or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                                 for v in item[1:]) or not item[1] <= item[2]:
                raise ValueError(f"within: each entry must be (size, low, high) with size one of "
                                 f"{', '.join(names)} and finite low <= high, not {item!r}")
        if not isinstance(self.reason, str) or not self.reason.strip():
            raise ValueError("reason must be the sentence that explains the finding")
        if (not isinstance(self.quantities, tuple) or not self.quantities
                or any(q not in QUANTITIES for q in self.quantities)):
            raise ValueError(f"quantities must be a non-empty tuple of {', '.join(QUANTITIES)}, "
                             f"not {self.quantities!r}")

    def matches(self, transform) -> bool:
        """Whether ``transform`` (a scenario.transforms.Transform) is of this kind with every size in its
        range (within tolerances.INVARIANCE_FINDING_RANGE_REL: a size computed from a vector or a quaternion
        carries a few roundings)."""
        from cross_checks.core import tolerances as tol
        if transform.kind != self.transform:
            return False
        sizes, slack = transform.parameters, tol.INVARIANCE_FINDING_RANGE_REL
        return all(name in sizes and lo * (1.0 - slack) <= sizes[name] <= hi * (1.0 + slack)
                   for name, lo, hi in self.within)

    def range_text(self) -> str:
        """The ranges in words (``distance_m 1000–10000``)."""
        return ", ".join(f"{n} {lo:g}" + (f"–{hi:g}" if hi != lo else "") for n, lo, hi in self.within)


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
    invariance_findings : the invariance checks the variant is known to break (:class:`InvarianceFinding`:
        the transform, the range of its sizes and the quantities where it was measured, and the reason), each
        reported as a known finding, not a failure (docs/invariance.md, "Declared findings"); () none.
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
    invariance_findings: tuple = ()

    def __post_init__(self):
        if not isinstance(self.invariance_findings, tuple) or not all(
                isinstance(f, InvarianceFinding) for f in self.invariance_findings):
            raise ValueError(f"invariance_findings must be a tuple of InvarianceFinding, "
                             f"not {self.invariance_findings!r}")
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


def check_variant(engine: str, variants, variant: str) -> None:
    """ValueError naming ``engine``'s variants when ``variant`` is not one of them."""
    if variant not in variants:
        raise ValueError(f"unknown {engine} variant {variant!r}; variants: {', '.join(variants)}")


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
    #: harness's forces and their plain-float twins, evaluated between an engine's steps).
    harness: tuple = ("cross_checks.engines.forces", "cross_checks.engines.step_floats")

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
