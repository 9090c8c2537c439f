"""Planted bugs: copies of the schemes and adapters, each with one bug a real implementation could have.

A reference mutant is an engine adapter (``mutant_NAME``, registered by ``apply``) that steps the one
definition of the equations with one bug and declares the reference scheme it imitates, so that it gets
exactly that scheme's expectations; an engine mutant patches (with pytest's ``monkeypatch``) one function
of the MuJoCo, PyBullet or Drake adapter, so the variant keeps its name and its expectations. A sweep of
``Mutant.swept`` meets the bug. tests/test_gates_mutants.py asserts that the sweep's
gates (``cli.sweep._gate_failures``) catch every one. ``exposed_by`` names the catalog scenarios whose
physics exercises the bug (used by the quick default-run subset; the slow test sweeps the catalog).
"""
from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from cross_checks import engines
from cross_checks.engines.base import EngineAdapter, Variant
from cross_checks.engines.reference import ReferenceAdapter
from reference_sim.forces import Members
from reference_sim.integrators import ImplicitSolveError, course_type, exp_map_times, get_step, rhs
from reference_sim.quaternion import quat_mul
from reference_sim.simulate import run_members


@dataclass(frozen=True)
class Mutant:
    """A planted bug. ``variant`` is the correct ENGINE:VARIANT the bug is planted in (its expectations are
    the mutant's); ``swept`` is what a sweep runs to meet the bug (see :meth:`apply`)."""

    name: str
    variant: str
    bug: str
    exposed_by: tuple
    apply: Callable  # apply(monkeypatch)
    adapter: object = None  # a reference mutant's MutantAdapter (its knob and step; tests/helpers/float32.py)

    @property
    def swept(self) -> str:
        return (f"mutant_{self.name}:{self.variant.split(':', 1)[1]}" if self.variant.startswith("reference:")
                else self.variant)


# --- the reference schemes: engine adapters stepping the definition with one bug -------------------------
#
# Each reference mutant is an engine ``mutant_NAME`` whose one variant declares the order of the reference
# scheme it imitates and ``imitates`` that scheme (Variant.imitates): it gets exactly that scheme's
# expectations. It steps with the one definition (reference_sim.integrators) plus its bug: either a knob on
# the members' parameters (then the run is the compiled path's) or a broken step written here.

def _normalized(y):
    return np.concatenate([y[..., :6], y[..., 6:10] / np.linalg.norm(y[..., 6:10], axis=-1, keepdims=True),
                           y[..., 10:]], axis=-1)


def _h(dt):
    return np.asarray(dt, dtype=float).reshape(-1, 1) if np.ndim(dt) else float(dt)


def _rk4_wrong_stage_weight(p, y, dt):
    h = _h(dt)
    k1 = rhs(p, y)
    k2 = rhs(p, y + (0.5 * h) * k1)
    k3 = rhs(p, y + (0.5 * h) * k2)
    k4 = rhs(p, y + h * k3)
    return _normalized(y + (h / 6.0) * (k1 + 3.0 * k2 + k3 + k4))   # BUG: weights (1, 3, 1, 1)/6: order 2


def _rk4_third_stage_from_k1(p, y, dt):
    h = _h(dt)
    k1 = rhs(p, y)
    k2 = rhs(p, y + (0.5 * h) * k1)
    k3 = rhs(p, y + (0.5 * h) * k1)   # BUG: y + h/2 k1 where y + h/2 k2 belongs
    k4 = rhs(p, y + h * k3)
    return _normalized(y + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4))


def _midpoint_stage_at_full_step(p, y, dt):
    h = _h(dt)
    return _normalized(y + h * rhs(p, y + h * rhs(p, y)))   # BUG: stage at y + h k1, not y + h/2 k1


def _course_quaternion_multiplied_on_the_right(p, y, dt):
    out = course_type(p, y, dt, gyro=False, expmap=False)
    w = (0.5 * _h(dt)) * out[..., 10:13]
    wq = np.concatenate([np.zeros(w.shape[:-1] + (1,)), w], axis=-1)
    q = y[..., 6:10] + quat_mul(y[..., 6:10], wq)   # BUG: q + q [0, Δt/2 ω]: world ω used as body ω
    out[..., 6:10] = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return out


