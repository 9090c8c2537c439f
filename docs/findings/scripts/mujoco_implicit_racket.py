"""MuJoCo: the implicit integrators turn a torque-free tennis racket (intermediate-axis spin) into a
major-axis spin. Free body I = (1, 2, 3) kg m^2, spin 2 rad/s about the intermediate axis (y) with 1 % on
x and z, no gravity, no geom; 1000 spin periods. Torque-free: E and |L| are constant, so is
delta = (2 E I2 - |L|^2) / |L|^2 (-5e-5 here: the body keeps flipping; -1/3 is a pure major-axis spin).
Usage: python mujoco_implicit_racket.py [INTEGRATOR [TIMESTEP]] (default implicitfast 0.05).
Exit 1 while delta at the end is below -0.1."""
import platform
import sys

import mujoco
import numpy as np

integrator = sys.argv[1] if len(sys.argv) > 1 else "implicitfast"
dt = float(sys.argv[2]) if len(sys.argv) > 2 else 0.05
I_P, T = np.array([1.0, 2.0, 3.0]), 1000 * 2 * np.pi / 2.0
model = mujoco.MjModel.from_xml_string(f"""
<mujoco><option gravity="0 0 0" timestep="{dt}" integrator="{integrator}"/>
  <worldbody><body><freejoint/><inertial pos="0 0 0" mass="1" diaginertia="1 2 3"/></body></worldbody>
</mujoco>""")
data = mujoco.MjData(model)
data.qvel[3:6] = [0.02, 2.0, 0.02]          # angular velocity, body axes (= world at the identity)


def invariants():
    w = data.qvel[3:6]                      # body axes
    L2 = np.sum((I_P * w) ** 2)
    return 0.5 * w @ (I_P * w), np.sqrt(L2), (w @ (I_P * w) * I_P[1] - L2) / L2


print(f"mujoco {mujoco.__version__}, {integrator}, dt = {dt} s, numpy {np.__version__}, "
      f"python {platform.python_version()}, {platform.platform()}")
E0, L0, d0 = invariants()
n = int(round(T / dt))
flips, side = [], 1.0                        # a flip: L's body-y share goes from > +1/2 to < -1/2 or back
for k in range(1, n + 1):
    mujoco.mj_step(model, data)
    share = I_P[1] * data.qvel[4] / np.linalg.norm(I_P * data.qvel[3:6])
    if share * side < -0.5:
        side = -side
        flips.append(k * dt)
    if k in (n // 100, n // 10, n // 4, n):
        E, L, d = invariants()
        print(f"t = {k * dt:7.1f} s: energy {E / E0 - 1:+.3e}, |L| {L / L0 - 1:+.3e}, delta {d:+.4e} "
              f"(start {d0:+.4e}), {len(flips)} flips so far"
              + (f", last at {flips[-1]:.0f} s" if flips else ""))
sys.exit(1 if d < -0.1 else 0)
