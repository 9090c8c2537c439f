"""A user's engine (a Python adapter with only a declared order: rbcheck knows none of its traits) in three
builds: correct, and two classic mistakes — the spring's rest length ignored, the inertia and its inverse
swapped. Each steps the course's scheme with the gyroscopic term (reference:course_gyro) on the scenario
AS THE BUGGY ENGINE READS IT, so it is a consistent first-order scheme of the wrong equations."""
from __future__ import annotations

import dataclasses

import numpy as np

from cross_checks.engines.base import EngineAdapter, Variant

__all__ = ["UserEngine", "misread"]


def misread(scenario, variant: str):
    """The scenario as the ``variant`` build of the user engine reads it."""
    p = scenario.problem
    if variant == "no_rest_length":
        forces = dataclasses.replace(p.forces, springs=tuple(dataclasses.replace(s, rest_length_m=0.0)
                                                             for s in p.forces.springs))
        p = dataclasses.replace(p, forces=forces)
    elif variant == "inverse_inertia":
        p = dataclasses.replace(p,
                                body=dataclasses.replace(p.body, inertia_B=np.linalg.inv(p.body.inertia_B)))
    return dataclasses.replace(scenario, problem=p)


class UserEngine(EngineAdapter):
    name = "userengine"
    variants = {
        "correct": Variant(1, "semi-implicit Euler with the gyroscopic term (correct)"),
        "no_rest_length": Variant(1, "the same, the spring's rest length ignored (a bug)"),
        "inverse_inertia": Variant(1, "the same, I and its inverse swapped (a bug)"),
    }

    def version(self) -> str:
        return "1.0"

    def simulate(self, scenario, variant, dt_s, n_steps):
        from cross_checks.engines import get_adapter
        return get_adapter("reference").simulate(misread(scenario, variant), "course_gyro", dt_s, n_steps)


class BulletBody:
    """One scenario body in a PyBullet world of its own (the adapter's ``BulletWorld`` of one body, LOCK not
    taken), seen as a single body: what the PyBullet convention tests and their NumPy oracle drive."""

    def __init__(self, scenario, variant: str, dt_s: float, y0=None):
        import numpy as np

        from cross_checks.engines import forces
        from cross_checks.engines import pybullet_engine as pe
        from cross_checks.engines.base import RunRequest
        self.world = pe.BulletWorld([RunRequest(scenario, float(dt_s), 1)], variant, float(dt_s))
        self.b, self.c, self.q_BP = self.world.bodies[0], self.world.c, self.world.q_BP[0]
        self.weight = forces.weight_W(scenario)
        self._np = np

    def set_state(self, y):
        self.world.set_state(self._np.asarray(y, dtype=float)[None])

    def read_raw(self) -> list:
        return list(self.world.read()[0])

    def raw_to_packed(self, raw):
        return self.world.packed(self._np.asarray(raw, dtype=float)[..., None, :])[..., 0, :]

    def apply(self, f_W, tau_W, x_W):
        """World force ``f_W`` at ``x_W`` and world torque ``tau_W`` (3 numbers each) for the next step."""
        self.world.last = [[float(v) for v in x_W] + [0.0] * 10]
        self.world.apply(self._np.asarray([f_W], dtype=float), self._np.asarray([tau_W], dtype=float))
