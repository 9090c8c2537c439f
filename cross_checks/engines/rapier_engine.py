"""Rapier (``rapier3d``, dimforge's Python bindings, 3D, float32) as an engine adapter (``rapier:VARIANT``);
the interface is cross_checks.engines.base.

One ``PhysicsWorld`` per group of runs (same Δt and gravity), one dynamic ``RigidBody`` per run, no
collider; mass properties ``MassProperties(local_com = 0, mass, principal moments, principal frame R_BP)``,
so body origin = COM and the body frame is the scenario's; defaults neutralised (:data:`WORLD_SETTINGS`,
:data:`BODY_SETTINGS`, one thread per world). State at the boundary: ``translation`` and ``linvel`` the
COM's (world), ``angvel`` in WORLD axes, ``Rotation3`` built (w, x, y, z) but read (x, y, z, w); the recorded
states are float32 values, the quaternion sign-continuous from the scenario's. The step (rapier
src/dynamics/solver/staged_island_solver/worker.rs, one substep): semi-implicit Euler whose explicit
gyroscopic step is rescaled to keep |L| (``gyroscopic_corrected_angvel``), first order. Forces: the user
force (world, at the COM) and torque (world) ACCUMULATE until reset: the harness's force minus the weight
``m g`` and torque, replaced before every step when state-dependent; the decay before the step
(base.apply_decay_prestep). Divergence: a bad state (non-finite, beyond BLOWUP_LIMIT) or a body Rapier
quarantined ends that run. Nothing is compiled at run time (:func:`timings`).
Conventions, defaults neutralised and what pins them: docs/engine_conventions.md, "Rapier 0.36.1".
"""
from __future__ import annotations

import math
import time

import numpy as np

from cross_checks.engines import base
from cross_checks.engines.base import EngineError, ModuleAdapter, Traits, Variant
from cross_checks.engines.step_floats import bad_floats, harness_fn
from reference_sim.quaternion import quat_from_matrix, same_side, sign_continuous
from reference_sim.simulate import Run, blowup_words, diverged

rapier, _IMPORT_ERROR = base.optional_import("rapier3d")

__all__ = ["ENGINE", "DIST", "VARIANTS", "WORLD_SETTINGS", "BODY_SETTINGS", "EngineError", "version",
           "simulate", "simulate_many", "one_step", "RapierWorld", "timings", "reset_timings",
           "compile_stats",
           "RapierAdapter"]

ENGINE = "rapier"
DIST = "rapier3d"

#: Rapier's rotation step: |L| kept exactly, the energy drifting towards the separatrix (either sign).
_GYRO_TRAITS = Traits(gyroscopic_term=True, translation_drift=0, rotation_drift="momentum",
                      rotation_sign=None, precision="float32")
#: Without gyroscopic forces ω_W changes only by the torque: ω constant without one.
_NO_GYRO_TRAITS = Traits(gyroscopic_term=False, translation_drift=0, rotation_drift="none", rotation_sign=0,
                         precision="float32")

#: Rapier's one integrator (symplectic Euler: rigid_body_components.rs, ``integrate_forces_and_velocities``),
#: with its gyroscopic forces on (Rapier's default, first) and off.
VARIANTS = {
    "symplectic_euler": Variant(1, "Rapier's step (gyroscopic forces on, its default): semi-implicit Euler "
                                   "in float32, explicit gyroscopic step in the principal frame rescaled to "
                                   "keep |L|, linearised normalised quaternion update with the new ω",
                                traits=_GYRO_TRAITS),
    "symplectic_euler_no_gyro": Variant(1, "Rapier's step with gyroscopic_forces(False): semi-implicit Euler "
                                           "in float32 without the gyroscopic term (ω_W changes only by the "
                                           "torque)",
                                        traits=_NO_GYRO_TRAITS),
}

