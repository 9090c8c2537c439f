"""The N-case kernel: each member computes exactly what its own single-case float stepper computes."""
import numpy as np
import pytest

from cross_checks.fuzz import generate
from cross_checks.fuzz.kernel import CaseKernel, columns, rows
from cross_checks.fuzz.pipeline import scenario_of
from reference_sim.scalar import ScalarStepper


def _problems(n=8):
    scs = [scenario_of(generate.draw(21, i).spec(0.01, 8)) for i in range(n)]
    return [sc.problem for sc in scs], np.array([0.0004 * (1 + i % 3) for i in range(n)])


def _steps_like_float_steppers(problems, hs, variant) -> bool:
    """Whether five kernel steps of ``variant`` equal, bit for bit, each member's own float stepper's."""
    kern = CaseKernel.stack(problems, variant, hs)
    y = columns([p.initial_packed() for p in problems])
    singles = [ScalarStepper(p, variant, float(h)) for p, h in zip(problems, hs)]
    ys = [[float(v) for v in p.initial_packed()] for p in problems]
    with np.errstate(all="ignore"):
        for _ in range(5):
            y = kern.step(y)
            ys = [s.step(v) for s, v in zip(singles, ys)]
    return np.array_equal(rows(y), np.array(ys))


@pytest.mark.parametrize("variant", ["course", "course_gyro", "expmap_gyro", "explicit_euler", "midpoint", "rk4",
                                     "implicit_euler"])
def test_every_member_is_bit_identical_to_its_own_float_stepper(variant):
    problems, hs = _problems()
    assert _steps_like_float_steppers(problems, hs, variant)


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


def test_kernels_of_every_scheme_on_the_same_problems_share_steppers_and_stay_bit_identical():
    """The steppers are built once per (problem, step) and shared by every scheme's kernel (their parameters
    do not depend on the scheme): each kernel still steps its own scheme, member for member."""
    problems, hs = _problems()
    first = CaseKernel.stack(problems, "rk4", hs)
    for variant in ("course", "explicit_euler", "midpoint", "implicit_euler", "rk4"):
        assert CaseKernel.stack(problems, variant, hs)._steppers[0] is first._steppers[0]
        assert _steps_like_float_steppers(problems, hs, variant), variant


def test_a_bug_planted_in_the_stepper_init_reaches_kernels_of_problems_stacked_before(monkeypatch):
    """A shared stepper built before a bug was planted in ScalarStepper.__init__ (tests/mutants.py plants
    them there) is never served after: the kernel computes what the patched float stepper computes."""
    problems, hs = _problems()
    clean = rows(CaseKernel.stack(problems, "course_gyro", hs).step(columns([p.initial_packed() for p in problems])))
    orig = ScalarStepper.__init__

    def init(self, *a, **kw):
        orig(self, *a, **kw)
        self.mg = [2.0 * v for v in self.mg]   # a planted bug: gravity twice
    monkeypatch.setattr(ScalarStepper, "__init__", init)
    assert _steps_like_float_steppers(problems, hs, "course_gyro")
    bugged = rows(CaseKernel.stack(problems, "course_gyro", hs).step(columns([p.initial_packed() for p in problems])))
    assert not np.array_equal(bugged, clean)


@pytest.mark.parametrize("variant", ["course", "expmap_gyro", "explicit_euler", "midpoint", "rk4", "leapfrog",
                                     "implicit_euler"])
def test_compiled_member_runs_are_each_members_own_float_stepper_run(monkeypatch, variant):
    # a free run per member, stepped compiled: bit for bit what the member's own float stepper computes (the
    # Python float path of reference_sim.simulate), a blown-up member included (cut where that path cuts it)
    from cross_checks.fuzz.kernel import runs_compiled
    from reference_sim import compiled
    from reference_sim import simulate as S
    problems, hs = _problems(6)
    n = [40, 80, 120, 40, 80, 120]
    y0 = [p.initial_packed() for p in problems]
    y0[2] = y0[2].copy()
    y0[2][10:13] = [3e3, 2e4, 3e3]   # a spin that most schemes blow up at these steps
    each = runs_compiled(variant, problems, hs, y0, n)
    assert each is not None and (variant == "course" or each[2][1] is not None)   # (course: no gyroscopic term)
    monkeypatch.setattr(compiled, "usable", lambda *a: False)
    for p, h, y, k_n, (y_fast, k) in zip(problems, hs, y0, n, each):
        slow = S.simulate(p, variant, float(h), k_n, y0=y)
        if slow.diverged_at_s is None:
            assert k is None and np.array_equal(y_fast, slow.y)
        else:
            assert k == len(slow.y) and np.array_equal(y_fast[:k], slow.y)


def test_a_planted_bug_in_a_step_method_sends_the_members_to_the_numpy_kernel(monkeypatch):
    from cross_checks.fuzz.kernel import runs_compiled
    problems, hs = _problems(2)
    monkeypatch.setattr(ScalarStepper, "_midpoint", lambda self, y: y)
    assert runs_compiled("midpoint", problems, hs, [p.initial_packed() for p in problems], [5, 5]) is None
