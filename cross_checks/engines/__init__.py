"""Engine registry: ``ENGINE:VARIANT`` names, availability, and running a scenario into a Trajectory.

One way in: every engine is an adapter class (:class:`~cross_checks.engines.base.EngineAdapter`)
registered under the entry-point group ``rbcheck.engines`` — rbcheck's own reference, MuJoCo and
PyBullet adapters included (see pyproject.toml) — or an engine file given with ``--engine-file``
(:mod:`cross_checks.engines.external`), which becomes an adapter of the same interface.

An entry point that cannot be loaded, or whose ``version()`` raises (e.g. its engine is not
installed), is listed as unavailable with the reason; it never stops rbcheck.
"""
from __future__ import annotations

import contextlib
import time
from dataclasses import dataclass

from cross_checks.core.names import NAME_RE, did_you_mean
from cross_checks.core.trajectory import Trajectory
from cross_checks.engines.base import (
    EngineAdapter,
    EngineError,
    NotExpressible,
    Traits,
    Variant,
)
from cross_checks.engines.install import EngineNotInstalled

__all__ = ["ENTRY_POINT_GROUP", "VariantInfo", "EngineEntry", "all_variants", "available_variants",
           "get_adapter", "split_variant", "default_variant", "run_variant", "run_variants", "run_requests",
           "engine_entries",
           "engine_variants", "declared_variant", "declared_order", "declared_imitation", "declared_traits",
           "has_one_step", "load_engine_files", "engine_files_registered", "register_adapter", "user_engines",
           "adopt_user_engines", "engine_provenance", "reset_registry", "EngineUnavailable", "UnknownVariant",
           "EngineAdapter", "EngineError", "Variant", "REQUIRED_ENGINES", "unusable_required_engines",
           "NotExpressible", "not_expressible", "Resolved", "resolve"]

ENTRY_POINT_GROUP = "rbcheck.engines"
#: rbcheck's own engines, in the order of `rbcheck list`; other engines follow by name.
BUILTIN_ENGINES = ("reference", "mujoco", "pybullet", "drake", "dart", "jaxsim", "genesis", "brax", "mjx",
                   "rapier", "physx", "mujoco_warp", "newton")
#: The engines rbcheck depends on (pyproject.toml pins them): one that cannot run here is an error of the
#: installation, never a variant quietly skipped. The others (Drake, engines to come) are optional extras.
REQUIRED_ENGINES = ("reference", "mujoco", "pybullet")


class EngineUnavailable(RuntimeError):
    """The engine cannot run here (its package cannot be imported, or its adapter cannot be loaded)."""


class UnknownVariant(ValueError):
    pass


@dataclass(frozen=True)
class VariantInfo:
    name: str          # ENGINE:VARIANT ("ENGINE:*" for an engine whose adapter cannot be loaded)
    engine: str
    variant: str
    available: bool
    reason: str        # why unavailable ("" when available)
    description: str
    version: str
    order: float | None = None   # declared global order
    source: str = ""             # where the engine comes from (entry point or engine file)
    installed: bool = True       # False: the engine's package is not installed at all (vs. failing to import)
    required: bool = False       # one of REQUIRED_ENGINES (rbcheck's own dependencies)
    default: bool = False        # the variant the engine's name alone means (default_variant)


@dataclass
class EngineEntry:
    """A registered engine: its adapter (None when it could not be loaded, ``load_error`` says why)."""

    name: str
    adapter: EngineAdapter | None
    source: str
    load_error: str = ""
    builtin: bool = False


_entries: dict | None = None      # name -> EngineEntry (entry points), built on first use
_user: dict = {}                   # name -> EngineEntry (engine files / register_adapter), in order
_versions: dict = {}               # name -> version string (available engines)
_failures: dict = {}               # name -> why unavailable
_absent: set = set()               # names whose package is not installed at all (a subset of _failures)


