"""The reference's N-body kernel stepping N DIFFERENT cases at once: one scheme, per-case parameters.

:class:`reference_sim.scalar.ScalarStepper` writes every variant's step once on plain numbers and runs it
on two backends: one body on Python floats, or N states of ONE problem on (N,) NumPy columns. A fuzz
batch holds N different cases (bodies, forces, steps). :class:`CaseKernel` stacks N float-backend
steppers — one per case, built by ``ScalarStepper.__init__`` itself, so a planted bug in a copy of a
scheme reaches the batch exactly as it reaches a single run — into one NumPy-backend stepper whose
parameters are (N,) columns: mass, inertia, gravity, drag, decay factors and rates, the time step, and
every force list padded with zero entries (a zero spring, force or torque adds an exact 0.0, so every
member computes the numbers its own float stepper computes, operation for operation).

Members are bit-identical to ``ScalarStepper(problem_i, variant, h_i).step`` (tested), with one
exception: ``leapfrog`` iterates its implicit half kick until EVERY member has converged, which moves a
member that converged earlier by round-off (its own stepper would have stopped). ``implicit_euler``
keeps each member's fixed point on its own stopping rule and hands a member that stalls to the Newton
solve of the batched definition, as the float stepper does.

State layout as everywhere: 13 (N,) columns [x_W (3), v_W (3), q_WB (w, x, y, z), w_W (3)] (m, m/s, -, rad/s).
"""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np

from reference_sim.integrators import IMPLICIT_TOL, ImplicitSolveError, get_step
from reference_sim.scalar import ScalarStepper

__all__ = ["CaseKernel", "columns", "rows", "clear_cache"]

_MAX_ITER = 50


def _col(values) -> np.ndarray:
    return np.ascontiguousarray(np.asarray(values, dtype=float))


def columns(y) -> list:
    """(N, 13) states -> the 13 contiguous (N,) columns the kernel steps."""
    y = np.asarray(y, dtype=float)
    return [np.ascontiguousarray(y[:, i]) for i in range(13)]


def rows(cols) -> np.ndarray:
    """13 (N,) columns -> (N, 13) states."""
    return np.stack([np.asarray(c, dtype=float) for c in cols], axis=-1)


#: Float steppers of the batch's (problem, step) members, shared by every variant: a stepper's parameters
#: (mass, inertia, forces, decay factors at its step) do not depend on the scheme, which the kernel takes
#: from its own ``variant``. {(id(problem), h, ScalarStepper.__init__): (problem, stepper)}; the problem is
#: kept so that its id cannot be reused while cached, and ``__init__`` is in the key so that a stepper built
#: before a bug was planted there (tests/mutants.py) is never served after.
_STEPPERS: dict = {}
_STEPPERS_MAX = 4096   # a batch: 64 cases x (3 free-running + 4 one-step rungs), and the drivers' harness


def _stepper(problem, h: float) -> ScalarStepper:
    """The float stepper of ``problem`` at step ``h`` (s), built once by ``ScalarStepper.__init__`` (with a
    fixed scheme name: its parameters are the same for every scheme) and shared by the batch's kernels."""
    key = (id(problem), h, ScalarStepper.__init__)
    hit = _STEPPERS.get(key)
    if hit is None or hit[0] is not problem:
        if len(_STEPPERS) >= _STEPPERS_MAX:
            _STEPPERS.clear()
        hit = _STEPPERS[key] = (problem, ScalarStepper(problem, "course", h))
    return hit[1]


#: Parameter columns per list of steppers (:func:`_parameters`): {ids: (steppers, [(attribute, value)])}.
_PARAMETERS: dict = {}
_PARAMETERS_MAX = 256


