"""MJX's world (MuJoCo's physics in JAX, float64): numpy, jax and mujoco only. ``rbcheck repro`` embeds this
file's code after worlds/mujoco.py, whose MjSpec model and state conversion it uses (it leaves out the
relative import below, and MuJoCo's ``Bodies`` and ``world``, which this file redefines). The model is
MuJoCo's ``build_model``, put on the device by
``mjx.put_model``; a step is :func:`step_one`: the pre-step decay as gains on qvel, the applied force and
torque in ``xfrc_applied`` (world force at the COM, world torque), then ``mjx.step``. rbcheck's adapter
(cross_checks/engines/mjx_engine.py) runs :func:`step_one` vmapped in a compiled loop."""
import jax
import mujoco
import numpy as np
from mujoco import mjx

from .mujoco import build_model, to_packed, to_qpos_qvel  # in a reproducer: the world above

jax.config.update("jax_enable_x64", True)   # MJX computes in float64 (process-global)


def step_one(m, d, gain, f):
    """One MJX step of the body of model ``m`` (body 1) from data ``d``: qvel scaled by ``gain`` (6,), the
    applied row ``f`` (6,: force, torque) set, then ``mjx.step``."""
    d = d.replace(qvel=d.qvel * gain, xfrc_applied=d.xfrc_applied.at[1].set(f))
    return mjx.step(m, d)


class Bodies:
    """One free body (an MJX model holds one here); raw rows ``[qpos (7), qvel (6)]``, ω in BODY axes."""

    def __init__(self, model):
        self.m = mjx.put_model(model)
        self.d = mjx.put_data(model, mujoco.MjData(model))
        self.f, self.gain, self._step = np.zeros(6), np.ones(6), jax.jit(step_one)

    def set_state(self, y):
        qpos, qvel = to_qpos_qvel(y)
        self.d = self.d.replace(qpos=jax.numpy.asarray(qpos[0]), qvel=jax.numpy.asarray(qvel[0]))

    def apply(self, f_W, tau_W):
        self.f = np.concatenate([np.asarray(f_W, dtype=float)[0], np.asarray(tau_W, dtype=float)[0]])

    def step(self):
        self.d = self._step(self.m, self.d, self.gain, self.f)

    def read(self):
        return np.concatenate([np.asarray(self.d.qpos), np.asarray(self.d.qvel)])[None]

    def packed(self, raw):
        raw = np.asarray(raw, dtype=float)
        return to_packed(raw[..., 0:7], raw[..., 7:13])


def world(bodies, gravity_W, variant, dt_s):
    return Bodies(build_model(bodies, gravity_W, variant, dt_s))