def _validate_adapter(adapter, name: str) -> str:
    """"" when ``adapter`` fulfils the interface under ``name``, else the reason."""
    if getattr(adapter, "name", None) != name:
        return f"its adapter's name is {getattr(adapter, 'name', None)!r}, not {name!r}"
    variants = getattr(adapter, "variants", None)
    if not isinstance(variants, dict) or not variants:
        return "its adapter declares no variants (variants must be a non-empty dict of Variant)"
    for v, spec in variants.items():
        if not isinstance(v, str) or not NAME_RE.match(v):
            return f"variant name {v!r} must match [a-z0-9_]+"
        if not isinstance(spec, Variant):
            return f"variants[{v!r}] must be a Variant(order, description), got {type(spec).__name__}"
    for meth in ("version", "simulate"):
        if not callable(getattr(adapter, meth, None)):
            return f"its adapter has no {meth}() method"
    return ""


def _load_entry_point(ep, dist_name: str) -> EngineEntry:
    entry = EngineEntry(ep.name, None, f"entry point {ep.name} = {ep.value} ({dist_name})",
                        builtin=(dist_name == "rbcheck" and ep.name in BUILTIN_ENGINES))
    if not NAME_RE.match(ep.name):
        entry.load_error = f"entry point name {ep.name!r} must match [a-z0-9_]+"
        return entry
    try:
        adapter = ep.load()()
    except Exception as exc:  # noqa: BLE001 - a broken plug-in is listed as unavailable, never fatal
        entry.load_error = f"cannot load {ep.value}: {type(exc).__name__}: {exc}"
        return entry
    why = _validate_adapter(adapter, ep.name)
    if why:
        entry.load_error = f"{ep.value}: {why}"
    else:
        entry.adapter = adapter
    return entry


def _load_entry_points() -> dict:
    """Every entry point of the group, loaded; a name registered twice keeps rbcheck's own engine (else
    the first found) and lists the other as unavailable under ``NAME (DISTRIBUTION)``."""
    from importlib.metadata import entry_points
    found = {}
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        dist = getattr(ep, "dist", None)
        dist_name = dist.metadata["Name"] if dist is not None else "?"
        entry = _load_entry_point(ep, dist_name)
        prev = found.get(ep.name)
        if prev is not None:
            if prev.source == entry.source:
                continue
            if entry.builtin and not prev.builtin:
                prev, entry = entry, prev
            found[ep.name] = prev
            loser = entry.source.rsplit("(", 1)[-1].rstrip(")")
            found[f"{ep.name} ({loser})"] = EngineEntry(
                ep.name, None, entry.source,
                f"the engine name {ep.name!r} is already registered by {prev.source}")
            continue
        found[ep.name] = entry
    order = {n: i for i, n in enumerate(BUILTIN_ENGINES)}
    return dict(sorted(found.items(), key=lambda kv: (order.get(kv[0], len(order)), kv[0])))


def _registry() -> dict:
    global _entries
    if _entries is None:
        _entries = _load_entry_points()
        if "reference" not in _entries:
            raise EngineUnavailable(
                f"no 'reference' engine under the entry-point group {ENTRY_POINT_GROUP!r}: rbcheck's "
                "installation metadata is missing or stale; reinstall it (pip install -e .)")
    return _entries


def engine_entries() -> list:
    """Every registered engine (entry points first, then engine files), including unloadable ones."""
    return list(_registry().values()) + list(_user.values())


def _entry(engine: str) -> EngineEntry:
    if engine in _user:
        return _user[engine]
    reg = _registry()
    if engine in reg:
        return reg[engine]
    names = list(dict.fromkeys(e.name for e in engine_entries()))
    raise UnknownVariant(f"unknown engine {engine!r}{did_you_mean(engine, names)}; "
                         f"engines: {', '.join(names)}"
                         + ("" if _user else " (add your own with --engine-file FILE)"))


def reset_registry() -> None:
    """Forget every engine: entry points are scanned again on next use, engine files dropped."""
    global _entries
    _entries = None
    _user.clear()
    _versions.clear()
    _failures.clear()
    _absent.clear()