def _parameters(steppers) -> list:
    """The kernel's (N,) parameter columns and ``if`` flags of ``steppers``: [(attribute, value)], computed once
    per list of steppers (every scheme's kernel of a batch stacks the same ones; the columns are never written
    into: reference_sim/scalar.py has no augmented assignment on a parameter)."""
    key = tuple(map(id, steppers))
    hit = _PARAMETERS.get(key)
    if hit is not None and all(a is b for a, b in zip(hit[0], steppers)):
        return hit[1]
    if len(_PARAMETERS) >= _PARAMETERS_MAX:
        _PARAMETERS.clear()
    k = SimpleNamespace()
    s = steppers
    k.h = _col([t.h for t in s])
    k.m = _col([t.m for t in s])
    k.I = [[_col([t.I[i][j] for t in s]) for j in range(3)] for i in range(3)]
    k.Iinv = [[_col([t.Iinv[i][j] for t in s]) for j in range(3)] for i in range(3)]
    k.mg = [_col([t.mg[i] for t in s]) for i in range(3)]
    k.c = _col([t.c for t in s])
    k.gv, k.gw = _col([t.gv for t in s]), _col([t.gw for t in s])
    k.kv, k.kw = _col([t.kv for t in s]), _col([t.kw for t in s])
    zero3 = [0.0, 0.0, 0.0]
    springs = _padded([t.springs for t in s], max(len(t.springs) for t in s), (zero3, zero3, 0.0, 0.0))
    k.springs = [([_col([m[j][0][i] for m in springs]) for i in range(3)],
                  [_col([m[j][1][i] for m in springs]) for i in range(3)],
                  _col([m[j][2] for m in springs]), _col([m[j][3] for m in springs]))
                 for j in range(len(springs[0]) if springs else 0)]
    k.fixed_f = [_col([t.fixed_f[i] for t in s]) for i in range(3)]
    for name in ("world_point", "body_point"):
        lists = _padded([getattr(t, name) for t in s], max(len(getattr(t, name)) for t in s), (zero3, zero3))
        setattr(k, name, [([_col([m[j][0][i] for m in lists]) for i in range(3)],
                           [_col([m[j][1][i] for m in lists]) for i in range(3)])
                          for j in range(len(lists[0]) if lists else 0)])
    k.tau_W = [_col([t.tau_W[i] for t in s]) for i in range(3)]
    k.tau_B = [_col([t.tau_B[i] for t in s]) for i in range(3)]
    # the ``if`` tests of the step: true when ANY member's entry is non-zero (the others add an exact 0.0)
    k.has_drag = bool(np.any(k.c))
    k.has_body_torque = bool(any(np.any(c) for c in k.tau_B))
    k.has_velocity_decay, k.has_angular_decay = bool(np.any(k.kv)), bool(np.any(k.kw))
    out = list(vars(k).items())
    _PARAMETERS[key] = (list(steppers), out)
    return out


def clear_cache() -> None:
    """Forget the shared steppers and parameter columns (the end of a batch)."""
    _STEPPERS.clear()
    _PARAMETERS.clear()


def _padded(lists, width, empty):
    """Per member a list of entries -> ``width`` entries each (``empty`` fills the missing ones)."""
    return [list(entries) + [empty] * (width - len(entries)) for entries in lists]


