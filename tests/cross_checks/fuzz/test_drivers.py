"""Batched engine paths give what each engine's own adapter gives, case by case."""
import numpy as np
import pytest

from cross_checks.engines import get_adapter
from cross_checks.fuzz import drivers, generate
from cross_checks.fuzz.pipeline import scenario_of


def _cases(n=6):
    return [scenario_of(generate.draw(31, i).spec(0.005 * (1 + i % 2), 8)) for i in range(n)]


@pytest.mark.parametrize("variant", ["reference:expmap_gyro", "reference:rk4", "mujoco:euler", "mujoco:implicitfast"])
def test_batched_ladder_equals_the_adapter_run_by_run(variant):
    scs = _cases()
    h0s = [sc.dt_s for sc in scs]
    ladder = drivers.run_ladder(variant, scs, h0s, 8)
    engine, var = variant.split(":")
    for r, runs in enumerate(ladder):
        for i, sc in enumerate(scs):
            run = get_adapter(engine).simulate(sc, var, h0s[i] / 2 ** r, 8 * 2 ** r)
            assert runs.status[i] == "ok"
            assert np.array_equal(runs.y[:, i], np.asarray(run.y)), (r, i)


def test_batched_one_step_equals_the_adapter():
    scs = _cases(4)
    ys = np.array([sc.problem.initial_packed() for sc in scs])
    hs = np.array([sc.dt_s for sc in scs])
    for variant in ("reference:midpoint", "mujoco:euler"):
        got = drivers.one_step(variant, scs, hs, ys)
        engine, var = variant.split(":")
        want = np.array([get_adapter(engine).one_step(sc, var, h, y[None, :])[0] for sc, h, y in zip(scs, hs, ys)])
        if engine == "reference":   # the adapter's one step is the batched definition: the same to round-off
            assert np.allclose(got, want, rtol=1e-12, atol=1e-13), variant
        else:
            assert np.array_equal(got, want), variant


def test_every_mujoco_variant_on_the_same_compiled_models_equals_the_adapter():
    """One compiled model per scenario, switched between integrators and steps in place (drivers._model):
    every variant's ladder and its one-step runs at four steps of each case (one rollout round per step)
    are still the adapter's, bit for bit, whichever variant compiled the model."""
    scs = _cases(4)
    h0s = [sc.dt_s for sc in scs]
    ys = np.array([sc.problem.initial_packed() for sc in scs])
    members = [(i, r) for i in range(len(scs)) for r in range(4)]
    m_scs = [scs[i] for i, _ in members]
    m_hs = np.array([h0s[i] / 2 ** r for i, r in members])
    m_ys = np.array([ys[i] for i, _ in members])
    for variant in ("mujoco:implicit", "mujoco:rk4", "mujoco:euler", "mujoco:implicitfast", "mujoco:implicit"):
        var = variant.split(":")[1]
        ladder = drivers.run_ladder(variant, scs, h0s, 8)
        for r, runs in enumerate(ladder):
            for i, sc in enumerate(scs):
                run = get_adapter("mujoco").simulate(sc, var, h0s[i] / 2 ** r, 8 * 2 ** r)
                assert np.array_equal(runs.y[:, i], np.asarray(run.y)), (variant, r, i)
        got = drivers.one_step(variant, m_scs, m_hs, m_ys)
        want = np.array([get_adapter("mujoco").one_step(sc, var, h, y[None, :])[0]
                         for sc, h, y in zip(m_scs, m_hs, m_ys)])
        assert np.array_equal(got, want), variant
    drivers.clear_cache()


def test_reference_members_that_blow_up_diverge_where_the_adapter_says_and_leave_the_others_alone():
    """Members of the batched reference ladder that blow up mid-run (at different steps) are marked
    "diverged" at the adapter's time with the adapter's states up to there; the other members of the same
    kernel are the adapter's runs."""
    scs = _cases(4)
    fast = []
    from tests.helpers.scenarios import with_initial
    for j, speed in enumerate((1e9, 3e7)):   # past the parser's physical ranges: set on the parsed case
        fast.append(with_initial(scenario_of(generate.draw(31, j).spec(0.004, 8)), v_W=[speed, 0.0, 0.0]))
    scs = scs[:2] + fast + scs[2:]
    h0s = [sc.dt_s for sc in scs]
    blown_at = set()
    for variant in ("reference:explicit_euler", "reference:rk4"):
        ladder = drivers.run_ladder(variant, scs, h0s, 8)
        for r, runs in enumerate(ladder):
            for i, sc in enumerate(scs):
                run = get_adapter("reference").simulate(sc, variant.split(":")[1], h0s[i] / 2 ** r, 8 * 2 ** r)
                k = len(run.y)
                assert np.array_equal(runs.y[:k, i], np.asarray(run.y)) and np.all(np.isnan(runs.y[k:, i]))
                if sc in fast:
                    assert runs.status[i] == "diverged" and runs.diverged_at_s[i] == run.diverged_at_s
                    blown_at.add(k)
                else:
                    assert runs.status[i] == "ok" and run.diverged_at_s is None
    assert len(blown_at) >= 3   # at the first step and at several later ones
