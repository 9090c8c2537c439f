"""Genesis (``genesis-world``) as an engine (``genesis:VARIANT``, CPU, float64): a world of bodies for
rbcheck's loop (cross_checks.engines.world, cross_checks.engines.loop).

:class:`GenesisBody`, the world: one MJCF body (:func:`mjcf_text`: a free joint, ``pos = 0`` so body origin =
COM, ``fullinertia`` the scenario's tensor in BODY axes) loaded with ``align=False`` and neutralised
(:data:`NEUTRAL_DOFS`, :func:`scene_options`), the runs that share a body, gravity, Δt and step count as the
environments of one scene, built once per process and reused (:func:`body`). State at the boundary: ``qpos =
[x_W, q_WB (w x y z)]``, DOF velocity ``[v_W, ω_B]`` (ω in BODY axes). Step (rigid/abd/forward_dynamics.py):
``euler`` is MuJoCo Euler's scheme; the implicit variants turn a lone free body by the implicit midpoint rule
and move it by semi-implicit Euler. The loop's forces (the weight off: Genesis applies gravity) before every
step. Importing this module or :func:`version` imports no Genesis; a process's first run initialises it
(:func:`genesis`) and compiles or loads its kernels (:func:`kernel_cache_dir`, :data:`BUILD_SECONDS`).
Conventions, defaults neutralised and what pins them: docs/engine_conventions.md, "Genesis 1.4.5".
"""
from __future__ import annotations

import contextlib
import functools
import importlib.util
import os
import sys
import tempfile
import time
from collections import OrderedDict
from pathlib import Path

import numpy as np

from cross_checks.core import files
from cross_checks.engines import base, install
from cross_checks.engines.base import EngineError, Traits, Variant
from cross_checks.engines.world import World, WorldEngine
from reference_sim.quaternion import quat_conj, rotate

__all__ = ["ENGINE", "DIST", "VARIANTS", "NEUTRAL_DOFS", "EngineError", "version", "genesis", "body",
           "kernel_cache_dir", "mjcf_text", "scene_options", "GenesisBody", "simulate", "simulate_many",
           "one_step", "to_qpos_vel", "to_packed", "BUILD_SECONDS", "GenesisAdapter"]

ENGINE, DIST = "genesis", "genesis-world"

#: The implicit variants on a lone free body: the rotation by the implicit midpoint rule (keeps the kinetic
#: energy and |L|² of torque-free tumbling), the translation by semi-implicit Euler.
_MIDPOINT_ROTATION = Traits(translation_drift=0, rotation_drift="none", rotation_sign=0)

#: The variants, named after ``gs.integrator``, Genesis's default first; all first order in the translation.
VARIANTS = {
    "approximate_implicitfast": Variant(
        1, "Genesis approximate_implicitfast (its default): on a lone free body implicitfast's midpoint "
           "rotation and semi-implicit Euler translation", traits=_MIDPOINT_ROTATION),
    "euler": Variant(1, "Genesis Euler: semi-implicit Euler, explicit gyroscopic term, quaternion by the "
                        "exponential map (MuJoCo Euler's scheme)",
                     traits=base.SYMPLECTIC_EULER_EXPLICIT_GYRO),
    "implicitfast": Variant(1, "Genesis implicitfast: on a lone free body the rotation by the implicit "
                               "midpoint rule (2nd order, energy-keeping), the translation by semi-implicit "
                               "Euler", traits=_MIDPOINT_ROTATION),
}

#: DOF settings of the free joint, each asserted after the build (Genesis getter suffix, neutral value).
NEUTRAL_DOFS = (("armature", 0.0), ("damping", 0.0), ("stiffness", 0.0), ("frictionloss", 0.0))
#: Every scene build of this process: ``(variant, n_envs, wall s)``, the first with the kernels' compilation.
BUILD_SECONDS: list = []
_SCENES_KEPT = 4   # scenes kept per process (the most recently used; each holds its kernels' data, ~MBs)
_SCENES: OrderedDict = OrderedDict()
_STATE: dict = {"gs": None, "pid": None}


def version() -> str:
    """genesis-world's version from its metadata, its packages (genesis, torch, quadrants) found without
    importing them: EngineNotInstalled when it is absent, ImportError when a package is missing."""
    ver = install.installed_version(DIST)
    if ver is None:
        raise install.EngineNotInstalled(f"{DIST} is not installed (pip install 'rbcheck[genesis]')")
    missing = ", ".join(repr(m) for m in ("genesis", "torch", "quadrants") if not _findable(m))
    if missing:
        raise ImportError(f"{DIST} {ver} is installed but cannot be imported: no module named {missing}")
    return ver


