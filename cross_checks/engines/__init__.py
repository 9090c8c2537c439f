"""Engine registry: ``ENGINE:VARIANT`` names, availability, and running a scenario into a Trajectory."""
from __future__ import annotations

import importlib
import time
from dataclasses import dataclass

from ..trajectory import Trajectory

__all__ = ["ENGINE_MODULES", "VariantInfo", "all_variants", "available_variants", "get_adapter",
           "split_variant", "run_variant", "EngineUnavailable", "UnknownVariant"]

#: Engine name -> adapter module. Order is the order of `rbcheck list`.
ENGINE_MODULES = {
    "reference": "cross_checks.engines.reference",
    "mujoco": "cross_checks.engines.mujoco_engine",
    "pybullet": "cross_checks.engines.pybullet_engine",
}

#: Variants each engine offers, listed even when the engine cannot be imported.
STATIC_VARIANTS = {
    "reference": ["course", "course_gyro", "expmap_gyro", "explicit_euler", "implicit_euler", "midpoint",
                  "leapfrog", "rk4"],
    "mujoco": ["euler", "rk4", "implicit", "implicitfast"],
    "pybullet": ["multibody", "maximal"],
}


class EngineUnavailable(RuntimeError):
    """The engine's Python package cannot be imported here."""


class UnknownVariant(ValueError):
    pass


@dataclass(frozen=True)
class VariantInfo:
    name: str          # ENGINE:VARIANT
    engine: str
    variant: str
    available: bool
    reason: str        # why unavailable ("" when available)
    description: str
    version: str


_adapters: dict = {}
_failures: dict = {}


def get_adapter(engine: str):
    """The adapter module of an engine; raises EngineUnavailable (with the import error) or UnknownVariant."""
    if engine not in ENGINE_MODULES:
        raise UnknownVariant(f"unknown engine {engine!r}; engines: {', '.join(ENGINE_MODULES)}")
    if engine in _adapters:
        return _adapters[engine]
    if engine in _failures:
        raise EngineUnavailable(_failures[engine])
    try:
        mod = importlib.import_module(ENGINE_MODULES[engine])
        mod.version()
    except ImportError as exc:
        _failures[engine] = f"{engine} cannot be imported: {exc}"
        raise EngineUnavailable(_failures[engine]) from None
    _adapters[engine] = mod
    return mod


def split_variant(name: str):
    """``"mujoco:rk4"`` -> ``("mujoco", "rk4")``, validated against the known variants."""
    if ":" not in name:
        raise UnknownVariant(f"engine variant must be ENGINE:VARIANT (e.g. reference:course), got {name!r}")
    engine, variant = name.split(":", 1)
    if engine not in STATIC_VARIANTS:
        raise UnknownVariant(f"unknown engine {engine!r} in {name!r}; engines: {', '.join(STATIC_VARIANTS)}")
    if variant not in STATIC_VARIANTS[engine]:
        raise UnknownVariant(f"unknown variant {variant!r} of {engine}; variants: "
                             + ", ".join(f"{engine}:{v}" for v in STATIC_VARIANTS[engine]))
    return engine, variant


def all_variants() -> list[VariantInfo]:
    """Every ENGINE:VARIANT with availability and a one-line description."""
    out = []
    for engine, variants in STATIC_VARIANTS.items():
        try:
            mod = get_adapter(engine)
            ok, reason, ver, desc = True, "", mod.version(), mod.VARIANTS
        except EngineUnavailable as exc:
            ok, reason, ver, desc = False, str(exc), "", {}
        for v in variants:
            out.append(VariantInfo(f"{engine}:{v}", engine, v, ok, reason, desc.get(v, ""), ver))
    return out


def available_variants() -> list[str]:
    return [v.name for v in all_variants() if v.available]


def run_variant(scenario, name: str, dt_s: float | None = None, duration_s: float | None = None) -> Trajectory:
    """Run ``scenario`` with engine variant ``name``; the Trajectory's meta records engine, version,
    variant, dt, scenario hash, status (``ok``/``diverged``) and ``diverged_at_s``."""
    engine, variant = split_variant(name)
    mod = get_adapter(engine)
    dt = scenario.dt_s if dt_s is None else float(dt_s)
    T = scenario.duration_s if duration_s is None else float(duration_s)
    n = scenario.n_steps(dt, T)
    t0 = time.perf_counter()
    run = mod.simulate(scenario, variant, dt, n)
    wall = time.perf_counter() - t0
    import reference_sim
    meta = {
        "engine": engine,
        "engine_version": mod.version(),
        "variant": name,
        "dt_s": dt,
        "duration_s": T,
        "n_steps": n,
        "scenario": scenario.name,
        "scenario_hash": scenario.content_hash,
        "scenario_source": scenario.source,
        "status": "diverged" if run.diverged_at_s is not None else "ok",
        "diverged_at_s": run.diverged_at_s,
        "message": run.message,
        "wall_s": wall,
        "rbcheck_version": reference_sim.__version__,
    }
    return Trajectory(run.t_s, run.y, meta)
