"""The compiled fast path: N members (each its own body, forces, decay and step) advanced by numba.

The kernels (``_compiled_kernels``) transcribe the definition, :mod:`reference_sim.integrators`, on the
floats of one member, operation for operation and in the definition's order, compiled with ``fastmath``
off: the states they write are those of the definition (tests/reference_sim/test_compiled.py).

The compiled loop stops at the first step that is not routine — a state that is non-finite or beyond the
blow-up limit, a leapfrog half kick or an implicit Euler fixed point that does not converge, a Newton
iteration of lp_midpoint or moser_veselov that does not converge or turns non-finite — and returns;
the caller (reference_sim.simulate) takes that one step with the definition (which raises, gives the bad
state, or solves the step with Newton's method) and resumes compiled.

numba is imported on first use, and the kernels are compiled once per machine (numba's cache); a cache folder
that cannot be written or read is skipped, said once, and the kernels compiled in memory
(:func:`load_compiled`); where numba cannot be imported, :func:`kernel` is None and runs step with the
definition.
State layout as everywhere: [x_W (3) m, v_W (3) m/s, q_WB (w, x, y, z), w_W (3) rad/s].
"""
from __future__ import annotations

import math
from contextlib import contextmanager

import numpy as np

from reference_sim.forces import Members
from reference_sim.integrators import BULLET_MAX_GYROSCOPIC_TORQUE, IMPLICIT_TOL, MAX_ITER

__all__ = ["VARIANT_CODES", "COMPILE_ESTIMATE_S", "kernel", "parameters", "advance", "lane_members", "warm",
           "unwritable",
           "ForceEvaluator"]

#: The variants the compiled loop knows, by code (the ``code`` argument of the kernel).
VARIANT_CODES = {"course": 0, "course_gyro": 1, "expmap_gyro": 2, "explicit_euler": 3, "midpoint": 4,
                 "rk4": 5, "leapfrog": 6, "implicit_euler": 7,
                 "implicit_gyro_body": 8, "implicit_gyro_world": 9, "explicit_gyro_clamped": 10,
                 "jolt_gyro": 11, "buss_augmented": 12, "dlm_splitting": 13, "lp_midpoint": 14,
                 "moser_veselov": 15}

#: How long compiling the kernels takes the first time on a machine (numba, ``cache=True``), as the sweep
#: says it: measured 53-75 s on 2 cores (a cold `rbcheck sweep tennis_racket --engines reference:course_gyro`:
#: 53 s; a first `rbcheck run tennis_racket --engine reference:rk4`: 70 s; issue 44: 55-75 s).
COMPILE_ESTIMATE_S = "about a minute (53-75 s measured on 2 cores)"

_KERNELS: list = []
#: Whether the kernels use numba's on-disk cache (``cache=`` of ``_compiled_kernels``): False once its folder
#: was found unusable, the kernels then being compiled in memory (:func:`load_compiled`).
_CACHE = [True]


def cache_wanted() -> bool:
    """``cache=`` for ``_compiled_kernels``' functions (read when that module is imported)."""
    return _CACHE[0]


def _kernels():
    """The kernels module, loaded (from numba's cache, else compiled) once per process, or None where numba
    cannot be imported."""
    if not _KERNELS:
        _KERNELS.append(load_compiled("reference_sim._compiled_kernels", _first_calls, _CACHE))
    return _KERNELS[0]


def load_compiled(name: str, first_calls, flag: list):
    """The module ``name`` of numba functions compiled with ``cache=flag[0]``, after ``first_calls(module)``
    loaded or compiled them; None where numba (or the module) cannot be imported.

    A cache is a cache: a folder numba cannot write (a read-only or missing ``NUMBA_CACHE_DIR``: checked
    first, so that numba does not fall back to the installation's ``__pycache__``), or files it cannot read
    or write (cut in half, a full disk: the first calls raise) make ``flag[0]`` False; the folder and the
    reason are said once on stderr, and the module is imported again without the cache, compiled in memory."""
    try:
        import numba
    except ImportError:
        return None
    folder = getattr(numba.config, "CACHE_DIR", "") or ""
    if flag[0] and folder:
        why = unwritable(folder)
        if why:
            flag[0] = False
            _say_skipped(folder, f"cannot write there: {why}")
    import importlib
    try:
        module = importlib.import_module(name)
    except (ImportError, RuntimeError, OSError):
        return None
    if not flag[0]:
        first_calls(module)
        return module
    try:
        with _compiling_alone(module):
            first_calls(module)
    except Exception as exc:  # noqa: BLE001 - whatever the cache's files did, compile in memory
        flag[0] = False
        _say_skipped(_cache_folder(module) or folder or "numba's cache folder",
                     f"{type(exc).__name__}: {exc}".strip())
        module = importlib.reload(module)
        first_calls(module)
    return module


