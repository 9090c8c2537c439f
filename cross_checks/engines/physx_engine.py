"""NVIDIA PhysX 5 (CPU, through SAPIEN's ``sapien.physx``) as an engine adapter (``physx:VARIANT``, float32);
the interface is cross_checks.engines.base.

One ``sapien.Scene`` with one ``PhysxCpuSystem`` (PhysX 5.3.1 as SAPIEN 3.0.3 bundles it, on the calling
thread) per variant, float32 Δt and gravity; one ``PhysxRigidDynamicComponent`` per run, no collision shape,
the full tensor given as principal moments and mass frame R_BP (the actor frame stays the scenario's body
frame), neutralised (:data:`BODY_SETTINGS`). State at the boundary: the actor pose ``Pose(p, q (w x y z))``,
the COM's linear velocity, ω in WORLD axes; the whole scene read with one ``pack()`` per step
(:data:`PACK_TO_PACKED`), the recorded quaternion sign-continuous from the scenario's. The step (PhysX's
``BodySim::updateForces``, ``bodyCoreComputeUnconstrainedVelocity``, ``integrateCore``/``integrateCoreStep``):
semi-implicit Euler with an explicit gyroscopic step rescaled to keep |L| and an exponential-map attitude,
first order; TGS keeps ω in sqrt-inertia space. Forces: before every step (PhysX clears them) the
harness's world force at the COM minus the weight ``m g`` and world torque, from the start-of-step state;
the decay before the step (base.apply_decay_prestep). :func:`simulate_many` steps the runs of one scene
together; nothing is compiled (:func:`compile_stats`). Divergence: the first non-finite or > BLOWUP_LIMIT
state ends that run, its body parked at rest so that PhysX never steps a NaN.
Conventions, defaults neutralised and what pins them: docs/engine_conventions.md,
"PhysX 5.3.1 (SAPIEN 3.0.3)".
"""
from __future__ import annotations

import dataclasses
import functools
import threading
import time
import warnings
from pathlib import Path

import numpy as np

from cross_checks.engines import base
from cross_checks.engines.base import EngineError, ModuleAdapter, Traits, Variant, installed_version
from cross_checks.engines.step_floats import harness_fn
from reference_sim.quaternion import same_side, sign_continuous
from reference_sim.simulate import BLOWUP_LIMIT, Run, blowup_words, diverged

__all__ = ["ENGINE", "VARIANTS", "BODY_SETTINGS", "PACK_TO_PACKED", "EngineError", "version", "simulate",
           "simulate_many", "one_step", "PhysxScene", "compile_stats", "reset_stats",
           "PhysxAdapter"]

ENGINE = "physx"
_DIST = "sapien"
_HINT = "pip install 'rbcheck[physx]'"

#: PhysX's rigid-body step: the renormalisation keeps |L| exactly while the rotational energy drifts at first
#: order, either sign (docs/verdicts.md §3).
_TRAITS = Traits(gyroscopic_term=True, translation_drift=0, rotation_drift="momentum", rotation_sign=None,
                 precision="float32")
#: TGS keeps ω in √I space and converts it back with two float32 3×3 products every step: four ordinary
#: steps' rounding (docs/verdicts.md, ``rounding_factor``).
_TGS_TRAITS = dataclasses.replace(_TRAITS, rounding_factor=4.0)
VARIANTS = {
    # sapien's default solver (PhysxSceneConfig.enable_tgs = True)
    "tgs": Variant(1, "PhysX 5 TGS (SAPIEN's default): semi-implicit Euler, explicit gyroscopic term "
                      "renormalised to |L|, exponential-map attitude; float32; ω kept in sqrt-inertia space",
                   traits=_TGS_TRAITS),
    "pgs": Variant(1, "PhysX 5 PGS: semi-implicit Euler, explicit gyroscopic term renormalised to |L|, "
                      "exponential-map attitude; float32",
                   traits=_TRAITS),
}

