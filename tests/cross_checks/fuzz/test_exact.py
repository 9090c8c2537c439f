"""The exact motion's right-hand side: every member of a batch evaluated at once equals the definition
(reference_sim.integrators.rhs) of its own problem, and the batched solve reproduces a closed form."""
import numpy as np

from cross_checks.fuzz import generate
from cross_checks.fuzz.exact import solve_members
from cross_checks.fuzz.pipeline import scenario_of
from reference_sim.body import RigidBody
from reference_sim.forces import ForceModel, Members
from reference_sim.integrators import rhs
from reference_sim.state import Problem, State


def _problems(n=40):
    scs = [scenario_of(generate.draw(9, i).spec(0.003, 8)) for i in range(n)]
    return [sc.problem for sc in scs], scs


def test_stacked_rhs_equals_the_definition_member_by_member():
    problems, _ = _problems()
    kinds = {f for i in range(len(problems)) for f in generate.draw(9, i).kinds["forces"]}
    assert len(kinds) >= 7   # every force kind the generator draws is exercised
    problems = problems + problems[:7]   # members sharing a problem (one-step starts)
    rng = np.random.default_rng(0)
    Y = np.array([p.initial_packed() for p in problems]) + 0.1 * rng.standard_normal((len(problems), 13))
    got = rhs(Members.stack(problems), Y)   # the members padded to the longest force lists: exact zeros added
    want = np.array([rhs(p, y) for p, y in zip(problems, Y)])
    assert np.array_equal(got, want)


def test_batched_solve_of_different_free_spins_is_their_closed_form():
    """Members with different bodies, spins and gravities in one solve: a spin w about the principal z axis
    keeps ω and turns by w t (q = (cos w t/2, 0, 0, sin w t/2)); the COM falls as x0 + v0 t + ½ g t²."""
    problems, spans, want = [], [], []
    t_s = np.array([0.0, 0.5, 1.0])
    for k, (w, g) in enumerate([(3.0, -9.81), (0.2, 0.0), (40.0, -1.0)]):
        body = RigidBody(mass_kg=1.0 + k, inertia_B=np.diag([1.0 + k, 2.0, 2.5]))
        x0, v0 = np.array([0.1 * k, 0.0, 1.0]), np.array([0.0, 0.5, 2.0])
        problems.append(Problem(body, ForceModel(gravity_W=np.array([0.0, 0.0, g])),
                                State(x0, v0, np.array([1.0, 0.0, 0.0, 0.0]), np.array([0.0, 0.0, w]))))
        T = 1.0 + k
        spans.append(T)
        t = t_s * T
        x = x0 + v0 * t[:, None] + 0.5 * np.outer(t * t, [0.0, 0.0, g])
        v = v0 + np.outer(t, [0.0, 0.0, g])
        q = np.stack([np.cos(0.5 * w * t), 0 * t, 0 * t, np.sin(0.5 * w * t)], axis=1)
        want.append(np.concatenate([x, v, q, np.tile([0.0, 0.0, w], (3, 1))], axis=1))
    got = solve_members(problems, spans, t_s, rtol=1e-12)
    assert np.allclose(got, np.stack(want, axis=1), rtol=0, atol=1e-9)
