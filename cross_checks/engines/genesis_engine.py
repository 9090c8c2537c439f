"""Genesis (``genesis-world``) as an engine adapter (``genesis:VARIANT``, CPU, float64); the interface is
cross_checks.engines.base.

One scene per (variant, Δt, body, gravity, number of environments) holding one MJCF body (:func:`mjcf_text`:
a free joint, ``pos = 0`` so body origin = COM, ``fullinertia`` the scenario's tensor in BODY axes), loaded
with ``align=False`` and neutralised (:data:`NEUTRAL_DOFS`, :func:`scene_options`). State at the boundary:
``qpos = [x_W, q_WB (w x y z)]``, DOF velocity ``[v_W, ω_B]`` (ω in BODY axes). The step
(genesis/engine/solvers/rigid/abd/forward_dynamics.py ``func_integrate``): ``euler`` is MuJoCo Euler's
scheme; ``implicitfast`` and ``approximate_implicitfast`` advance a lone free body's rotation by the
implicit midpoint rule and its translation by semi-implicit Euler. Forces: before every step (Genesis clears
them) the harness's world force at the COM minus the weight ``m g`` and world torque, from the start-of-step
state; the decay before the step (forces.apply_decay_prestep). :func:`simulate_many` and :func:`one_step` run
batches as the environments of one scene. Divergence: a bad state (non-finite, beyond BLOWUP_LIMIT) or a
NaN Genesis raises on ends the run. Importing this module or asking :func:`version` imports no Genesis; the
first run of a process initialises it (:func:`genesis`) and compiles or loads its kernels
(:func:`kernel_cache_dir`, :data:`BUILD_SECONDS`).
Conventions, defaults neutralised and what pins them: docs/engine_conventions.md, "Genesis 1.4.5".
"""

from __future__ import annotations

import contextlib
import functools
import importlib.util
import math
import os
import tempfile
import time
from collections import OrderedDict
from pathlib import Path

import numpy as np

from cross_checks.core import files
from cross_checks.engines import base, forces, install
from cross_checks.engines.base import EngineError, ModuleAdapter, Traits, Variant
from cross_checks.engines.step_floats import harness_fn
from reference_sim.quaternion import quat_conj, rotate
from reference_sim.simulate import Run, bad_rows, blowup_words, diverged

__all__ = [
    "ENGINE",
    "DIST",
    "VARIANTS",
    "NEUTRAL_DOFS",
    "EngineError",
    "version",
    "genesis",
    "kernel_cache_dir",
    "mjcf_text",
    "scene_options",
    "GenesisBody",
    "body",
    "simulate",
    "simulate_many",
    "one_step",
    "to_qpos_vel",
    "to_packed",
    "BUILD_SECONDS",
    "GenesisAdapter",
]

ENGINE = "genesis"
DIST = "genesis-world"

#: The implicit variants on a lone free body: the rotation by the implicit midpoint rule (keeps the kinetic
#: energy and |L|² of torque-free tumbling), the translation by semi-implicit Euler.
_MIDPOINT_ROTATION = Traits(translation_drift=0, rotation_drift="none", rotation_sign=0)

#: The variants, named after ``gs.integrator``, Genesis's default first; every one first order in the
#: translation.
VARIANTS = {
    "approximate_implicitfast": Variant(
        1,
        "Genesis approximate_implicitfast (its default): on a lone free body "
        "implicitfast's midpoint rotation and semi-implicit Euler translation",
        traits=_MIDPOINT_ROTATION,
    ),
    "euler": Variant(
        1,
        "Genesis Euler: semi-implicit Euler, explicit gyroscopic term, quaternion by the "
        "exponential map (MuJoCo Euler's scheme)",
        traits=base.SYMPLECTIC_EULER_EXPLICIT_GYRO,
    ),
    "implicitfast": Variant(
        1,
        "Genesis implicitfast: on a lone free body the rotation by the implicit midpoint "
        "rule (2nd order, energy-keeping), the translation by semi-implicit Euler",
        traits=_MIDPOINT_ROTATION,
    ),
}

