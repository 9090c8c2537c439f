"""DART (``dartpy``) as an engine (``dart:VARIANT``, float64): the free bodies of
cross_checks.engines.worlds.dart (each alone in a DART ``World``: FreeJoint positions ``[r, x_W]``, ``r`` the
rotation vector of R_WB, velocities ``[ω_W, v_W]`` in WORLD axes) for rbcheck's loop. ``World::step``, DART's
only integrator (semi-implicit Euler, explicit gyroscopic term, exponential map: MuJoCo Euler's scheme),
called as ``step(False)``, which keeps the wrench set before it. Forces: the loop's (the weight taken off),
set before every step; a torque fixed in body axes is DART's own (``takes_body_torque``). The recorded
quaternion is sign-continuous from the scenario's, the state at t = 0 the scenario's (the rotation vector's
round trip is not exact); a blown-up body is parked at rest (DART would step on, warning). Conventions,
defaults neutralised and what pins them: docs/engine_conventions.md, "DART 6.x".
"""
from __future__ import annotations

import functools
import math

import numpy as np

from cross_checks.engines import base, install, world
from cross_checks.engines.base import EngineError, Variant
from cross_checks.engines.loop import host_problem
from cross_checks.engines.world import World, WorldEngine
from reference_sim.simulate import BLOWUP_LIMIT

dart, _IMPORT_ERROR, dtw = install.optional_world("dartpy", "dart", "FormBody", "FormBodies")
if _IMPORT_ERROR is None:
    from cross_checks.engines.worlds.dart import JOINT_SETTINGS, from_dart_state, neutralise, to_dart_state

__all__ = ["ENGINE", "VARIANTS", "JOINT_SETTINGS", "EngineError", "version", "simulate", "simulate_many",
           "one_step", "DartBody", "DartWorld", "DartAdapter", "neutralise", "to_dart_state",
           "from_dart_state"]

ENGINE = "dart"
#: DART's one integrator (``World::step``): semi-implicit Euler, first order.
VARIANTS = {
    "semi_implicit_euler": Variant(1, "DART World::step: semi-implicit Euler, explicit gyroscopic term (its "
                                      "own articulated-body dynamics), exponential-map rotation update with "
                                      "the new ω", traits=base.SYMPLECTIC_EULER_EXPLICIT_GYRO),
}


def _packed_floats(row) -> list:
    """One DART state (12 floats ``[r, x_W, ω_W, v_W]``) -> the packed state (13 floats) for the force
    evaluation of the next step: :func:`from_dart_state` in plain floats (the quaternion's sign does not
    matter to a force)."""
    r0, r1, r2, x0, x1, x2, w0, w1, w2, v0, v1, v2 = row
    theta = math.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
    if theta < 1e-4:     # sin(θ/2)/θ by its series, as reference_sim.quaternion.quat_exp
        t2 = theta * theta
        s = 0.5 - t2 / 48.0 + t2 * t2 / 3840.0
    else:
        s = math.sin(0.5 * theta) / theta
    return [x0, x1, x2, v0, v1, v2, math.cos(0.5 * theta), s * r0, s * r1, s * r2, w0, w1, w2]


#: ``(mass_kg, inertia_B (3, 3), None)``: DART takes the full tensor (``Inertia(m, 0, I_B)``)
body_spec = world.body_spec


def body_entry(scenario) -> tuple:
    """The scenario's body as worlds.dart.FormBody takes it (world.body_entry)."""
    return world.body_entry(scenario, body_spec)


class DartBody(dtw.FormBody):
    """A scenario's free body alone in a DART world stepping at ``dt_s``
    (:class:`cross_checks.engines.worlds.dart.FormBody`, what ``rbcheck repro`` embeds: its COM off the
    origin and its welded parts too); ``set_state``/``read`` at the boundary."""

    def __init__(self, scenario, dt_s: float):
        _ENGINE.require_installed()
        super().__init__(body_entry(scenario), scenario.problem.forces.gravity_W, dt_s)
        if not self.ok:
            raise EngineError(f"DART {version()} rejects the inertia of scenario "
                              f"{scenario.name!r} (dart::dynamics::Inertia::verify "
                              "is false: a mass or moment that is not positive)")


