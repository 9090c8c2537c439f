"""PyBullet runs of a fuzz batch: what ``pybullet_engine.simulate`` and ``one_step`` give, run by run, at a
fraction of the per-run cost.

The adapter starts every run with ``resetSimulation`` (0.9 ms, more than a 50-step run costs) and, for
forces that depend on the state, builds a plain-float force evaluator every step. Here each process keeps
ONE world of its own (its own DIRECT client, so the adapter's world is never touched); a run removes the
previous body and creates its own with the adapter's settings (gravity, ``fixedTimeStep``,
``numSubSteps = 0``, ``createMultiBody``, ``changeDynamics(**DYNAMICS_SETTINGS)``) — or, when the previous
run was of the same case and variant (the rungs of a ladder, the one-step rungs), keeps that body and sets
the step and gravity again (a body costs ~1 ms to create, more than a short run) — and the force
evaluator of a run is built once. Everything else is the adapter's own code: its ``_Body`` conversions
(pose in, state out, priming of maximal bodies), ``apply``, ``decay_factors``, the harness formulas
(``harness_force_torque_floats``: start-of-step state, pre-step decay, the weight left to PyBullet).
Runs are bit-identical to the adapter's (tested, every force kind, both variants); a run that blows up or
that PyBullet rejects is re-run through the adapter by the caller, so its "diverged at t = …" and its
message are the adapter's. The body is built by the adapter's own ``_Body.__init__`` (in this world, with
no reset): a bug planted there reaches these runs too.
"""
from __future__ import annotations

import os

import numpy as np

from reference_sim.simulate import bad_rows

__all__ = ["simulate", "one_step", "Rejected"]


class Rejected(RuntimeError):
    """PyBullet rejected the body here: the caller runs the case through the adapter (its message)."""


_WORLD = {"pid": None, "c": None, "b": None, "body": None, "key": None, "scenario": None}


def _world() -> int:
    """This process's own DIRECT client (connected once: ~0.1 s)."""
    from cross_checks.engines import pybullet_engine as pe
    p = pe.p
    if _WORLD["pid"] != os.getpid() or _WORLD["c"] is None or not p.isConnected(physicsClientId=_WORLD["c"]):
        c = p.connect(p.DIRECT)
        if c < 0:
            raise Rejected("pybullet.connect(DIRECT) failed")
        _WORLD.update(pid=os.getpid(), c=c, b=None, body=None, key=None, scenario=None)
    return _WORLD["c"]


def _body(scenario, variant: str, dt_s: float, y0):
    """A ``pybullet_engine._Body`` of the scenario in this process's world, built by the adapter's own
    ``_Body.__init__``. The world holds one body: the previous run's when it was built for the same
    scenario and variant (by the same ``__init__``) — its step set to ``dt_s`` and the adapter's gravity
    set again; the caller puts it at its start state, as the adapter does with a new body (bit-identical,
    tested: consecutive runs of one case at other steps) — or else a new one, the previous body removed."""
    from cross_checks.engines import pybullet_engine as pe
    c = _world()
    key = (id(scenario), variant, pe._Body.__init__)
    try:
        if _WORLD["b"] is not None and _WORLD["key"] == key and _WORLD["scenario"] is scenario:
            B = _WORLD["body"]
            pe.p.setGravity(*[float(g) for g in scenario.problem.forces.gravity_W], physicsClientId=c)
            pe.p.setPhysicsEngineParameter(fixedTimeStep=float(dt_s), numSubSteps=0, physicsClientId=c)
            return B
        if _WORLD["b"] is not None:
            pe.p.removeBody(_WORLD["b"], physicsClientId=c)
            _WORLD.update(b=None, body=None, key=None, scenario=None)
        B = pe._Body(scenario, variant, dt_s, y0, client=c)
    except (pe.EngineError, pe.p.error) as exc:
        raise Rejected(str(exc)) from None
    _WORLD.update(b=B.b, body=B, key=key, scenario=scenario)
    return B