#: The ``gs.integrator`` member of each variant.
_INTEGRATORS = {
    "euler": "Euler",
    "implicitfast": "implicitfast",
    "approximate_implicitfast": "approximate_implicitfast",
}

#: DOF settings of the free joint, each asserted after the build (Genesis getter suffix, neutral value per
#: DOF).
NEUTRAL_DOFS = (("armature", 0.0), ("damping", 0.0), ("stiffness", 0.0), ("frictionloss", 0.0))

#: Wall time (s) of every scene build in this process: ``(variant, n_envs, seconds)``; the first includes the
#: kernels' compilation or loading from the on-disk cache.
BUILD_SECONDS: list = []

#: Scenes kept per process (the most recently used; each holds its kernels' data, ~MBs).
_SCENES_KEPT = 4
#: Steps between divergence checks of a free run (checked vectorised per chunk).
_CHUNK = 256

_STATE: dict = {"gs": None, "pid": None}
_SCENES: OrderedDict = OrderedDict()


# --- availability, without importing Genesis ---------------------------------------------------------------


def version() -> str:
    """The installed genesis-world distribution's version, from its metadata; its packages (``genesis``,
    ``torch``, ``quadrants``) are found without importing them. EngineNotInstalled when the distribution is
    absent, ImportError when a package is missing."""
    ver = install.installed_version(DIST)
    if ver is None:
        raise install.EngineNotInstalled(f"{DIST} is not installed (pip install 'rbcheck[genesis]')")
    missing = [m for m in ("genesis", "torch", "quadrants") if not _findable(m)]
    if missing:
        raise ImportError(
            f"{DIST} {ver} is installed but cannot be imported: no module named "
            f"{', '.join(repr(m) for m in missing)}"
        )
    return ver


def _findable(name: str) -> bool:
    try:
        return importlib.util.find_spec(name) is not None
    except (ImportError, ValueError):
        return False


def kernel_cache_dir() -> Path:
    """Where Genesis's kernel compiler (Quadrants) keeps its compiled kernels and Genesis its asset caches:
    core.files.kernel_cache_dir("genesis"), not under ``$RBCHECK_CACHE_DIR`` (a fresh result cache must not
    recompile every kernel). An environment that already sets ``QD_OFFLINE_CACHE_FILE_PATH`` /
    ``GS_CACHE_FILE_PATH`` keeps them."""
    return files.kernel_cache_dir("genesis")


def genesis():
    """The ``genesis`` module, imported and initialised once per process with the CPU backend in float64
    (``gs.init`` is process-global and may run once). A Genesis initialised by someone else is accepted only
    with that backend and precision; one initialised in a parent before a fork is refused (its kernel runtime
    and torch threads do not survive a fork)."""
    gs = _STATE["gs"]
    if gs is not None:
        if _STATE["pid"] != os.getpid():
            raise EngineError(
                f"Genesis was initialised in process {_STATE['pid']} before this process was forked "
                "from it; initialise it only in the worker processes"
            )
        return gs
    ver = version()
    cache = kernel_cache_dir()
    os.environ.setdefault("QD_OFFLINE_CACHE_FILE_PATH", str(cache / "kernels"))
    os.environ.setdefault("GS_CACHE_FILE_PATH", str(cache / "assets"))
    try:
        import genesis as gs
    except Exception as exc:  # noqa: BLE001 - a broken install is the engine's failure, with its words
        raise EngineError(f"{DIST} {ver} cannot be imported: {type(exc).__name__}: {exc}") from exc
    failed = f"Genesis {ver}: gs.init(backend=gs.cpu, precision='64') failed"
    try:
        with _quiet_stderr():
            gs.init(backend=gs.cpu, precision="64", logging_level="warning")
    except gs.GenesisException as exc:  # a second gs.init is refused: the check below judges the first
        if "already initialized" not in str(exc):
            raise EngineError(f"{failed}: {exc}") from exc
    except Exception as exc:  # noqa: BLE001
        raise EngineError(f"{failed}: {exc}") from exc
    if gs.backend != gs.cpu or gs.np_float is not np.float64:
        raise EngineError(
            f"Genesis {ver} was initialised in this process with backend {gs.backend} and "
            f"{np.dtype(gs.np_float).name}; rbcheck needs gs.init(backend=gs.cpu, precision='64')"
        )
    _STATE["gs"], _STATE["pid"] = gs, os.getpid()
    return gs


