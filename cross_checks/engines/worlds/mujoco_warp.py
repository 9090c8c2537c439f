"""MuJoCo Warp's world (MuJoCo's physics as NVIDIA Warp kernels, float32 on Warp's CPU device): numpy, warp,
mujoco and mujoco_warp only. ``rbcheck repro`` embeds this file as it is after worlds/mujoco.py, whose MjSpec
model and state conversion it uses (the relative import below is the only line it leaves out).

The model is MuJoCo's ``build_model`` with ``mjDSBL_AUTORESET`` cleared (:func:`host_model`: ``mjw.put_model``
refuses it; a Warp world never resets), put on the CPU device with ``opt.timestep`` one per world
(:func:`device_model`). :class:`Worlds` holds the worlds of one ``mjw.put_data(..., nworld=N)`` with zero-copy
NumPy views of their qpos, qvel and xfrc_applied (float32); a step is one ``mjw.step`` recorded once as a
Warp graph and replayed (:meth:`Worlds.capture`, :meth:`Worlds.step`), as rbcheck's adapter
(cross_checks/engines/mujoco_warp_engine.py) runs it. State: ``qpos = [x_W, q_WB (w x y z)]``,
``qvel = [v_W, ω_B (BODY axes)]``; forces in ``xfrc_applied`` (world force at the COM without the weight,
world torque), kept between steps.
"""
import mujoco
import mujoco_warp as mjw
import numpy as np
import warp as wp

from .mujoco import build_model, to_packed, to_qpos_qvel  # in a reproducer: the world above

BODY = 1   # body id of the free body (0 is the world)


def host_model(model):
    """The MjModel ``model`` with ``mjDSBL_AUTORESET`` cleared (mujoco_warp refuses it)."""
    model.opt.disableflags &= ~int(mujoco.mjtDisableBit.mjDSBL_AUTORESET)
    return model


def device_model(m_host, dts):
    """``mjw.put_model(m_host)`` on the CPU device with ``opt.timestep`` one per world (``dts``, s)."""
    with wp.ScopedDevice("cpu"):
        wm = mjw.put_model(m_host)
        wm.opt.timestep = wp.array(np.asarray(dts, dtype=np.float32), dtype=wp.float32)
    return wm


def warm_up(m_host, callback=None):
    """Load (compile on first use ever, else read from Warp's kernel cache) every kernel a step of ``m_host``
    launches (with the stage-force ``callback``, if any) by one uncaptured step of a scratch world."""
    wm = mjw.put_model(m_host)
    wd = mjw.put_data(m_host, mujoco.MjData(m_host), nworld=1)
    if callback is not None:
        wm.callback.control = callback
    with wp.ScopedDevice("cpu"):
        mjw.step(wm, wd)
    wp.synchronize()


class Worlds:
    """The worlds of model ``wm`` (:func:`device_model` of ``m_host``) on the CPU device, one per entry of its
    ``opt.timestep``, with zero-copy NumPy views ``qpos``, ``qvel``, ``xfrc`` (float32); ``callback``: the
    model's ``callback.control`` (forces evaluated at every stage), if any."""

    def __init__(self, wm, m_host, callback=None):
        self.m = wm
        with wp.ScopedDevice("cpu"):
            self.d = mjw.put_data(m_host, mujoco.MjData(m_host), nworld=wm.opt.timestep.shape[0])
        self.qpos, self.qvel = self.d.qpos.numpy(), self.d.qvel.numpy()
        self.xfrc = self.d.xfrc_applied.numpy()
        self.shared = (np.shares_memory(self.qpos, self.d.qpos.numpy())
                       and np.shares_memory(self.xfrc, self.d.xfrc_applied.numpy()))
        self.graph = None
        if callback is not None:
            self.m.callback.control = callback

    def capture(self):
        """Record one step as a graph (replayed by :meth:`step`); the state is not advanced by recording."""
        saved = self.qpos.copy(), self.qvel.copy()
        with wp.ScopedDevice("cpu"), wp.ScopedCapture() as cap:
            mjw.step(self.m, self.d)
        self.qpos[:], self.qvel[:] = saved
        self.graph = cap.graph

    def step(self):
        if self.graph is not None:
            wp.capture_launch(self.graph)
        else:
            with wp.ScopedDevice("cpu"):
                mjw.step(self.m, self.d)


class Bodies(Worlds):
    """One free body (a model holds one here) in as many worlds as states given; raw rows
    ``[qpos (7), qvel (6)]`` (float32 values), ω in BODY axes. The first :meth:`step` records the graph that
    every step replays (after the state and forces are set, as the adapter's rollout does)."""

    def set_state(self, y):
        self.qpos[:], self.qvel[:] = to_qpos_qvel(y)

    def apply(self, f_W, tau_W):   # world force at the COM (N; mujoco_warp adds the weight), torque (N m)
        self.xfrc[:, BODY, 0:3], self.xfrc[:, BODY, 3:6] = f_W, tau_W

    def step(self):
        if self.graph is None:
            self.capture()
        super().step()

    def read(self):
        return np.concatenate((self.qpos, self.qvel), axis=1).astype(float)

    def packed(self, raw):
        raw = np.asarray(raw, dtype=float)
        return to_packed(raw[..., 0:7], raw[..., 7:13])


def world(bodies, gravity_W, variant, dt_s):
    # a reproducer prints its numbers: Warp's greeting and kernel-load lines (LOG_INFO) off, its warnings kept
    wp.config.log_level = max(wp.config.log_level, wp.LOG_WARNING)
    m = host_model(build_model(bodies, gravity_W, variant, dt_s))
    warm_up(m)
    return Bodies(device_model(m, [dt_s]), m)