def register_adapter(adapter: EngineAdapter, source: str) -> EngineEntry:
    """Add an adapter (an engine file's) to this process's registry. Raises ValueError when its name is
    taken by another engine or the adapter does not fulfil the interface."""
    name = getattr(adapter, "name", "")
    if name in _registry():
        raise ValueError(f"name {name!r} is already an engine ({_registry()[name].source}); "
                         "choose another name")
    if name in _user:
        prev = _user[name]
        if prev.source == source and getattr(prev.adapter, "same_as", lambda _: False)(adapter):
            return prev
        raise ValueError(f"name {name!r} is already registered by {prev.source}; choose another name")
    why = _validate_adapter(adapter, name)
    if why:
        raise ValueError(why)
    entry = EngineEntry(name, adapter, source)
    _user[name] = entry
    return entry


def load_engine_files(paths) -> list:
    """Register the engine files ``paths`` (validated first, all or none). Raises
    :class:`~cross_checks.engines.external.EngineFileError` (``FILE: FIELD: REASON``)."""
    from cross_checks.engines.external import EngineFileError, load_engine_file
    adapters = [load_engine_file(p) for p in paths or []]
    out = []
    for a in adapters:
        try:
            out.append(register_adapter(a, a.source))
        except ValueError as exc:
            raise EngineFileError(a.path, "name", str(exc)) from None
    return out


@contextlib.contextmanager
def engine_files_registered(paths):
    """Register the engine files ``paths`` for the duration of the block (engines registered before
    it stay): how assert_engine keeps one test's engine files from leaking into the next."""
    before = set(_user)
    try:
        yield load_engine_files(paths)
    finally:
        for name in set(_user) - before:
            del _user[name]
            _versions.pop(name, None)
            _failures.pop(name, None)


def user_engines() -> list:
    """The engine-file adapters registered in this process (picklable), for worker processes."""
    return [e.adapter for e in _user.values()]


def adopt_user_engines(adapters) -> None:
    """Register in this (worker) process the engines :func:`user_engines` listed in the parent."""
    for a in adapters or ():
        if a.name not in _user:
            register_adapter(a, a.source)


def get_adapter(engine: str) -> EngineAdapter:
    """The adapter of an engine; raises EngineUnavailable (with the reason) or UnknownVariant."""
    e = _entry(engine)
    if e.adapter is None:
        raise EngineUnavailable(f"{engine}: {e.load_error}")
    if engine in _failures:
        raise EngineUnavailable(_failures[engine])
    if engine not in _versions:
        try:
            _versions[engine] = str(e.adapter.version())
        except EngineNotInstalled as exc:   # rbcheck's adapters say "X is not installed (how to install)"
            _failures[engine] = str(exc)
            _absent.add(engine)
            raise EngineUnavailable(_failures[engine]) from None
        except ImportError as exc:
            text = str(exc)
            _failures[engine] = (text if "cannot be imported" in text
                                 else f"{engine} cannot be imported: {text}")
            raise EngineUnavailable(_failures[engine]) from None
        except Exception as exc:  # noqa: BLE001 - a plug-in's version() may fail in any way
            _failures[engine] = f"{engine}: version() failed: {type(exc).__name__}: {exc}"
            raise EngineUnavailable(_failures[engine]) from None
    return e.adapter


def engine_variants(engine: str) -> list:
    """Variant names an engine offers ([] when its adapter cannot be loaded)."""
    e = _entry(engine)
    return list(e.adapter.variants) if e.adapter is not None else []


def default_variant(engine: str) -> str:
    """``ENGINE:VARIANT`` of the variant an engine name alone means in ``rbcheck run``: the first variant
    its adapter declares (each built-in adapter declares the engine's own default first: the course's
    step, MuJoCo's Euler, PyBullet's multibody). UnknownVariant for an unknown or unloadable engine."""
    e = _entry(engine)
    if e.adapter is None:
        raise UnknownVariant(f"engine {engine} cannot be loaded: {e.load_error}")
    if not e.adapter.variants:
        raise UnknownVariant(f"engine {engine} declares no variant")
    return f"{engine}:{next(iter(e.adapter.variants))}"


