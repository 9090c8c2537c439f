"""Newton SolverFeatherstone: a free body's rotation depends on how far it is from the world origin.

A torque-free box (10 kg, 0.1 x 0.4 x 0.9 m: principal moments 0.808, 0.683, 0.142 kg m^2) tumbling at
omega = (0.1, 5, 0.1) rad/s, no gravity, on a FREE joint, placed at distances d from the origin (along -z).
Its dynamics do not depend on d. (1) One step of dt = 1 ms: the change of omega at each d against the
float64 explicit step of Euler's equations. (2) 2 s of steps: the kinetic energy (constant). Exit 1 while
the one-step change at 1 km is off by more than 1 %.
"""
import platform
import sys

import numpy as np
import warp as wp

wp.config.quiet = True
import newton  # noqa: E402

M, I_B = 10.0, np.diag([0.808333333333, 0.683333333333, 0.141666666667])
W0, DT = np.array([0.1, 5.0, 0.1]), 1e-3


def model_at(d):
    b = newton.ModelBuilder(gravity=(0.0, 0.0, 0.0))
    b.add_body(xform=wp.transform(wp.vec3(0.0, 0.0, 0.0), wp.quat_identity()), com=wp.vec3(0.0, 0.0, 0.0),
               mass=M, inertia=wp.mat33(*I_B.ravel()))
    model = b.finalize(device="cpu", skip_validation_inertia=True)
    solver = newton.solvers.SolverFeatherstone(model, angular_damping=0.0, update_mass_matrix_interval=1)
    s0, s1 = model.state(), model.state()
    s0.joint_q.assign(np.array([0.0, 0.0, -d, 0.0, 0.0, 0.0, 1.0], dtype=np.float32))   # x, q (x y z w)
    s0.joint_qd.assign(np.array([0.0, 0.0, 0.0, *W0], dtype=np.float32))   # v_COM, omega (world)
    return solver, s0, s1


def energy(state):
    q = state.joint_q.numpy()[3:7].astype(float)
    w = state.joint_qd.numpy()[3:6].astype(float)
    x, y, z, s = q
    R = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * s), 2 * (x * z + y * s)],
                  [2 * (x * y + z * s), 1 - 2 * (x * x + z * z), 2 * (y * z - x * s)],
                  [2 * (x * z - y * s), 2 * (y * z + x * s), 1 - 2 * (x * x + y * y)]])
    return 0.5 * w @ (R @ I_B @ R.T @ w)


expected = DT * np.linalg.solve(I_B, -np.cross(W0, I_B @ W0))   # float64, at the identity attitude
print(f"newton {newton.__version__}, warp {wp.__version__}, numpy {np.__version__}, "
      f"python {platform.python_version()}, {platform.platform()}")
print(f"(1) one step; expected change of omega (float64): {expected}")
off = {}
for d in (0.0, 10.0, 100.0, 250.0, 1000.0):
    solver, s0, s1 = model_at(d)
    solver.step(s0, s1, None, None, DT)
    got = s1.joint_qd.numpy()[3:6].astype(float) - W0.astype(np.float32)
    off[d] = np.linalg.norm(got - expected) / np.linalg.norm(expected)
    print(f"  d = {d:6.0f} m: change {got}, off by {100 * off[d]:.3g} %")
print("(2) 2000 steps of 1 ms; kinetic energy relative to its start")
for d in (0.0, 250.0, 1000.0):
    solver, s0, s1 = model_at(d)
    e0 = energy(s0)
    for _ in range(2000):
        solver.step(s0, s1, None, None, DT)
        s0, s1 = s1, s0
    w = np.linalg.norm(s0.joint_qd.numpy()[3:6])
    print(f"  d = {d:6.0f} m: energy {energy(s0) / e0 - 1:+.3e}, |omega| {w:.4g}")
sys.exit(1 if off[1000.0] > 0.01 else 0)
