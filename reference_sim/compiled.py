"""The compiled fast path of a single-body reference run: :mod:`reference_sim.scalar`'s steps, compiled.

A reference run of one body steps the plain-float kernel (:class:`reference_sim.scalar.ScalarStepper`) in
Python: 5–30 µs a step, which made the reference schemes two thirds of a default sweep's run stage. This
module is the same arithmetic, operation for operation and in the same order, compiled by numba
(``fastmath`` off, so no reassociation or fused multiply-add): every state it writes is bit-identical to
the one the Python step writes (tests/reference_sim/test_compiled.py, on the catalog and on random
problems, every variant). ``ScalarStepper`` stays the readable definition of the fast path, and the code
the planted-bug zoo (tests/mutants.py) patches:

* the parameters (mass, inertia, forces, decay factors and rates, flags) are read from a stepper built by
  ``ScalarStepper.__init__`` — a bug planted there reaches the compiled run too;
* the arithmetic is used only while ``ScalarStepper``'s step methods are the ones this module transcribes
  (:func:`usable`): a patched method makes the run step in Python, through the patch.

The compiled loop stops at the first step that is not routine — a state that is non-finite or beyond
``BLOWUP_LIMIT``, a leapfrog half kick that does not converge, an implicit Euler fixed point that stalls
(the Python step then hands it to Newton's method) — and returns. The caller takes that one step in Python
(which raises, flags the bad state, or solves it exactly as a Python-only run would) and resumes compiled.
So a run, a divergence and its message are the ones of the Python path, only faster.

numba is imported on first use (~0.5 s), and the kernels are compiled once per machine (``cache=True``).
State layout as everywhere: [x_W (3) m, v_W (3) m/s, q_WB (w, x, y, z), w_W (3) rad/s].
"""
from __future__ import annotations

import numpy as np

__all__ = ["VARIANT_CODES", "usable", "parameters", "run_until_exceptional"]

#: The variants the compiled loop knows, by code (the ``variant`` argument of the kernels).
VARIANT_CODES = {"course": 0, "course_gyro": 1, "expmap_gyro": 2, "explicit_euler": 3, "midpoint": 4,
                 "rk4": 5, "leapfrog": 6, "implicit_euler": 7}


def usable(stepper, variant: str | None = None) -> bool:
    """Whether a run of ``stepper`` may step compiled: a float-backend ``ScalarStepper`` (not a subclass)
    whose step methods are the shipped ones, and a variant the compiled loop knows (``variant``, default the
    stepper's own: a stepper's parameters do not depend on its scheme, so one stepper serves every scheme)."""
    from reference_sim.scalar import SHIPPED_CLASS, SHIPPED_METHODS
    if type(stepper) is not SHIPPED_CLASS:
        return False
    variant = stepper.variant if variant is None else variant
    if stepper.backend != "float" or variant not in VARIANT_CODES:
        return False
    d = SHIPPED_CLASS.__dict__
    if any(d.get(name) is not fn for name, fn in SHIPPED_METHODS.items()):
        return False
    if any(name in vars(stepper) for name in SHIPPED_METHODS):   # nor replaced on the instance
        return False
    return _kernel() is not None


_KERNEL: list = []


def _kernel():
    """The compiled run loop, or None where numba cannot be imported or cannot cache (then every run steps
    in Python).
    numba is imported, and the kernels compiled or loaded from numba's cache, once per process."""
    if not _KERNEL:
        try:
            from reference_sim import _compiled_kernels
        except (ImportError, RuntimeError, OSError):   # no numba, or nowhere numba may write its cache
            _KERNEL.append(None)
        else:
            _KERNEL.append(_compiled_kernels.run)
    return _KERNEL[0]


def parameters(stepper) -> tuple:
    """The compiled kernels' arguments after ``variant`` and the state arrays, read from ``stepper``'s
    attributes (what ``ScalarStepper.__init__`` set, planted bugs included)."""
    f = np.float64
    scalars = np.array([stepper.h, stepper.m, stepper.c, stepper.gv, stepper.gw, stepper.kv, stepper.kw], dtype=f)
    flags = np.array([stepper.has_drag, stepper.has_body_torque, stepper.has_velocity_decay,
                      stepper.has_angular_decay], dtype=np.bool_)
    springs = np.array([[*a, *r, k, L0] for a, r, k, L0 in stepper.springs], dtype=f).reshape(-1, 8)
    world = np.array([[*fv, *r] for fv, r in stepper.world_point], dtype=f).reshape(-1, 6)
    body = np.array([[*fv, *r] for fv, r in stepper.body_point], dtype=f).reshape(-1, 6)
    return (scalars, flags, np.array(stepper.I, dtype=f), np.array(stepper.Iinv, dtype=f),
            np.array(stepper.mg, dtype=f), np.array(stepper.fixed_f, dtype=f), np.array(stepper.tau_W, dtype=f),
            np.array(stepper.tau_B, dtype=f), springs, world, body)


def run_until_exceptional(stepper, rows: np.ndarray, start: int, n_steps: int, limit: float,
                          variant: str | None = None, params: tuple | None = None) -> int:
    """Step ``rows[start]`` compiled, writing ``rows[start + 1]``, … (``rows`` (n_steps + 1, 13), C order),
    until ``n_steps`` is reached or the next step is not routine (module doc; a state with a component beyond
    ``limit`` is not), with the scheme ``variant`` (default: the stepper's) and the stepper's
    :func:`parameters` (``params``: computed once by a caller that calls again). ``rows`` may be longer than
    ``n_steps + 1`` (a run taken in chunks). Returns the index of the last state written: ``n_steps``, or
    k < n_steps when step k + 1 must be taken in Python."""
    if rows.dtype != np.float64 or not rows.flags.c_contiguous or rows.ndim != 2 or rows.shape[1] != 13:
        raise ValueError("rows must be a C-contiguous float64 (n, 13) array")
    if not 0 <= start <= n_steps < rows.shape[0]:   # the compiled loop does not check its indices
        raise ValueError(f"steps {start}..{n_steps} do not fit rows of {rows.shape[0]} states")
    from reference_sim.scalar import IMPLICIT_TOL, MAX_ITER
    code = VARIANT_CODES[stepper.variant if variant is None else variant]
    return int(_kernel()(code, rows, int(start), int(n_steps), float(limit), float(IMPLICIT_TOL), int(MAX_ITER),
                         *(parameters(stepper) if params is None else params)))



def warm() -> bool:
    """Load (or, the first time on a machine, compile) the compiled loop in this process — before a process
    pool forks, so that every forked worker inherits it instead of loading or compiling it again. True when
    the compiled path is available."""
    run = _kernel()
    if run is None:
        return False
    from reference_sim.body import RigidBody
    from reference_sim.forces import ForceModel
    from reference_sim.scalar import ScalarStepper
    from reference_sim.state import Problem, State
    problem = Problem(RigidBody(1.0, [1.0, 1.0, 1.0]), ForceModel(),
                      State(np.zeros(3), np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0]), np.zeros(3)))
    rows = np.zeros((2, 13))
    rows[0, 6] = 1.0
    run_until_exceptional(ScalarStepper(problem, "rk4", 0.01), rows, 0, 1, 1e8)   # one signature: all compiled
    return True
