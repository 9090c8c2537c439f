"""Drake as an engine (``drake:VARIANT``, float64): the free bodies of cross_checks.engines.worlds.drake for
rbcheck's loop. Constant forces are fixed once on the plant's applied generalized force port (Drake keeps
them); state-dependent forces or decay are a LeafSystem evaluating ``forces.stage_force_torque`` at every
derivative evaluation, each stage of a multi-stage scheme at its own state (that time is rbcheck's). A step
Drake refuses ends its body's run. Conventions and what pins them: docs/engine_conventions.md, "Drake 1.51.1".
"""
from __future__ import annotations

import dataclasses
import functools
import time

import numpy as np

from cross_checks.engines import base, forces, install, world
from cross_checks.engines.base import EngineError, Variant
from cross_checks.engines.forces import stage_force_torque
from cross_checks.engines.world import World, WorldEngine

pydrake, _IMPORT_ERROR, dkw = install.optional_world("pydrake", "drake", "FormBody", "FormBodies")
from cross_checks.engines.worlds.com import com_state

__all__ = ["ENGINE", "VARIANTS", "version", "simulate", "simulate_many", "one_step", "DrakeModel",
           "DrakeWorld", "DrakeAdapter", "body_spec"]

ENGINE = "drake"
#: Drake's invariance finding under a COM offset (docs/engine_conventions.md, "Invariance"; CI's sweep).
ORIGIN_STEP_FINDING = base.InvarianceFinding(
    "com_offset", (("gyration_radii", 1.5, 1.5),),
    "the engine's, by design: Drake steps the free body's origin and turns the body about it (as its "
    "semi-explicit Euler, MuJoCo and DART do), so with the origin off the COM the COM moves otherwise by "
    "the step's truncation error, step-dependent at order 1 on the other catalog scenarios; on "
    "tumbling_box, thrown near the intermediate-axis separatrix (the motion amplifies a perturbation "
    "~850×), the implicit Euler's deviation shrinks 0.00937, 0.00364, 0.00231 m/s at Δt, Δt/2, Δt/4 — "
    "order 1.01 over the two halvings, but 0.66 at the second, below the 0.7 the refinement asks of each",
    ("position", "velocity"))
#: The variants, named after Drake's integrators (``ResetIntegratorFromFlags``; docs/engine_conventions.md).
VARIANTS = {
    "semi_explicit_euler": Variant(1.0, "Drake semi-explicit Euler: v from the start-of-step forces "
                                        "(explicit gyroscopic term), then q from the new v; quaternion "
                                        "integrated linearly, not renormalised",
                                   traits=base.SYMPLECTIC_EULER_EXPLICIT_GYRO),
    "runge_kutta2": Variant(2.0, "Drake RK2 (explicit trapezoid / Heun), forces at both stages",
                            traits=base.HIGHER_ORDER),
    "runge_kutta3": Variant(3.0, "Drake RK3 (Kutta's third-order scheme), forces at every stage",
                            traits=base.HIGHER_ORDER),
    "implicit_euler": Variant(1.0, "Drake implicit Euler on the whole state (Newton iteration, "
                                   "finite-difference Jacobian)",
                              traits=dataclasses.replace(base.WHOLE_STATE_IMPLICIT_EULER,
                                                         invariance_findings=(ORIGIN_STEP_FINDING,))),
}


def body_spec(body) -> tuple:
    """``(mass_kg, moments (3,), R_BP (3, 3) or None)`` as worlds.drake.spatial_inertia takes them
    (world.principal_spec: a diagonal tensor as its diagonal, no frame rotation)."""
    return world.principal_spec(body, frame=lambda R_BP: R_BP)


@functools.lru_cache(maxsize=1)
def _force_system_class():
    """The LeafSystem class (defined on first use: pydrake may be absent when this module is imported)."""
    from pydrake.systems.framework import LeafSystem

    class StageForces(LeafSystem):
        """The plant's state (13) in, the generalized force ``[τ_W, f_W − m g]`` (6) of the scenario's forces
        and decay there out (gravity is the plant's own); ``host_s``: the seconds of it (rbcheck's)."""

        def __init__(self, scenario, com_B_m=None):
            super().__init__()
            self._scenario, self._weight, self.host_s = scenario, forces.weight_W(scenario).tolist(), 0.0
            self._com = com_B_m   # the body origin Bo off the COM: the state converted, the torque about Bo
            self._x = self.DeclareVectorInputPort("state", 13)
            self.DeclareVectorOutputPort("generalized_force", 6, self._calc)

        def _calc(self, context, output):
            # plain floats: this runs at every derivative evaluation (a Newton iteration's Jacobian too)
            t0 = time.perf_counter()
            x = self._x.Eval(context).tolist()
            y = [x[4], x[5], x[6], x[10], x[11], x[12], x[0], x[1], x[2], x[3], x[7], x[8], x[9]]
            if self._com is not None:
                y = com_state(dkw.from_drake_state(np.array(x)), self._com)
            f, tau = stage_force_torque(self._scenario, y)
            w = self._weight
            if self._com is not None:   # f − m g at the COM: f − m g at Bo and the torque (R c) × (f − m g)
                r_W = y[0:3] - np.asarray(x[4:7])
                tau = np.asarray(tau) + np.cross(r_W, np.asarray(f) - np.asarray(w))
            output.SetFromVector(np.array([tau[0], tau[1], tau[2], f[0] - w[0], f[1] - w[1], f[2] - w[2]]))
            self.host_s += time.perf_counter() - t0
    return StageForces