class CaseKernel(ScalarStepper):
    """One scheme (``variant``) stepping N cases, each with its own problem and step (see module doc).

    Build with :meth:`stack`; ``step(cols) -> cols`` and ``rhs(cols)`` act on 13 (N,) columns.
    ``problems`` and ``h_s`` keep what each member was built from (``take`` selects members).
    Parameters are plain (N,) arrays, so each operation of the step is one NumPy call on the batch.
    """

    # ScalarStepper's ``if`` flags, set per batch by _from_steppers (plain attributes over its properties)
    has_drag = has_body_torque = has_velocity_decay = has_angular_decay = False

    @classmethod
    def stack(cls, problems, variant: str, h_s) -> CaseKernel:
        """The kernel of ``variant`` for members ``problems[i]`` at steps ``h_s[i]`` (s)."""
        h_s = [float(h) for h in np.broadcast_to(np.asarray(h_s, dtype=float), (len(problems),))]
        get_step(variant)  # validates the name (the shared steppers may have been built for another)
        steppers = [_stepper(p, h) for p, h in zip(problems, h_s)]
        return cls._from_steppers(steppers, list(problems), variant, h_s)

    @classmethod
    def _from_steppers(cls, steppers, problems, variant, h_s) -> CaseKernel:
        k = object.__new__(cls)
        k.problems, k.h_s, k.variant = problems, h_s, variant
        k.problem = problems[0]
        k.xp = ScalarStepper(problems[0], variant, h_s[0], backend="numpy").xp
        k.backend = "numpy"
        k.n = len(steppers)
        for name, value in _parameters(steppers):
            setattr(k, name, value)
        k._steppers = steppers
        k.step = {
            "course": lambda y: k._course(y, gyro=False, expmap=False),
            "course_gyro": lambda y: k._course(y, gyro=True, expmap=False),
            "expmap_gyro": lambda y: k._course(y, gyro=True, expmap=True),
            "explicit_euler": k._explicit_euler,
            "midpoint": k._midpoint,
            "rk4": k._rk4,
            "leapfrog": k._leapfrog_guarded,
            "implicit_euler": k._implicit_euler,
        }[variant]
        return k

    def take(self, idx) -> CaseKernel:
        """The kernel of the members ``idx`` only (same steppers, same arithmetic)."""
        idx = [int(i) for i in np.atleast_1d(idx)]
        return self._from_steppers([self._steppers[i] for i in idx], [self.problems[i] for i in idx], self.variant,
                                   [self.h_s[i] for i in idx])

    # -- what the adapters' harness evaluates, per member ------------------------------------------
    def force_torque_cols(self, y):
        """World force at the COM and world torque (6 (N,) columns) at states ``y`` (13 columns), the
        rotation taken from q/|q| — ScalarStepper.force_torque, member by member."""
        qw, qx, qy, qz = y[6:10]
        n = np.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
        return self._force_torque(y[0:3], y[3:6], self._rot(qw / n, qx / n, qy / n, qz / n))

    # -- schemes whose iteration must stop member by member ------------------------------------------
    def _leapfrog_guarded(self, y):
        """Leapfrog on the whole batch; a batch whose implicit half kick does not converge for some member
        is stepped member by member instead (each on its own float stepper's rule)."""
        try:
            return self._leapfrog(y)
        except ImplicitSolveError:
            return self._per_member(y)

    def _per_member(self, y):
        """Leapfrog, each member on its own float stepper (its stopping rule)."""
        out = [np.empty(self.n) for _ in range(13)]
        for i, st in enumerate(self._steppers):
            try:
                yi = st._leapfrog([float(c[i]) for c in y])   # the shared stepper's own step is not this scheme's
            except (ImplicitSolveError, np.linalg.LinAlgError, ArithmeticError, ValueError):
                yi = [math.nan] * 13
            for c, v in zip(out, yi):
                c[i] = v
        return out

    def _implicit_euler(self, y):
        """Backward Euler: each member's fixed point ``z ← y + Δt F(z)`` from the explicit predictor, stopped
        on its own rule (converged: IMPLICIT_TOL; not contracting by 0.9: Newton of the batched definition
        for that member) — the float stepper's iteration, member by member."""
        h = self.h
        z = [a + h * b for a, b in zip(y, self.rhs(y))]
        running = np.ones(self.n, dtype=bool)
        converged = np.zeros(self.n, dtype=bool)
        prev = np.full(self.n, np.inf)
        with np.errstate(all="ignore"):
            for _ in range(_MAX_ITER):
                z_new = [a + h * b for a, b in zip(y, self.rhs(z))]
                d = np.max([np.abs(a - b) / (1.0 + np.abs(a)) for a, b in zip(z_new, z)], axis=0)
                z = [np.where(running, a, b) for a, b in zip(z_new, z)]
                done = running & (d <= IMPLICIT_TOL)
                converged |= done
                stall = running & ~done & ~(d < 0.9 * prev)
                prev = np.where(running, d, prev)
                running &= ~(done | stall)
                if not running.any():
                    break
        out = self._finish(z)
        for i in np.flatnonzero(~converged):
            try:
                yi = get_step("implicit_euler")(self.problems[i], np.array([float(c[i]) for c in y]), self.h_s[i])
            except (ImplicitSolveError, np.linalg.LinAlgError):
                yi = np.full(13, np.nan)
            for c, v in zip(out, yi):
                c[i] = v
        return out


def runs_compiled(variant: str, problems, h_s, y0, n_steps):
    """Each member's free run of ``variant``, stepped compiled (reference_sim.compiled) member by member:
    ``[(y (n_steps[i] + 1, 13), k)]`` with ``k`` the step at which the member diverged (its states from ``k``
    on are not meaningful) or None; or None when the compiled path is not usable (a planted bug in a step
    method, or no numba) — then the caller steps the NumPy-wide kernel.

    Each member is bit-identical to ``ScalarStepper(problems[i], variant, h_s[i])``'s own steps (the kernel's
    leapfrog, which iterates until every member has converged, is not; see the module doc). A step the compiled
    loop does not take (a blow-up, a solve it does not finish) is taken by that float stepper: it raises or
    gives a bad state (the member diverged at that step) or solves it, and the loop resumes."""
    from reference_sim import compiled
    steppers = [_stepper(p, float(h)) for p, h in zip(problems, h_s)]
    if not steppers or not compiled.usable(steppers[0], variant):
        return None
    from reference_sim.simulate import steps_compiled
    out = []
    with np.errstate(all="ignore"):
        for p, h, st, y, n in zip(problems, h_s, steppers, y0, n_steps):
            rows = np.empty((int(n) + 1, 13))
            rows[0] = y
            # the float stepper of the scheme itself, built only for a step the compiled loop hands over
            python_step = (lambda row, p=p, h=float(h): ScalarStepper(p, variant, h).step(row))
            k, _ = steps_compiled(st, rows, int(n), python_step, variant)
            out.append((rows, k))
    return out
