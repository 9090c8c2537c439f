"""One engine machinery: an engine supplies a :class:`World` of B bodies; rbcheck owns the loop that steps it.

An engine is a :class:`WorldEngine` subclass: declarations (its distribution, the pip extra that installs it,
its variants, whether it applies gravity itself, whether applied forces persist between its steps) and one
method, :meth:`WorldEngine.build`, that returns a world of bodies for a variant at one Δt. Everything else —
the harness forces and the pre-step velocity decay, the weight an engine applies itself, divergence, the
quaternion sign, recording, the one-step mode, grouping requests into worlds, the installed version, and the
time spent inside the engine apart from rbcheck's own — is :mod:`cross_checks.engines.loop`'s, written once.

The world's contract (states packed as in reference_sim.state: ``[x_W (m), v_W (m/s, COM), q_WB (w, x, y, z),
ω_W (rad/s, world axes)]``, one row per body, in the order of the requests it was built for):

* ``set_state(y)``: put body i at ``y[i]`` (B, 13).
* ``apply(f_W, tau_W)``: the world force at the COM (N) and world torque (N m), (B, 3) each, for the next
  step (the weight already taken off when the engine applies gravity itself); with ``float_rows`` True,
  also B rows of 3 plain floats each (what the loop then gives it per step, without building arrays).
* ``step()``: one step of every body. Only this (and ``rollout``) is timed as the engine's own work.
* ``read()``: the bodies' current states in the engine's own layout (B, R) (a cheap copy; or in a form of the
  world's own that its ``rows`` turns into such rows), and ``packed(raw)``: such rows (..., B, R) as packed
  states (..., B, 13) (identity by default);
* optional ``first(y0)``: the raw rows recorded as step 0 after ``set_state(y0)`` (by default what ``read()``
  gives; a float32 engine gives ``y0`` itself, so that a run starts at the scenario's state exactly and its
  quaternion sign follows the scenario's);
* optional ``decay(g_v, g_w)``: scale every body's velocities by (B,) factors before a step (by default the
  packed state is read, scaled and set again);
* optional ``applier(f_W, tau_W)``: a callable of no argument that applies those constant forces (and the
  body-axes torques of ``apply_body_torque``) for the next step, as ``apply(f_W, tau_W)`` does, or None when
  that applies nothing: what the loop calls before every step of an engine that clears forces (by default
  ``apply`` itself, the arrays bound);
* optional ``rows(reads)``: a chunk's reads (a list of what ``read()`` gave, one per step) as an array (n, B,
  R) (by default NumPy's conversion of the list; with ``float_reads`` True, reads of B rows of R plain
  floats, flattened in one pass);
* optional ``rollout(n_steps, harness)``: ``n_steps`` steps with the applied forces held, the raw states
  (n_steps, B, R) after each, in the engine's compiled loop (used when nothing changes between steps: no
  state-dependent force, no decay); with ``rollout_forces`` True, a rollout that takes every kind of force
  itself, calling back the loop's ``harness`` (cross_checks.engines.loop.Harness: ``wrench(y)`` at packed
  states, the decay factors ``g_v``, ``g_w``) per step or stage as its compiled loop needs them (the loop
  then runs every run there, after ``apply`` of the start forces unless ``per_stage``; the seconds of those
  callbacks go to ``host_s``);
* optional ``rollout_into``: True when ``rollout`` also takes ``out=`` (an (n_steps, B, R) float64 array view)
  and writes the raw states there, returning nothing the loop needs (no copy of the whole record);
* optional ``rollout_takes_all_forces``: True when ``rollout(n_steps, harness)`` takes every kind of force
  itself (the loop's :class:`~cross_checks.engines.loop.Harness`: its compiled loop calls ``harness``'s
  evaluators back from the host per step or stage, and applies the decay): the loop then uses it for every
  run of the world and for the one-step mode (``rollout(1, harness)`` after ``set_state(rows)``); the
  seconds of its host callbacks go to ``host_s``;
* ``apply_body_torque(tau_B)``, for an engine that declares ``takes_body_torque``: the bodies' torques fixed
  in body axes (B, 3) (N m), kept over every following step (by the engine, or re-applied by the world's
  ``apply`` where the engine clears forces after a step);
* optional ``warnings``: a list the world appends ``(body, step, words)`` to when the engine reports that a
  body's step failed (the step counted from 1 since the last ``set_state``);
* optional ``per_stage``: True when the world evaluates the harness forces inside the engine's step, at every
  stage (then the loop applies neither forces nor decay), and ``host_s``: the seconds of that evaluation
  spent inside ``step()``, which are rbcheck's, not the engine's;
* optional ``first_cause_only``: True when a warning in a step after the body's first bad state is a
  consequence (an engine refusing to step a state that had already blown up), left out of the run's words;
* optional ``exact_start``: True when ``packed(read())`` after ``set_state(y)`` is not ``y`` bit for bit
  (e.g. a rotation vector's round trip): the loop then records the requested initial state at t = 0;
* optional ``close()``.

The contract is tested for every installed engine by tests/cross_checks/engines/test_contract.py; a complete
engine of a few dozen lines is in docs/engines.md.
"""
from __future__ import annotations