#: Rigid-dynamic settings every body gets, each set explicitly: (sapien setter, value).
BODY_SETTINGS = (
    ("set_linear_damping", 0.0),
    ("set_angular_damping", 0.0),
    ("set_max_linear_velocity", 1e16),      # |v|² must stay finite in float32 (PhysX stores the square)
    ("set_max_angular_velocity", 1e16),
    ("set_max_depenetration_velocity", 1e16),
    ("set_max_contact_impulse", 1e16),
    ("set_sleep_threshold", 0.0),           # DySleep.cpp: a zero threshold resets the wake counter every step
    ("set_solver_position_iterations", 1),
    ("set_solver_velocity_iterations", 1),
    ("set_disable_gravity", False),
    ("set_kinematic", False),
)

#: Columns of one body's ``pack()`` row ``[q (w x y z), p, v, ω]`` in rbcheck's packed order [x, v, q, ω].
PACK_TO_PACKED = np.array([4, 5, 6, 7, 8, 9, 0, 1, 2, 3, 10, 11, 12])

#: Where a body whose run diverged is parked (at rest at the origin), so that PhysX never steps a NaN.
_REST = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])

_LOCK = threading.RLock()
_STATS = {"scenes": 0, "bodies": 0, "build_seconds": 0.0, "step_seconds": 0.0, "body_steps": 0}


def compile_stats() -> dict:
    """This process's PhysX work so far: ``compilations`` (always 0: PhysX's CPU pipeline compiles nothing),
    ``compile_seconds`` (0.0), ``scenes`` and ``bodies`` built and ``build_seconds`` (wall s making them, the
    cost before a first step), ``step_seconds`` (wall s inside the step loops, force evaluation and state
    reads included) and ``body_steps`` (steps × bodies advanced)."""
    return {"compilations": 0, "compile_seconds": 0.0, **_STATS}


def reset_stats() -> None:
    """Zero :func:`compile_stats`."""
    _STATS.update(scenes=0, bodies=0, build_seconds=0.0, step_seconds=0.0, body_steps=0)


# --- the engine, imported on first use ----------------------------------------------------------------------

def _check_installed() -> None:
    """EngineNotInstalled when sapien is not installed; ImportError when it is but cannot be found."""
    import importlib.util
    if installed_version(_DIST) is None:
        raise base.EngineNotInstalled(f"sapien is not installed ({_HINT})")
    if importlib.util.find_spec("sapien") is None:
        raise ImportError(f"sapien {installed_version(_DIST)} is installed but cannot be imported: "
                          "no module named 'sapien'")


def version() -> str:
    """SAPIEN's version and the PhysX release it bundles, e.g. ``3.0.3 (PhysX 5.3.1)``, from package
    metadata and the PhysX header SAPIEN ships (EngineNotInstalled when sapien is absent). Nothing is
    imported: importing sapien starts a thread, and the sweep's parent forks its workers."""
    _check_installed()
    return _dist_version()


@functools.lru_cache(maxsize=1)
def _dist_version() -> str:
    return f"{installed_version(_DIST)} (PhysX {_physx_release()})"


def _physx_release() -> str:
    """PhysX's MAJOR.MINOR.BUGFIX from ``sapien/include/physx/include/foundation/PxPhysicsVersion.h`` (found
    by import spec, not imported); "unknown" when the header is not there."""
    import importlib.util
    import re
    spec = importlib.util.find_spec("sapien")
    if spec is None or not spec.origin:
        return "unknown"
    header = Path(spec.origin).parent / "include" / "physx" / "include" / "foundation" / "PxPhysicsVersion.h"
    try:
        text = header.read_text(errors="replace")
    except OSError:
        return "unknown"
    parts = [re.search(rf"#define PX_PHYSICS_VERSION_{k}\s+(\d+)", text)
             for k in ("MAJOR", "MINOR", "BUGFIX")]
    return ".".join(m.group(1) for m in parts) if all(parts) else "unknown"


@functools.lru_cache(maxsize=1)
def _engine():
    """``(sapien, sapien.physx)``, imported once; the "Failed to find system libvulkan" warning SAPIEN gives
    at import (harmless: no rendering here) silenced. ImportError with SAPIEN's words when it fails."""
    _check_installed()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            import sapien
            import sapien.physx as px
    except Exception as exc:  # noqa: BLE001 - a broken install: the engine's own words
        raise ImportError(f"sapien {installed_version(_DIST)} is installed but cannot be imported: "
                          f"{type(exc).__name__}: {exc}") from exc
    return sapien, px


