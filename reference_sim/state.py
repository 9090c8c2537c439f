"""The state of a free rigid body and the problem (body + forces + initial state) the integrators solve."""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from reference_sim.body import RigidBody
from reference_sim.forces import ForceModel, Members
from reference_sim.quaternion import quat_normalize

__all__ = ["State", "Problem", "pack", "STATE_SIZE"]

#: Packed state layout along the last axis: x_W (0:3), v_W (3:6), q_WB (6:10, w x y z), w_W (10:13).
STATE_SIZE = 13
X, V, Q, W = slice(0, 3), slice(3, 6), slice(6, 10), slice(10, 13)


@dataclass(frozen=True, eq=False)
class State:
    """State ``(x, v, q, ω)`` with any leading batch shape.

    x_W : (..., 3) COM position, world, m.
    v_W : (..., 3) COM velocity, world, m/s.
    q_WB : (..., 4) orientation body→world, unit quaternion (w, x, y, z).
    w_W : (..., 3) angular velocity, WORLD axes, rad/s.
    """

    x_W: np.ndarray
    v_W: np.ndarray
    q_WB: np.ndarray
    w_W: np.ndarray

    def packed(self) -> np.ndarray:
        return pack(self.x_W, self.v_W, self.q_WB, self.w_W)


def pack(x_W, v_W, q_WB, w_W) -> np.ndarray:
    """Concatenate a state into ``(..., 13)`` = [x_W, v_W, q_WB (w x y z), w_W]."""
    arrs = np.broadcast_arrays(*(np.asarray(a, dtype=float)[..., :0] for a in (x_W, v_W, q_WB, w_W)))
    lead = arrs[0].shape[:-1]
    return np.concatenate([np.broadcast_to(np.asarray(a, dtype=float), lead + (np.shape(a)[-1],))
                           for a in (x_W, v_W, q_WB, w_W)], axis=-1)


@dataclass(frozen=True, eq=False)
class Problem:
    """A free-body initial value problem: body, forces and initial state (one body, or a batch)."""

    body: RigidBody
    forces: ForceModel
    initial: State

    @cached_property
    def members(self) -> Members:
        """This problem's parameters as one member (reference_sim.forces.Members), built once."""
        return Members.stack([(self.body, self.forces)])

    def initial_packed(self) -> np.ndarray:
        y = self.initial.packed()
        y[..., Q] = quat_normalize(y[..., Q])
        return y