def _leapfrog_explicit_half_kick(p, y, dt):
    h = _h(dt)
    d = rhs(p, y)
    z = y.copy()
    # BUG
    z[..., 3:6], z[..., 10:13] = y[..., 3:6] + 0.5 * h * d[..., 3:6], y[..., 10:13] + 0.5 * h * d[..., 10:13]
    z[..., 0:3] = y[..., 0:3] + h * z[..., 3:6]
    q = exp_map_times(h, z[..., 10:13], y[..., 6:10])
    z[..., 6:10] = q / np.linalg.norm(q, axis=-1, keepdims=True)
    d = rhs(p, z)
    z[..., 3:6], z[..., 10:13] = z[..., 3:6] + 0.5 * h * d[..., 3:6], z[..., 10:13] + 0.5 * h * d[..., 10:13]
    return z


@dataclass(frozen=True, eq=False)
class _LeversUnrotated(Members):
    """BUG: body points (spring attachments, force points) and body vectors used
    in body axes as world ones."""

    def force_torque(self, x_W, v_W, R_WB):
        return super().force_torque(x_W, v_W, np.broadcast_to(np.eye(3), np.shape(R_WB)))


def _lever_arms_not_rotated(m):
    return _LeversUnrotated(*(getattr(m, f.name) for f in dataclasses.fields(m)))


def _gyroscopic_sign_flipped(m):
    return dataclasses.replace(m, inertia_B=-m.inertia_B)   # BUG: I⁻¹(τ + ω × Iω)


def _gyroscopic_term_dropped(m):
    return dataclasses.replace(m, inertia_B=0.0 * m.inertia_B)   # BUG: no ω × Iω


def _course_decay_twice(m):
    return dataclasses.replace(m, decay_gamma=m.decay_gamma ** 2)   # BUG: e^{−kΔt} applied twice per step


def _whole_state_decay_left_out(m):
    # BUG: no −k v, −k ω in the right-hand side
    return dataclasses.replace(m, decay_rates=0.0 * m.decay_rates)


def _body_torque_applied_in_world_axes(m):
    # BUG: not rotated
    return dataclasses.replace(m, torque_W=m.torque_W + m.torque_B, torque_B=0.0 * m.torque_B)


def _torque_cross_product_reversed(m):
    wp = m.world_points.copy()
    wp[..., 3:6] *= -1.0   # BUG: f × r instead of r × f
    return dataclasses.replace(m, world_points=wp)


def _drag_sign_flipped(m):
    return dataclasses.replace(m, drag=-m.drag)   # BUG: f = +c v


def _unchanged(m):
    return m


def batched(requests, knob, step) -> list:
    """The runs of ``requests`` (RunRequest) as the members of one ``run_members`` call, ``knob`` applied to
    the stacked members, with ``step`` (a variant name or a step function): each run is the request's run
    alone, bit for bit (every row of the definition advances on its own:
    test_mutants_run_batched_as_they_run_alone), and a ladder's Python steps are taken once for all its
    rungs, not once per rung."""
    problems = [r.scenario.problem for r in requests]
    if not problems:
        return []
    return run_members(knob(Members.stack(problems)), step, [r.dt_s for r in requests],
                       [r.n_steps for r in requests], np.array([p.initial_packed() for p in problems]))


