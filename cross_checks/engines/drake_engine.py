"""Drake as an engine adapter (``drake:VARIANT``, float64); the interface is cross_checks.engines.base.

A continuous ``MultibodyPlant`` with one free body, its spatial inertia about the body origin = COM in body
axes, gravity the plant's own. State at the boundary: ``q = [q_WB (w x y z), x_W]``, ``v = [ω_W, v_W]``
(angular first, both in WORLD axes); Drake does not renormalise the quaternion, so the recorded one is
``q/|q|``. Forces: the applied generalized force ``[τ_W, f_W − m g]``, a fixed value when constant, else a
LeafSystem evaluating ``base.stage_force_torque`` (the decay as damping in the right-hand side) at every
derivative evaluation, so every stage of a multi-stage scheme sees its own stage state. A run is one
``Simulator.AdvanceTo(k Δt)`` per step in fixed-step mode. Divergence: a bad state
(reference_sim.simulate.bad_rows) or an exception Drake raises while stepping ends the run.
Conventions and what pins them: docs/engine_conventions.md, "Drake 1.51.1".
"""
from __future__ import annotations

import functools

import numpy as np

from cross_checks.engines import base
from cross_checks.engines.base import EngineError, ModuleAdapter, Variant, stage_force_torque
from reference_sim.simulate import Run, bad_rows, blowup_words, diverged

try:  # the module imports without pydrake so the registry can report why it is unavailable
    import pydrake  # noqa: F401
    from pydrake.math import RotationMatrix
    from pydrake.multibody.plant import MultibodyPlant
    from pydrake.multibody.tree import RotationalInertia, SpatialInertia
    from pydrake.systems.analysis import ResetIntegratorFromFlags, Simulator
    from pydrake.systems.framework import DiagramBuilder, LeafSystem
except ImportError as _exc:
    pydrake = None
    _IMPORT_ERROR = _exc
else:
    _IMPORT_ERROR = None

__all__ = ["ENGINE", "VARIANTS", "version", "simulate", "one_step", "DrakeModel", "DrakeAdapter",
           "to_drake_state", "from_drake_state"]

ENGINE = "drake"
#: variant -> (Drake's integrator name, declared global order, description)
VARIANTS = {
    "semi_explicit_euler": ("semi_explicit_euler", 1,
                            "Drake semi-explicit Euler: v from the start-of-step forces (explicit gyroscopic "
                            "term), then q from the new v; quaternion integrated linearly, not renormalised"),
    "runge_kutta2": ("runge_kutta2", 2, "Drake RK2 (explicit trapezoid / Heun), forces at both stages"),
    "runge_kutta3": ("runge_kutta3", 3, "Drake RK3 (Kutta's third-order scheme), forces at every stage"),
    "implicit_euler": ("implicit_euler", 1,
                       "Drake implicit Euler on the whole state (Newton "
                       "iteration, finite-difference Jacobian)"),
}

#: What each step does besides its order (cross_checks.engines.base.Traits; docs/engine_conventions.md).
TRAITS = {"semi_explicit_euler": base.SYMPLECTIC_EULER_EXPLICIT_GYRO,
          "implicit_euler": base.WHOLE_STATE_IMPLICIT_EULER, "runge_kutta2": base.HIGHER_ORDER,
          "runge_kutta3": base.HIGHER_ORDER}

#: Steps between divergence checks of a free run.
_CHUNK = 256
#: The fixed step's maximum is Δt (1 + FIXED_STEP_SLACK): AdvanceTo(k Δt) from (k − 1) Δt is then one
#: step even where k Δt − (k − 1) Δt exceeds Δt by a rounding.
FIXED_STEP_SLACK = 1e-9
#: Accuracy asked of the implicit Euler's Newton iteration (Drake uses the target accuracy to stop it
#: in fixed-step mode too): far below the scheme's own O(Δt²) local error at every Δt of the catalog.
NEWTON_ACCURACY = 1e-6
#: Drake's integrators that iterate (and so take a target accuracy in fixed-step mode).
_IMPLICIT = ("implicit_euler",)


def _require():
    base.require(pydrake, _IMPORT_ERROR, "drake", hint="pip install 'rbcheck[drake]'")


def version() -> str:
    _require()
    return base.installed_version("drake") or getattr(pydrake, "__version__", "unknown")   # from source


# --- state conversion --------------------------------------------------------------------------------

