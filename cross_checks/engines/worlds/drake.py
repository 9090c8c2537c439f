"""Drake's world (``pydrake``, float64): numpy and pydrake only (``rbcheck repro`` embeds this file as it is).

Each body is a continuous ``MultibodyPlant`` (time step 0) holding one free rigid body, its spatial inertia
about the body origin = COM in body axes, gravity the plant's own uniform field, simulated by a ``Simulator``
of its own whose integrator is the variant (``ResetIntegratorFromFlags``: "semi_explicit_euler",
"runge_kutta2", "runge_kutta3", "implicit_euler") in fixed-step mode: step n is ``AdvanceTo(n Δt)``.
Drake's state is ``q = [q_WB (w x y z), x_W]``, ``v = [ω_W, v_W]`` (angular first, both in WORLD axes); Drake
does not renormalise the quaternion, so the packed one is ``q/|q|``. Forces: ``[τ_W, f_W]`` (world torque,
world force at the COM without the weight, which the plant applies) fixed on the applied generalized force
port, where they stay until fixed again. A body whose origin Bo is off its COM, or of welded parts, is a
:class:`FormBody` (:func:`form_world`): Drake's x and v are then Bo's, and the force at the COM goes on the
applied spatial force port. docs/engine_conventions.md, "Drake 1.51.1".
"""
import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.math import SpatialForce
from pydrake.multibody.plant import ExternallyAppliedSpatialForce, MultibodyPlant
from pydrake.multibody.tree import RotationalInertia, SpatialInertia
from pydrake.systems.analysis import ResetIntegratorFromFlags, Simulator

from .com import com_state, origin_state

#: The fixed step's maximum is Δt (1 + FIXED_STEP_SLACK): AdvanceTo(k Δt) from (k − 1) Δt is then one
#: step even where k Δt − (k − 1) Δt exceeds Δt by a rounding.
FIXED_STEP_SLACK = 1e-9
#: Accuracy asked of the implicit Euler's Newton iteration (Drake uses the target accuracy to stop it
#: in fixed-step mode too): far below the scheme's own O(Δt²) local error at every Δt of rbcheck's catalog.
NEWTON_ACCURACY = 1e-6


def spatial_inertia(mass_kg, moments, R_BP=None, com_B=None):
    """The spatial inertia about the body origin Bo, in body axes, of a body of ``mass_kg`` whose central
    inertia has the principal ``moments`` (kg m²) along the columns of ``R_BP`` (3, 3) (None: the body axes,
    the moments then the tensor's diagonal as given), its COM at ``com_B`` (m) from Bo (None: at Bo)."""
    inertia = RotationalInertia(*moments)
    if R_BP is not None:
        inertia = inertia.ReExpress(RotationMatrix(np.asarray(R_BP, dtype=float)))
    com = np.zeros(3) if com_B is None else np.asarray(com_B, dtype=float)
    return SpatialInertia.MakeFromCentralInertia(float(mass_kg), com, inertia)


def to_drake_state(y):
    """Packed states (..., 13) ``[x_W, v_W, q_WB, ω_W]`` -> Drake's ``[q_WB, x_W, ω_W, v_W]`` (..., 13)."""
    y = np.asarray(y, dtype=float)
    return np.concatenate([y[..., 6:10], y[..., 0:3], y[..., 10:13], y[..., 3:6]], axis=-1)


def from_drake_state(x):
    """Drake's states (..., 13) -> packed (..., 13), the quaternion normalised (Drake's is not unit)."""
    x = np.asarray(x, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):   # a blown-up state stays inf/NaN
        q = x[..., 0:4] / np.linalg.norm(x[..., 0:4], axis=-1, keepdims=True)
    return np.concatenate([x[..., 4:7], x[..., 10:13], q, x[..., 7:10]], axis=-1)


class Body:
    """One free body ``(mass_kg, moments (3,), R_BP (3, 3) or None)`` (:func:`spatial_inertia`) in a plant of
    its own under ``gravity_W`` (m/s²), simulated with the integrator ``variant``. :meth:`add_bodies` and
    :meth:`system` are what a richer body (rbcheck's adapter: a COM off the origin, welded parts, forces
    evaluated at every stage) changes."""

    def __init__(self, spec, gravity_W, variant):
        self.spec = spec
        self.build(gravity_W, variant)

    def add_bodies(self, plant):
        """Add the body to ``plant``; return it (the floating one)."""
        return plant.AddRigidBody("body", spatial_inertia(*self.spec))

    def system(self, plant):
        """The system the simulator runs: the plant itself."""
        return plant

    def build(self, gravity_W, variant):
        self.plant = plant = MultibodyPlant(0.0)
        self.body = self.add_bodies(plant)
        plant.mutable_gravity_field().set_gravity_vector(np.asarray(gravity_W, dtype=float))
        plant.Finalize()
        self.simulator = Simulator(self.system(plant))
        self.context = plant.GetMyMutableContextFromRoot(self.simulator.get_mutable_context())
        self.integrator_name = variant
        self.integrator = ResetIntegratorFromFlags(self.simulator, variant, 1.0)

    def fixed_step(self, dt_s):
        """Fixed-step mode at ``dt_s`` (s; see FIXED_STEP_SLACK)."""
        self.integrator.set_maximum_step_size(float(dt_s) * (1.0 + FIXED_STEP_SLACK))
        self.integrator.set_fixed_step_mode(True)
        if self.integrator_name == "implicit_euler":  # its Newton tolerance (explicit ones refuse any)
            self.integrator.set_target_accuracy(NEWTON_ACCURACY)

    def apply(self, f_W, tau_W):
        """World force (N) at the COM, without the weight, and world torque (N m), from now on."""
        port = self.plant.get_applied_generalized_force_input_port()
        port.FixValue(self.context, np.concatenate([tau_W, f_W]))

    def set_state(self, y, t_s=0.0):
        """The packed state ``y`` (13,) at time ``t_s`` (s)."""
        self.set_drake_state(to_drake_state(y), t_s)

    def set_drake_state(self, x, t_s=0.0):
        """Drake's state ``x`` (13,) at time ``t_s`` (s)."""
        self.simulator.get_mutable_context().SetTime(float(t_s))
        self.plant.SetPositionsAndVelocities(self.context, x)
        self.simulator.Initialize()

    def drake_state(self):
        return self.plant.GetPositionsAndVelocities(self.context)