@contextlib.contextmanager
def _quiet_stderr():
    """File descriptor 2 into a temporary file while Genesis compiles: its kernel compiler prints a warning
    per kernel ("qd.loop_config(serialize=True) does not have effect ...") straight to fd 2; any other line is
    written back to stderr afterwards."""
    import sys

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
            kept = [
                ln
                for ln in tmp.read().decode(errors="replace").splitlines(keepends=True)
                if ln.strip() and "serialize=True" not in ln
            ]
            if kept:
                sys.stderr.write("".join(kept))


# --- the model -------------------------------------------------------------------------------------------


def mjcf_text(scenario, dt_s: float = 0.01) -> str:
    """The scenario's body as an MJCF document: a free joint and an explicit inertial at the body origin, the
    full tensor in body axes (``fullinertia`` = Ixx Iyy Izz Ixy Ixz Iyz, kg m²), the mass (kg); the compiler
    told to keep the body frame and the inertia exactly as given (no free-joint alignment, no inertia from
    geoms, no balancing, no bounds). The joint's limit time constant (MuJoCo's default 0.02 s; no limit acts:
    the joint is free and limits are off) is raised to 2Δt where Genesis would raise it itself, with a
    warning, at Δt > 0.01 s."""
    b = scenario.problem.body
    inertia = np.asarray(b.inertia_B, dtype=float)
    full = " ".join(
        repr(float(v))
        for v in (inertia[0, 0], inertia[1, 1], inertia[2, 2], inertia[0, 1], inertia[0, 2], inertia[1, 2])
    )
    timeconst = max(0.02, 2.0 * float(dt_s))
    return (
        '<mujoco model="rbcheck"><compiler alignfree="false" inertiafromgeom="false" balanceinertia="false" '
        f'boundmass="0" boundinertia="0"/><default><joint solreflimit="{timeconst!r} 1"/></default>'
        '<worldbody><body name="body"><joint type="free" name="free"/>'
        f'<inertial pos="0 0 0" mass="{float(b.mass_kg)!r}" fullinertia="{full}"/>'
        '</body></worldbody></mujoco>'
    )


def scene_options(variant: str, dt_s: float, gravity_W):
    """``(SimOptions, RigidOptions)`` of a scene: the step and gravity from the run, one substep, the
    variant's integrator, collision, joint limits and hibernation off."""
    gs = genesis()
    sim = gs.options.SimOptions(dt=float(dt_s), substeps=1, gravity=tuple(float(g) for g in gravity_W))
    rigid = gs.options.RigidOptions(
        integrator=getattr(gs.integrator, _INTEGRATORS[variant]),
        enable_collision=False,
        enable_joint_limit=False,
        use_hibernation=False,
        disable_constraint=True,
    )
    return sim, rigid


