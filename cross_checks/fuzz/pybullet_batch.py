"""PyBullet runs of a fuzz batch: what ``pybullet_engine.simulate`` and ``one_step`` give, run by run, at a
fraction of the per-run cost.

The adapter starts every run with ``resetSimulation`` (0.9 ms, more than a 50-step run costs). Here each
process keeps ONE world of its own (its own DIRECT client, so the adapter's world is never touched); a run
removes the previous body and creates its own with the adapter's settings (gravity, ``fixedTimeStep``,
``numSubSteps = 0``, ``createMultiBody``, ``changeDynamics(**DYNAMICS_SETTINGS)``) — or, when the previous
run was of the same case and variant (the rungs of a ladder, the one-step rungs), keeps that body and sets
the step and gravity again (a body costs ~1 ms to create, more than a short run). The runs themselves are
the adapter's own code on that body (``pybullet_engine.free_run`` and ``one_steps``: its ``BulletBody``
conversions, ``apply``, ``decay_factors``, the harness), so they are bit-identical to the adapter's (tested,
every force kind, both variants); a run that blows up or that PyBullet rejects is re-run through the
adapter by the caller, so its "diverged at t = …" and its message are the adapter's. The body is built by
the adapter's own ``BulletBody.__init__`` (in this world, with no reset): a bug planted there reaches these runs
too.
"""
from __future__ import annotations

import os

import numpy as np

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
    """A ``pybullet_engine.BulletBody`` of the scenario in this process's world, built by the adapter's own
    ``BulletBody.__init__``. The world holds one body: the previous run's when it was built for the same
    scenario and variant (by the same ``__init__``) — its step set to ``dt_s`` and the adapter's gravity
    set again; the caller puts it at its start state, as the adapter does with a new body (bit-identical,
    tested: consecutive runs of one case at other steps) — or else a new one, the previous body removed."""
    from cross_checks.engines import pybullet_engine as pe
    c = _world()
    key = (id(scenario), variant, pe.BulletBody.__init__)
    try:
        if _WORLD["b"] is not None and _WORLD["key"] == key and _WORLD["scenario"] is scenario:
            B = _WORLD["body"]
            pe.p.setGravity(*[float(g) for g in scenario.problem.forces.gravity_W], physicsClientId=c)
            pe.p.setPhysicsEngineParameter(fixedTimeStep=float(dt_s), numSubSteps=0, physicsClientId=c)
            return B
        if _WORLD["b"] is not None:
            pe.p.removeBody(_WORLD["b"], physicsClientId=c)
            _WORLD.update(b=None, body=None, key=None, scenario=None)
        B = pe.BulletBody(scenario, variant, dt_s, y0, client=c)
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


def simulate(scenario, variant: str, dt_s: float, n_steps: int):
    """Packed states (n_steps + 1, 13) of the adapter's free run (``pybullet_engine.free_run`` on this
    world's body); None when the run blew up (the caller re-runs it through the adapter). Raises Rejected
    when PyBullet rejects the body."""
    from cross_checks.engines import pybullet_engine as pe
    y0 = scenario.problem.initial_packed()
    with pe.LOCK, np.errstate(all="ignore"):
        run = pe.free_run(_body(scenario, variant, dt_s, y0), scenario, y0, dt_s, n_steps)
    return None if run.diverged_at_s is not None else run.y


def one_step(scenario, variant: str, dt_s: float, y_start) -> np.ndarray:
    """``pybullet_engine.one_step``: one step of ``dt_s`` from each row of ``y_start`` (T, 13)."""
    from cross_checks.engines import pybullet_engine as pe
    y_start = np.asarray(y_start, dtype=float).reshape(-1, 13)
    with pe.LOCK, np.errstate(all="ignore"):
        return pe.one_steps(_body(scenario, variant, dt_s, y_start[0]), scenario, dt_s, y_start)
