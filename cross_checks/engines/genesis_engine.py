"""Genesis (``genesis-world``) as an engine (``genesis:VARIANT``, CPU, float64): a world of bodies for
rbcheck's loop (cross_checks.engines.world, cross_checks.engines.loop).

:class:`GenesisBody`, the world (built on cross_checks/engines/worlds/genesis.py, NumPy and Genesis only:
what ``rbcheck repro`` embeds): one MJCF body (:func:`mjcf_text`: a free joint, ``pos = 0`` so body origin =
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
from cross_checks.engines.world import World, WorldEngine, body_spec  # the full tensor (fullinertia)
from cross_checks.engines.worlds import genesis as gw  # numpy only at import: Genesis on first use

__all__ = ["ENGINE", "DIST", "VARIANTS", "NEUTRAL_DOFS", "EngineError", "version", "genesis", "body",
           "kernel_cache_dir", "mjcf_text", "scene_options", "GenesisBody", "body_spec", "start_for_repro",
           "simulate", "simulate_many", "one_step", "to_qpos_vel", "to_packed", "BUILD_SECONDS",
           "GenesisAdapter"]

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
            gw.init()   # the world's gs.init (none when Genesis is initialised already: judged below)
    except Exception as exc:  # noqa: BLE001 - gs.init's own words
        raise EngineError(f"Genesis {ver}: gs.init(backend=gs.cpu, precision='64') failed: {exc}") from exc
    if gs.backend != gs.cpu or gs.np_float is not np.float64 or not gs.use_zerocopy:
        raise EngineError(f"Genesis {ver} was initialised in this process with backend {gs.backend}, "
                          f"{np.dtype(gs.np_float).name} and zero-copy {gs.use_zerocopy}; rbcheck needs "
                          "gs.init(backend=gs.cpu, precision='64') and zero-copy (GS_ENABLE_ZEROCOPY not 0)")
    _STATE["gs"], _STATE["pid"] = gs, os.getpid()
    return gs


def start_for_repro() -> None:
    """Genesis initialised as the adapter does (:func:`genesis`: rbcheck's kernel cache, quiet): ``rbcheck
    repro`` calls it before running a script's world here."""
    genesis()


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
    """The scenario's body as MJCF (the world's :func:`cross_checks.engines.worlds.genesis.mjcf_text`: a free
    joint, an inertial at the body origin, ``fullinertia`` in body axes, frame and inertia kept as given)."""
    b = scenario.problem.body
    return gw.mjcf_text(b.mass_kg, b.inertia_B, dt_s)


def scene_options(variant: str, dt_s: float, gravity_W):
    """``(SimOptions, RigidOptions)`` of a scene (the world's: the run's step and gravity, one substep, the
    variant's ``gs.integrator``, collision, joint limits, constraints and hibernation off), Genesis
    initialised as :func:`genesis` does first."""
    genesis()
    return gw.scene_options(variant, dt_s, gravity_W)


class GenesisBody(gw.Body, World):
    """A scenario's free body in a scene of ``n_envs`` environments (0: unbatched) at ``dt_s``
    (:class:`cross_checks.engines.worlds.genesis.Body`, what ``rbcheck repro`` embeds), a group's runs one per
    environment; raw rows ``[qpos (7), DOF velocity (6)]`` (n = max(n_envs, 1), 13). A step Genesis refuses
    (a NaN it detected) warns every environment with its words; then no step, the last state read."""

    exact_start = True         # the recorded t = 0 state is the scenario's (ω's round trip to body axes)
    first_cause_only = True    # a bad state found before Genesis refused a step: the run's only words

    def __init__(self, xml: str, variant: str, dt_s: float, gravity_W, n_envs: int = 0):
        World.__init__(self)
        genesis()
        t0 = time.perf_counter()
        try:
            with _quiet_stderr():
                gw.Body.__init__(self, xml, variant, dt_s, gravity_W, n_envs)
        except gw.NotNeutral as exc:
            raise EngineError(f"Genesis {version()} {exc}") from None
        except Exception as exc:  # noqa: BLE001 - Genesis (or MuJoCo's compiler inside it) refused the model
            raise EngineError(f"Genesis {version()} rejected the model: {type(exc).__name__}: {exc}") from exc
        BUILD_SECONDS.append((variant, int(n_envs), time.perf_counter() - t0))

    def set_state(self, y) -> None:
        """Every environment at packed state(s) ``y`` (n, 13) (or (13,)); steps and warnings start again."""
        gw.Body.set_state(self, y)
        self.steps, self.failed, self.warnings, self.last = 0, False, [], None

    def read(self):
        """``[qpos, vel]`` (n, 13): ``get_qpos()``'s and ``get_dofs_velocity()``'s numbers (tested); after a
        step Genesis refused, the last state read."""
        if not self.failed or self.last is None:
            return gw.Body.read(self)
        return self.last

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


#: The state conversions at the boundary: the world's (qpos ``[x_W, q_WB]``, DOF velocity ``[v_W, ω_B]``).
to_qpos_vel, to_packed = gw.to_qpos_vel, gw.to_packed
NEUTRAL_DOFS = gw.NEUTRAL_DOFS


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