class GenesisBody:
    """A scenario's free body alone in a built Genesis scene of ``n_envs`` environments (0: unbatched)
    stepping at ``dt_s``; ``set_state``/``read``/``apply`` at the boundary, every array (n, ...) with n =
    max(n_envs, 1)."""

    def __init__(self, xml: str, variant: str, dt_s: float, gravity_W, n_envs: int = 0):
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
        self.n_envs, self.n = int(n_envs), max(int(n_envs), 1)
        self.link = entity.base_link_idx
        self.links_idx = [self.link]
        self.dt_s = float(dt_s)
        self._views()
        for name, value in NEUTRAL_DOFS:
            got = getattr(entity, f"get_dofs_{name}")().numpy()
            if not np.all(got == value):
                raise EngineError(
                    f"Genesis {version()} left the free joint's {name} at {got.tolist()}, not {value}"
                )

    def set_state(self, y) -> None:
        """Put every environment at the packed state(s) ``y`` (n, 13) (or (13,) for all)."""
        qpos, vel = to_qpos_vel(np.broadcast_to(np.asarray(y, dtype=float), (self.n, 13)))
        if self.n_envs == 0:
            qpos, vel = qpos[0], vel[0]
        self.entity.set_qpos(qpos, zero_velocity=False)
        self.entity.set_dofs_velocity(vel)

    def set_velocity(self, vel) -> None:
        """The DOF velocities ``[v_W, ω_B]`` (n, 6), the link velocities left to the next step's forward pass
        (``skip_forward=True``: Genesis marks them stale and the step recomputes them; the same step, tested).
        """
        vel = np.asarray(vel, dtype=float)
        self.entity.set_dofs_velocity(vel[0] if self.n_envs == 0 else vel, skip_forward=True)

    def _views(self) -> None:
        """NumPy views of the solver's own arrays (Genesis's zero-copy CPU path,
        ``gs.utils.misc.qd_to_torch(..., copy=False)``, what its getters and ``clear_external_force`` use):
        qpos (n, 7), DOF velocity (n, 6), and the body's external wrench accumulators ``cfrc_applied_vel`` /
        ``cfrc_applied_ang`` and COM arm ``i_pos`` (n, 3)."""
        from genesis.utils.misc import qd_to_torch

        if not self.gs.use_zerocopy:
            self._qpos = None
            return
        s, links = self.solver, self.solver.dyn_state.links
        self._qpos = qd_to_torch(s.qpos, transpose=True, copy=False).numpy()
        self._vel = qd_to_torch(s.dyn_state.dofs.vel, transpose=True, copy=False).numpy()
        self._f_vel = qd_to_torch(links.cfrc_applied_vel, copy=False).numpy()[self.link]
        self._f_ang = qd_to_torch(links.cfrc_applied_ang, copy=False).numpy()[self.link]
        self._i_pos = qd_to_torch(links.i_pos, copy=False).numpy()[self.link]

    def read(self):
        """``(qpos (n, 7), vel (n, 6))``: Genesis's state as it is (copies: ``entity.get_qpos()`` and
        ``get_dofs_velocity()``'s numbers, tested, without their torch round trip)."""
        if self._qpos is None:
            qpos, vel = self.entity.get_qpos().numpy(), self.entity.get_dofs_velocity().numpy()
            return qpos.reshape(self.n, 7), vel.reshape(self.n, 6)
        return self._qpos[:, 0:7].copy(), self._vel[:, 0:6].copy()

    def apply_fast(self, f_W, tau_W) -> None:
        """:meth:`apply` by writing what Genesis's kernel writes (genesis/engine/solvers/rigid/abd/misc.py,
        ``func_apply_link_external_wrench`` with ``ref=link_COM``, ``local=False``) into the accumulators,
        which the previous step cleared: ``cfrc_applied_vel −= f``, ``cfrc_applied_ang −= τ + i_pos × f``
        (i_pos: the COM's arm from the root COM, zero for a lone body). The same step bit for bit (tested),
        without the API's argument sanitising and kernel launch."""
        if self._qpos is None:
            self.apply(f_W, tau_W)
            return
        f = np.asarray(f_W, dtype=float).reshape(self.n, 3)
        t = np.asarray(tau_W, dtype=float).reshape(self.n, 3)
        self._f_vel -= f
        self._f_ang -= t + np.cross(self._i_pos, f)

    def apply(self, f_W, tau_W) -> None:
        """World force ``f_W`` (n, 3) (N) at the COM and world torque ``tau_W`` (n, 3) (N m), for the next
        step only (Genesis clears them after it): ``rigid_solver.apply_links_external_wrench(force, torque,
        ref=link_COM, local=False)``."""
        f = np.asarray(f_W, dtype=float).reshape(self.n, 1, 3)
        t = np.asarray(tau_W, dtype=float).reshape(self.n, 1, 3)
        if self.n_envs == 0:
            f, t = f[0], t[0]
        self.solver.apply_links_external_wrench(
            force=f, torque=t, links_idx=self.links_idx, ref=self.gs.link_ref_frame.link_COM, local=False
        )

    def step(self) -> str:
        """One step; "" or Genesis's words when it refused to go on (a NaN it detected)."""
        try:
            self.scene.step()
        except Exception as exc:  # noqa: BLE001 - gs.GenesisException and what its kernels raise
            return f"Genesis: {' '.join(str(exc).split())}"
        return ""

    def reset_time(self) -> None:
        """Back to t = 0 (the state is set by the caller)."""
        with contextlib.suppress(Exception):
            self.scene.sim._steps.zero_()


