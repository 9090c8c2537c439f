"""Newton's world (NVIDIA Warp's CPU device, float32): numpy, warp and newton only (and mujoco for the
``mujoco_cpu`` solver's autoreset flag); ``rbcheck repro`` embeds this file as it is.

One Newton world per body (each with its own gravity) in models of at most ``max_batch`` bodies: jointless
links for ``semi_implicit`` and ``xpbd`` (``State.body_q``/``body_qd``), a FREE joint for ``featherstone``
and ``mujoco_cpu`` (``joint_q``/``joint_qd``); ``com = 0`` (body origin = COM), the mass and the full inertia
tensor (about the COM, body axes), kept by ``finalize`` (checked); no shape. Every solver default that is
not the physics set explicitly (:data:`SOLVER_SETTINGS`). State: ``[x_W, q_WB (x, y, z, w)]`` (Warp
quaternions are xyzw) and ``[v_W (COM), ω_W]``, linear first, world axes; the force (the weight off: Newton
applies gravity) and torque in the input state's ``body_f`` before every step.
docs/engine_conventions.md, "Newton 1.8.0".
"""
import warnings

import numpy as np

#: The solver class of each variant (``newton.solvers.<name>``).
SOLVERS = {"semi_implicit": "SolverSemiImplicit", "xpbd": "SolverXPBD", "featherstone": "SolverFeatherstone",
           "mujoco_cpu": "SolverMuJoCo"}
#: Constructor arguments of each solver: every default that is not the scenario's physics, set explicitly
#: (Newton 1.8.0's defaults: angular_damping 0.05 for SemiImplicit and Featherstone).
SOLVER_SETTINGS = {
    "semi_implicit": {"angular_damping": 0.0},
    "xpbd": {"angular_damping": 0.0, "iterations": 2, "enable_restitution": False},
    "featherstone": {"angular_damping": 0.0, "update_mass_matrix_interval": 1},
    "mujoco_cpu": {"use_mujoco_cpu": True, "integrator": "implicitfast", "disable_contacts": True,
                   "kinematic_switchable_roots": False},
}
#: Variants whose state is Newton's generalized coordinates (``joint_q``/``joint_qd`` of a FREE joint).
GENERALIZED = frozenset({"featherstone", "mujoco_cpu"})
#: Variants whose model takes one body only (SolverMuJoCo on MuJoCo C refuses a model of several worlds).
ONE_BODY = frozenset({"mujoco_cpu"})


class Refused(Exception):
    """Newton refused the model or (``solver``) the solver, in its own words; ``backend``: a module the solver
    needs is missing (ImportError)."""

    def __init__(self, message, solver=False, backend=False):
        super().__init__(message)
        self.solver, self.backend = solver, backend


def engine():
    """``(warp, newton)``; Warp's log level at warnings (no banner, no module-load lines on stdout)."""
    import warp as wp
    wp.config.log_level = wp.LOG_WARNING
    import newton
    return wp, newton


def build_model(variant, bodies):
    """A finalized Newton model on the CPU with one world per body of ``bodies`` (``(mass kg, I_B kg m²
    (3, 3), gravity_W m/s² (3,))`` each): FREE-jointed bodies for :data:`GENERALIZED`, else jointless links;
    com = 0, no shape. Refused when ``finalize`` fails or did not keep the mass or the inertia."""
    wp, newton = engine()
    builder = newton.ModelBuilder(gravity=(0.0, 0.0, 0.0))
    add = builder.add_body if variant in GENERALIZED else builder.add_link
    for mass, inertia, gravity in bodies:
        builder.begin_world(gravity=tuple(float(g) for g in gravity))
        add(xform=wp.transform(wp.vec3(0.0, 0.0, 0.0), wp.quat_identity()), com=wp.vec3(0.0, 0.0, 0.0),
            mass=float(mass), inertia=wp.mat33(*(float(v) for v in np.asarray(inertia, dtype=float).ravel())))
        builder.end_world()
    try:
        # skip_validation_inertia: finalize would otherwise "correct" a tensor it finds non-physical (another
        # body); any warning of finalize refuses the model
        with warnings.catch_warnings():
            warnings.simplefilter("error", category=UserWarning)
            model = builder.finalize(device="cpu", skip_validation_inertia=True)
    except Exception as exc:  # noqa: BLE001 - Newton refuses the model: its own words
        raise Refused(f"refused the model: {type(exc).__name__}: {exc}") from None
    want_m = np.array([b[0] for b in bodies], dtype=np.float32)
    want_i = np.array([np.asarray(b[1], dtype=float) for b in bodies], dtype=np.float32)
    if not (np.array_equal(model.body_mass.numpy(), want_m)
            and np.array_equal(model.body_inertia.numpy(), want_i)):
        raise Refused("changed the body's mass or inertia when finalizing the model")
    return model