def unwritable(folder) -> str:
    """Why a cache cannot be kept in ``folder`` ("" when it can be created, and a file created and written in
    it): numba's kernel cache here, every cache of cross_checks (core.files.usable_cache_dir)."""
    import os
    import tempfile
    try:
        os.makedirs(folder, exist_ok=True)
        fd, probe = tempfile.mkstemp(prefix=".rbcheck-probe-", dir=folder)
        try:
            os.write(fd, b"\0" * 4096)
        finally:
            os.close(fd)
            os.unlink(probe)
    except OSError as exc:
        return exc.strerror or str(exc)
    return ""


#: How long a process waits for another one compiling the same kernels (:func:`_compiling_alone`) before it
#: compiles them itself: several times the longest compile measured (COMPILE_ESTIMATE_S), so that only a
#: process that stopped while compiling (suspended, not killed: a kill releases the lock) is not waited for.
COMPILE_WAIT_S = 900.0


@contextmanager
def _compiling_alone(module):
    """Held while ``module``'s first calls load its functions from numba's cache or compile them: a second
    process doing the same on this machine (both workers of ``pytest -n 2`` in a fresh clone, the sweeps its
    tests start meanwhile, two rbcheck commands started together) waits until the first has compiled and
    written the cache, then loads it, instead of compiling the same kernels again (about a minute of CPU
    each). An exclusive ``flock`` on a file beside numba's cache files, released when the first calls return
    or the process ends; where there is no cache folder or no lock can be taken there, or after
    :data:`COMPILE_WAIT_S`, each process loads or compiles on its own, as before."""
    import os
    import time
    try:
        import fcntl
    except ImportError:   # no flock here
        yield
        return
    folder, fd = _cache_folder(module), None
    if folder:
        try:
            os.makedirs(folder, exist_ok=True)   # numba makes it when it writes the first file
            fd = os.open(os.path.join(folder, f"{module.__name__}.rbcheck-compile.lock"),
                         os.O_CREAT | os.O_RDWR, 0o666)
            deadline = time.monotonic() + COMPILE_WAIT_S
            while True:
                try:
                    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                    break
                except BlockingIOError:
                    if time.monotonic() > deadline:
                        break
                    time.sleep(0.1)
        except OSError:
            pass
    try:
        yield
    finally:
        if fd is not None:
            os.close(fd)   # the lock goes with the descriptor


def _cache_folder(module) -> str:
    """The folder numba keeps ``module``'s cache in (its ``run`` function's), or ""."""
    for f in vars(module).values():
        path = getattr(getattr(f, "_cache", None), "_cache_path", None)
        if path:
            return str(path)
    return ""


def _say_skipped(folder: str, why: str) -> None:
    import sys
    print(f"rbcheck: numba's cache folder {folder} skipped ({why}); the reference's compiled steps are "
          "compiled in memory instead, in each process", file=sys.stderr, flush=True)


def _first_calls(k) -> None:
    """One call of each kernel on one member: loads them from numba's cache, or compiles them."""
    from reference_sim.body import RigidBody
    from reference_sim.forces import ForceModel
    p = Members.stack([(RigidBody(1.0, [1.0, 1.0, 1.0]), ForceModel())])
    rows = np.zeros((2, 13))
    rows[0, 6] = 1.0
    params = parameters(p, [0.01])
    k.run(VARIANT_CODES["rk4"], rows, np.zeros(1, dtype=np.int64), np.zeros(1, dtype=np.int64),
          np.ones(1, dtype=np.int64), 1e8, float(IMPLICIT_TOL), int(MAX_ITER),
          float(BULLET_MAX_GYROSCOPIC_TORQUE), *params)
    k.force_torque_at(rows[0], True, *params)
    k.force_torque_rows(rows[:1], np.empty((1, 6)), *params)
    k.lane_members(VARIANT_CODES["rk4"], params[0], params[7], params[8], params[9])


def kernel():
    """The compiled run loop (``_compiled_kernels.run``), or None without numba."""
    k = _kernels()
    return None if k is None else k.run