class Bodies:
    """Bodies (each a :class:`Body` in fixed-step mode at ``dt_s``) stepped to ``n Δt`` in turn; raw rows
    Drake's states ``[q_WB, x_W, ω_W, v_W]``. A step Drake refuses (it raises: NaN detected, Newton failed) is
    noted in ``warnings`` as ``(body, step, words)``; that body is not stepped again and reads as NaN from
    then on (``hold_failed``: as its last state)."""

    hold_failed = False

    def __init__(self, models, dt_s):
        self.models, self.dt_s = models, dt_s
        self.warnings = getattr(self, "warnings", [])

    def set_state(self, y):
        for m, row in zip(self.models, y):
            m.set_state(row)
        self.n, self.failed, self.last = 0, set(), np.array([m.drake_state() for m in self.models])

    def apply(self, f_W, tau_W):
        """Fixed until fixed again (a zero wrench leaves the port unconnected)."""
        for m, f, tau in zip(self.models, f_W, tau_W):
            if f.any() or tau.any():
                m.apply(f, tau)

    def step(self):
        self.n += 1
        for k, m in enumerate(self.models):
            try:
                if k not in self.failed:
                    m.simulator.AdvanceTo(self.n * self.dt_s)
            except RuntimeError as exc:
                words = str(exc).strip().splitlines()
                self.failed.add(k)
                self.warnings.append((k, self.n, f"Drake: {words[0] if words else type(exc).__name__}"))

    def read(self):
        rows = np.array([m.drake_state() for m in self.models])
        for k in self.failed:
            rows[k] = self.last[k] if self.hold_failed else np.nan
        self.last = rows
        return rows

    def packed(self, raw):
        return from_drake_state(raw)


def world(bodies, gravity_W, variant, dt_s):
    models = [Body(spec, gravity_W, variant) for spec in bodies]
    for m in models:
        m.fixed_step(dt_s)
    return Bodies(models, dt_s)


class FormBody(Body):
    """:class:`Body` of a spec that may also give the COM ``com_B`` (m, body axes from the body origin Bo;
    None: at Bo) and welded parts (each ``(mass_kg, moments, R_BP, com_B)``, their COMs from the first's
    frame: a ``WeldJoint`` from the first part's frame to each other's, the same frame). Drake's x and v
    are Bo's: the packed state's (the COM's) converted (worlds/com.py); the world force at the COM goes on
    the applied spatial force port at the point c of the body (Drake moves it to Bo in every
    configuration)."""

    def __init__(self, spec, gravity_W, variant):
        com = spec[3] if len(spec) > 3 else None
        self.com_B = None if com is None else np.asarray(com, dtype=float)
        super().__init__(spec, gravity_W, variant)

    def add_bodies(self, plant):
        parts = self.spec[4] if len(self.spec) > 4 else ()
        if not parts:
            return plant.AddRigidBody("body", spatial_inertia(*self.spec[:3], self.com_B))
        bodies = [plant.AddRigidBody("body" if k == 0 else f"body_part{k}", spatial_inertia(*part))
                  for k, part in enumerate(parts)]
        for child in bodies[1:]:
            plant.WeldFrames(bodies[0].body_frame(), child.body_frame(), RigidTransform())
        return bodies[0]

    def apply(self, f_W, tau_W):
        """World force (N) at the COM, without the weight, and world torque (N m), from now on."""
        if self.com_B is None:
            super().apply(f_W, tau_W)
            return
        F = ExternallyAppliedSpatialForce()
        F.body_index, F.p_BoBq_B = self.body.index(), self.com_B
        F.F_Bq_W = SpatialForce(np.asarray(tau_W, dtype=float), np.asarray(f_W, dtype=float))
        self.plant.get_applied_spatial_force_input_port().FixValue(self.context, AbstractValue.Make([F]))

    def set_state(self, y, t_s=0.0):
        """The packed state ``y`` (13,) of the COM at time ``t_s`` (s)."""
        self.set_drake_state(to_drake_state(y if self.com_B is None else origin_state(y, self.com_B)), t_s)


class FormBodies(Bodies):
    """:class:`Bodies` of :class:`FormBody` (and :class:`Body`) models: a body whose origin is off its COM
    reads as its COM's state."""

    def packed(self, raw):
        raw = np.asarray(raw, dtype=float)
        return np.stack([from_drake_state(raw[..., k, :]) if getattr(m, "com_B", None) is None
                         else com_state(from_drake_state(raw[..., k, :]), m.com_B)
                         for k, m in enumerate(self.models)], axis=-2)


def form_world(bodies, gravity_W, variant, dt_s):
    """:func:`world` of bodies that may have a COM off their origin or welded parts (:class:`FormBody`)."""
    models = [FormBody(spec, gravity_W, variant) for spec in bodies]
    for m in models:
        m.fixed_step(dt_s)
    return FormBodies(models, dt_s)
