"""The N-case reference: each member computes exactly what its own problem computes alone."""
import numpy as np
import pytest

from cross_checks.fuzz import generate
from cross_checks.fuzz.kernel import CaseKernel, columns, rows, runs_compiled
from cross_checks.fuzz.pipeline import scenario_of
from reference_sim.integrators import VARIANTS, get_step


def _problems(n=8):
    scs = [scenario_of(generate.draw(21, i).spec(0.01, 8)) for i in range(n)]
    return [sc.problem for sc in scs], np.array([0.0004 * (1 + i % 3) for i in range(n)])


@pytest.mark.parametrize("variant", list(VARIANTS))
def test_every_member_is_bit_identical_to_its_own_problem_alone(variant):
    problems, hs = _problems()
    kern = CaseKernel.stack(problems, variant, hs)
    y = columns([p.initial_packed() for p in problems])
    ys = [p.initial_packed() for p in problems]
    with np.errstate(all="ignore"):
        for _ in range(5):
            y = kern.step(y)
            ys = [get_step(variant)(p, v, float(h)) for p, h, v in zip(problems, hs, ys)]
    assert np.array_equal(rows(y), np.array(ys))
    sub = kern.take([3, 1])
    assert np.array_equal(rows(sub.step(columns(np.array(ys)[[3, 1]]))),
                          [get_step(variant)(problems[i], ys[i], float(hs[i])) for i in (3, 1)])


@pytest.mark.parametrize("variant", ["course", "expmap_gyro", "explicit_euler", "midpoint", "rk4", "leapfrog",
                                     "implicit_euler"])
def test_member_runs_are_each_members_own_run(variant):
    # a free run per member: bit for bit the member's run alone (reference_sim.simulate), a blown-up member
    # included (cut where its own run is cut)
    from reference_sim import simulate as S
    problems, hs = _problems(6)
    n = [40, 80, 120, 40, 80, 120]
    y0 = [p.initial_packed() for p in problems]
    y0[2] = y0[2].copy()
    y0[2][10:13] = [3e3, 2e4, 3e3]   # a spin that most schemes blow up at these steps
    each = runs_compiled(variant, problems, hs, y0, n)
    assert variant == "course" or each[2][1] is not None   # (course: no gyroscopic term)
    for p, h, y, k_n, (y_fast, k) in zip(problems, hs, y0, n, each):
        alone = S.simulate(p, variant, float(h), k_n, y0=y)
        if alone.diverged_at_s is None:
            assert k is None and np.array_equal(y_fast, alone.y)
        else:
            assert k == len(alone.y) and np.array_equal(y_fast[:k], alone.y) and np.all(np.isnan(y_fast[k:]))


def test_the_forces_of_every_member_are_its_own():
    problems, hs = _problems()
    y = np.array([p.initial_packed() for p in problems])
    got = np.array(CaseKernel.stack(problems, "course", hs).force_torque_cols(columns(y))).T
    for p, row, g in zip(problems, y, got):
        f, tau = p.forces.force_torque(p.body, row[0:3], row[3:6], row[6:10] / np.linalg.norm(row[6:10]))
        assert np.array_equal(g, np.concatenate([f, tau]))