class MutantAdapter(EngineAdapter):
    """``mutant_NAME:VARIANT``: the reference scheme VARIANT with one bug (``members``: a knob on the
    parameters; ``step``: a broken step of the definition's signature), declared as imitating it."""

    def __init__(self, name: str, variant: str, bug: str, members=None, step=None):
        self.name, self.mutant, self.scheme = f"mutant_{name}", name, variant.split(":", 1)[1]
        spec = ReferenceAdapter.variants[self.scheme]
        self.variants = {self.scheme: Variant(spec.order, f"{spec.description} WITH A PLANTED BUG: {bug}",
                                              imitates=variant)}
        self.knob, self.step = members or _unchanged, step

    def version(self) -> str:
        return "planted"

    def same_as(self, other) -> bool:
        return isinstance(other, MutantAdapter) and other.name == self.name

    def source_files(self) -> list:
        return [__file__]

    def simulate(self, scenario, variant: str, dt_s: float, n_steps: int):
        p = scenario.problem
        return run_members(self.knob(p.members), self.step or variant,
                           [dt_s], [n_steps], p.initial_packed()[None])[0]

    def simulate_many(self, variant: str, requests) -> list:
        """The runs of ``requests`` as the members of one run, as the reference adapter batches its own
        (:func:`batched`)."""
        return batched(requests, self.knob, self.step or variant)

    def one_step(self, scenario, variant: str, dt_s: float, y_start):
        step = self.step or get_step(variant)
        with np.errstate(all="ignore"):
            try:
                return step(self.knob(scenario.problem.members), np.asarray(y_start, dtype=float), dt_s)
            except ImplicitSolveError:
                return np.full(np.shape(y_start), np.nan)


def _planter(adapter):
    """``apply(monkeypatch)`` of a reference mutant: register its adapter until the monkeypatch is undone (the
    registry's table of registered engines is replaced by a copy that the undo puts back)."""
    def apply(mp):
        mp.setattr(engines, "_user", dict(engines._user))
        engines.register_adapter(adapter, "tests/mutants.py")
    return apply


def _reference(name, variant, bug, exposed_by, members=None, step=None) -> Mutant:
    adapter = MutantAdapter(name, variant, bug, members, step)
    return Mutant(name, variant, bug, exposed_by, _planter(adapter), adapter)


# --- the engine adapters --------------------------------------------------------------------------------

def _mujoco_world_omega_as_body(mp):
    from cross_checks.engines.worlds import mujoco as mjw  # the world's own conversion (what repro embeds)

    def to_qpos_qvel(y):
        y = np.asarray(y, dtype=float)
        qpos = np.concatenate([y[..., 0:3], y[..., 6:10]], axis=-1)
        qvel = np.concatenate([y[..., 3:6], y[..., 10:13]], axis=-1)   # BUG: ω_W written where ω_B belongs
        return qpos, qvel
    mp.setattr(mjw, "to_qpos_qvel", to_qpos_qvel)


def _mujoco_body_omega_read_as_world(mp):
    from cross_checks.engines import packed_rows
    from cross_checks.engines.worlds import mujoco as mjw

    def to_packed(qpos, qvel):
        # BUG
        return np.concatenate([qpos[..., 0:3], qvel[..., 0:3], qpos[..., 3:7], qvel[..., 3:6]], axis=-1)
    mp.setattr(mjw, "to_packed", to_packed)
    # a whole record is converted by packed_rows' compiled kernel (to_packed's numbers, tested apart): off,
    # so that the record goes through the conversion with the bug
    mp.setattr(packed_rows, "_kernels", lambda: None)


def _mujoco_gravity_twice(mp):
    from cross_checks.engines import mujoco_engine as me
    # BUG: the weight is left in the applied force, and MuJoCo adds gravity itself
    mp.setattr(me.MujocoEngine, "applies_gravity", False)


def _mujoco_rk4_forces_held_over_the_step(mp):
    from cross_checks.engines import mujoco_engine as me
    mp.setattr(me, "_RK4_STAGE_FORCES", False)   # BUG: state-dependent forces frozen at the step start


def _mujoco_rk4_decay_twice(mp):
    from cross_checks.engines import mujoco_engine as me
    orig = me.stage_force_torque_floats

    def stage(scenario, y):
        fx, fy, fz, tx, ty, tz = orig(scenario, y)
        k_v, _ = scenario.problem.forces.decay_rates_per_s()
        mk = scenario.problem.body.mass_kg * k_v   # BUG: damping counted twice
        return fx - mk * y[3], fy - mk * y[4], fz - mk * y[5], tx, ty, tz
    mp.setattr(me, "stage_force_torque_floats", stage)