def _engine_or_error():
    try:
        return _engine()
    except ImportError as exc:
        raise EngineError(str(exc)) from None


def _f32(v) -> np.ndarray:
    return np.asarray(v, dtype=np.float32)


# --- a scene of free bodies -------------------------------------------------------------------------------

class PhysxScene:
    """One SAPIEN scene of ``variant``'s solver at ``dt_s`` with gravity ``gravity_W`` and no other entity
    than the bodies :meth:`add` puts in it (none collides: no shape)."""

    def __init__(self, variant: str, dt_s: float, gravity_W):
        base.check_variant(ENGINE, VARIANTS, variant)
        sapien, px = _engine_or_error()
        t0 = time.perf_counter()
        cfg = px.PhysxSceneConfig()
        cfg.gravity = _f32(gravity_W)
        cfg.enable_tgs = variant == "tgs"
        with _LOCK:   # the scene config is SAPIEN's process-global default, read when the system is made
            before = px.get_scene_config()
            px.set_scene_config(cfg)
            try:
                self.system = px.PhysxCpuSystem()
            finally:      # SAPIEN's default left as it was for any other user of sapien in the process
                px.set_scene_config(before)
        self.scene = sapien.Scene(systems=[self.system])
        self.system.set_timestep(float(dt_s))
        self.bodies: list = []
        self.entities: list = []
        _STATS["scenes"] += 1
        _STATS["build_seconds"] += time.perf_counter() - t0

    def add(self, body, y) -> object:
        """A rigid dynamic of ``body`` (reference_sim RigidBody) at the packed state ``y`` (13,), neutralised
        (BODY_SETTINGS); returns its component."""
        from reference_sim.quaternion import quat_from_matrix
        sapien, px = _engine()
        t0 = time.perf_counter()
        moments, R_BP = body.principal_axes()
        entity = sapien.Entity()
        c = px.PhysxRigidDynamicComponent()
        entity.add_component(c)
        try:
            c.set_mass(float(body.mass_kg))
            c.set_inertia(_f32(moments))
            c.set_cmass_local_pose(sapien.Pose(_f32([0.0, 0.0, 0.0]), _f32(quat_from_matrix(R_BP))))
        except Exception as exc:  # noqa: BLE001 - PhysX/SAPIEN refuses the mass properties: its words
            raise EngineError(f"PhysX (sapien {installed_version(_DIST)}) refuses the body: "
                              f"{type(exc).__name__}: {exc}") from None
        neutralise(c)
        self.scene.add_entity(entity)
        self.set_state(c, y)
        self.bodies.append(c)
        self.entities.append(entity)
        _STATS["bodies"] += 1
        _STATS["build_seconds"] += time.perf_counter() - t0
        return c

    def set_state(self, c, y) -> None:
        """Put body ``c`` at the packed state ``y`` (13,): actor pose, COM velocity, world ω."""
        y = np.asarray(y, dtype=float)
        c.set_entity_pose(_engine()[0].Pose(_f32(y[0:3]), _f32(y[6:10])))
        c.set_linear_velocity(_f32(y[3:6]))
        c.set_angular_velocity(_f32(y[10:13]))

    def read(self) -> np.ndarray:
        """Every body's ``pack()`` row ``[q (w x y z), p, v, ω]`` (B, 13) float32 (a copy)."""
        return np.frombuffer(self.system.pack(), dtype=np.float32).reshape(-1, 13).copy()

    def step(self) -> None:
        self.system.step()


def neutralise(c) -> None:
    """Every setting of BODY_SETTINGS on the rigid dynamic ``c``, whatever it was."""
    for setter, value in BODY_SETTINGS:
        getattr(c, setter)(value)


def _packed_row(r) -> list:
    """A ``pack()`` row (13 floats) -> the packed state as 13 Python floats (for the force model)."""
    return r[4:10] + r[0:4] + r[10:13]