def parameters(p: Members, h_s) -> tuple:
    """The kernel's per-member arguments after the state arrays, for members ``p`` at steps ``h_s`` (N,) s."""
    h = np.asarray(h_s, dtype=float).reshape(-1)
    gv, gw = (np.broadcast_to(g, (len(h), 1)) for g in p.decay_factors(h))
    sc = np.ascontiguousarray(np.column_stack([h, p.mass_kg[:, 0], p.drag[:, 0], gv[:, 0], gw[:, 0],
                                               p.decay_rates[:, 0], p.decay_rates[:, 1]]))
    # the principal moments and axes of I_B, as the definition's dlm_splitting computes them (LAPACK, matrix
    # by matrix: a member's are the same in any batch)
    moments, axes = np.linalg.eigh(p.inertia_B)
    arrays = (p.inertia_B, p.inertia_inv_B, p.weight_W, p.force_W, p.torque_W, p.torque_B, p.springs,
              p.world_points, p.body_points, moments, axes)
    return (sc, *(np.ascontiguousarray(a, dtype=np.float64) for a in arrays))


def advance(variant: str, rows: np.ndarray, offsets, pos, stop, limit: float, params: tuple) -> None:
    """Advance each member i from state ``rows[offsets[i] + pos[i]]`` to ``pos[i] = stop[i]``, or to the step
    before one that is not routine (module doc); ``pos`` (N,) int64 is updated in place. ``rows``: a
    C-contiguous float64 (M, 13) array holding every member's rows from its offset on."""
    if rows.dtype != np.float64 or not rows.flags.c_contiguous or rows.ndim != 2 or rows.shape[1] != 13:
        raise ValueError("rows must be a C-contiguous float64 (M, 13) array")
    offsets, stop = np.asarray(offsets, dtype=np.int64), np.asarray(stop, dtype=np.int64)
    if np.any(offsets + stop >= rows.shape[0]) or np.any(pos < 0):  # the compiled loop does not check indices
        raise ValueError(f"steps up to {stop.tolist()} do not fit rows of {rows.shape[0]} states")
    kernel()(VARIANT_CODES[variant], rows, offsets, pos, stop, float(limit), float(IMPLICIT_TOL),
             int(MAX_ITER), float(BULLET_MAX_GYROSCOPIC_TORQUE), *params)


def lane_members(variant: str, params: tuple) -> np.ndarray:
    """The members (N,) bool whose steps the compiled loop takes LANES at a time, vectorised across members
    (``_compiled_kernels.lane_members``: a course-type variant, a batch without springs or point forces, a
    member without drag); the others it steps one by one. Either way the states are the definition's."""
    return _kernels().lane_members(VARIANT_CODES[variant], params[0], params[7], params[8], params[9])