#: IntegrationParameters set on every world: (attribute, value). Rapier 0.36.1's defaults are 4, 400, 1, 1.0.
WORLD_SETTINGS = (
    ("num_solver_iterations", 1),                         # substeps per step (default 4)
    ("normalized_max_linear_velocity", math.inf),         # linear speed cap (default 400 m/s)
    ("max_ccd_substeps", 0),                              # continuous collision detection (default 1)
    ("length_unit", 1.0),                                 # scales the speed cap and the contact tolerances
)
#: RigidBodyBuilder settings every body gets (builder method, value); the gyroscopic flag is the variant's.
BODY_SETTINGS = (
    ("can_sleep", False),                  # default True: asleep after 0.5 s below 0.05 m/s and 0.05 rad/s
    ("allow_fast_rotation", True),         # default False: |ω| capped at (π/4)/Δt
    ("linear_damping", 0.0),
    ("angular_damping", 0.0),
    ("gravity_scale", 1.0),
    ("ccd_enabled", False),
    ("additional_solver_iterations", 0),   # extra substeps for this body's island
)

_STATS = {"builds": 0, "build_seconds": 0.0, "step_seconds": 0.0, "steps": 0, "body_steps": 0}


def timings() -> dict:
    """This process's world builds and stepping, apart: ``builds``, ``build_seconds`` (worlds and bodies
    created and set up), ``steps`` (``PhysicsWorld.step`` calls), ``step_seconds`` (wall s inside them),
    ``body_steps`` (steps × bodies they advanced). Rapier compiles nothing at run time (``compile_seconds``
    is always 0, kept for comparison with the JIT engines)."""
    return {**_STATS, "compile_seconds": 0.0}


def reset_timings() -> None:
    _STATS.update(builds=0, build_seconds=0.0, step_seconds=0.0, steps=0, body_steps=0)


def compile_stats() -> dict:
    """:func:`timings` under the name the JIT engines' adapters use (mjx_engine.compile_stats): Rapier's
    ``compilations`` are always 0."""
    return {**timings(), "compilations": 0}


def _require():
    base.require(rapier, _IMPORT_ERROR, DIST, hint="pip install 'rbcheck[rapier]'")


def version() -> str:
    """The installed rapier3d distribution's version (EngineNotInstalled when it is absent)."""
    _require()
    return base.release(DIST)


def _mass_properties(body):
    """``rapier3d.MassProperties`` of an rbcheck RigidBody: COM at the origin, the principal moments and the
    rotation of the principal axes in body coordinates (identity for a diagonal tensor)."""
    I = np.asarray(body.inertia_B, dtype=float)
    if body.is_diagonal():
        moments, q_BP = np.diag(I).copy(), np.array([1.0, 0.0, 0.0, 0.0])
    else:
        moments, R_BP = body.principal_axes()
        q_BP = quat_from_matrix(R_BP)
    return rapier.MassProperties(local_com=(0.0, 0.0, 0.0), mass=float(body.mass_kg),
                                 principal_inertia=tuple(float(m) for m in moments),
                                 principal_inertia_local_frame=rapier.Rotation3(*(float(c) for c in q_BP)))