def make_solver(variant, model):
    """The variant's Newton solver for ``model``, every setting of SOLVER_SETTINGS applied; for
    ``mujoco_cpu`` MuJoCo's autoreset off (it would restart a blown-up body from rest, with a warning)."""
    _, newton = engine()
    with warnings.catch_warnings():
        # SolverMuJoCo warns when MuJoCo is not the ~=3.17.0 Newton 1.8.0 declares
        warnings.filterwarnings("ignore", message="MuJoCo dependency version mismatch")
        try:
            solver = getattr(newton.solvers, SOLVERS[variant])(model, **SOLVER_SETTINGS[variant])
        except (ImportError, ValueError) as exc:   # a missing backend, a model it refuses: its own words
            raise Refused(f"{SOLVERS[variant]} refused the model: {type(exc).__name__}: {exc}",
                          solver=True, backend=isinstance(exc, ImportError)) from None
    if variant == "mujoco_cpu":
        import mujoco
        solver.mj_model.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_AUTORESET)
    return solver


def to_newton_rows(y):
    """Packed states (N, 13) ``[x_W, v_W, q_WB (w x y z), ω_W]`` -> ``(q (N, 7) [x, qx, qy, qz, qw],
    qd (N, 6) [v_COM, ω], both world axes)``, float64 (the caller casts)."""
    y = np.asarray(y, dtype=float).reshape(-1, 13)
    q = np.concatenate([y[:, 0:3], y[:, 7:10], y[:, 6:7]], axis=1)
    qd = np.concatenate([y[:, 3:6], y[:, 10:13]], axis=1)
    return q, qd


def from_newton_rows(q, qd):
    """Newton's ``(q (..., 7) [x, qx, qy, qz, qw], qd (..., 6) [v, ω])`` -> packed (..., 13), float64."""
    q = np.asarray(q, dtype=float)
    qd = np.asarray(qd, dtype=float)
    return np.concatenate([q[..., 0:3], qd[..., 0:3], q[..., 6:7], q[..., 3:6], qd[..., 3:6]], axis=-1)


class Batch:
    """Bodies stepping together in one model: its solver, two states (swapped each step) and their zero-copy
    NumPy views of the pose (N, 7), velocity (N, 6) and applied wrench (N, 6) (float32)."""

    def __init__(self, variant, bodies):
        self.model = build_model(variant, bodies)
        self.solver = make_solver(variant, self.model)
        self.states = [self.model.state(), self.model.state()]
        q, qd = ("joint_q", "joint_qd") if variant in GENERALIZED else ("body_q", "body_qd")
        self.views = [(getattr(s, q).numpy().reshape(-1, 7), getattr(s, qd).numpy().reshape(-1, 6),
                       s.body_f.numpy()) for s in self.states]   # (q, qd, f) of each state

    def step(self, dt_s):
        self.solver.step(self.states[0], self.states[1], None, None, dt_s)
        self.states.reverse()
        self.views.reverse()


class Bodies:
    """``bodies`` (``(mass, I_B, gravity_W)`` each) as :class:`Batch` models of at most ``max_batch`` (one for
    :data:`ONE_BODY`) stepping at ``dt_s``. Raw rows: ``[q (x, q_xyzw), qd (v, ω)]`` (13 float32 values),
    world axes."""

    def __init__(self, variant, bodies, dt_s, max_batch=256):
        self.dt_s, size = float(dt_s), 1 if variant in ONE_BODY else int(max_batch)
        self.parts = [(slice(s, s + size), Batch(variant, bodies[s:s + size]))
                      for s in range(0, len(bodies), size)]

    def set_state(self, y):
        q, qd = to_newton_rows(y)
        for part, b in self.parts:
            b.views[0][0][:], b.views[0][1][:] = q[part], qd[part]

    def apply(self, f_W, tau_W):   # into the input state's body_f (float32), for the next step
        for part, b in self.parts:
            f = b.views[0][2]
            f[:, 0:3], f[:, 3:6] = f_W[part], tau_W[part]

    def decay(self, g_v, g_w):   # the float32 velocities scaled in float64, rounded to float32
        for part, b in self.parts:
            qd = b.views[0][1]
            qd[:, 0:3] *= g_v[part, None]
            qd[:, 3:6] *= g_w[part, None]

    def step(self):
        for _, b in self.parts:
            b.step(self.dt_s)

    def read(self):
        return np.concatenate([np.concatenate(b.views[0][0:2], axis=1) for _, b in self.parts]).astype(float)

    def packed(self, raw):
        raw = np.asarray(raw, dtype=float)
        return from_newton_rows(raw[..., 0:7], raw[..., 7:13])


def world(bodies, gravity_W, variant, dt_s):
    return Bodies(variant, [(mass_kg, inertia_B, gravity_W) for mass_kg, inertia_B, _ in bodies], dt_s)