def _findable(name: str) -> bool:
    with contextlib.suppress(ImportError, ValueError):
        return importlib.util.find_spec(name) is not None
    return False


def kernel_cache_dir() -> Path:
    """Where Quadrants keeps Genesis's kernels and Genesis its assets (unless ``QD_OFFLINE_CACHE_FILE_PATH`` /
    ``GS_CACHE_FILE_PATH`` are set): not under ``$RBCHECK_CACHE_DIR`` (a fresh one must not recompile)."""
    return files.kernel_cache_dir("genesis")


def genesis():
    """The ``genesis`` module, initialised once per process (``gs.init`` is process-global) on the CPU in
    float64 with zero-copy arrays; one initialised by someone else is taken only so, one initialised before a
    fork is refused (its kernel runtime and torch threads do not survive a fork)."""
    gs = _STATE["gs"]
    if gs is not None:
        if _STATE["pid"] != os.getpid():
            raise EngineError(f"Genesis was initialised in process {_STATE['pid']} before this process was "
                              "forked from it; initialise it only in the worker processes")
        return gs
    ver, cache = version(), kernel_cache_dir()
    os.environ.setdefault("QD_OFFLINE_CACHE_FILE_PATH", str(cache / "kernels"))
    os.environ.setdefault("GS_CACHE_FILE_PATH", str(cache / "assets"))
    try:
        import genesis as gs
    except Exception as exc:  # noqa: BLE001 - a broken install is the engine's failure, with its words
        raise EngineError(f"{DIST} {ver} cannot be imported: {type(exc).__name__}: {exc}") from exc
    try:
        with _quiet_stderr():
            gs.init(backend=gs.cpu, precision="64", logging_level="warning")
    except Exception as exc:  # noqa: BLE001 - a second gs.init is refused: the check below judges the first
        if not (isinstance(exc, gs.GenesisException) and "already initialized" in str(exc)):
            raise EngineError(f"Genesis {ver}: gs.init(backend=gs.cpu, precision='64') failed: {exc}") \
                from exc
    if gs.backend != gs.cpu or gs.np_float is not np.float64 or not gs.use_zerocopy:
        raise EngineError(f"Genesis {ver} was initialised in this process with backend {gs.backend}, "
                          f"{np.dtype(gs.np_float).name} and zero-copy {gs.use_zerocopy}; rbcheck needs "
                          "gs.init(backend=gs.cpu, precision='64') and zero-copy (GS_ENABLE_ZEROCOPY not 0)")
    _STATE["gs"], _STATE["pid"] = gs, os.getpid()
    return gs


@contextlib.contextmanager
def _quiet_stderr():
    """Fd 2 into a temporary file while Genesis compiles (Quadrants prints "qd.loop_config(serialize=True)
    does not have effect ..." per kernel there); every other line written back to stderr afterwards."""
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError, AttributeError):
        yield
        return
    with tempfile.TemporaryFile(mode="w+b") as tmp:
        os.dup2(tmp.fileno(), 2)
        try:
            yield
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            tmp.seek(0)
            lines = tmp.read().decode(errors="replace").splitlines(keepends=True)
            sys.stderr.write("".join(ln for ln in lines if ln.strip() and "serialize=True" not in ln))


def mjcf_text(scenario, dt_s: float = 0.01) -> str:
    """The scenario's body as MJCF: a free joint, an inertial at the body origin (mass, kg; ``fullinertia`` =
    Ixx Iyy Izz Ixy Ixz Iyz, kg m², body axes), the compiler told to keep frame and inertia as given (no
    free-joint alignment, inertia from geoms, balancing, bounds); the joint's limit time constant (none acts)
    raised from MuJoCo's 0.02 s to 2Δt where Genesis would, with a warning, at Δt > 0.01 s."""
    b = scenario.problem.body
    J = np.asarray(b.inertia_B, dtype=float)
    full = " ".join(repr(float(v)) for v in (J[0, 0], J[1, 1], J[2, 2], J[0, 1], J[0, 2], J[1, 2]))
    timeconst = max(0.02, 2.0 * float(dt_s))   # s
    return ('<mujoco model="rbcheck"><compiler alignfree="false" inertiafromgeom="false" '
            'balanceinertia="false" boundmass="0" boundinertia="0"/>'
            f'<default><joint solreflimit="{timeconst!r} 1"/></default>'
            '<worldbody><body name="body"><joint type="free" name="free"/>'
            f'<inertial pos="0 0 0" mass="{float(b.mass_kg)!r}" fullinertia="{full}"/>'
            '</body></worldbody></mujoco>')