def to_drake_state(y):
    """Packed states (..., 13) ``[x_W, v_W, q_WB, ω_W]`` -> Drake's ``[q_WB, x_W, ω_W, v_W]`` (..., 13)."""
    y = np.asarray(y, dtype=float)
    return np.concatenate([y[..., 6:10], y[..., 0:3], y[..., 10:13], y[..., 3:6]], axis=-1)


def from_drake_state(x):
    """Drake's states (..., 13) -> packed (..., 13), the quaternion normalised (Drake's is not unit)."""
    x = np.asarray(x, dtype=float)
    q = x[..., 0:4]
    with np.errstate(invalid="ignore", divide="ignore"):
        q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return np.concatenate([x[..., 4:7], x[..., 10:13], q, x[..., 7:10]], axis=-1)


@functools.lru_cache(maxsize=1)
def _force_system_class():
    """The LeafSystem class (defined on first use: pydrake may be absent when this module is imported)."""

    class StageForces(LeafSystem):
        """Input: the plant's state (13); output: the generalized force ``[τ_W, f_W − m g]`` (6) of the
        scenario's forces and decay at that state (gravity is the plant's own)."""

        def __init__(self, scenario):
            super().__init__()
            self._scenario = scenario
            p = scenario.problem
            self._weight = (p.body.mass_kg * np.asarray(p.forces.gravity_W, dtype=float)).tolist()
            self._x = self.DeclareVectorInputPort("state", 13)
            self.DeclareVectorOutputPort("generalized_force", 6, self._calc)

        def _calc(self, context, output):
            # plain floats: this runs at every derivative evaluation (a Newton iteration's Jacobian too)
            x = self._x.Eval(context).tolist()
            y = [x[4], x[5], x[6], x[10], x[11], x[12], x[0], x[1], x[2], x[3], x[7], x[8], x[9]]
            f, tau = stage_force_torque(self._scenario, y)
            w = self._weight
            output.SetFromVector(np.array([tau[0], tau[1], tau[2], f[0] - w[0], f[1] - w[1], f[2] - w[2]]))

    return StageForces


def _spatial_inertia(body):
    """The body's spatial inertia about its origin = COM, in body axes (principal moments rotated by
    R_BP for a full tensor)."""
    if body.is_diagonal():
        I = RotationalInertia(*np.diag(body.inertia_B))
    else:
        moments, R_BP = body.principal_axes()
        I = RotationalInertia(*moments).ReExpress(RotationMatrix(R_BP))
    return SpatialInertia.MakeFromCentralInertia(float(body.mass_kg), np.zeros(3), I)


class DrakeModel:
    """A scenario's free body in Drake, with a simulator whose integrator is ``integrator`` (a Drake
    integrator name); ``set_state``/``state`` in the packed layout."""

    def __init__(self, scenario, integrator: str):
        _require()
        p = scenario.problem
        forces = p.forces
        plant = MultibodyPlant(0.0)
        try:
            self.body = plant.AddRigidBody("body", _spatial_inertia(p.body))
        except RuntimeError as exc:  # Drake's validity checks of the inertia
            raise EngineError(
                f"Drake {version()} rejected the inertia of scenario {scenario.name!r}: {exc}") from None
        plant.mutable_gravity_field().set_gravity_vector(np.asarray(forces.gravity_W, dtype=float))
        plant.Finalize()
        self.plant = plant
        self.per_stage = bool(forces.state_dependent or forces.has_decay)
        if self.per_stage:
            builder = DiagramBuilder()
            builder.AddSystem(plant)
            fs = builder.AddSystem(_force_system_class()(scenario))
            builder.Connect(plant.get_state_output_port(), fs.get_input_port(0))
            builder.Connect(fs.get_output_port(0), plant.get_applied_generalized_force_input_port())
            system = builder.Build()
        else:
            system = plant
        self.simulator = Simulator(system)
        root = self.simulator.get_mutable_context()
        self.context = plant.GetMyMutableContextFromRoot(root)
        if not self.per_stage and (forces.point_forces or forces.torques):
            y0 = p.initial_packed()
            f, tau = stage_force_torque(scenario, y0)     # constant: any state gives the same
            weight = p.body.mass_kg * np.asarray(forces.gravity_W, dtype=float)
            plant.get_applied_generalized_force_input_port().FixValue(self.context,
                                                                      np.concatenate([tau, f - weight]))
        self.integrator_name = integrator
        self.integrator = ResetIntegratorFromFlags(self.simulator, integrator, 1.0)

    def fixed_step(self, dt_s: float) -> None:
        """Fixed-step mode at ``dt_s`` (see FIXED_STEP_SLACK)."""
        self.integrator.set_maximum_step_size(float(dt_s) * (1.0 + FIXED_STEP_SLACK))
        self.integrator.set_fixed_step_mode(True)
        if self.integrator_name in _IMPLICIT:  # its Newton tolerance (explicit ones refuse any accuracy)
            self.integrator.set_target_accuracy(NEWTON_ACCURACY)

    def set_state(self, y, t_s: float = 0.0) -> None:
        self.simulator.get_mutable_context().SetTime(float(t_s))
        self.plant.SetPositionsAndVelocities(self.context, to_drake_state(y))
        self.simulator.Initialize()

    def drake_state(self) -> np.ndarray:
        return self.plant.GetPositionsAndVelocities(self.context)

    def state(self) -> np.ndarray:
        return from_drake_state(self.drake_state())