class ForceEvaluator:
    """One body's forces at a single state, as plain floats, for an engine's per-step loop (where a NumPy call
    costs more than the engine's step): the compiled ``Members.force_torque`` of the definition, or the
    definition itself without numba."""

    def __init__(self, problem):
        self.members = problem.members
        self.params = parameters(self.members, [1.0])   # the step does not enter the forces
        k = _kernels()
        self._at = None if k is None else k.force_torque_at
        # forces that do not depend on the state (ForceModel.state_dependent), and a stage without decay
        # forces: the same 6 numbers at every state, evaluated once
        fm = problem.forces
        self._constant = {False: not fm.state_dependent, True: not fm.state_dependent and not fm.has_decay}
        self._known: dict = {}
        # where only torques fixed in body axes depend on the state (no spring, point force or drag; at a
        # stage, no decay): the kernel's few operations in plain floats (a call of the compiled kernel with
        # its 14 arguments costs more than the arithmetic): the constant force, the world torque and τ_B, once
        sc, _, _, mg, fW, tW, tB, springs, wp, bp = self.params[:10]
        rotating = springs.shape[1] == 0 and wp.shape[1] == 0 and bp.shape[1] == 0 and sc[0, 2] == 0.0
        self._rotating = {False: bool(rotating), True: bool(rotating and sc[0, 5] == 0.0 and sc[0, 6] == 0.0)}
        self._f = tuple(float(mg[0, k] + fW[0, k]) for k in range(3))
        self._tW, self._tB = tuple(float(t) for t in tW[0]), tuple(float(t) for t in tB[0])

    def force_torque(self, y, stage: bool = False) -> tuple:
        """World force at the COM (N) and world torque about it (N m), 6 floats, at state ``y`` (13 numbers),
        the rotation taken from q/|q|. ``stage``: the decay included as the force ``−m k_v v`` and the torque
        ``−k_ω I_W ω`` (so that v̇ gets −k_v v and ω̇ gets −k_ω ω)."""
        if self._constant[stage]:
            known = self._known.get(stage)
            if known is None:
                known = self._known[stage] = self._evaluate(y, stage)
            return known
        if self._rotating[stage]:
            floats = y if isinstance(y, (list, tuple)) else np.asarray(y, dtype=float).tolist()
            return self._body_torque(floats, stage)
        return self._evaluate(y, stage)

    def _body_torque(self, y, stage: bool) -> tuple:
        """``_compiled_kernels.force_torque_at`` where only body-axes torques depend on the state, operation
        for operation in plain floats (its IEEE results): the rotation of q/|q| (``_rot``), ``R τ_B``
        (``_mv``) added to the world torque; the force constant. A quaternion whose norm is zero in floats
        (all zero, or its squares underflowing: a division by zero, which Python floats raise on) goes to
        the kernel."""
        qw, qx, qy, qz = y[6], y[7], y[8], y[9]
        n = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
        if n == 0.0:
            return self._evaluate(y, stage)
        qw, qx, qy, qz = qw / n, qx / n, qy / n, qz / n
        fx, fy, fz = self._f
        tx, ty, tz = self._tW
        a0, a1, a2 = self._tB
        if a0 != 0.0 or a1 != 0.0 or a2 != 0.0:
            tx = tx + ((1.0 - 2.0 * (qy * qy + qz * qz)) * a0 + 2.0 * (qx * qy - qw * qz) * a1
                       + 2.0 * (qx * qz + qw * qy) * a2)
            ty = ty + (2.0 * (qx * qy + qw * qz) * a0 + (1.0 - 2.0 * (qx * qx + qz * qz)) * a1
                       + 2.0 * (qy * qz - qw * qx) * a2)
            tz = tz + (2.0 * (qx * qz - qw * qy) * a0 + 2.0 * (qy * qz + qw * qx) * a1
                       + (1.0 - 2.0 * (qx * qx + qy * qy)) * a2)
        return fx, fy, fz, tx, ty, tz

    def _evaluate(self, y, stage: bool) -> tuple:
        if self._at is not None:
            return self._at(np.asarray(y, dtype=np.float64), stage, *self.params)
        from reference_sim.quaternion import matrix_from_quat
        from reference_sim.vec import mat_t_vec3, matvec3
        p, y = self.members, np.asarray(y, dtype=float)[None]
        q = y[:, 6:10]
        R = matrix_from_quat(q / np.sqrt(q[:, 0:1] * q[:, 0:1] + q[:, 1:2] * q[:, 1:2] + q[:, 2:3] * q[:, 2:3]
                                          + q[:, 3:4] * q[:, 3:4]))
        f, tau = p.force_torque(y[:, 0:3], y[:, 3:6], R)
        if stage:
            f = f - p.mass_kg * p.decay_rates[:, 0:1] * y[:, 3:6]
            tau = tau - p.decay_rates[:, 1:2] * matvec3(R, matvec3(p.inertia_B, mat_t_vec3(R, y[:, 10:13])))
        return tuple(float(c) for c in (*f[0], *tau[0]))


class ForceRows:
    """The forces of N bodies (one problem each) at N states at once, for an engine loop stepping them
    together: the compiled ``Members.force_torque`` of each member (the numbers of :class:`ForceEvaluator`,
    member by member), or None where numba is missing (:meth:`of`)."""

    def __init__(self, problems, kernel, index=None):
        # each distinct problem stacked once, its parameters gathered per body (the same values, member by
        # member: a batch of one scenario's copies costs one member's stacking)
        if index is None:
            first: dict = {}
            for p in problems:
                first.setdefault(id(p), (len(first), p))
            index = np.array([first[id(p)][0] for p in problems])
            problems = [p for _, p in first.values()]
        unique = parameters(Members.stack(list(problems)), np.ones(len(problems)))
        self.params = tuple(np.ascontiguousarray(a[index]) for a in unique)
        self._rows = kernel

    @classmethod
    def of(cls, problems, index=None):
        """The rows of ``problems`` (one per body), or, with ``index`` (N,) int, of ``problems[index[i]]``
        for body i (``problems`` then each distinct problem once)."""
        k = _kernels()
        return None if k is None else cls(problems, k.force_torque_rows, index)

    def force_torque(self, Y, part: slice | None = None) -> np.ndarray:
        """World force at the COM (N) and world torque (N m) of each body, (N, 6), at states ``Y`` (N, 13);
        ``part``: the bodies (a slice of them, in order) whose states ``Y`` holds, when not all."""
        Y = np.ascontiguousarray(Y, dtype=np.float64)
        out = np.empty((len(Y), 6))
        params = self.params if part is None else tuple(a[part] for a in self.params)
        self._rows(Y, out, *params)
        return out


def warm() -> bool:
    """Load (or, the first time on a machine, compile) the compiled loop in this process — before a process
    pool forks, so that every forked worker inherits it. True when the compiled path is available."""
    return kernel() is not None   # loading the kernels makes their first calls (_first_calls)
