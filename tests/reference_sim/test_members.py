"""N different problems as the members of one evaluation of the definition (reference_sim.forces.Members):
each member computes exactly what its own problem computes alone — its steps, its compiled free run
(reference_sim.simulate.run_members) and its forces."""
import numpy as np
import pytest

from cross_checks.fuzz import generate
from cross_checks.fuzz.pipeline import scenario_of
from reference_sim import simulate as S
from reference_sim.forces import Members
from reference_sim.integrators import VARIANTS, get_step
from reference_sim.quaternion import matrix_from_quat


def _problems(n=8):
    scs = [scenario_of(generate.draw(21, i).spec(0.01, 8)) for i in range(n)]
    return [sc.problem for sc in scs], np.array([0.0004 * (1 + i % 3) for i in range(n)])


@pytest.mark.parametrize("variant", list(VARIANTS))
def test_every_member_steps_bit_identically_to_its_own_problem_alone(variant):
    problems, hs = _problems()
    members = Members.stack(problems)
    step = get_step(variant)
    y = np.array([p.initial_packed() for p in problems])
    ys = list(y)
    with np.errstate(all="ignore"):
        for _ in range(5):
            y = step(members, y, hs)
            ys = [step(p, v, float(h)) for p, h, v in zip(problems, hs, ys)]
    assert np.array_equal(y, np.array(ys))
    idx = [3, 1]
    assert np.array_equal(step(members.take(idx), y[idx], hs[idx]),
                          [step(problems[i], ys[i], float(hs[i])) for i in idx])


@pytest.mark.parametrize("variant", ["course", "expmap_gyro", "explicit_euler", "midpoint", "rk4", "leapfrog",
                                     "implicit_euler"])
def test_member_runs_are_each_members_own_run(variant):
    # a free run per member: bit for bit the member's run alone, a blown-up member included (cut where its own
    # run is cut, with its own message)
    problems, hs = _problems(6)
    n = [40, 80, 120, 40, 80, 120]
    y0 = np.array([p.initial_packed() for p in problems])
    y0[2, 10:13] = [3e3, 2e4, 3e3]   # a spin that most schemes blow up at these steps
    runs = S.run_members(Members.stack(problems), variant, hs, n, y0)
    assert variant == "course" or runs[2].diverged_at_s is not None   # (course: no gyroscopic term)
    for p, h, y, k_n, run in zip(problems, hs, y0, n, runs):
        alone = S.simulate(p, variant, float(h), k_n, y0=y)
        assert np.array_equal(run.y, alone.y) and run.diverged_at_s == alone.diverged_at_s
        assert run.message == alone.message


def test_the_forces_of_every_member_are_its_own():
    problems, _ = _problems()
    y = np.array([p.initial_packed() for p in problems])
    q = y[:, 6:10] / np.linalg.norm(y[:, 6:10], axis=1, keepdims=True)
    f, tau = Members.stack(problems).force_torque(y[:, 0:3], y[:, 3:6], matrix_from_quat(q))
    for p, row, fi, ti in zip(problems, y, f, tau):
        fe, te = p.forces.force_torque(p.body, row[0:3], row[3:6], row[6:10] / np.linalg.norm(row[6:10]))
        assert np.array_equal(fi, fe) and np.array_equal(ti, te)