def release() -> None:
    """Remove the world's body (the end of a batch): the next run builds its own."""
    from cross_checks.engines import pybullet_engine as pe
    if _WORLD["b"] is not None and _WORLD["pid"] == os.getpid() and _WORLD["c"] is not None:
        try:
            pe.p.removeBody(_WORLD["b"], physicsClientId=_WORLD["c"])
        except pe.p.error:
            pass
    _WORLD.update(b=None, body=None, key=None, scenario=None)


def _forces(scenario, dt_s):
    """``harness_force_torque_floats(scenario, ·, dt_s)`` with its float evaluator built once: y -> 6 floats."""
    from cross_checks.engines.base import _float_forces, decay_factors
    ft = _float_forces(scenario).force_torque
    gv, gw = decay_factors(scenario, dt_s)

    def f(y):
        fx, fy, fz, tx, ty, tz = ft(y)
        return gv * fx, gv * fy, gv * fz, gw * tx, gw * ty, gw * tz
    return f


def simulate(scenario, variant: str, dt_s: float, n_steps: int):
    """Packed states (n_steps + 1, 13) of the adapter's free run; None when the run blew up (the caller
    re-runs it through the adapter). Raises Rejected when PyBullet rejects the body."""
    from cross_checks.engines import pybullet_engine as pe
    p = pe.p
    forces = scenario.problem.forces
    y0 = scenario.problem.initial_packed()
    with pe._LOCK, np.errstate(all="ignore"):
        B = _body(scenario, variant, dt_s, y0)
        B.set_state(y0)
        c, b = B.c, B.b
        decay = forces.has_decay
        gv, gw = pe.decay_factors(scenario, dt_s)
        ft = _forces(scenario, dt_s)
        wx, wy, wz = (float(w) for w in B.weight)
        fx, fy, fz, tx, ty, tz = ft(y0)
        f = np.array([fx - wx, fy - wy, fz - wz])
        tau = np.array([tx, ty, tz])
        state_dependent = forces.state_dependent   # a property that walks the force lists: read once
        applies = decay or state_dependent or bool(np.any(f != 0.0) or np.any(tau != 0.0))
        raw = np.empty((n_steps + 1, 13))
        raw[0] = B.read_raw()
        step, pose, vel = p.stepSimulation, p.getBasePositionAndOrientation, p.getBaseVelocity
        for n in range(1, n_steps + 1):
            row = raw[n - 1]
            if state_dependent and n > 1:
                fx, fy, fz, tx, ty, tz = ft(B.raw_to_packed(row))
                f = np.array([fx - wx, fy - wy, fz - wz])
                tau = np.array([tx, ty, tz])
            if decay:
                p.resetBaseVelocity(b, (row[3:6] * gv).tolist(), (row[10:13] * gw).tolist(), physicsClientId=c)
            if applies:
                B.apply(f, tau, row[0:3])
            step(physicsClientId=c)
            ps, orn = pose(b, physicsClientId=c)
            lin, ang = vel(b, physicsClientId=c)
            raw[n] = ps + lin + orn + ang
        if bad_rows(raw).any():
            return None
        return B.raw_to_packed(raw)


def one_step(scenario, variant: str, dt_s: float, y_start) -> np.ndarray:
    """``pybullet_engine.one_step``: one step of ``dt_s`` from each row of ``y_start`` (T, 13)."""
    from cross_checks.engines import pybullet_engine as pe
    p = pe.p
    y_start = np.asarray(y_start, dtype=float).reshape(-1, 13)
    y_dec = pe.apply_decay_prestep(scenario, y_start, dt_s)
    out = np.empty_like(y_start)
    with pe._LOCK, np.errstate(all="ignore"):
        B = _body(scenario, variant, dt_s, y_start[0])
        ft = _forces(scenario, dt_s)
        for i in range(len(y_start)):
            fx, fy, fz, tx, ty, tz = ft(y_start[i])
            B.set_state(y_dec[i])
            B.apply(np.array([fx, fy, fz]) - B.weight, np.array([tx, ty, tz]), y_start[i, 0:3])
            p.stepSimulation(physicsClientId=B.c)
            out[i] = B.read_raw()
        return B.raw_to_packed(out)