def _group_key(variant, r: base.RunRequest):
    g = _f32(r.scenario.problem.forces.gravity_W)
    return (variant, float(np.float32(r.dt_s)), g.tobytes())


# --- adapter entry points ----------------------------------------------------------------------------------

def simulate(scenario, variant: str, dt_s: float, n_steps: int) -> Run:
    """Free run of ``n_steps`` steps of ``dt_s`` from the scenario's initial state, every step recorded (one
    request of :func:`simulate_many`)."""
    return base.one_request(simulate_many, scenario, variant, dt_s, n_steps)


def simulate_many(variant: str, requests) -> list:
    """The runs of ``requests`` (``base.RunRequest``), each a Run (or its EngineError): requests of the same
    float32 Δt and gravity share one scene, stepped together."""
    base.check_variant(ENGINE, VARIANTS, variant)
    try:
        _engine_or_error()
    except EngineError as exc:
        return [exc] * len(requests)
    return base.run_in_groups(requests, lambda r: _group_key(variant, r),
                              lambda reqs: _run_group(variant, reqs))


def _plan(r, y0, comp) -> tuple:
    """What body ``comp`` of request ``r`` (initial state ``y0``) needs before each step: ``(comp, harness or
    None (state-dependent forces), weight floats N, constant (force, torque) float32 or None, decay factors
    (γ_v, γ_ω) or None)``."""
    fm = r.scenario.problem.forces
    harness = harness_fn(r.scenario, r.dt_s)
    w = [float(c) for c in base.weight_W(r.scenario)]
    const = None
    if not fm.state_dependent:
        fx, fy, fz, tx, ty, tz = harness([float(v) for v in y0])
        f, tau = _f32([fx - w[0], fy - w[1], fz - w[2]]), _f32([tx, ty, tz])
        const = (f, tau) if (np.any(f != 0.0) or np.any(tau != 0.0)) else None
    decay = tuple(float(g) for g in base.decay_factors(r.scenario, r.dt_s)) if fm.has_decay else None
    return comp, harness if fm.state_dependent else None, w, const, decay


def _pre_step(busy, prev, i: int, y0, ends, alive) -> None:
    """Before step ``i``: each busy body's force and torque from its state ``prev[k]`` (packed float32 rows)
    and its decay, for the bodies still running."""
    for k, c, harness, w, const, decay in busy:
        if i >= ends[k] or not alive[k]:
            continue
        if harness is not None:
            fx, fy, fz, tx, ty, tz = harness(y0[k].tolist() if i == 0 else _packed_row(prev[k].tolist()))
            c.add_force_torque(_f32([fx - w[0], fy - w[1], fz - w[2]]), _f32([tx, ty, tz]))
        elif const is not None:
            c.add_force_torque(*const)
        if decay is not None:
            gv, gw = decay
            c.set_linear_velocity(prev[k, 7:10] * np.float32(gv))
            c.set_angular_velocity(prev[k, 10:13] * np.float32(gw))


def _retire_blown(S, comps, cur, i: int, ends, alive, bad_at) -> None:
    """The bodies whose state ``cur`` after step ``i`` is beyond BLOWUP_LIMIT or non-finite: their
    divergence recorded (``bad_at[k] = i + 1`` when within their run), set at rest so that the others go on;
    ``cur`` re-read."""
    with np.errstate(invalid="ignore"):
        ok = np.abs(cur).max(axis=1) <= BLOWUP_LIMIT
    for k in np.flatnonzero(~ok):
        if alive[k]:
            if i < ends[k]:
                bad_at[k] = i + 1
            alive[k] = False
            S.set_state(comps[k], _REST)
    cur[:] = np.frombuffer(S.system.pack(), dtype=np.float32).reshape(len(comps), 13)


