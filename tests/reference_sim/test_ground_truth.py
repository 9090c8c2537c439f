"""The ground truth is independent of the kernel the reference schemes step with: a bug planted in
reference_sim.scalar (what the fuzz and the gates plant bugs in) must not move it."""
import numpy as np

from reference_sim.body import RigidBody
from reference_sim.forces import ForceModel, Spring
from reference_sim.ground_truth import ground_truth
from reference_sim.state import Problem, State


def test_a_bug_planted_in_the_schemes_kernel_does_not_move_the_ground_truth(monkeypatch):
    import reference_sim.scalar as scalar
    p = Problem(RigidBody(2.0, [0.3, 0.5, 0.7]),
                ForceModel(springs=(Spring(np.array([0.0, 0.0, 1.0]), np.array([0.1, 0.0, 0.0]), 20.0, 0.2),)),
                State(np.zeros(3), np.array([0.1, 0.0, 0.0]), np.array([1.0, 0.0, 0.0, 0.0]), np.array([0.2, 3.0, 0.1])))
    t = np.linspace(0.0, 1.0, 11)
    before = ground_truth(p, t)

    def wrong_rhs(self, y):  # a flipped gyroscopic sign, as a planted bug would have it
        d = list(orig(self, y))
        return d[:10] + [-a for a in d[10:13]]
    orig = scalar.ScalarStepper.rhs
    monkeypatch.setattr(scalar.ScalarStepper, "rhs", wrong_rhs)
    np.testing.assert_array_equal(ground_truth(p, t), before)