class RapierWorld:
    """A world stepping at ``dt_s`` under ``gravity_W`` with the neutral settings; bodies added with
    :meth:`add`, states set and read at the boundary in rbcheck's packed layout."""

    def __init__(self, dt_s: float, gravity_W, variant: str):
        _require()
        base.check_variant(ENGINE, VARIANTS, variant)
        t0 = time.perf_counter()
        self.world = w = rapier.PhysicsWorld(gravity=tuple(float(g) for g in gravity_W))
        w.set_num_threads(1)
        ip = w.integration_parameters        # a live view: modified in place
        ip.dt = float(dt_s)
        for attr, value in WORLD_SETTINGS:
            setattr(ip, attr, value)
        self.gyro = VARIANTS[variant].traits.gyroscopic_term
        self.dt_s = float(dt_s)
        self.handles: list = []
        _STATS["builds"] += 1
        _STATS["build_seconds"] += time.perf_counter() - t0

    def add(self, body, y) -> int:
        """Add a body (rbcheck RigidBody) at the packed state ``y`` (13,); its index."""
        t0 = time.perf_counter()
        b = rapier.RigidBody.dynamic().additional_mass_properties(_mass_properties(body))
        for method, value in BODY_SETTINGS:
            b = getattr(b, method)(value)
        b = b.gyroscopic_forces(self.gyro)
        h = self.world.add_body(b)
        self.handles.append(h)
        self.set_state(len(self.handles) - 1, y)
        _STATS["build_seconds"] += time.perf_counter() - t0
        return len(self.handles) - 1

    def body(self, i: int):
        return self.world.rigid_bodies[self.handles[i]]

    def set_state(self, i: int, y) -> None:
        """Put body ``i`` at the packed state ``y`` (13,) (rounded to float32 by Rapier)."""
        y = [float(v) for v in y]
        rb = self.body(i)
        rb.position = rapier.Isometry3((y[0], y[1], y[2]), rapier.Rotation3(y[6], y[7], y[8], y[9]))
        rb.linvel = (y[3], y[4], y[5])
        rb.angvel = (y[10], y[11], y[12])

    def set_velocities(self, i: int, v, w) -> None:
        rb = self.body(i)
        rb.linvel = tuple(v)
        rb.angvel = tuple(w)

    def read(self, i: int) -> list:
        """Body ``i``'s state as 13 floats ``[x_W, v_W, q (w x y z), ω_W]`` (float32 values)."""
        rb = self.body(i)
        qx, qy, qz, qw = rb.rotation.to_tuple()
        return [*rb.translation.to_tuple(), *rb.linvel.to_tuple(), qw, qx, qy, qz, *rb.angvel.to_tuple()]

    def enabled(self, i: int) -> bool:
        return self.body(i).is_enabled

    def apply(self, i: int, f_W, tau_W) -> None:
        """Replace body ``i``'s user force (world, at the COM, N) and torque (world, N m): Rapier keeps them
        for every later step until replaced."""
        rb = self.body(i)
        rb.reset_forces(False)
        rb.reset_torques(False)
        rb.add_force(tuple(f_W), False)
        rb.add_torque(tuple(tau_W), False)

    def step(self) -> None:
        t0 = time.perf_counter()
        self.world.step()
        _STATS["step_seconds"] += time.perf_counter() - t0
        _STATS["steps"] += 1
        _STATS["body_steps"] += len(self.handles)

    def quarantined(self) -> set:
        """Indices of the bodies Rapier quarantined in the last step (non-finite state)."""
        bad = set(self.world.quarantine.bodies)
        return {i for i, h in enumerate(self.handles) if h in bad} if bad else set()


def _recorded(rows, y0, dt_s: float, why: str = "") -> Run:
    """The Run of packed states ``rows`` (steps 1..n) after the initial state ``y0``, quaternions continuous
    from y0's; ``why`` non-empty: the run diverged in step n + 1."""
    y = np.empty((len(rows) + 1, 13))
    y[0] = y0
    if rows:
        y[1:] = np.array(rows)
        y[1:, 6:10] = sign_continuous(y[1:, 6:10], first=y0[6:10])
    if why:
        return diverged(y, dt_s, why)
    return Run(dt_s * np.arange(len(y)), y)


def _group_key(r) -> tuple:
    return (float(r.dt_s), tuple(float(g) for g in r.scenario.problem.forces.gravity_W))