def _runs(reqs, raw, y0, bad_at) -> list:
    """The Run of each request from its recorded float32 rows ``raw[k]`` (PhysX's packing)."""
    runs = []
    for k, r in enumerate(reqs):
        n = r.n_steps if bad_at[k] is None else bad_at[k]
        y = np.empty((n + 1, 13))
        y[0] = y0[k]
        y[1:] = raw[k, 1:n + 1][:, PACK_TO_PACKED]
        y[1:, 6:10] = sign_continuous(y[1:, 6:10], first=y0[k][6:10])
        runs.append(Run(r.dt_s * np.arange(n + 1), y) if bad_at[k] is None
                    else diverged(y[:n].copy(), r.dt_s, f" ({blowup_words(y[n])})"))
    return runs


def _run_group(variant: str, reqs) -> list:
    """The Runs of ``reqs`` (one Δt, one gravity) in one scene: the bodies stepped together, each visited
    before a step only when it has a force, a torque or a decay; a body that blows up is set at rest."""
    r0 = reqs[0]
    S = PhysxScene(variant, r0.dt_s, r0.scenario.problem.forces.gravity_W)
    B = len(reqs)
    y0 = [r.scenario.problem.initial_packed() for r in reqs]
    comps = [S.add(r.scenario.problem.body, y0[k]) for k, r in enumerate(reqs)]
    ends = [r.n_steps for r in reqs]
    raw = np.empty((B, max(ends) + 1, 13), dtype=np.float32)
    raw[:, 0] = S.read()
    plans = [_plan(r, y0[k], comps[k]) for k, r in enumerate(reqs)]
    busy = [(k, *p) for k, p in enumerate(plans) if p[1] is not None or p[3] is not None or p[4] is not None]
    alive, bad_at = [True] * B, [None] * B
    last = max(ends)                      # the longest run still going
    step, pack = S.system.step, S.system.pack
    t0 = time.perf_counter()
    i = 0
    while i < last:
        _pre_step(busy, raw[:, i], i, y0, ends, alive)
        step()
        cur = raw[:, i + 1]
        cur[:] = np.frombuffer(pack(), dtype=np.float32).reshape(B, 13)
        with np.errstate(invalid="ignore"):
            fine = np.abs(cur).max() <= BLOWUP_LIMIT
        if not fine:
            _retire_blown(S, comps, cur, i, ends, alive, bad_at)
            last = max([ends[k] for k in range(B) if alive[k]], default=0)
        i += 1
    _STATS["step_seconds"] += time.perf_counter() - t0
    _STATS["body_steps"] += i * B
    return _runs(reqs, raw, y0, bad_at)


@base.on_rows
def one_step(scenario, variant: str, dt_s: float, y_start) -> np.ndarray:
    """One step of ``dt_s`` from each row of ``y_start`` (T, 13), all rows as bodies of one scene: the forces
    from the row, the pre-step decay. Rows the engine blows up come back as PhysX left them."""
    S = PhysxScene(variant, dt_s, scenario.problem.forces.gravity_W)
    with np.errstate(all="ignore"):
        y_dec = base.apply_decay_prestep(scenario, y_start, dt_s)
    harness = harness_fn(scenario, dt_s)
    w = base.weight_W(scenario)
    body = scenario.problem.body
    for i, y in enumerate(y_start.tolist()):
        c = S.add(body, y_dec[i])
        fx, fy, fz, tx, ty, tz = harness(y)
        c.add_force_torque(_f32([fx - w[0], fy - w[1], fz - w[2]]), _f32([tx, ty, tz]))
    t0 = time.perf_counter()
    S.step()
    _STATS["step_seconds"] += time.perf_counter() - t0
    _STATS["body_steps"] += len(y_start)
    out = S.read()[:, PACK_TO_PACKED].astype(float)
    out[:, 6:10] = same_side(out[:, 6:10], y_start[:, 6:10])
    return out


class PhysxAdapter(ModuleAdapter):
    """``physx:VARIANT`` — registered under the entry-point group ``rbcheck.engines``; optional
    (``pip install 'rbcheck[physx]'``)."""

    def engine_files(self) -> list:
        """SAPIEN's compiled module and bundled library (PhysX is linked into them)."""
        return [*base.package_files("sapien", pattern="pysapien*.so"),
                *base.package_files("sapien", "../sapien.libs", pattern="libsapien*")]