def body_entry(scenario) -> tuple:
    """The scenario's body as worlds.drake.FormBody takes it (world.body_entry: its COM is p_BoBcm)."""
    return world.body_entry(scenario, body_spec)


class DrakeModel(dkw.FormBody):
    """A scenario's free body (worlds.drake.FormBody: its COM, its welded parts; the per-stage forces added
    here) simulated by the Drake integrator ``integrator``; ``set_state``/``state`` packed. With
    ``constant_forces``, the scenario's constant forces fixed on the plant here (else by :meth:`apply`)."""

    def __init__(self, scenario, integrator: str, constant_forces: bool = True):
        _ENGINE.require_installed()
        p = scenario.problem
        self.scenario = scenario
        self.per_stage = bool(p.forces.state_dependent or p.forces.has_decay)
        self.stage_forces = None
        super().__init__(body_entry(scenario), p.forces.gravity_W, integrator)   # sets com_B
        if constant_forces and not self.per_stage and (p.forces.point_forces or p.forces.torques):
            f, tau = stage_force_torque(scenario, p.initial_packed())     # constant: any state gives the same
            self.apply(f - forces.weight_W(scenario), tau)

    def add_bodies(self, plant):
        try:
            return dkw.FormBody.add_bodies(self, plant)
        except RuntimeError as exc:  # Drake's validity checks of the inertia
            raise EngineError(
                f"Drake {version()} rejected the inertia of scenario {self.scenario.name!r}: {exc}") from None

    def system(self, plant):
        """The plant; with forces at every stage, a diagram: its state into the LeafSystem, into its port."""
        if not self.per_stage:
            return plant
        from pydrake.systems.framework import DiagramBuilder
        builder = DiagramBuilder()
        builder.AddSystem(plant)
        fs = self.stage_forces = builder.AddSystem(_force_system_class()(self.scenario, self.com_B))
        builder.Connect(plant.get_state_output_port(), fs.get_input_port(0))
        builder.Connect(fs.get_output_port(0), plant.get_applied_generalized_force_input_port())
        return builder.Build()

    def state(self) -> np.ndarray:   # packed; the COM's where the origin is off it (worlds.com.com_state)
        y = dkw.from_drake_state(self.drake_state())
        return y if self.com_B is None else com_state(y, self.com_B)


def _model(scenario, variant: str, dt_s: float, constant_forces: bool = True) -> DrakeModel:
    model = DrakeModel(scenario, variant, constant_forces)   # the variants are named after the integrators
    model.fixed_step(dt_s)
    return model


class DrakeWorld(dkw.FormBodies, World):
    """B :class:`DrakeModel` bodies, constant forces the loop's, stepped in turn (worlds.drake.FormBodies). A
    step Drake refuses warns and keeps the body's last state; after a blow-up, a consequence."""

    first_cause_only = True
    hold_failed = True   # the loop ends the body's run at the step Drake refused (its warning)

    def __init__(self, requests, variant: str, dt_s: float):
        World.__init__(self)
        dkw.FormBodies.__init__(self, [_model(r.scenario, variant, dt_s, False) for r in requests], dt_s)
        self.per_stage = self.models[0].per_stage

    @property
    def host_s(self) -> float:
        return sum(m.stage_forces.host_s for m in self.models if m.stage_forces is not None)


class DrakeEngine(WorldEngine):
    """``drake:VARIANT`` — registered under the entry-point group ``rbcheck.engines``."""

    name, variants, world = ENGINE, VARIANTS, DrakeWorld
    distribution, module, extra, imported = "drake", "pydrake", "drake", "pydrake"
    #: the COM off the body origin (SpatialInertia with p_BoBcm); welded parts (WeldJoint)
    body_forms = frozenset({"com_offset", "welded_parts"})
    keeps_forces = True     # a fixed input port value stays until it is fixed again
    chunk = 256

    def version(self) -> str:   # the metadata's, else pydrake's own (a build from source)
        self.require_installed()
        return install.installed_version("drake") or getattr(pydrake, "__version__", "unknown")

    def per_stage(self, scenario, variant):
        return bool(scenario.problem.forces.state_dependent or scenario.problem.forces.has_decay)


_ENGINE, version, simulate, simulate_many, one_step = DrakeEngine.exported()
DrakeAdapter = DrakeEngine