import functools
import itertools
import math
import sys

import numpy as np

from cross_checks.engines import base, install
from cross_checks.engines.step_floats import bad_floats
from reference_sim.quaternion import quat_from_matrix
from reference_sim.simulate import BLOWUP_LIMIT

__all__ = ["World", "HostRowsWorld", "WorldEngine", "MANY_BODIES", "body_spec", "blown_up", "body_specs",
           "body_entry", "principal_spec"]

#: Above this many bodies a world is "many bodies": the harness evaluates their forces in one compiled call
#: (loop.Harness.rows) and a world may take them and give its reads as arrays; at or below it, per body in
#: plain floats (a few bodies' arrays cost more than the engine's step). The same numbers either way.
MANY_BODIES = 4


def body_spec(body) -> tuple:
    """``(mass_kg, inertia_B (3, 3) kg m², None)``: the body as given to an engine that takes the full tensor
    about the COM in body axes, no frame rotation (what ``rbcheck repro`` writes of it: an adapter's
    ``body_spec``)."""
    return float(body.mass_kg), np.asarray(body.inertia_B, dtype=float), None


class World:
    """The base of a world (see the module docstring): ``packed`` is the identity, ``decay`` goes through the
    packed state, the state recorded at t = 0 is the world's reading, and a world has no warnings, no
    per-stage forces and nothing to close."""

    per_stage = False
    float_rows = False
    float_reads = False
    rollout_takes_all_forces = False
    host_s = 0.0
    rollout_forces = False
    rollout_into = False
    exact_start = False
    first_cause_only = False

    def __init__(self):
        self.warnings: list = []

    # The contract's methods: every world defines set_state and read; apply and step too, unless its
    # rollout takes every force itself (rollout_takes_all_forces: the loop then never calls them).
    def set_state(self, y) -> None:   # pragma: no cover
        raise TypeError(f"{type(self).__name__} does not define set_state (the World contract)")

    def apply(self, f_W, tau_W) -> None:   # pragma: no cover
        raise TypeError(f"{type(self).__name__} does not define apply (the World contract)")

    def step(self) -> None:   # pragma: no cover
        raise TypeError(f"{type(self).__name__} does not define step (the World contract)")

    def read(self):   # pragma: no cover
        raise TypeError(f"{type(self).__name__} does not define read (the World contract)")

    def first(self, y0):
        """The raw rows (B, R) recorded as step 0 after ``set_state(y0)``: what :meth:`read` gives."""
        return self.rows([self.read()])[0]

    def packed(self, raw) -> np.ndarray:
        return np.asarray(raw, dtype=float)

    def packed_row(self, raw) -> list:
        """One read's raw rows (B, R) as packed states (B rows of 13 numbers): :meth:`packed` of them, bit for
        bit; a world may give it in plain floats, for the loop's per-step forces."""
        return self.packed(self.rows([raw]))[0]

    def applier(self, f_W, tau_W):
        """A callable of no argument applying the constant forces ``f_W``, ``tau_W`` (B, 3) for the next step
        (and the body-axes torques of ``apply_body_torque``), or None when that applies nothing."""
        return functools.partial(self.apply, f_W, tau_W)

    def rows(self, reads):
        """A chunk's reads (a list of ``read()``'s results, one per step) as raw rows (n, B, R): where they
        are B rows of R plain floats each (``float_reads``), all in one pass."""
        if not self.float_reads:
            return np.asarray(reads, dtype=float)
        n, B, R = len(reads), len(reads[0]), len(reads[0][0])
        flat = itertools.chain.from_iterable(itertools.chain.from_iterable(reads))
        return np.fromiter(flat, dtype=float, count=n * B * R).reshape(n, B, R)

    def decay(self, g_v, g_w) -> None:
        y = self.packed(self.rows([self.read()]))[0].copy()
        y[:, 3:6] *= np.asarray(g_v, dtype=float)[:, None]
        y[:, 10:13] *= np.asarray(g_w, dtype=float)[:, None]
        self.set_state(y)

    def close(self) -> None:
        pass