def split_variant(name: str):
    """``"mujoco:rk4"`` -> ``("mujoco", "rk4")``, validated against the registered variants."""
    if ":" not in name:
        raise UnknownVariant(f"engine variant must be ENGINE:VARIANT (e.g. reference:course), got {name!r}")
    engine, variant = name.split(":", 1)
    e = _entry(engine)
    if e.adapter is None:
        raise UnknownVariant(f"engine {engine} cannot be loaded: {e.load_error}")
    if variant not in e.adapter.variants:
        raise UnknownVariant(f"unknown variant {variant!r} of {engine}"
                             f"{did_you_mean(variant, e.adapter.variants)}; variants: "
                             + ", ".join(f"{engine}:{v}" for v in e.adapter.variants))
    return engine, variant


def declared_variant(name: str):
    """The :class:`Variant` an engine declares for ``ENGINE:VARIANT`` (None when the engine or variant is
    unknown or unavailable here): its order, traits and imitation are read from it."""
    engine, _, variant = name.partition(":")
    try:
        e = _entry(engine)
    except (UnknownVariant, EngineUnavailable):
        return None
    return e.adapter.variants.get(variant) if e.adapter is not None else None


def declared_order(name: str) -> float | None:
    """The order an engine declares for ``ENGINE:VARIANT`` (None when unknown)."""
    return getattr(declared_variant(name), "order", None)


def declared_traits(name: str):
    """The Traits ``name`` (``ENGINE:VARIANT``) declares (Variant.traits), or None."""
    return getattr(declared_variant(name), "traits", None)


def declared_imitation(name: str) -> str:
    """The ``ENGINE:VARIANT`` whose scheme ``name`` declares it imitates (Variant.imitates; "" when none)."""
    return getattr(declared_variant(name), "imitates", "") or ""


class Resolved(str):
    """``ENGINE:VARIANT`` resolved once (:func:`resolve`), for the sweep's plan, a fuzz batch and ``check`` to
    pass down instead of looking the name up again: a ``str`` equal to the name (a key, a results row's
    ``variant``, a message's word, pickled to a worker as itself) that carries what its engine declares —

    * ``engine``, ``variant``: the two halves of the name;
    * ``order``: the declared global order (None when no loadable engine declares the name);
    * ``traits``: its own Traits, or those of the variant it ``imitates``; DEFAULT_TRAITS when neither;
    * ``precision``: "float64" or "float32" (Traits.precision), and ``rounding_unit``: ε of that precision
      × Traits.rounding_factor, the unit of every round-off floor of its runs;
    * ``one_step``: its engine has a one-step (local error) mode;
    * ``known``: a loadable engine declares it (False for a name read from someone else's results).

    Immutable by convention: made only by :func:`resolve`."""

    engine: str
    variant: str
    order: float | None
    traits: Traits
    imitates: str
    precision: str
    rounding_unit: float
    one_step: bool
    known: bool

    def __new__(cls, name: str, **fields):
        obj = super().__new__(cls, name)
        obj.__dict__.update(fields)
        return obj

    def __reduce__(self):
        return (_rebuilt, (str(self), dict(self.__dict__)))

    def __repr__(self) -> str:
        return f"Resolved({str(self)!r})"

    def cannot_express(self, scenario) -> str:
        """:func:`not_expressible` of ``scenario`` for this variant: "" when its engine can run the scenario's
        physics as written, else the engine's sentence."""
        return not_expressible(scenario, self)

    @property
    def adapter(self) -> EngineAdapter:
        """The engine's adapter (:func:`get_adapter`: EngineUnavailable when it cannot run here)."""
        return get_adapter(self.engine)


def _rebuilt(name: str, fields: dict) -> Resolved:
    return Resolved(name, **fields)


