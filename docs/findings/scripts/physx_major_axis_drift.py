"""PhysX 5.3.1 (through SAPIEN 3.0.3, CPU, PGS; gyroscopic forces on, as SAPIEN sets them): a stable spin
about the major axis drifts to the intermediate-axis separatrix. Body I = (1, 2, 3) kg m^2, spin 2 rad/s
about the major axis (z) with 1 % on x and y, no gravity, no shape, dt = 0.05 s (|w| dt = 0.1), 1000 spin
periods (62 832 steps). Torque-free: E and |L| are constant, and so is
delta = (2 E I2 - |L|^2) / |L|^2 (-1/3 for a pure major-axis spin, 0 on the separatrix).
Exit 1 while |delta| at the end is below half its start."""
import platform
import sys
import warnings
from importlib.metadata import version

import numpy as np

with warnings.catch_warnings():
    warnings.simplefilter("ignore")        # "Failed to find system libvulkan": no rendering here
    import sapien
    import sapien.physx as px

I_P, W0, DT, N = np.array([1.0, 2.0, 3.0]), np.array([0.02, 0.02, 2.0]), 0.05, 62832
TGS = "--tgs" in sys.argv

cfg = px.PhysxSceneConfig()
cfg.gravity = np.float32([0, 0, 0])
cfg.enable_tgs = TGS
px.set_scene_config(cfg)
system = px.PhysxCpuSystem()
scene = sapien.Scene(systems=[system])
system.set_timestep(DT)
entity, c = sapien.Entity(), px.PhysxRigidDynamicComponent()
entity.add_component(c)
c.set_mass(1.0)
c.set_inertia(np.float32(I_P))
c.set_cmass_local_pose(sapien.Pose(np.float32([0, 0, 0]), np.float32([1, 0, 0, 0])))
for setter, value in (("set_linear_damping", 0.0), ("set_angular_damping", 0.0),     # defaults 0, 0.05
                      ("set_max_angular_velocity", 1e16), ("set_sleep_threshold", 0.0)):  # 100 rad/s, 0.005
    getattr(c, setter)(value)
scene.add_entity(entity)
c.set_angular_velocity(np.float32(W0))


def invariants():
    q, w = c.get_entity_pose().q.astype(float), c.get_angular_velocity().astype(float)   # q: w x y z
    qw, qx, qy, qz = q
    R = np.array([[1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qz * qw), 2 * (qx * qz + qy * qw)],
                  [2 * (qx * qy + qz * qw), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qx * qw)],
                  [2 * (qx * qz - qy * qw), 2 * (qy * qz + qx * qw), 1 - 2 * (qx * qx + qy * qy)]])
    L = R @ (I_P * (R.T @ w))
    E, L2 = 0.5 * w @ L, L @ L
    return E, np.sqrt(L2), (2 * E * I_P[1] - L2) / L2


print(f"sapien {version('sapien')} (PhysX 5.3.1), {'TGS' if TGS else 'PGS'}, numpy {np.__version__}, "
      f"python {platform.python_version()}, {platform.platform()}")
E0, L0, d0 = invariants()
for k in range(1, N + 1):
    system.step()
    if k in (N // 100, N // 20, N // 10, N):
        E, L, d = invariants()
        print(f"t = {k * DT:7.1f} s: energy {E / E0 - 1:+.3e}, |L| {L / L0 - 1:+.3e}, delta {d:+.3e} "
              f"(start {d0:+.4f}; a major-axis spin keeps it)")
sys.exit(1 if abs(d) < 0.5 * abs(d0) else 0)