class HostRowsWorld(World):
    """A world whose bodies' states are kept on the host as packed rows (B, 13) between calls of a compiled
    ``rollout`` that takes every force itself (a JAX engine: Brax, jaxsim): ``set_state`` keeps a copy,
    ``read`` gives it; ``ends`` holds each request's steps, ``host_s`` the seconds that are rbcheck's."""

    rollout_takes_all_forces = True

    def __init__(self, requests):
        super().__init__()
        self.ends = [int(r.n_steps) for r in requests]
        self.host_s = 0.0
        self.y = np.empty((len(requests), 13))

    def set_state(self, y):
        self.y = np.array(y, dtype=float)

    def read(self):
        return self.y


def blown_up(rows, live) -> list:
    """The bodies k with ``live[k]`` whose row of ``rows`` (B rows of plain floats, or a (B, R) array) is
    non-finite or beyond BLOWUP_LIMIT (reference_sim.simulate.bad_rows): what a world whose engine would step
    on from a bad state stops once read (PhysX, DART, Rapier). [] after one pass in the common case."""
    if isinstance(rows, np.ndarray):
        size = np.abs(rows)
        if size.max() <= BLOWUP_LIMIT:   # (NaN compares False)
            return []
        return np.flatnonzero(np.asarray(live, dtype=bool) & ~(size.max(axis=1) <= BLOWUP_LIMIT)).tolist()
    if math.hypot(*itertools.chain.from_iterable(rows)) <= BLOWUP_LIMIT:   # at least every |component|
        return []
    return [k for k, row in enumerate(rows) if live[k] and bad_floats(row)]


def body_specs(requests, spec_of) -> list:
    """``spec_of(body)`` of each request's body, computed once per distinct body (a batch is mostly copies of
    a few)."""
    specs: dict = {}
    for r in requests:
        if id(r.scenario.problem.body) not in specs:
            specs[id(r.scenario.problem.body)] = spec_of(r.scenario.problem.body)
    return [specs[id(r.scenario.problem.body)] for r in requests]


def principal_spec(body, frame=quat_from_matrix, diagonal=None) -> tuple:
    """``(mass_kg, principal moments (3,) kg m², principal frame)`` of a RigidBody for an engine that takes a
    diagonal inertia (PyBullet, Rapier, Drake): a diagonal tensor as its diagonal, ``diagonal`` its frame (its
    axes kept in their order); a full one as its principal moments and ``frame(R_BP)``
    (reference_sim.body.principal_axes; by default q_BP (w, x, y, z))."""
    if body.is_diagonal():
        return float(body.mass_kg), np.diag(body.inertia_B).copy(), diagonal
    moments, R_BP = body.principal_axes()
    return float(body.mass_kg), moments, frame(R_BP)