def scene_options(variant: str, dt_s: float, gravity_W):
    """``(SimOptions, RigidOptions)`` of a scene: the run's step and gravity, one substep, the variant's
    ``gs.integrator`` (``Euler`` for euler), collision, joint limits, constraints and hibernation off."""
    gs = genesis()
    sim = gs.options.SimOptions(dt=float(dt_s), substeps=1, gravity=tuple(float(g) for g in gravity_W))
    rigid = gs.options.RigidOptions(
        integrator=getattr(gs.integrator, "Euler" if variant == "euler" else variant), enable_collision=False,
        enable_joint_limit=False, use_hibernation=False, disable_constraint=True)
    return sim, rigid


class GenesisBody(World):
    """A scenario's free body in a scene of ``n_envs`` environments (0: unbatched) at ``dt_s``, a group's runs
    one per environment; raw rows ``[qpos (7), DOF velocity (6)]`` (n = max(n_envs, 1), 13). A step Genesis
    refuses (a NaN it detected) warns every environment with its words; then no step, the last state read."""

    exact_start = True         # the recorded t = 0 state is the scenario's (ω's round trip to body axes)
    first_cause_only = True    # a bad state found before Genesis refused a step: the run's only words

    def __init__(self, xml: str, variant: str, dt_s: float, gravity_W, n_envs: int = 0):
        super().__init__()
        gs = genesis()
        sim, rigid = scene_options(variant, dt_s, gravity_W)
        t0 = time.perf_counter()
        try:
            with _quiet_stderr():
                scene = gs.Scene(sim_options=sim, rigid_options=rigid, show_viewer=False)
                entity = scene.add_entity(gs.morphs.MJCF(file=xml, default_armature=0.0, align=False))
                scene.build(n_envs=int(n_envs))
                scene.step()  # compiles (or loads) the step's kernels here, so that builds are timed apart
        except Exception as exc:  # noqa: BLE001 - Genesis (or MuJoCo's compiler inside it) refused the model
            raise EngineError(f"Genesis {version()} rejected the model: {type(exc).__name__}: {exc}") from exc
        BUILD_SECONDS.append((variant, int(n_envs), time.perf_counter() - t0))
        self.gs, self.scene, self.entity, self.solver = gs, scene, entity, scene.sim.rigid_solver
        self.n_envs, self.n, self.dt_s = int(n_envs), max(int(n_envs), 1), float(dt_s)
        self.link = entity.base_link_idx
        # zero-copy NumPy views (qd_to_torch(..., copy=False), as Genesis's getters) of qpos (n, 7), the DOF
        # velocity (n, 6), the body's wrench accumulators cfrc_applied_vel/_ang and COM arm i_pos (n, 3)
        from genesis.utils.misc import qd_to_torch
        s, links = self.solver, self.solver.dyn_state.links
        self._qpos = qd_to_torch(s.qpos, transpose=True, copy=False).numpy()
        self._vel = qd_to_torch(s.dyn_state.dofs.vel, transpose=True, copy=False).numpy()
        self._f_vel, self._f_ang, self._i_pos = (qd_to_torch(a, copy=False).numpy()[self.link] for a in (
            links.cfrc_applied_vel, links.cfrc_applied_ang, links.i_pos))
        for name, value in NEUTRAL_DOFS:
            if not np.all((got := getattr(entity, f"get_dofs_{name}")().numpy()) == value):
                raise EngineError(f"Genesis {version()} left the free joint's {name} at {got.tolist()}, "
                                  f"not {value}")

    def set_state(self, y) -> None:
        """Every environment at packed state(s) ``y`` (n, 13) (or (13,)); steps and warnings start again."""
        qpos, vel = to_qpos_vel(np.broadcast_to(np.asarray(y, dtype=float), (self.n, 13)))
        if self.n_envs == 0:
            qpos, vel = qpos[0], vel[0]
        self.entity.set_qpos(qpos, zero_velocity=False)
        self.entity.set_dofs_velocity(vel)
        self.steps, self.failed, self.warnings, self.last = 0, False, [], None

    def read(self):
        """``[qpos, vel]`` (n, 13): ``get_qpos()``'s and ``get_dofs_velocity()``'s numbers (tested)."""
        if not self.failed or self.last is None:
            self.last = np.concatenate([self._qpos[:, 0:7], self._vel[:, 0:6]], axis=1)
        return self.last

    def packed(self, raw):
        raw = np.asarray(raw, dtype=float)
        return to_packed(raw[..., 0:7], raw[..., 7:13])

    def decay(self, g_v, g_w) -> None:
        """The DOF velocities last read, scaled, without a forward pass (the same step, tested)."""
        vel = self.last[:, 7:13] * np.repeat(np.stack([g_v, g_w], axis=1), 3, axis=1)
        self.entity.set_dofs_velocity(vel[0] if self.n_envs == 0 else vel, skip_forward=True)

    def apply(self, f_W, tau_W) -> None:
        """World force ``f_W`` (n, 3) (N) at the COM and world torque ``tau_W`` (N m), for the next step only,
        as ``apply_links_external_wrench(ref=link_COM, local=False)``'s kernel (rigid/abd/misc.py) writes them
        (nothing when all are zero) into the accumulators the last step cleared: ``cfrc_applied_vel −= f``,
        ``cfrc_applied_ang −= τ + i_pos × f`` (i_pos: the COM's arm, 0 for a lone body); the same step bit for
        bit (tested), without the API's argument checks and kernel launch."""
        f = np.asarray(f_W, dtype=float).reshape(self.n, 3)
        t = np.asarray(tau_W, dtype=float).reshape(self.n, 3)
        if f.any() or t.any():
            self._f_vel -= f
            self._f_ang -= t + np.cross(self._i_pos, f)

    def step(self) -> None:
        """One step (none after a step Genesis refused: its words are every environment's warning)."""
        self.steps += 1
        if not self.failed:
            try:
                self.scene.step()
            except Exception as exc:  # noqa: BLE001 - gs.GenesisException and what its kernels raise
                self.failed, why = True, f"Genesis: {' '.join(str(exc).split())}"
                self.warnings += [(i, self.steps, why) for i in range(self.n)]


