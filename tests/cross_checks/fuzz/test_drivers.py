"""A batch's runs are each engine's own adapter's runs, case by case, recorded
whole; a failure is one case's."""
import numpy as np
import pytest

from cross_checks import engines
from cross_checks.engines import get_adapter, resolve
from cross_checks.engines.base import EngineAdapter, EngineError, Variant
from cross_checks.fuzz import drivers, generate
from cross_checks.fuzz.pipeline import scenario_of


def _cases(n=6):
    return [scenario_of(generate.draw(31, i).spec(0.005 * (1 + i % 2), 8)) for i in range(n)]


@pytest.mark.parametrize("variant", ["reference:expmap_gyro", "mujoco:rk4", "pybullet:maximal"])
def test_the_ladder_is_the_adapters_runs(variant):
    scs = _cases()
    h0s = [sc.dt_s for sc in scs]
    ladder = drivers.run_ladder(resolve(variant), scs, h0s, 8)
    engine, var = variant.split(":")
    for r, runs in enumerate(ladder):
        for i, sc in enumerate(scs):
            run = get_adapter(engine).simulate(sc, var, h0s[i] / 2 ** r, 8 * 2 ** r)
            assert runs.status[i] == "ok" and runs.h_s[i] == h0s[i] / 2 ** r
            assert np.array_equal(runs.y[:, i], np.asarray(run.y)), (r, i)


def test_one_steps_are_the_adapters_and_none_without_a_one_step_mode():
    scs = _cases(4)
    members = [(sc, sc.dt_s / 2 ** r) for sc in scs for r in range(3)]
    ys = np.array([sc.problem.initial_packed() for sc, _ in members])
    for variant in ("reference:midpoint", "mujoco:euler", "pybullet:multibody"):
        got = drivers.one_step(resolve(variant), [m[0] for m in members], [m[1] for m in members], ys)
        engine, var = variant.split(":")
        want = np.array([get_adapter(engine).one_step(sc, var, h, y[None, :])[0]
                         for (sc, h), y in zip(members, ys)])
        assert np.array_equal(got, want), variant


def test_members_that_blow_up_diverge_where_the_adapter_says_and_leave_the_others_alone():
    from tests.helpers.scenarios import with_initial
    scs = _cases(4)
    fast = [with_initial(scenario_of(generate.draw(31, j).spec(0.004, 8)), v_W=[speed, 0.0, 0.0])
            # past the parser's physical ranges: set on the parsed case
            for j, speed in enumerate((1e9, 3e7))]
    scs = scs[:2] + fast + scs[2:]
    h0s = [sc.dt_s for sc in scs]
    blown_at = set()
    for variant in ("reference:explicit_euler", "mujoco:euler"):
        engine, var = variant.split(":")
        for r, runs in enumerate(drivers.run_ladder(resolve(variant), scs, h0s, 8)):
            for i, sc in enumerate(scs):
                run = get_adapter(engine).simulate(sc, var, h0s[i] / 2 ** r, 8 * 2 ** r)
                k = len(run.y)
                assert np.array_equal(runs.y[:k, i], np.asarray(run.y)) and np.all(np.isnan(runs.y[k:, i]))
                if any(sc is f for f in fast):
                    assert runs.status[i] == "diverged" and runs.diverged_at_s[i] == run.diverged_at_s
                    assert runs.message[i] == (run.message or f"diverged at t = {run.diverged_at_s:.6g} s")
                    blown_at.add(k)
                else:
                    assert runs.status[i] == "ok" and run.diverged_at_s is None
    assert len(blown_at) >= 2


class _Fragile(EngineAdapter):
    """A test engine: the course's step through the reference, except that it refuses a step below
    ``refused_below_s`` (EngineError) and, as a batch, fails as a whole with an error of its own."""

    name = "fragile"
    variants = {"course": Variant(1, "the reference's course step")}
    refused_below_s = 0.0

    def version(self):
        return "1"

    def simulate(self, scenario, variant, dt_s, n_steps):
        if dt_s < self.refused_below_s:
            raise EngineError(f"step {dt_s:g} s refused")
        return get_adapter("reference").simulate(scenario, "course", dt_s, n_steps)

    def simulate_many(self, variant, requests):
        if len(requests) > 1:
            raise RuntimeError("the batch fell over")
        return super().simulate_many(variant, requests)


@pytest.fixture
def fragile():
    engines.reset_registry()
    adapter = _Fragile()
    engines.register_adapter(adapter, "tests/cross_checks/fuzz/test_drivers.py")
    yield adapter
    engines.reset_registry()


def test_a_batch_that_fails_as_a_whole_runs_case_by_case_and_a_refused_run_is_that_cases_failure(fragile):
    scs = _cases(3)
    h0s = [sc.dt_s for sc in scs]
    fragile.refused_below_s = min(h0s) / 3   # every case's finest rung, and the 2-cases' middle one
    ladder = drivers.run_ladder(resolve("fragile:course"), scs, h0s, 8)
    for r, runs in enumerate(ladder):
        for i, sc in enumerate(scs):
            h = h0s[i] / 2 ** r
            if h < fragile.refused_below_s:
                assert runs.status[i] == "failed" and runs.message[i] == f"EngineError: step {h:g} s refused"
                assert np.all(np.isnan(runs.y[:, i]))
            else:
                want = get_adapter("reference").simulate(sc, "course", h, 8 * 2 ** r)
                assert runs.status[i] == "ok" and np.array_equal(runs.y[:, i], want.y)
    assert "failed" in ladder[2].status and "ok" in ladder[0].status
    # no one-step mode
    assert drivers.one_step(resolve("fragile:course"), scs, h0s, np.zeros((3, 13))) is None
