"""Brax spring and positional pipelines: a torque-free tennis racket never flips (no gyroscopic term).
Free body I = (1, 2, 3) kg m^2, spin 2 rad/s about the intermediate axis (y) with 0.5 % on x and z, no
gravity, dt = 1 ms, 30 s, float64. The physical motion flips (L's share on body y goes from +1 to -1)
every ~9 s, first at t = 6.1 s. Usage: python brax_no_gyro_racket.py [spring|positional|generalized].
Exit 1 while the body never flips."""
import platform
import sys
import warnings
from importlib.metadata import version

import jax

jax.config.update("jax_enable_x64", True)
import jax.numpy as jp  # noqa: E402
import numpy as np  # noqa: E402
from brax.io import mjcf  # noqa: E402

name = sys.argv[1] if len(sys.argv) > 1 else "spring"
pipeline = {"spring": "brax.spring.pipeline", "positional": "brax.positional.pipeline",
            "generalized": "brax.generalized.pipeline"}[name]
P = __import__(pipeline, fromlist=["step"])
XML = """<mujoco><compiler inertiafromgeom="false"/><option timestep="0.001" gravity="0 0 0"/>
  <worldbody><body><freejoint/><inertial pos="0 0 0" mass="1" diaginertia="1 2 3"/>
  <geom type="sphere" size="0.01" contype="0" conaffinity="0" mass="0"/></body></worldbody></mujoco>"""
with warnings.catch_warnings():
    warnings.simplefilter("ignore")           # "Brax System, piplines and environments are not actively ..."
    sys_ = mjcf.loads(XML)
sys_ = sys_.replace(vel_damping=0.0, ang_damping=0.0, matrix_inv_iterations=0)
I_P, N = np.array([1.0, 2.0, 3.0]), 30000
state = P.init(sys_, jp.zeros(7).at[3].set(1.0), jp.array([0, 0, 0, 0.01, 2.0, 0.01]))  # qd: v, omega_body


def rollout(state):
    def f(s, _):
        s = P.step(sys_, s, jp.zeros(sys_.act_size()))
        return s, (s.x.rot[0], s.xd.ang[0])
    return jax.lax.scan(f, state, None, length=N)[1]


rot, ang = map(np.asarray, jax.jit(rollout)(state))
w, x, y, z = rot.T
R = np.stack([np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
              np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
              np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1)], -2)
w_B = np.einsum("nji,nj->ni", R, ang)                    # body-axes omega
L_B = I_P * w_B
share = L_B[:, 1] / np.linalg.norm(L_B, axis=1)
flips, side = [], 1.0
for k, s in enumerate(share):
    if s * side < -0.5:
        side = -side
        flips.append((k + 1) * 1e-3)
E = 0.5 * np.sum(w_B * L_B, axis=1)
print(f"brax {version('brax')} ({name}), jax {jax.__version__}, numpy {np.__version__}, "
      f"python {platform.python_version()}, {platform.platform()}")
print(f"{len(flips)} flips in 30 s" + (f" (first at {flips[0]:.2f} s)" if flips else "")
      + f", expected 3 (first at 6.06 s); L's body-y share from {share.min():+.4f} to {share.max():+.4f}; "
      f"world omega moved by {np.abs(ang - ang[0]).max():.3g} rad/s; energy {E[-1] / E[0] - 1:+.2e}")
sys.exit(0 if flips else 1)