class DartWorld(dtw.FormBodies, World):
    """B bodies, each a :class:`DartBody`, stepped in turn by ``World.step(False)`` (World::step's
    resetCommand false: the external wrench set before it kept). DART holds that wrench in body axes
    (``setExtForce``/``setExtTorque`` turn a world one at the call), so only body-axes torques are set once
    (:meth:`applier`). Raw rows: ``[r, x_W, ω_W, v_W]`` (12). A blown-up body is parked at rest, its forces
    cleared, and gets none from then on (DART would go on from the bad state; the loop ends its run)."""

    exact_start = True
    float_reads = True

    def __init__(self, requests, variant: str, dt_s: float):
        World.__init__(self)
        dtw.FormBodies.__init__(self, [DartBody(r.scenario, dt_s) for r in requests])
        # the forces the harness evaluates (the body-axes torques are DART's own: takes_body_torque)
        self.always = [host_problem(r.scenario.problem, True).forces.state_dependent for r in requests]
        # the free joint's getters: the skeleton's numbers (welded parts have no DOF), ~5 % cheaper a call
        self._reads = [(b.joint.getPositions, b.joint.getVelocities) for b in self.bodies]
        steps = [functools.partial(b.world.step, False) for b in self.bodies]   # keep the external wrench
        if len(steps) == 1:
            self.step = steps[0]   # the engine's call itself: no Python frame per step
            (pos, vel), = self._reads

            def read():   # read() of one body, its calls bound
                row = pos().tolist() + vel().tolist()
                rows = self.last = [row]
                if not math.hypot(*row) <= BLOWUP_LIMIT:   # (NaN compares False)
                    self._bad(rows)
                return rows
            self.read = read
        else:
            def step():
                for one in steps:
                    one()
            self.step = step

    def applier(self, f_W, tau_W):
        """Constant forces: where no body has a world force or torque, the body-axes torques set once, here
        (``step(False)`` keeps them), and None; otherwise :meth:`apply` before every step (DART would keep
        a world wrench in body axes, turning with the body)."""
        if np.any(np.asarray(f_W, dtype=float)) or np.any(np.asarray(tau_W, dtype=float)) or any(self.always):
            return functools.partial(self.apply, f_W, tau_W)
        self.apply(f_W, tau_W)
        return None

    def read(self):
        """Every body's state, 12 floats ``[r, x_W, ω_W, v_W]`` (Bodies.read's); a blown-up body parked."""
        rows = self.last = [pos().tolist() + vel().tolist() for pos, vel in self._reads]
        self._bad(rows)
        return rows

    def _bad(self, rows):
        """Each live body whose row blew up (world.blown_up; DART's |r| ≤ π: the packed state's verdict) at
        rest at the origin with no force, never given one again (``live``)."""
        for k in world.blown_up(rows, self.live):
            b = self.bodies[k]
            self.live[k] = False
            b.skeleton.setPositions(np.zeros(6))
            b.skeleton.setVelocities(np.zeros(6))
            b.node.clearExternalForces()

    def packed_row(self, raw):
        if any(b.com_B is not None for b in self.bodies):
            return self.packed(np.asarray(raw, dtype=float)[None])[0].tolist()
        return [_packed_floats(r) for r in (raw if isinstance(raw, list) else np.asarray(raw).tolist())]

    def decay(self, g_v, g_w):
        """The velocities last read, scaled (the pose is not set again: its round trip is not exact); a body
        whose origin is off its COM: the COM's v and ω scaled, the origin's v = v − ω × R c set."""
        if all(b.com_B is None for b in self.bodies):
            dtw.FormBodies.decay(self, g_v, g_w)
            return
        y_all = self.packed(np.asarray(self.last, dtype=float)[None])[0]
        for k, (b, prev, gv, gw) in enumerate(zip(self.bodies, self.last, g_v.tolist(), g_w.tolist())):
            if b.com_B is None:
                b.skeleton.setVelocities(np.array(prev[6:12]) * (gw, gw, gw, gv, gv, gv))
                continue
            y = y_all[k]
            r_W = y[0:3] - np.asarray(prev[3:6])
            w, v = gw * y[10:13], gv * y[3:6]
            b.skeleton.setVelocities(np.concatenate([w, v - np.cross(w, r_W)]))


class DartEngine(WorldEngine):
    """``dart:VARIANT`` — registered under the entry-point group ``rbcheck.engines``; optional
    (``pip install 'rbcheck[dart]'``)."""

    name, variants, world = ENGINE, VARIANTS, DartWorld
    distribution, extra, imported = "dartpy", "dart", "dart"
    #: the COM off the body origin (Inertia's local COM); welded parts (WeldJoint children)
    body_forms = frozenset({"com_offset", "welded_parts"})
    sign_continuity = True
    #: BodyNode.setExtTorque(τ, isLocal=True) takes a torque in the body's own axes (DART turns it): the world
    #: sets the bodies' body-axes torques before every step (DART clears them), no harness evaluation
    #: (pinned: tests/cross_checks/engines/test_dart_engine.py)
    takes_body_torque = True


_ENGINE, version, simulate, simulate_many, one_step = DartEngine.exported()
DartAdapter = DartEngine