def _run_group(variant: str, reqs) -> list:
    """The Runs of ``reqs`` (one Δt, one gravity) as bodies of one world, stepped together to the longest."""
    dt_s, gravity = _group_key(reqs[0])
    W = RapierWorld(dt_s, gravity, variant)
    members = []
    for r in reqs:
        y0 = r.scenario.problem.initial_packed()
        i = W.add(r.scenario.problem.body, y0)
        forces = r.scenario.problem.forces
        harness = harness_fn(r.scenario, dt_s)
        gv, gw = (float(g) for g in base.decay_factors(r.scenario, dt_s))
        wx, wy, wz = base.weight_W(r.scenario).tolist()
        fx, fy, fz, tx, ty, tz = harness([float(v) for v in y0])
        f, tau = (fx - wx, fy - wy, fz - wz), (tx, ty, tz)
        W.apply(i, f, tau)
        members.append({"i": i, "y0": y0, "n": int(r.n_steps), "rows": [], "why": "", "prev": y0.tolist(),
                        "harness": harness, "weight": (wx, wy, wz), "state": bool(forces.state_dependent),
                        "decay": bool(forces.has_decay), "g": (gv, gw), "live": int(r.n_steps) > 0})
    k = 0
    while any(m["live"] for m in members):
        k += 1
        for m in members:
            if not m["live"]:
                continue
            prev = m["prev"]
            if m["state"] and k > 1:
                fx, fy, fz, tx, ty, tz = m["harness"](prev)
                wx, wy, wz = m["weight"]
                W.apply(m["i"], (fx - wx, fy - wy, fz - wz), (tx, ty, tz))
            if m["decay"]:
                gv, gw = m["g"]
                W.set_velocities(m["i"], (gv * prev[3], gv * prev[4], gv * prev[5]),
                                 (gw * prev[10], gw * prev[11], gw * prev[12]))
        W.step()
        quarantined = W.quarantined()
        for m in members:
            if not m["live"]:
                continue
            row = W.read(m["i"])
            if m["i"] in quarantined or not W.enabled(m["i"]):
                m["why"] = " (non-finite state: Rapier quarantined the body)"
            elif bad_floats(row):
                m["why"] = f" ({blowup_words(row)})"
            if m["why"]:
                m["live"] = False
                W.body(m["i"]).is_enabled = False     # stepped no further
                continue
            m["rows"].append(row)
            m["prev"] = row
            if len(m["rows"]) >= m["n"]:
                m["live"] = False
                W.body(m["i"]).is_enabled = False     # done: stepped no further
    return [_recorded(m["rows"], m["y0"], dt_s, m["why"]) for m in members]


def simulate(scenario, variant: str, dt_s: float, n_steps: int) -> Run:
    """Free run of ``n_steps`` steps of ``dt_s`` from the scenario's initial state, every step recorded."""
    return base.one_request(simulate_many, scenario, variant, dt_s, n_steps)


def simulate_many(variant: str, requests) -> list:
    """The runs of ``requests`` (``base.RunRequest``), each a Run (or its EngineError): the requests of one Δt
    and one gravity run as bodies of one world (each body's run is its run alone, bit for bit)."""
    base.check_variant(ENGINE, VARIANTS, variant)
    _require()

    def run_group(reqs):
        try:
            return _run_group(variant, reqs)
        except (rapier.RapierError, RuntimeError) as exc:   # the engine refused: its own words
            raise EngineError(f"Rapier {version()} failed: {type(exc).__name__}: {exc}") from exc

    return base.run_in_groups(requests, _group_key, run_group)


@base.on_rows
def one_step(scenario, variant: str, dt_s: float, y_start) -> np.ndarray:
    """One step of ``dt_s`` from each row of ``y_start`` (T, 13), all rows as bodies of one world stepped
    once: the forces from the row, the pre-step decay. A row Rapier quarantines comes back non-finite."""
    W = RapierWorld(dt_s, scenario.problem.forces.gravity_W, variant)
    y_dec = base.apply_decay_prestep(scenario, y_start, dt_s)
    harness = harness_fn(scenario, dt_s)
    wx, wy, wz = base.weight_W(scenario).tolist()
    body = scenario.problem.body
    for row, row_dec in zip(y_start.tolist(), y_dec):
        i = W.add(body, row_dec)
        fx, fy, fz, tx, ty, tz = harness(row)
        W.apply(i, (fx - wx, fy - wy, fz - wz), (tx, ty, tz))
    W.step()
    quarantined = W.quarantined()
    out = np.array([W.read(i) if i not in quarantined else [math.nan] * 13 for i in range(len(y_start))])
    out[:, 6:10] = same_side(out[:, 6:10], y_start[:, 6:10])
    return out


class RapierAdapter(ModuleAdapter):
    """``rapier:VARIANT`` — registered under the entry-point group ``rbcheck.engines``; optional
    (``pip install 'rbcheck[rapier]'``)."""

    def engine_files(self) -> list:
        """rapier3d's compiled module (a rebuilt or reinstalled wheel is a new engine)."""
        return [] if rapier is None else base.library_files(getattr(rapier, "_rapier3d", None))
