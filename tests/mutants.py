"""Planted bugs: copies of the schemes and adapters, each with one bug a real implementation could have.

Each :class:`Mutant` patches (with pytest's ``monkeypatch``) one function or method of the code a sweep
runs for ``variant`` — the plain-float kernel (reference_sim.scalar) for single-body reference runs,
the MuJoCo, PyBullet and Drake adapters for theirs — so the variant keeps its name and therefore exactly the
expectations of the correct scheme. tests/test_gates_mutants.py asserts that the sweep's
gates (``cli._gate_failures``) catch every one. ``exposed_by`` names the catalog scenarios whose
physics exercises the bug (used by the quick default-run subset; the slow test sweeps the catalog).
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from reference_sim.scalar import ScalarStepper


@dataclass(frozen=True)
class Mutant:
    name: str
    variant: str
    bug: str
    exposed_by: tuple
    apply: Callable  # apply(monkeypatch)


def _after_init(monkeypatch, change):
    """Run ``change(stepper)`` after every ScalarStepper.__init__ (a setting the step then uses)."""
    orig = ScalarStepper.__init__

    def init(self, *a, **kw):
        orig(self, *a, **kw)
        change(self)

    monkeypatch.setattr(ScalarStepper, "__init__", init)


# --- the reference schemes (plain-float kernel: what a single-body reference run executes) -------------

def _rk4_wrong_stage_weight(mp):
    def _rk4(self, y):
        h = self.h
        k1 = self.rhs(y)
        k2 = self.rhs([a + (0.5 * h) * b for a, b in zip(y, k1)])
        k3 = self.rhs([a + (0.5 * h) * b for a, b in zip(y, k2)])
        k4 = self.rhs([a + h * b for a, b in zip(y, k3)])
        h6 = h / 6.0   # BUG: weights (1, 3, 1, 1)/6 instead of (1, 2, 2, 1)/6 — consistent, but order 2
        return self._finish([a + h6 * (b1 + 3.0 * b2 + b3 + b4) for a, b1, b2, b3, b4 in zip(y, k1, k2, k3, k4)])
    mp.setattr(ScalarStepper, "_rk4", _rk4)


def _rk4_third_stage_from_k1(mp):
    def _rk4(self, y):
        h = self.h
        k1 = self.rhs(y)
        k2 = self.rhs([a + (0.5 * h) * b for a, b in zip(y, k1)])
        k3 = self.rhs([a + (0.5 * h) * b for a, b in zip(y, k1)])   # BUG: y + h/2 k1 where y + h/2 k2 belongs
        k4 = self.rhs([a + h * b for a, b in zip(y, k3)])
        h6 = h / 6.0
        return self._finish([a + h6 * (b1 + 2.0 * b2 + 2.0 * b3 + b4) for a, b1, b2, b3, b4 in zip(y, k1, k2, k3, k4)])
    mp.setattr(ScalarStepper, "_rk4", _rk4)


def _midpoint_stage_at_full_step(mp):
    def _midpoint(self, y):
        h = self.h
        k1 = self.rhs(y)
        k2 = self.rhs([a + h * b for a, b in zip(y, k1)])   # BUG: stage at y + h k1, not y + h/2 k1
        return self._finish([a + h * b for a, b in zip(y, k2)])
    mp.setattr(ScalarStepper, "_midpoint", _midpoint)


def _gyroscopic_sign_flipped(mp):
    orig = ScalarStepper._ang_acc

    def _ang_acc(self, R, wx, wy, wz, tx, ty, tz, gyro):
        if not gyro:
            return orig(self, R, wx, wy, wz, tx, ty, tz, gyro)
        a0 = orig(self, R, wx, wy, wz, tx, ty, tz, False)
        a1 = orig(self, R, wx, wy, wz, tx, ty, tz, True)
        return tuple(2.0 * p - q for p, q in zip(a0, a1))   # BUG: I⁻¹(τ + ω × Iω)
    mp.setattr(ScalarStepper, "_ang_acc", _ang_acc)


def _gyroscopic_term_dropped(mp):
    orig = ScalarStepper._ang_acc
    mp.setattr(ScalarStepper, "_ang_acc",
               lambda self, R, wx, wy, wz, tx, ty, tz, gyro: orig(self, R, wx, wy, wz, tx, ty, tz, False))


def _course_decay_twice(mp):
    def change(s):
        s.gv, s.gw = s.gv * s.gv, s.gw * s.gw   # BUG: e^{−kΔt} applied twice per step
    _after_init(mp, change)


def _whole_state_decay_left_out(mp):
    def change(s):
        s.kv = s.kw = 0.0   # BUG: no −k v, −k ω in the right-hand side
    _after_init(mp, change)


def _course_quaternion_multiplied_on_the_right(mp):
    orig = ScalarStepper._course

    def _course(self, y, gyro, expmap):
        out = orig(self, y, gyro, expmap)
        # BUG: q + q [0, Δt/2 ω] (world ω used as if it were body ω): redo the attitude update that way
        h = self.h
        qw, qx, qy, qz = y[6:10]
        wx, wy, wz = out[10:13]
        hx, hy, hz = 0.5 * h * wx, 0.5 * h * wy, 0.5 * h * wz
        nw = qw - (qx * hx + qy * hy + qz * hz)
        nx = qx + (qw * hx + qy * hz - qz * hy)
        ny = qy + (qw * hy + qz * hx - qx * hz)
        nz = qz + (qw * hz + qx * hy - qy * hx)
        n = (nw * nw + nx * nx + ny * ny + nz * nz) ** 0.5
        out[6:10] = [nw / n, nx / n, ny / n, nz / n]
        return out
    mp.setattr(ScalarStepper, "_course", _course)


def _leapfrog_explicit_half_kick(mp):
    def _leapfrog(self, y):
        h = self.h
        half = 0.5 * h
        d = self.rhs(y)
        u = [a + half * b for a, b in zip(y[3:6] + y[10:13], d[3:6] + d[10:13])]  # BUG: not iterated
        z = list(y)
        z[3:6], z[10:13] = u[0:3], u[3:6]
        z[0], z[1], z[2] = y[0] + h * u[0], y[1] + h * u[1], y[2] + h * u[2]
        ew, ex, ey, ez = self._exp(*u[3:6])
        qw, qx, qy, qz = y[6:10]
        nw = ew * qw - ex * qx - ey * qy - ez * qz
        nx = ew * qx + ex * qw + ey * qz - ez * qy
        ny = ew * qy + ey * qw + ez * qx - ex * qz
        nz = ew * qz + ez * qw + ex * qy - ey * qx
        n = (nw * nw + nx * nx + ny * ny + nz * nz) ** 0.5
        z[6], z[7], z[8], z[9] = nw / n, nx / n, ny / n, nz / n
        d = self.rhs(z)
        z[3:6] = [a + half * b for a, b in zip(u[0:3], d[3:6])]
        z[10:13] = [a + half * b for a, b in zip(u[3:6], d[10:13])]
        return z
    mp.setattr(ScalarStepper, "_leapfrog", _leapfrog)


def _lever_arms_not_rotated(mp):
    orig = ScalarStepper._force_torque
    eye = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    # BUG: body points (spring attach, force point) used in body axes as if they were world vectors
    mp.setattr(ScalarStepper, "_force_torque", lambda self, x, v, R: orig(self, x, v, eye))


def _body_torque_applied_in_world_axes(mp):
    def change(s):
        s.tau_W = [a + b for a, b in zip(s.tau_W, s.tau_B)]   # BUG: body-frame torque not rotated
        s.tau_B = [0.0, 0.0, 0.0]
    _after_init(mp, change)


def _torque_cross_product_reversed(mp):
    def change(s):
        s.world_point = [(f, [-c for c in r]) for f, r in s.world_point]   # BUG: f × r instead of r × f
    _after_init(mp, change)


def _drag_sign_flipped(mp):
    def change(s):
        s.c = -s.c   # BUG: f = +c v
    _after_init(mp, change)


# --- the engine adapters --------------------------------------------------------------------------------

def _mujoco_world_omega_as_body(mp):
    from cross_checks.engines import mujoco_engine as me

    def to_qpos_qvel(y):
        y = np.asarray(y, dtype=float)
        qpos = np.concatenate([y[..., 0:3], y[..., 6:10]], axis=-1)
        qvel = np.concatenate([y[..., 3:6], y[..., 10:13]], axis=-1)   # BUG: ω_W written where ω_B belongs
        return qpos, qvel
    mp.setattr(me, "to_qpos_qvel", to_qpos_qvel)


def _mujoco_body_omega_read_as_world(mp):
    from cross_checks.engines import mujoco_engine as me

    def to_packed(qpos, qvel):
        return np.concatenate([qpos[..., 0:3], qvel[..., 0:3], qpos[..., 3:7], qvel[..., 3:6]], axis=-1)  # BUG
    mp.setattr(me, "to_packed", to_packed)


def _mujoco_gravity_twice(mp):
    from cross_checks.engines import mujoco_engine as me
    orig = me.harness_force_torque

    def harness(scenario, y, dt_s):
        f, tau = orig(scenario, y, dt_s)   # BUG: the weight is left in, and MuJoCo adds gravity itself
        return f + scenario.problem.body.mass_kg * np.asarray(scenario.problem.forces.gravity_W), tau
    mp.setattr(me, "harness_force_torque", harness)


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
    orig = pe.BulletBody.__init__

    def init(self, *a, **kw):
        orig(self, *a, **kw)
        self.q_BP = None   # BUG: the principal frame taken as the body frame
    mp.setattr(pe.BulletBody, "__init__", init)


def _pybullet_quaternion_order(mp):
    from cross_checks.engines import pybullet_engine as pe
    mp.setattr(pe, "_xyzw", lambda q: [float(q[0]), float(q[1]), float(q[2]), float(q[3])])   # BUG: wxyz passed


def _pybullet_decay_left_out(mp):
    from cross_checks.engines import pybullet_engine as pe
    mp.setattr(pe, "decay_factors", lambda scenario, dt_s: (1.0, 1.0))   # BUG: no decay at all


def _pybullet_torque_in_link_frame(mp):
    from cross_checks.engines import pybullet_engine as pe

    def apply(self, f_W, tau_W, x_W):   # 3 floats each, as BulletBody.apply
        p = pe.p
        if any(v != 0.0 for v in f_W):
            p.applyExternalForce(self.b, -1, list(f_W), list(x_W), p.WORLD_FRAME, physicsClientId=self.c)
        if any(v != 0.0 for v in tau_W):   # BUG: a world torque given in the link (body) frame
            p.applyExternalTorque(self.b, -1, list(tau_W), p.LINK_FRAME, physicsClientId=self.c)
    mp.setattr(pe.BulletBody, "apply", apply)


def _drake_omega_in_body_axes(mp):
    from cross_checks.engines import drake_engine as de
    from reference_sim.quaternion import quat_conj, rotate

    def to_drake_state(y):
        y = np.asarray(y, dtype=float)
        w_B = rotate(quat_conj(y[..., 6:10]), y[..., 10:13])   # BUG: ω in body axes where Drake wants ω_W
        return np.concatenate([y[..., 6:10], y[..., 0:3], w_B, y[..., 3:6]], axis=-1)
    mp.setattr(de, "to_drake_state", to_drake_state)


def _drake_quaternion_order(mp):
    from cross_checks.engines import drake_engine as de

    def to_drake_state(y):
        y = np.asarray(y, dtype=float)
        q = y[..., [7, 8, 9, 6]]                                 # BUG: (x, y, z, w) given as (w, x, y, z)
        return np.concatenate([q, y[..., 0:3], y[..., 10:13], y[..., 3:6]], axis=-1)
    mp.setattr(de, "to_drake_state", to_drake_state)


def _drake_decay_twice(mp):
    from cross_checks.engines import drake_engine as de
    orig = de.stage_force_torque

    def stage(scenario, y):
        f, tau = orig(scenario, y)
        k_v, _ = scenario.problem.forces.decay_rates_per_s()
        return f - scenario.problem.body.mass_kg * k_v * np.asarray(y[3:6]), tau   # BUG: damping counted twice
    mp.setattr(de, "stage_force_torque", stage)


def _drake_gravity_twice(mp):
    from cross_checks.engines import drake_engine as de
    orig = de.stage_force_torque

    def stage(scenario, y):
        f, tau = orig(scenario, y)   # BUG: the weight added again, and Drake's gravity field applies it too
        return f + scenario.problem.body.mass_kg * np.asarray(scenario.problem.forces.gravity_W), tau
    mp.setattr(de, "stage_force_torque", stage)


MUTANTS = [
    Mutant("rk4_wrong_stage_weight", "reference:rk4", "RK4 stage weights (1, 3, 1, 1)/6: order 2",
           ("applied_torque",), _rk4_wrong_stage_weight),
    Mutant("rk4_third_stage_from_k1", "reference:rk4", "RK4's third stage from k1 instead of k2 (a typo)",
           ("particle_body",), _rk4_third_stage_from_k1),
    Mutant("midpoint_stage_at_full_step", "reference:midpoint", "mid-point stage at y + Δt k1: order 1",
           ("projectile",), _midpoint_stage_at_full_step),
    Mutant("gyroscopic_sign_flipped", "reference:expmap_gyro", "+ω × Iω instead of −ω × Iω",
           ("tennis_racket",), _gyroscopic_sign_flipped),
    Mutant("gyroscopic_sign_flipped_rk4", "reference:rk4", "+ω × Iω in the whole-state right-hand side",
           ("particle_body",), _gyroscopic_sign_flipped),
    Mutant("gyroscopic_term_dropped", "reference:course_gyro", "the gyroscopic torque left out",
           ("tennis_racket",), _gyroscopic_term_dropped),
    Mutant("course_decay_twice", "reference:course", "velocity decay applied twice per step",
           ("velocity_decay",), _course_decay_twice),
    Mutant("rk4_decay_left_out", "reference:rk4", "no decay in the right-hand side",
           ("velocity_decay",), _whole_state_decay_left_out),
    Mutant("course_quaternion_on_the_right", "reference:course", "q + q [0, Δt/2 ω]: world ω used as body ω",
           ("constant_spin",), _course_quaternion_multiplied_on_the_right),
    Mutant("leapfrog_explicit_half_kick", "reference:leapfrog", "first half kick not solved: explicit",
           ("tennis_racket",), _leapfrog_explicit_half_kick),
    Mutant("lever_arms_not_rotated", "reference:rk4", "body points used in body axes as world vectors",
           ("applied_torque",), _lever_arms_not_rotated),
    Mutant("body_torque_in_world_axes", "reference:expmap_gyro", "a body-frame torque applied unrotated",
           ("applied_torque",), _body_torque_applied_in_world_axes),
    Mutant("torque_cross_product_reversed", "reference:midpoint", "τ = f × r instead of r × f",
           ("applied_torque",), _torque_cross_product_reversed),
    Mutant("drag_sign_flipped", "reference:course", "drag f = +c v",
           ("linear_drag",), _drag_sign_flipped),
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
    Mutant("pybullet_quaternion_order", "pybullet:maximal", "(w, x, y, z) passed where (x, y, z, w) is expected",
           ("constant_spin",), _pybullet_quaternion_order),
    Mutant("pybullet_decay_left_out", "pybullet:multibody", "no velocity decay",
           ("velocity_decay",), _pybullet_decay_left_out),
    Mutant("pybullet_torque_in_link_frame", "pybullet:maximal", "a world torque applied in the link frame",
           ("applied_torque",), _pybullet_torque_in_link_frame),
    Mutant("drake_omega_in_body_axes", "drake:semi_explicit_euler", "ω_B given where Drake's state has ω_W",
           ("constant_spin",), _drake_omega_in_body_axes),
    Mutant("drake_quaternion_order", "drake:runge_kutta3", "(x, y, z, w) given where Drake's state has (w, x, y, z)",
           ("constant_spin",), _drake_quaternion_order),
    Mutant("drake_decay_twice", "drake:runge_kutta2", "the decay force counted twice in the stage forces",
           ("velocity_decay",), _drake_decay_twice),
    Mutant("drake_gravity_twice", "drake:implicit_euler", "the weight left in the applied force",
           ("applied_torque",), _drake_gravity_twice),
]