def _model(scenario, variant: str, dt_s: float) -> DrakeModel:
    base.check_variant(ENGINE, VARIANTS, variant)
    model = DrakeModel(scenario, VARIANTS[variant][0])
    model.fixed_step(dt_s)
    return model


def _first_bad(x_out, start: int, stop: int):
    """``(step, reason)`` of the first recorded row in ``[start, stop)`` that is non-finite or beyond
    BLOWUP_LIMIT, else None."""
    bad = bad_rows(from_drake_state(x_out[start:stop]))
    if not bad.any():
        return None
    n = start + int(np.argmax(bad))
    return n, blowup_words(x_out[n])


def _diverged(x_out, dt_s: float, n_bad: int, what: str) -> Run:
    return diverged(from_drake_state(x_out[:n_bad]), dt_s, f" ({what})")


def simulate(scenario, variant: str, dt_s: float, n_steps: int) -> Run:
    """Free run of ``n_steps`` fixed steps of ``dt_s`` from the scenario's initial
    state, every step recorded."""
    model = _model(scenario, variant, dt_s)
    y0 = scenario.problem.initial_packed()
    model.set_state(y0)
    x_out = np.empty((n_steps + 1, 13))
    x_out[0] = to_drake_state(y0)
    advance, get = model.simulator.AdvanceTo, model.drake_state
    start = 1
    with np.errstate(all="ignore"):
        while start <= n_steps:
            stop = min(start + _CHUNK, n_steps + 1)
            for n in range(start, stop):
                try:
                    advance(n * dt_s)
                # Drake refuses to go on (NaN detected, Newton failed): divergence
                except RuntimeError as exc:
                    first = _first_bad(x_out, start, n)
                    if first is not None:     # the state had already blown up: that is the time
                        return _diverged(x_out, dt_s, *first)
                    words = str(exc).strip().splitlines()
                    return _diverged(x_out, dt_s, n, f"Drake: {words[0] if words else type(exc).__name__}")
                x_out[n] = get()
            first = _first_bad(x_out, start, stop)
            if first is not None:
                return _diverged(x_out, dt_s, *first)
            start = stop
    return Run(dt_s * np.arange(n_steps + 1), from_drake_state(x_out))


@base.on_rows
def one_step(scenario, variant: str, dt_s: float, y_start) -> np.ndarray:
    """One fixed step of ``dt_s`` from each row of ``y_start`` (T, 13), the simulator re-initialised
    from exactly that state (Drake's integrators keep no history between steps except the implicit
    Euler's Jacobian, which re-initialising drops). A row Drake refuses comes back non-finite."""
    model = _model(scenario, variant, dt_s)
    out = np.full_like(y_start, np.nan)
    with np.errstate(all="ignore"):
        for i, y in enumerate(y_start):
            try:
                model.set_state(y)
                model.simulator.AdvanceTo(dt_s)
            except RuntimeError:
                continue
            out[i] = model.state()
    return out


class DrakeAdapter(ModuleAdapter):
    """``drake:VARIANT`` — registered under the entry-point group ``rbcheck.engines``."""

    variants = {v: Variant(float(order), desc, traits=TRAITS[v]) for v, (_, order, desc) in VARIANTS.items()}

    def engine_files(self) -> list:
        """Drake's shared libraries (a rebuilt or reinstalled libdrake.so is a new engine)."""
        return base.library_files(pydrake)