def _pybullet_principal_axes_dropped(mp):
    from cross_checks.engines import pybullet_engine as pe
    orig = pe.BulletWorld._add

    def add(self, scenario):
        orig(self, scenario)
        self.q_BP[-1] = None   # BUG: the principal frame taken as the body frame
    mp.setattr(pe.BulletWorld, "_add", add)


def _pybullet_quaternion_order(mp):
    from cross_checks.engines.worlds import pybullet as pe  # the adapter's world (what repro embeds)
    # BUG: wxyz passed
    mp.setattr(pe, "_xyzw", lambda q: [float(q[0]), float(q[1]), float(q[2]), float(q[3])])


def _pybullet_decay_left_out(mp):
    from cross_checks.engines import pybullet_engine as pe
    mp.setattr(pe.BulletWorld, "decay", lambda self, g_v, g_w: None)   # BUG: no decay in a run


def _pybullet_torque_in_link_frame(mp):
    from cross_checks.engines import pybullet_engine as pe

    def apply(self, f_W, tau_W):   # (B, 3) each, as BulletWorld.apply
        p = pe.p
        for b, f, tau, prev in zip(self.bodies, f_W.tolist(), tau_W.tolist(), self.last):
            if any(v != 0.0 for v in f):
                p.applyExternalForce(b, -1, f, prev[0:3], p.WORLD_FRAME, physicsClientId=self.c)
            if any(v != 0.0 for v in tau):   # BUG: a world torque given in the link (body) frame
                p.applyExternalTorque(b, -1, tau, p.LINK_FRAME, physicsClientId=self.c)
    mp.setattr(pe.BulletWorld, "apply", apply)


def _drake_omega_in_body_axes(mp):
    from cross_checks.engines.worlds import drake as dkw
    from reference_sim.quaternion import quat_conj, rotate

    def to_drake_state(y):
        y = np.asarray(y, dtype=float)
        w_B = rotate(quat_conj(y[..., 6:10]), y[..., 10:13])   # BUG: ω in body axes where Drake wants ω_W
        return np.concatenate([y[..., 6:10], y[..., 0:3], w_B, y[..., 3:6]], axis=-1)
    mp.setattr(dkw, "to_drake_state", to_drake_state)


def _drake_quaternion_order(mp):
    from cross_checks.engines.worlds import drake as dkw

    def to_drake_state(y):
        y = np.asarray(y, dtype=float)
        q = y[..., [7, 8, 9, 6]]                                 # BUG: (x, y, z, w) given as (w, x, y, z)
        return np.concatenate([q, y[..., 0:3], y[..., 10:13], y[..., 3:6]], axis=-1)
    mp.setattr(dkw, "to_drake_state", to_drake_state)


def _drake_decay_twice(mp):
    from cross_checks.engines import drake_engine as de
    orig = de.stage_force_torque

    def stage(scenario, y):
        f, tau = orig(scenario, y)
        k_v, _ = scenario.problem.forces.decay_rates_per_s()
        return f - scenario.problem.body.mass_kg * k_v * np.asarray(y[3:6]), tau  # BUG: damping counted twice
    mp.setattr(de, "stage_force_torque", stage)


def _drake_gravity_twice(mp):
    from cross_checks.engines import drake_engine as de
    orig = de.stage_force_torque

    def stage(scenario, y):
        f, tau = orig(scenario, y)   # BUG: the weight added again, and Drake's gravity field applies it too
        return f + scenario.problem.body.mass_kg * np.asarray(scenario.problem.forces.gravity_W), tau
    mp.setattr(de, "stage_force_torque", stage)