def resolve(name, *, strict: bool = False, engine_alone: bool = False) -> Resolved:
    """``name`` (``ENGINE:VARIANT``) as a :class:`Resolved` (itself when it already is one). Without
    ``strict`` it never raises: a name no loadable engine declares (one read from someone else's results)
    resolves to the cautious defaults (no order, DEFAULT_TRAITS), as its verdicts are then judged. ``strict``
    (a user's input): UnknownVariant, with :func:`split_variant`'s words, unless a loadable engine declares
    the name; ``engine_alone``: an engine name alone means its default variant (:func:`default_variant`)."""
    if isinstance(name, Resolved) and (name.known or not strict):
        return name
    from cross_checks.core.tolerances import MACHINE_EPSILON
    from cross_checks.engines.base import DEFAULT_TRAITS
    name = str(name)
    if engine_alone and ":" not in name:
        name = default_variant(name)
    if strict:
        split_variant(name)
    engine, _, variant = name.partition(":")
    spec = declared_variant(name)
    imitates = getattr(spec, "imitates", "") or ""
    traits = (getattr(spec, "traits", None) or getattr(declared_variant(imitates), "traits", None)
              or DEFAULT_TRAITS)
    return Resolved(name, engine=engine, variant=variant, order=getattr(spec, "order", None), traits=traits,
                    imitates=imitates, precision=traits.precision,
                    rounding_unit=MACHINE_EPSILON[traits.precision] * float(traits.rounding_factor),
                    one_step=has_one_step(name), known=spec is not None)


def has_one_step(name: str) -> bool:
    """Whether the engine of ``ENGINE[:VARIANT]`` has a one-step (local error) mode."""
    try:
        e = _entry(name.split(":", 1)[0])
    except (UnknownVariant, EngineUnavailable):
        return False
    return bool(e.adapter is not None and e.adapter.has_one_step)


#: The body forms beyond "a body whose frame origin is its COM" (docs/invariance.md): an adapter says which it
#: builds in its ``body_forms`` (a set of these); a scenario that needs another is "cannot express" for it.
BODY_FORMS = {"com_offset": "a body whose frame origin is not at its COM (body.com)",
              "welded_parts": "a body of welded parts (body.parts)"}


def body_form_missing(adapter, scenario) -> str:
    """"" when ``adapter`` builds the scenario's body as given (its ``body_forms``), else the sentence saying
    which form it cannot build: an adapter that does not declare a form would build the body at its COM
    (the same physics, so the check would say nothing), and must not pretend it expressed it."""
    need = ("welded_parts" if getattr(scenario, "body_parts", ())
            else "com_offset" if getattr(scenario, "body_com_B_m", None) is not None else "")
    if not need or need in getattr(adapter, "body_forms", ()):
        return ""
    return f"{adapter.name or type(adapter).__name__} cannot express {BODY_FORMS[need]}"


def not_expressible(scenario, name: str) -> str:
    """"" when engine variant ``name`` can run ``scenario``'s physics as written, else the engine's sentence
    saying what of it the engine cannot take (EngineAdapter.expressible). An engine that cannot be loaded
    here says nothing (its runs fail with the reason it cannot run)."""
    engine, variant = (name.engine, name.variant) if isinstance(name, Resolved) else split_variant(name)
    try:
        adapter = get_adapter(engine)
    except Exception:  # noqa: BLE001 - unavailable: its runs say why
        return ""
    return adapter.expressible(scenario, variant) or body_form_missing(adapter, scenario)


def all_variants() -> list[VariantInfo]:
    """Every ENGINE:VARIANT with availability, declared order and a one-line description."""
    out = []
    for e in engine_entries():
        required = e.builtin and e.name in REQUIRED_ENGINES
        if e.adapter is None:
            out.append(VariantInfo(f"{e.name}:*", e.name, "*", False, f"{e.name}: {e.load_error}", "", "",
                                   None, e.source, True, required))
            continue
        try:
            get_adapter(e.name)
            ok, reason, ver = True, "", _versions[e.name]
        except EngineUnavailable as exc:
            ok, reason, ver = False, str(exc), ""
        for i, (v, spec) in enumerate(e.adapter.variants.items()):
            out.append(VariantInfo(f"{e.name}:{v}", e.name, v, ok, reason, spec.description, ver, spec.order,
                                   e.source, e.name not in _absent, required, default=i == 0))
    return out


def unusable_required_engines() -> dict:
    """``{engine: why}`` of the required engines (REQUIRED_ENGINES) that cannot run here: an installation
    to repair (exit 2 in the commands), never variants to skip."""
    return {v.engine: v.reason for v in all_variants() if v.required and not v.available}


def available_variants() -> list[Resolved]:
    """Every ENGINE:VARIANT that can run here, resolved (:class:`Resolved`)."""
    return [resolve(v.name) for v in all_variants() if v.available]


