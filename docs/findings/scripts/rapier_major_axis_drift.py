"""Rapier (rapier3d, gyroscopic forces on): a stable spin about the major axis drifts to the
intermediate-axis separatrix. Body I = (1, 2, 3) kg m^2, spin 2 rad/s about the major axis (z) with 1 %
on x and y, no gravity, no collider, dt = 0.05 s (|w| dt = 0.1), 1000 spin periods (62 832 steps).
Torque-free: the energy E and |L| are constant, and so is the separatrix distance
delta = (2 E I2 - |L|^2) / |L|^2 (-1/3 for a pure major-axis spin, 0 on the separatrix).
Exit 1 while |delta| at the end is below half its start."""
import math
import platform
import sys
from importlib.metadata import version

import numpy as np
import rapier3d as rapier

I_P, W0, DT, N = np.array([1.0, 2.0, 3.0]), (0.02, 0.02, 2.0), 0.05, 62832


def invariants(rb):
    qx, qy, qz, qw = rb.rotation.to_tuple()
    w = np.array(rb.angvel.to_tuple(), dtype=float)
    R = np.array([[1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qz * qw), 2 * (qx * qz + qy * qw)],
                  [2 * (qx * qy + qz * qw), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qx * qw)],
                  [2 * (qx * qz - qy * qw), 2 * (qy * qz + qx * qw), 1 - 2 * (qx * qx + qy * qy)]])
    L = R @ (I_P * (R.T @ w))
    E, L2 = 0.5 * w @ L, L @ L
    return E, math.sqrt(L2), (2 * E * I_P[1] - L2) / L2


world = rapier.PhysicsWorld(gravity=(0.0, 0.0, 0.0))
world.set_num_threads(1)
p = world.integration_parameters
p.dt, p.num_solver_iterations = DT, 1                      # one integration per step (default: 4 substeps)
mp = rapier.MassProperties(local_com=(0.0, 0.0, 0.0), mass=1.0, principal_inertia=tuple(I_P),
                           principal_inertia_local_frame=rapier.Rotation3(1.0, 0.0, 0.0, 0.0))
b = (rapier.RigidBody.dynamic().additional_mass_properties(mp).can_sleep(False).allow_fast_rotation(True)
     .linear_damping(0.0).angular_damping(0.0).gyroscopic_forces(True))
rb = world.rigid_bodies[world.add_body(b)]
rb.angvel = W0
print(f"rapier3d {version('rapier3d')}, numpy {np.__version__}, python {platform.python_version()}, "
      f"{platform.platform()}")
world.step()                                               # mass properties take effect at the first step
rb.position = rapier.Isometry3((0.0, 0.0, 0.0), rapier.Rotation3(1.0, 0.0, 0.0, 0.0))
rb.angvel = W0
E0, L0, d0 = invariants(rb)
for k in range(1, N + 1):
    world.step()
    if k in (N // 100, N // 20, N // 10, N):
        E, L, d = invariants(rb)
        print(f"t = {k * DT:7.1f} s: energy {E / E0 - 1:+.3e}, |L| {L / L0 - 1:+.3e}, delta {d:+.3e} "
              f"(start {d0:+.4f}; a major-axis spin keeps it)")
sys.exit(1 if abs(d) < 0.5 * abs(d0) else 0)