MUTANTS = [
    _reference("rk4_wrong_stage_weight", "reference:rk4", "RK4 stage weights (1, 3, 1, 1)/6: order 2",
               ("applied_torque",), step=_rk4_wrong_stage_weight),
    _reference("rk4_third_stage_from_k1", "reference:rk4", "RK4's third stage from k1 instead of k2 (a typo)",
               ("particle_body",), step=_rk4_third_stage_from_k1),
    _reference("midpoint_stage_at_full_step", "reference:midpoint", "mid-point stage at y + Δt k1: order 1",
               ("projectile",), step=_midpoint_stage_at_full_step),
    _reference("gyroscopic_sign_flipped", "reference:expmap_gyro", "+ω × Iω instead of −ω × Iω",
               ("tennis_racket",), members=_gyroscopic_sign_flipped),
    _reference("gyroscopic_sign_flipped_rk4", "reference:rk4", "+ω × Iω in the whole-state right-hand side",
               ("particle_body",), members=_gyroscopic_sign_flipped),
    _reference("gyroscopic_term_dropped", "reference:course_gyro", "the gyroscopic torque left out",
               ("tennis_racket",), members=_gyroscopic_term_dropped),
    _reference("course_decay_twice", "reference:course", "velocity decay applied twice per step",
               ("velocity_decay",), members=_course_decay_twice),
    _reference("rk4_decay_left_out", "reference:rk4", "no decay in the right-hand side",
               ("velocity_decay",), members=_whole_state_decay_left_out),
    _reference("course_quaternion_on_the_right", "reference:course",
               "q + q [0, Δt/2 ω]: world ω used as body ω", ("constant_spin",),
               step=_course_quaternion_multiplied_on_the_right),
    _reference("leapfrog_explicit_half_kick", "reference:leapfrog", "first half kick not solved: explicit",
               ("tennis_racket",), step=_leapfrog_explicit_half_kick),
    _reference("lever_arms_not_rotated", "reference:rk4", "body points used in body axes as world vectors",
               ("applied_torque",), members=_lever_arms_not_rotated, step=get_step("rk4")),
    _reference("body_torque_in_world_axes", "reference:expmap_gyro", "a body-frame torque applied unrotated",
               ("applied_torque",), members=_body_torque_applied_in_world_axes),
    _reference("torque_cross_product_reversed", "reference:midpoint", "τ = f × r instead of r × f",
               ("applied_torque",), members=_torque_cross_product_reversed),
    _reference("drag_sign_flipped", "reference:course", "drag f = +c v",
               ("linear_drag",), members=_drag_sign_flipped),
    Mutant("mujoco_world_omega_as_body", "mujoco:euler", "ω_W written into qvel[3:6] (body axes)",
           ("constant_spin",), _mujoco_world_omega_as_body),
    Mutant("mujoco_body_omega_read_as_world", "mujoco:rk4", "qvel[3:6] (body axes) read as ω_W",
           ("constant_spin",), _mujoco_body_omega_read_as_world),
    Mutant("mujoco_gravity_twice", "mujoco:implicit", "the weight left in the applied force",
           ("projectile",), _mujoco_gravity_twice),
    Mutant("mujoco_rk4_forces_held", "mujoco:rk4", "state-dependent forces held over the RK4 step",
           ("spring_oscillator",), _mujoco_rk4_forces_held_over_the_step),
    Mutant("mujoco_rk4_decay_twice", "mujoco:rk4", "the decay force counted twice in the stage forces",
           ("velocity_decay",), _mujoco_rk4_decay_twice),
    Mutant("pybullet_principal_axes_dropped", "pybullet:multibody", "the inertia's principal frame ignored",
           ("particle_body",), _pybullet_principal_axes_dropped),
    Mutant("pybullet_quaternion_order", "pybullet:maximal",
           "(w, x, y, z) passed where (x, y, z, w) is expected", ("constant_spin",),
           _pybullet_quaternion_order),
    Mutant("pybullet_decay_left_out", "pybullet:multibody", "no velocity decay",
           ("velocity_decay",), _pybullet_decay_left_out),
    Mutant("pybullet_torque_in_link_frame", "pybullet:maximal", "a world torque applied in the link frame",
           ("applied_torque",), _pybullet_torque_in_link_frame),
    Mutant("drake_omega_in_body_axes", "drake:semi_explicit_euler", "ω_B given where Drake's state has ω_W",
           ("constant_spin",), _drake_omega_in_body_axes),
    Mutant("drake_quaternion_order", "drake:runge_kutta3",
           "(x, y, z, w) given where Drake's state has (w, x, y, z)", ("constant_spin",),
           _drake_quaternion_order),
    Mutant("drake_decay_twice", "drake:runge_kutta2", "the decay force counted twice in the stage forces",
           ("velocity_decay",), _drake_decay_twice),
    Mutant("drake_gravity_twice", "drake:implicit_euler", "the weight left in the applied force",
           ("applied_torque",), _drake_gravity_twice),
]