def engine_provenance(engine: str) -> dict:
    """What identifies an engine's results: version, where it comes from, and for an engine file its
    SHA-256 (and that of the programs its commands name)."""
    e = _entry(engine)
    info = {"version": _versions.get(engine, ""), "source": e.source}
    extra = getattr(e.adapter, "provenance", None)
    if callable(extra):
        info.update(extra())
    return info


def run_variants(scenario, name: str, dts, duration_s: float | None = None) -> list:
    """Run ``scenario`` with engine variant ``name`` at each Δt of ``dts`` (s) in one
    ``EngineAdapter.simulate_many`` call: per Δt a Trajectory (see :func:`run_variant`), or the
    EngineError its run raised. Each run's ``wall_s`` is the call's wall time shared in proportion to the
    runs' steps (an engine that batches has no time of its own per run)."""
    from cross_checks.engines.base import RunRequest
    T = scenario.duration_s if duration_s is None else float(duration_s)
    return run_requests(name, [RunRequest(scenario, float(dt), scenario.n_steps(float(dt), T)) for dt in dts])


def run_requests(name: str, requests) -> list:
    """The runs of ``requests`` (base.RunRequest, of any scenarios) with engine variant ``name`` in one
    ``EngineAdapter.simulate_many`` call: per request a Trajectory, the EngineError its run raised, or
    NotExpressible when the engine cannot take that scenario (nothing is run for it). ``wall_s`` as in
    :func:`run_variants`. The long runs of a sweep run all the long-run scenarios of a variant this way."""
    engine, variant = split_variant(name)
    adapter = get_adapter(engine)
    requests = list(requests)
    why = [adapter.expressible(r.scenario, variant) or body_form_missing(adapter, r.scenario)
           for r in requests]
    todo = [r for r, w in zip(requests, why) if not w]
    t0 = time.perf_counter()
    done = adapter.simulate_many(variant, todo) if todo else []
    wall = time.perf_counter() - t0
    steps = sum(r.n_steps for r in todo) or 1
    # a run whose loop timed itself (engine_s + host_s, per world) gets those and a share of the rest of the
    # call's time; the others share the call's time in proportion to their steps
    timed = [(getattr(x, "engine_s", None) or 0.0) + (getattr(x, "host_s", None) or 0.0)
             if getattr(x, "host_s", None) is not None else None for x in done]
    rest = max(0.0, wall - sum(t for t in timed if t is not None))
    runs = iter(zip(done, timed))
    import reference_sim
    out: list = []
    for r, w in zip(requests, why):
        if w:
            out.append(NotExpressible(w))
            continue
        run, own = next(runs)
        if isinstance(run, EngineError):
            out.append(run)
            continue
        meta = {
            "engine": engine,
            "engine_version": adapter.version(),
            "variant": name,
            "dt_s": r.dt_s,
            "duration_s": r.n_steps * r.dt_s,
            "n_steps": r.n_steps,
            "scenario": r.scenario.name,
            "scenario_hash": r.scenario.content_hash,
            "scenario_source": r.scenario.source,
            "status": "diverged" if run.diverged_at_s is not None else "ok",
            "diverged_at_s": run.diverged_at_s,
            "message": run.message,
            "wall_s": wall * (r.n_steps / steps) if own is None else own + rest * (r.n_steps / steps),
            # the seconds inside the engine's own step (the host loop's split; NaN where the adapter owns its
            # loop and cannot tell them apart)
            "engine_s": float("nan") if getattr(run, "engine_s", None) is None else float(run.engine_s),
            "rbcheck_version": reference_sim.__version__,
        }
        out.append(Trajectory(run.t_s, run.y, meta))
    return out


def run_variant(scenario, name: str, dt_s: float | None = None,
                duration_s: float | None = None) -> Trajectory:
    """Run ``scenario`` with engine variant ``name``; the Trajectory's meta records engine, version,
    variant, dt, scenario hash, status (``ok``/``diverged``) and ``diverged_at_s``. Raises the engine's
    EngineError."""
    traj = run_variants(scenario, name, [scenario.dt_s if dt_s is None else float(dt_s)], duration_s)[0]
    if isinstance(traj, EngineError):
        raise traj
    return traj
