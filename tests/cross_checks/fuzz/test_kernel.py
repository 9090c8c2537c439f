"""The N-case kernel: each member computes exactly what its own single-case float stepper computes."""
import numpy as np
import pytest

from reference_sim.scalar import ScalarStepper

from cross_checks.fuzz import generate
from cross_checks.fuzz.kernel import CaseKernel, columns, rows
from cross_checks.fuzz.pipeline import scenario_of


def _problems(n=8):
    scs = [scenario_of(generate.draw(21, i).spec(0.01, 8)) for i in range(n)]
    return [sc.problem for sc in scs], np.array([0.0004 * (1 + i % 3) for i in range(n)])


@pytest.mark.parametrize("variant", ["course", "course_gyro", "expmap_gyro", "explicit_euler", "midpoint", "rk4",
                                     "implicit_euler"])
def test_every_member_is_bit_identical_to_its_own_float_stepper(variant):
    problems, hs = _problems()
    kern = CaseKernel.stack(problems, variant, hs)
    y = columns([p.initial_packed() for p in problems])
    singles = [ScalarStepper(p, variant, float(h)) for p, h in zip(problems, hs)]
    ys = [[float(v) for v in p.initial_packed()] for p in problems]
    with np.errstate(all="ignore"):
        for _ in range(5):
            y = kern.step(y)
            ys = [s.step(v) for s, v in zip(singles, ys)]
    assert np.array_equal(rows(y), np.array(ys))


def test_leapfrog_members_agree_to_round_off():
    """Leapfrog iterates its implicit half kick until every member has converged (see kernel's docstring)."""
    problems, hs = _problems()
    kern = CaseKernel.stack(problems, "leapfrog", hs)
    y = columns([p.initial_packed() for p in problems])
    singles = [ScalarStepper(p, "leapfrog", float(h)) for p, h in zip(problems, hs)]
    ys = [[float(v) for v in p.initial_packed()] for p in problems]
    for _ in range(5):
        y = kern.step(y)
        ys = [s.step(v) for s, v in zip(singles, ys)]
    assert np.allclose(rows(y), np.array(ys), rtol=1e-12, atol=1e-12)