def body_entry(scenario, spec_of) -> tuple:
    """The scenario's body as the worlds' ``FormBody``/``form_world`` take it (worlds/dart.py, drake.py,
    pybullet.py; ``rbcheck repro`` writes the same entry into a script): ``spec_of(body)``; a body whose
    origin is off its COM (scenario.body_com_B_m) also with that COM (m, body axes from the origin) and its
    welded parts (scenario.body_parts; none: no fifth item), each ``(*spec_of(part), its COM)``."""
    from reference_sim.body import RigidBody
    com = getattr(scenario, "body_com_B_m", None)
    spec = spec_of(scenario.problem.body)
    if com is None:
        return spec
    parts = [(*spec_of(RigidBody(p.mass_kg, p.inertia_B)), [float(v) for v in p.com_B_m])
             for p in getattr(scenario, "body_parts", ())]
    return (*spec, [float(v) for v in com], *([parts] if parts else []))


class WorldEngine(base.EngineAdapter):
    """An engine adapter whose engine supplies a :class:`World` and whose runs are the host loop's
    (:mod:`cross_checks.engines.loop`). Subclass it, declare the fields below and ``world`` or :meth:`build`.

    ``distribution`` (the pip distribution whose version every result records), ``module`` (its import name,
    default ``distribution``), ``extra`` (rbcheck's pip extra that installs it, "" for a required engine) and
    ``runs_on`` (``(label, distribution)`` of what it runs on, recorded beside its version) give
    :meth:`version`, the install checks and :meth:`engine_files`; ``imported``, where the adapter module
    imported its engine at its own import (install.optional_world), the name of its global that holds the
    engine module (None there: not importable, its ``_IMPORT_ERROR`` says why); ``world``, the class (or a
    function) that :meth:`build` makes a world of, ``world(requests, variant, dt_s)``.
    """

    distribution: str = ""
    module: str = ""
    extra: str = ""
    runs_on: tuple = ()
    imported: str = ""
    world = None
    #: The engine adds gravity itself (the loop takes the weight off the harness force).
    applies_gravity: bool = True
    #: Forces applied to a body stay applied over the next steps until changed (MuJoCo's xfrc_applied): the
    #: loop applies constant forces once. False: the engine clears them after every step (Bullet, PhysX).
    keeps_forces: bool = False
    #: The engine applies a torque fixed in body axes itself, turning it with the body (MuJoCo: a free joint's
    #: rotational DOFs are body axes, so qfrc_applied holds it; PyBullet: applyExternalTorque in LINK_FRAME;
    #: DART: setExtTorque(τ, isLocal=True)): the loop gives a world the bodies' body-axes torques once
    #: (``World.apply_body_torque(tau_B)``, (B, 3) N m), which the world keeps applied over every following
    #: step (MuJoCo keeps it; a world whose engine clears forces re-applies it in ``apply``), and evaluates
    #: the other forces only.
    takes_body_torque: bool = False
    #: The quaternion the engine returns may change sign between steps: the loop picks, after each step, the
    #: sign on the previous state's side (reference_sim.quaternion.same_side).
    sign_continuity: bool = False
    #: A world may hold runs of different Δt (the loop then groups requests by ``group_key`` alone, the
    #: harness has each body's own decay factors, and ``build`` gets the first request's Δt; each request
    #: keeps its own): for an engine that batches a Δt ladder in one compiled call (Brax).
    mixed_steps: bool = False
    #: Runs of any length share a world of one Δt and float32 gravity (:meth:`group_key`), the world ending
    #: each body's run itself (bodies that never interact, an engine that computes in float32: Rapier, PhysX).
    any_length: bool = False
    #: Steps between the loop's divergence checks.
    chunk: int = 1024
    #: Harness modules whose code decides the results besides the engine's own (the result cache's key).
    harness: tuple = ("cross_checks.engines.forces", "cross_checks.engines.loop",
                      "cross_checks.engines.world")

    def build(self, requests, variant: str, dt_s: float) -> World:
        """A world of the bodies of ``requests`` (base.RunRequest, at step ``dt_s``) for ``variant``. Raise
        :class:`~cross_checks.engines.base.EngineError` with the engine's words when it rejects a model.
        By default ``world(requests, variant, dt_s)`` once the engine is installed
        (:meth:`require_installed`)."""
        if self.world is None:
            raise TypeError(f"{type(self).__name__} declares no world and does not define build")
        self.require_installed()
        return type(self).world(requests, variant, dt_s)

    def group_key(self, request) -> tuple:
        """Requests with equal keys are run in one world: equal step and step count, or with ``any_length``,
        equal step and float32 gravity."""
        if self.any_length:
            return (float(request.dt_s), np.float32(request.scenario.problem.forces.gravity_W).tobytes())
        return (float(request.dt_s), int(request.n_steps))

    def world_key(self, request, variant: str) -> tuple:
        """The loop's grouping of ``variant``'s requests into worlds: a world has one step (whatever
        :meth:`group_key` says) and one way of taking the forces (:meth:`per_stage`). An engine whose world
        holds bodies of different steps (each body's Δt its request's) overrides it."""
        return (None if self.mixed_steps else float(request.dt_s), self.group_key(request),
                self.per_stage(request.scenario, variant))

    def per_stage(self, scenario, variant: str) -> bool:
        """True when ``variant`` evaluates the forces of ``scenario`` at every stage of its step (its world
        does: ``World.per_stage``), so the loop applies neither forces nor decay before the step."""
        return False

    def require_installed(self):
        """install.require of the engine (its words name ``distribution``): of the adapter module's global
        ``imported`` and its ``_IMPORT_ERROR`` where it imported the engine at its own import, else of
        importing ``module`` now."""
        adapter = vars(sys.modules[type(self).__module__])
        found = ((adapter[self.imported], adapter.get("_IMPORT_ERROR")) if self.imported
                 else install.optional_import(self.module or self.distribution))
        hint = f"pip install 'rbcheck[{self.extra}]'" if self.extra else ""
        install.require(*found, self.distribution, hint=hint)

    def version(self) -> str:
        self.require_installed()
        return install.release(self.distribution, self.runs_on)

    @classmethod
    def exported(cls) -> tuple:
        """``(engine, version, simulate, simulate_many, one_step)``: an instance and its methods, what an
        adapter module exports as its functions (tests and scripts call them)."""
        engine = cls()
        return engine, engine.version, engine.simulate, engine.simulate_many, engine.one_step

    def simulate(self, scenario, variant: str, dt_s: float, n_steps: int):
        from cross_checks.engines import loop
        return base.one_request(lambda v, reqs: loop.run(self, v, reqs), scenario, variant, dt_s, n_steps)

    def simulate_many(self, variant: str, requests) -> list:
        from cross_checks.engines import loop
        return loop.run(self, variant, list(requests))

    def one_step(self, scenario, variant: str, dt_s: float, y_start) -> np.ndarray:
        from cross_checks.engines import loop
        return loop.one_step(self, scenario, variant, dt_s, y_start)

    def engine_files(self) -> list:
        """The engine's compiled libraries (hashed into the result cache's key)."""
        mod, _ = install.optional_import(self.module or self.distribution)
        return install.library_files(mod)

    def source_files(self) -> list:
        import importlib
        from pathlib import Path
        # a harness module may list its files itself (packed_rows: with its kernels', numba not imported)
        mods = [importlib.import_module(m) for m in self.harness]
        harness = [f for m in mods
                   for f in getattr(m, "source_files", lambda m=m: [Path(m.__file__ or "")])()]
        return [*super().source_files(), *harness, *self.engine_files()]
