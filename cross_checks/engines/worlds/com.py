"""A body whose frame origin Bo is not at its centre of mass (numpy only: ``rbcheck repro`` embeds this file's
code before the engine's world, cross_checks/sweep/repro.py).

The engines that take such a body (MuJoCo's ``ipos``, Drake's ``p_BoBcm``, DART's ``Inertia`` local COM)
step the state of its frame origin Bo, while rbcheck's packed states ``[x_W (m), v_W (m/s), q_WB (w, x, y,
z), ω_W (rad/s, world axes)]`` are the COM's. With ``c`` the COM in body axes from Bo (m) and ``R = R(q_WB)``:
``x = x_o + R c`` and ``v = v_o + ω × R c``; the orientation and ω are the same for both points. A body of
welded parts is one such body: its COM is the parts' composite COM from the frame origin of the first.
Each world's ``form_world`` (the invariance claims ``com_offset`` and ``welded_split``) and the adapter
convert with these functions (the same code in both; docs/repro.md, docs/invariance.md).
"""
import numpy as np


def _com_cross(a, b):
    a0, a1, a2, b0, b1, b2 = a[..., 0], a[..., 1], a[..., 2], b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def com_arm_W(q_WB, com_B):
    """``R(q_WB) c``: the COM's offset from the frame origin in world axes (m), (..., 3), of quaternions
    ``q_WB`` (..., 4) (w, x, y, z; unit) and the COM ``com_B`` (..., 3) or (3,) (m, body axes from Bo)."""
    q = np.asarray(q_WB, dtype=float)
    c = np.broadcast_to(np.asarray(com_B, dtype=float), q[..., 1:].shape)
    s, u = q[..., :1], q[..., 1:]
    t = 2.0 * _com_cross(u, c)
    return c + s * t + _com_cross(u, t)


def com_state(y_o, com_B):
    """Packed states of the frame origin Bo (..., 13) -> the COM's: ``x = x_o + R c``,
    ``v = v_o + ω × R c``."""
    y_o = np.asarray(y_o, dtype=float)
    r_W = com_arm_W(y_o[..., 6:10], com_B)
    return np.concatenate([y_o[..., 0:3] + r_W, y_o[..., 3:6] + np.cross(y_o[..., 10:13], r_W),
                           y_o[..., 6:10], y_o[..., 10:13]], axis=-1)


def origin_state(y, com_B):
    """Packed COM states (..., 13) -> the frame origin Bo's: ``x_o = x − R c``, ``v_o = v − ω × R c``."""
    y = np.array(y, dtype=float)
    r_W = com_arm_W(y[..., 6:10], com_B)
    y[..., 0:3], y[..., 3:6] = y[..., 0:3] - r_W, y[..., 3:6] - np.cross(y[..., 10:13], r_W)
    return y