def body(scenario, variant: str, dt_s: float, n_envs: int = 0) -> GenesisBody:
    """The scene of ``scenario``'s body for ``variant`` at ``dt_s`` with ``n_envs`` environments: built once
    per process and reused (the :data:`_SCENES_KEPT` most recent), its state and wrench set by every run."""
    base.check_variant(ENGINE, VARIANTS, variant)
    xml = mjcf_text(scenario, dt_s)
    g = tuple(float(v) for v in scenario.problem.forces.gravity_W)
    key = (variant, float(dt_s), xml, g, int(n_envs))
    hit = _SCENES.get(key)
    if hit is not None:
        _SCENES.move_to_end(key)
        hit.reset_time()
        return hit
    b = GenesisBody(xml, variant, dt_s, g, n_envs)
    _SCENES[key] = b
    while len(_SCENES) > _SCENES_KEPT:
        _, old = _SCENES.popitem(last=False)
        with contextlib.suppress(Exception):
            old.scene.destroy()
    return b


# --- state conversion (the boundary) ------------------------------------------------------------------------


def to_qpos_vel(y):
    """Packed states (..., 13) ``[x_W, v_W, q_WB (w x y z), ω_W]`` -> qpos (..., 7) ``[x_W, q_WB]``, DOF
    velocity (..., 6) ``[v_W, ω_B]`` (ω in BODY axes)."""
    y = np.asarray(y, dtype=float)
    q = y[..., 6:10]
    return (
        np.concatenate([y[..., 0:3], q], axis=-1),
        np.concatenate([y[..., 3:6], rotate(quat_conj(q), y[..., 10:13])], axis=-1),
    )


def to_packed(qpos, vel):
    """qpos (..., 7), DOF velocity (..., 6) -> packed states (..., 13) with ω in WORLD axes."""
    q = qpos[..., 3:7]
    return np.concatenate([qpos[..., 0:3], vel[..., 0:3], q, rotate(q, vel[..., 3:6])], axis=-1)


# --- runs ---------------------------------------------------------------------------------------------


def simulate(scenario, variant: str, dt_s: float, n_steps: int) -> Run:
    """Free run of ``n_steps`` steps of ``dt_s`` from the scenario's initial state, every step recorded."""
    return _simulate_batch([scenario], variant, dt_s, n_steps)[0]


