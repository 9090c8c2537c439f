"""The ground truth solves the definition (reference_sim.integrators.rhs), never the compiled fast path the
reference schemes run on: a fault in that path cannot move the reference the runs are judged against."""
import numpy as np

from reference_sim.body import RigidBody
from reference_sim.forces import ForceModel, Spring
from reference_sim.ground_truth import ground_truth
from reference_sim.state import Problem, State


def test_the_compiled_path_does_not_enter_the_ground_truth(monkeypatch):
    from reference_sim import compiled
    p = Problem(RigidBody(2.0, [0.3, 0.5, 0.7]),
                ForceModel(springs=(Spring(np.array([0.0, 0.0, 1.0]),
                                           np.array([0.1, 0.0, 0.0]), 20.0, 0.2),)),
                State(np.zeros(3), np.array([0.1, 0.0, 0.0]),
                      np.array([1.0, 0.0, 0.0, 0.0]), np.array([0.2, 3.0, 0.1])))
    t = np.linspace(0.0, 1.0, 11)
    before = ground_truth(p, t)

    def broken(*_a, **_k):
        raise AssertionError("the ground truth stepped the compiled path")
    monkeypatch.setattr(compiled, "advance", broken)
    monkeypatch.setattr(compiled, "kernel", broken)
    np.testing.assert_array_equal(ground_truth(p, t), before)