# --- long runs: a planted drift of the energy towards L²/2I₂ (docs/verdicts.md "Long runs") ---------------
#
# Not in MUTANTS (those are swept on the catalog's ladders): these adapters exist for the long runs. Each
# takes the midpoint rule's step (it keeps the energy, |Π| and L to round-off) and then turns the body-axes
# momentum Π towards the intermediate axis at |Π| kept (Π₂ grows at
# LONG_RUN_PLANTED_RATE per second): the energy moves to L²/2I₂ from either side while |L| stays — the drift
# Jolt's step makes, planted. One adapter DECLARES that it keeps the energy and L (Traits.keeps, as the
# midpoint rule does): the judge must fail it; the other declares a "momentum" step (as Jolt's): named, not
# failed.

#: The planted turn's rate, 1/s: Π₂ grows by e^{0.2 t}, so δ moves by more than SECULAR_MIN_CHANGE within
#: ~20 s of a spin of 2 rad/s.
LONG_RUN_PLANTED_RATE = 0.2


def energy_to_intermediate_step(p, y, dt):
    """The midpoint rule's step, then Π (body axes) turned towards the intermediate axis (axis 2 of a diagonal
    inertia) at |Π| kept: |L| stays to round-off, the energy moves to L²/2I₂."""
    from reference_sim.integrators import members
    from reference_sim.quaternion import matrix_from_quat
    from reference_sim.vec import mat_t_vec3, matvec3
    y1 = get_step("lp_midpoint")(p, y, dt)
    m = members(p)
    R = matrix_from_quat(y1[..., 6:10])
    Pi = matvec3(m.inertia_B, mat_t_vec3(R, y1[..., 10:13]))
    nudged = Pi + LONG_RUN_PLANTED_RATE * _h(dt) * Pi * np.array([0.0, 1.0, 0.0])
    nudged *= np.linalg.norm(Pi, axis=-1, keepdims=True) / np.linalg.norm(nudged, axis=-1, keepdims=True)
    y1[..., 10:13] = matvec3(R, matvec3(m.inertia_inv_B, nudged))
    return y1


class LongRunMutant(EngineAdapter):
    """``NAME:step``: :func:`energy_to_intermediate_step`, declaring ``traits``."""

    def __init__(self, name: str, traits, what: str):
        self.name = name
        what = f"the midpoint rule with the energy planted to drift to L²/2I₂; {what}"
        self.variants = {"step": Variant(1, what, traits=traits)}

    def version(self) -> str:
        return "planted"

    def source_files(self) -> list:
        return [__file__]

    def simulate(self, scenario, variant: str, dt_s: float, n_steps: int):
        p = scenario.problem
        return run_members(p.members, energy_to_intermediate_step, [dt_s], [n_steps],
                           p.initial_packed()[None])[0]

    def simulate_many(self, variant: str, requests) -> list:
        return batched(requests, _unchanged, energy_to_intermediate_step)


def long_run_mutants() -> dict:
    """``{name: apply(monkeypatch)}`` of the two long-run mutants: ``planted_keeps`` (declares the energy and
    L kept) and ``planted_momentum`` (declares a "momentum" step)."""
    from cross_checks.engines.base import Traits
    return {n: _planter(LongRunMutant(n, tr, what)) for n, tr, what in (
        ("planted_keeps", Traits(keeps=("energy", "angular_momentum")), "declares the energy and L kept"),
        ("planted_momentum", Traits(rotation_drift="momentum", rotation_sign=None),
         "declares a momentum-rescaled step (Jolt's kind)"))}