def body(scenario, variant: str, dt_s: float, n_envs: int = 0) -> GenesisBody:
    """The scene of ``scenario``'s body for ``variant`` at ``dt_s`` with ``n_envs`` environments, built once
    per process and reused (the :data:`_SCENES_KEPT` most recent), its time set back to 0."""
    base.check_variant(ENGINE, VARIANTS, variant)
    xml = mjcf_text(scenario, dt_s)
    key = (variant, float(dt_s), xml, tuple(float(v) for v in scenario.problem.forces.gravity_W), int(n_envs))
    hit = _SCENES.pop(key, None)
    if hit is not None:
        with contextlib.suppress(Exception):
            hit.scene.sim._steps.zero_()
    _SCENES[key] = hit or GenesisBody(xml, variant, dt_s, key[3], n_envs)
    while len(_SCENES) > _SCENES_KEPT:
        _, old = _SCENES.popitem(last=False)
        with contextlib.suppress(Exception):
            old.scene.destroy()
    return _SCENES[key]


def to_qpos_vel(y):
    """Packed states (..., 13) ``[x_W, v_W, q_WB (w x y z), ω_W]`` -> qpos (..., 7) ``[x_W, q_WB]``, DOF
    velocity (..., 6) ``[v_W, ω_B]`` (ω in BODY axes)."""
    y = np.asarray(y, dtype=float)
    q = y[..., 6:10]
    return (np.concatenate([y[..., 0:3], q], axis=-1),
            np.concatenate([y[..., 3:6], rotate(quat_conj(q), y[..., 10:13])], axis=-1))


def to_packed(qpos, vel):
    """qpos (..., 7), DOF velocity (..., 6) -> packed states (..., 13) with ω in WORLD axes."""
    q = qpos[..., 3:7]
    return np.concatenate([qpos[..., 0:3], vel[..., 0:3], q, rotate(q, vel[..., 3:6])], axis=-1)


class GenesisEngine(WorldEngine):
    """``genesis:VARIANT`` — registered under the entry-point group ``rbcheck.engines``; optional
    (``pip install 'rbcheck[genesis]'``)."""

    name, variants, distribution, extra = ENGINE, VARIANTS, DIST, "genesis"

    version = staticmethod(version)   # the module's: Genesis, torch and Quadrants found, not imported

    def build(self, requests, variant, dt_s):
        n = len(requests)
        return body(requests[0].scenario, variant, dt_s, n_envs=0 if n == 1 else n)

    def group_key(self, request) -> tuple:   # one scene per body, gravity, Δt and step count
        sc = request.scenario
        return (mjcf_text(sc, request.dt_s), tuple(map(float, sc.problem.forces.gravity_W)),
                float(request.dt_s), int(request.n_steps))

    def engine_files(self) -> list:   # Genesis's rigid solver sources, found without importing it
        return list(_genesis_files())


@functools.lru_cache(maxsize=1)
def _genesis_files() -> tuple:   # what the results depend on beyond the version string
    return tuple(install.package_files("genesis", "engine/solvers/rigid", "engine/solvers/rigid/abd"))


_ENGINE = GenesisEngine()
#: The module's functions (tests and scripts call them): the engine's, through the host loop.
simulate, simulate_many, one_step = _ENGINE.simulate, _ENGINE.simulate_many, _ENGINE.one_step
GenesisAdapter = GenesisEngine
