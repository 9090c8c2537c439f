"""DART (``dartpy``) as an engine (``dart:VARIANT``, float64): a world of free bodies for rbcheck's loop
(cross_checks.engines.world, cross_checks.engines.loop).

Each body alone in a DART ``World`` of its own (:class:`DartBody`): one ``FreeJoint``/``BodyNode`` pair, its
inertia ``Inertia(m, com_B = 0, I_B)`` (body origin = COM, the scenario's tensor as given), neutralised
(:data:`JOINT_SETTINGS`, :func:`neutralise`). State at the boundary: FreeJoint positions ``[r, x_W]`` (``r``
the rotation vector of R_WB) and velocities ``[ω_W, v_W]``, both in WORLD axes; the recorded quaternion is
sign-continuous from the scenario's initial one, recorded as given (the rotation vector's round trip is not
exact). The step is ``World::step`` (dart/simulation/World.cpp): semi-implicit Euler, explicit gyroscopic
term, exponential-map rotation — MuJoCo Euler's scheme, DART's only integrator, called as ``step(False)``
(which keeps the wrench set before it). Forces: the loop's, set before every step (DART would hold a world
wrench in body axes): the world force at the COM minus the weight ``m g``, then the world torque
(``setExtForce`` replaces the whole wrench); a torque fixed in body axes is DART's own
(``takes_body_torque``: ``setExtTorque(τ_B, isLocal=True)`` once where it is a body's only constant force,
else added to the world torque before every step); the decay by setting the velocities last read, scaled.
Divergence: the loop's (DART goes on after a blow-up, warning: the world parks a blown-up body at rest).
Conventions, defaults neutralised and what pins them: docs/engine_conventions.md, "DART 6.x".
"""
from __future__ import annotations

import functools
import itertools
import math

import numpy as np

from cross_checks.engines import base, install
from cross_checks.engines.base import EngineError, Variant
from cross_checks.engines.loop import host_problem
from cross_checks.engines.step_floats import bad_floats
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

def _require():
    install.require(dart, _IMPORT_ERROR, "dartpy", hint="pip install 'rbcheck[dart]'")


def version() -> str:
    """The installed dartpy distribution's version (EngineNotInstalled when it is absent)."""
    _require()
    return install.release("dartpy")


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


def body_spec(body) -> tuple:
    """``(mass_kg, inertia_B (3, 3), None)``: DART takes the full tensor (``Inertia(m, 0, I_B)``)."""
    return float(body.mass_kg), np.asarray(body.inertia_B, dtype=float), None


def body_entry(scenario) -> tuple:
    """The scenario's body as :class:`cross_checks.engines.worlds.dart.FormBody` takes it: its
    :func:`body_spec`; a body whose origin is off its COM (scenario.body_com_B_m) also with that COM (m)
    and its welded parts (scenario.body_parts; none: no fifth item), each ``(mass_kg, inertia_B, None, com)``.
    ``rbcheck repro`` writes the same entry into a script."""
    com = getattr(scenario, "body_com_B_m", None)
    spec = body_spec(scenario.problem.body)
    if com is None:
        return spec
    parts = [(float(q.mass_kg), np.asarray(q.inertia_B, dtype=float), None, [float(v) for v in q.com_B_m])
             for q in getattr(scenario, "body_parts", ())]
    return (*spec, [float(v) for v in com], *([parts] if parts else []))


class DartBody(dtw.FormBody):
    """A scenario's free body alone in a DART world stepping at ``dt_s``
    (:class:`cross_checks.engines.worlds.dart.FormBody`, what ``rbcheck repro`` embeds: its COM off the
    origin and its welded parts too); ``set_state``/``read`` at the boundary."""

    def __init__(self, scenario, dt_s: float):
        _require()
        super().__init__(body_entry(scenario), scenario.problem.forces.gravity_W, dt_s)
        if not self.ok:
            raise EngineError(f"DART {version()} rejects the inertia of scenario "
                              f"{scenario.name!r} (dart::dynamics::Inertia::verify "
                              "is false: a mass or moment that is not positive)")


class DartWorld(dtw.FormBodies, World):
    """B bodies, each a :class:`DartBody`, stepped in turn by ``World.step(False)``, which keeps the external
    wrench set before it (World::step's resetCommand; the default, True, clears it). DART holds that wrench
    in body axes (``setExtForce``/``setExtTorque`` turn a world one at the call), so only the body-axes
    torques stay right over later steps: a world whose only constant forces are those sets them once
    (:meth:`applier`); world forces are set before every step, as before. Raw rows: DART's ``[r, x_W, ω_W,
    v_W]`` (12). A body whose state blew up is parked at rest, its forces cleared, and gets no force from then
    on (DART would go on from the bad state, warning on stderr; the loop ends its run)."""

    exact_start = True

    def __init__(self, requests, dt_s: float):
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
                if not math.hypot(*row) <= BLOWUP_LIMIT:
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
        """Every body's state, 12 floats ``[r, x_W, ω_W, v_W]`` (Bodies.read's); a body whose state is
        non-finite or beyond BLOWUP_LIMIT is parked (:meth:`_bad`)."""
        rows = self.last = [pos().tolist() + vel().tolist() for pos, vel in self._reads]
        if not math.hypot(*itertools.chain.from_iterable(rows)) <= BLOWUP_LIMIT:   # (NaN compares False)
            self._bad(rows)
        return rows

    def _bad(self, rows):
        """Park each live body whose row is non-finite or beyond BLOWUP_LIMIT (DART's |r| ≤ π: the packed
        state's verdict)."""
        for k, row in enumerate(rows):
            if self.live[k] and bad_floats(row):
                self._park(k)

    def _park(self, k):
        """Body k at rest at the origin with no force, never given one again (``live``)."""
        b = self.bodies[k]
        self.live[k] = False
        b.skeleton.setPositions(np.zeros(6))
        b.skeleton.setVelocities(np.zeros(6))
        b.node.clearExternalForces()

    def rows(self, reads):
        """A chunk's reads (per step, B lists of 12 floats) as an array (n, B, 12), in one pass."""
        n, B = len(reads), len(self.bodies)
        flat = itertools.chain.from_iterable(itertools.chain.from_iterable(reads))
        return np.fromiter(flat, dtype=float, count=n * B * 12).reshape(n, B, 12)

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

    name, variants = ENGINE, VARIANTS
    distribution, module, extra = "dartpy", "dartpy", "dart"
    #: the COM off the body origin (Inertia's local COM); welded parts (WeldJoint children)
    body_forms = frozenset({"com_offset", "welded_parts"})
    sign_continuity = True
    #: BodyNode.setExtTorque(τ, isLocal=True) takes a torque in the body's own axes (DART turns it): the world
    #: sets the bodies' body-axes torques before every step (DART clears them), no harness evaluation
    #: (pinned: tests/cross_checks/engines/test_dart_engine.py)
    takes_body_torque = True

    def version(self) -> str:
        return version()

    def build(self, requests, variant, dt_s):
        _require()
        return DartWorld(requests, dt_s)


_ENGINE = DartEngine()
simulate, simulate_many, one_step = _ENGINE.simulate, _ENGINE.simulate_many, _ENGINE.one_step
DartAdapter = DartEngine
