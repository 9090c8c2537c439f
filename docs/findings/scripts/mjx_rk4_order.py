"""MJX RK4 on a torque-free tumbling body: the attitude converges at order 2, not 4.
Free body I = (1, 2, 3) kg m^2, spin 2 rad/s about the intermediate axis with 0.5 % on the others (the
tennis racket), no gravity, no geom, 10 s, float64. The error at each dt is measured against MuJoCo C's
RK4 at dt = 0.0003125 s (MuJoCo >= 4.0's RK4 converges at order 4 here); the order is
log2(e(dt) / e(dt/2)). Exit 1 while the fitted order is below 3.5."""
import platform
import sys
from importlib.metadata import version

import jax

jax.config.update("jax_enable_x64", True)
import mujoco  # noqa: E402
import numpy as np  # noqa: E402
from mujoco import mjx  # noqa: E402

XML = """<mujoco><option gravity="0 0 0" timestep="{dt}" integrator="RK4"/>
  <worldbody><body><freejoint/><inertial pos="0 0 0" mass="1" diaginertia="1 2 3"/></body></worldbody>
</mujoco>"""
T, W0 = 10.0, [0.01, 2.0, 0.01]          # angular velocity, body axes


def final_quat_c(dt):
    m = mujoco.MjModel.from_xml_string(XML.format(dt=dt))
    d = mujoco.MjData(m)
    d.qvel[3:6] = W0
    mujoco.mj_step(m, d, int(round(T / dt)))
    return d.qpos[3:7].copy()


def final_quat_mjx(dt):
    m = mujoco.MjModel.from_xml_string(XML.format(dt=dt))
    d = mujoco.MjData(m)
    d.qvel[3:6] = W0
    mx, dx = mjx.put_model(m), mjx.put_data(m, d)
    n = int(round(T / dt))
    dx = jax.jit(lambda dx: jax.lax.fori_loop(0, n, lambda _, x: mjx.step(mx, x), dx))(dx)
    return np.asarray(dx.qpos[3:7])


def angle(q, p):                         # rotation angle between two unit quaternions (w x y z), rad
    w = q[0] * p[0] + q[1:] @ p[1:]                   # the relative rotation conj(q) p
    v = q[0] * p[1:] - p[0] * q[1:] - np.cross(q[1:], p[1:])
    return 2 * np.arctan2(np.linalg.norm(v), abs(w))


print(f"mujoco {mujoco.__version__}, mujoco-mjx {version('mujoco-mjx')}, jax {jax.__version__}, "
      f"numpy {np.__version__}, python {platform.python_version()}, {platform.platform()}")
ref = final_quat_c(0.0003125)
errs = {dt: angle(final_quat_mjx(dt), ref) for dt in (0.01, 0.005, 0.0025)}
c_errs = {dt: angle(final_quat_c(dt), ref) for dt in errs}
dts = sorted(errs, reverse=True)
for dt in dts:
    print(f"dt = {dt:<7} attitude error after {T:.0f} s: MJX {errs[dt]:.3e} rad, "
          f"MuJoCo C {c_errs[dt]:.3e} rad")
order, c_order = (np.log2(e[dts[-2]] / e[dts[-1]]) for e in (errs, c_errs))
print(f"MJX RK4 attitude order (last halving): {order:.2f}, expected 4; MuJoCo C RK4: {c_order:.2f}")
if c_order < 3.5:
    print("MuJoCo C's RK4 is not fourth order here (MuJoCo < 4.0): the reference is not accurate enough")
sys.exit(1 if order < 3.5 else 0)