def _simulate_batch(scenarios, variant: str, dt_s: float, n_steps: int) -> list:
    """The free runs of ``scenarios`` (sharing one body, gravity and ``variant``) as the environments of one
    scene: per environment its initial state, forces and decay; a Run each (diverged ones stop at their step).
    """
    n = len(scenarios)
    B = body(scenarios[0], variant, dt_s, n_envs=0 if n == 1 else n)
    y0 = np.array([sc.problem.initial_packed() for sc in scenarios])
    B.set_state(y0)
    weight = np.array([forces.weight_W(sc) for sc in scenarios])
    harness = [harness_fn(sc, dt_s) for sc in scenarios]
    per_step = any(sc.problem.forces.state_dependent for sc in scenarios)
    decay = any(sc.problem.forces.has_decay for sc in scenarios)
    g = np.array([[float(v) for v in forces.decay_factors(sc, dt_s)] for sc in scenarios])
    gvel = np.repeat(g, 3, axis=1)  # (n, 6): γ_v γ_v γ_v γ_ω γ_ω γ_ω
    ft = np.array([h(y.tolist()) for h, y in zip(harness, y0)])  # (n, 6) from the initial state
    f, tau = ft[:, 0:3] - weight, ft[:, 3:6]
    applies = per_step or bool(np.any(f != 0.0) or np.any(tau != 0.0))
    qpos_out = np.empty((n_steps + 1, n, 7))
    vel_out = np.empty((n_steps + 1, n, 6))
    qpos_out[0], vel_out[0] = B.read()
    y = np.empty((n_steps + 1, n, 13))
    y[0] = y0
    stop = [None] * n  # per environment: (first bad step, why)
    with np.errstate(all="ignore"):
        for start in range(1, n_steps + 1, _CHUNK):
            end = min(start + _CHUNK, n_steps + 1)
            for k in range(start, end):
                if per_step and k > 1:
                    yp = to_packed(qpos_out[k - 1], vel_out[k - 1])
                    ft = np.array([h(row.tolist()) for h, row in zip(harness, yp)])
                    f, tau = ft[:, 0:3] - weight, ft[:, 3:6]
                if decay:
                    B.set_velocity(vel_out[k - 1] * gvel)
                if applies:
                    B.apply_fast(f, tau)
                why = B.step()
                if why:
                    end = k
                    break
                qpos_out[k], vel_out[k] = B.read()
            y[start:end] = to_packed(qpos_out[start:end], vel_out[start:end])
            for i in range(n):  # the first bad state, else the step Genesis refused
                bad = bad_rows(y[start:end, i])
                if stop[i] is None and bad.any():
                    j = int(np.argmax(bad))
                    stop[i] = (start + j, f" ({blowup_words(y[start + j, i])})")
                elif stop[i] is None and why:
                    stop[i] = (end, f" ({why})")
            if all(s is not None for s in stop) or end < min(start + _CHUNK, n_steps + 1):
                break
    out = []
    for i in range(n):
        if stop[i] is not None:
            out.append(diverged(y[: stop[i][0], i].copy(), dt_s, stop[i][1]))
        else:
            out.append(Run(dt_s * np.arange(n_steps + 1), y[:, i].copy()))
    return out


def _batch_key(r) -> tuple:
    p = r.scenario.problem
    return (
        mjcf_text(r.scenario, r.dt_s),
        tuple(float(v) for v in p.forces.gravity_W),
        float(r.dt_s),
        int(r.n_steps),
    )


def simulate_many(variant: str, requests) -> list:
    """The runs of ``requests`` (``base.RunRequest``): those that share a body, gravity, Δt and step count run
    as the environments of one scene (``scene.build(n_envs=N)``), the others one by one; each element
    :func:`simulate`'s Run (tested) or its EngineError."""

    def run_group(reqs):
        return _simulate_batch([r.scenario for r in reqs], variant, reqs[0].dt_s, reqs[0].n_steps)

    return base.run_in_groups(requests, _batch_key, run_group)


@base.on_rows
def one_step(scenario, variant: str, dt_s: float, y_start) -> np.ndarray:
    """One step of ``dt_s`` from each row of ``y_start`` (T, 13), all rows at once as the environments of one
    scene: the forces from each row, the pre-step decay, the state set per environment. A row whose step blows
    up comes back as Genesis left it (a step Genesis refuses: NaN rows)."""
    T = len(y_start)
    B = body(scenario, variant, dt_s, n_envs=0 if T == 1 else T)
    harness = harness_fn(scenario, dt_s)
    ft = np.array([harness(row) for row in y_start.tolist()]).reshape(T, 6)
    B.set_state(forces.apply_decay_prestep(scenario, y_start, dt_s))
    B.apply(ft[:, 0:3] - forces.weight_W(scenario), ft[:, 3:6])
    if B.step():
        return np.full(y_start.shape, math.nan)
    qpos, vel = B.read()
    with np.errstate(all="ignore"):
        return to_packed(qpos, vel)


class GenesisAdapter(ModuleAdapter):
    """``genesis:VARIANT`` — registered under the entry-point group ``rbcheck.engines``; optional
    (``pip install 'rbcheck[genesis]'``)."""

    def engine_files(self) -> list:
        """Genesis's rigid solver sources (read from the installed distribution without importing it)."""
        return list(_genesis_files())


@functools.lru_cache(maxsize=1)
def _genesis_files() -> tuple:
    """The rigid solver's step sources of the installed Genesis (found, not imported): what its results depend
    on beyond the version string."""
    return tuple(install.package_files("genesis", "engine/solvers/rigid", "engine/solvers/rigid/abd"))
