"""Float32 schemes for the tests of the precision model: the reference's schemes with their state stored in
float32 after every step — what a float32 engine keeps between steps (each component rounded to the nearest of
24 significant bits, IEEE 754 binary32) — correct or with one of the planted bugs of tests/mutants.py.

Each is an engine adapter ``f32_NAME:VARIANT`` declaring the traits of the reference scheme it imitates
with ``precision="float32"`` (or a precision given, to show what a wrong declaration does): the sweep,
the fuzz and ``check`` then judge it with float32 round-off floors and the float32 ladder
(docs/verdicts.md, "Precision")."""
from __future__ import annotations

import dataclasses

import numpy as np

from cross_checks import engines
from cross_checks.engines import declared_traits
from cross_checks.engines.base import EngineAdapter, Variant
from cross_checks.engines.reference import ReferenceAdapter
from reference_sim.forces import Members
from reference_sim.integrators import ImplicitSolveError, get_step
from reference_sim.simulate import run_members


def to_float32(y):
    """``y`` rounded to float32 and back (float64 arrays holding float32 values)."""
    return np.asarray(y, dtype=np.float64).astype(np.float32).astype(np.float64)


def _unchanged(members):
    return members


class Float32Adapter(EngineAdapter):
    """``f32_NAME:VARIANT``: reference scheme VARIANT, its state rounded to float32 after every step; with a
    mutant (tests/mutants.py), that mutant's knob and broken step."""

    def __init__(self, name: str, variant: str, mutant=None, precision: str = "float32",
                 rounding_factor: float = 1.0):
        self.name, self.scheme = f"f32_{name}", variant.split(":", 1)[1]
        spec = ReferenceAdapter.variants[self.scheme]
        bug = f" WITH A PLANTED BUG: {mutant.bug}" if mutant is not None else ""
        traits = dataclasses.replace(declared_traits(variant), precision=precision,
                                     rounding_factor=rounding_factor)
        self.variants = {self.scheme: Variant(spec.order, f"{spec.description}, state in float32{bug}",
                                              imitates=variant, traits=traits)}
        ad = mutant.adapter if mutant is not None else None
        self.knob = ad.knob if ad is not None else _unchanged
        self.step = (ad.step if ad is not None else None) or get_step(self.scheme)

    def version(self) -> str:
        return "float32 test scheme"

    def same_as(self, other) -> bool:
        return isinstance(other, Float32Adapter) and other.name == self.name

    def source_files(self) -> list:
        return [__file__]

    def _f32_step(self, members, y, dt):
        return to_float32(self.step(members, y, dt))

    def simulate(self, scenario, variant: str, dt_s: float, n_steps: int):
        p = scenario.problem
        y0 = to_float32(p.initial_packed()[None])
        return run_members(self.knob(p.members), self._f32_step, [dt_s], [n_steps], y0)[0]

    def simulate_many(self, variant: str, requests) -> list:
        """The runs of ``requests`` as the members of one run (``run_members``), as the reference adapter
        batches its own: each member's run is :meth:`simulate`'s, bit for bit (every row of the definition
        advances on its own; tests/cross_checks/analysis/test_precision.py asserts it for these schemes), and
        the definition's Python steps are taken once for all the runs of a ladder instead of once per run (a
        ladder's rungs are steps of T/Δt: the finest alone is half of the steps of all of them)."""
        problems = [r.scenario.problem for r in requests]
        if not problems:
            return []
        y0 = to_float32(np.array([p.initial_packed() for p in problems]))
        return run_members(self.knob(Members.stack(problems)), self._f32_step, [r.dt_s for r in requests],
                           [r.n_steps for r in requests], y0)

    def one_step(self, scenario, variant: str, dt_s: float, y_start):
        with np.errstate(all="ignore"):
            try:
                return self._f32_step(self.knob(scenario.problem.members), to_float32(y_start), dt_s)
            except ImplicitSolveError:
                return np.full(np.shape(y_start), np.nan)


def register(monkeypatch, adapter: Float32Adapter) -> str:
    """Register ``adapter`` until the monkeypatch is undone; returns its ``ENGINE:VARIANT``."""
    monkeypatch.setattr(engines, "_user", dict(engines._user))
    engines.register_adapter(adapter, "tests/helpers/float32.py")
    return f"{adapter.name}:{adapter.scheme}"
