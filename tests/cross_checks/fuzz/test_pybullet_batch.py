"""The fuzz's PyBullet runs (one world per process, a body per run) are the adapter's runs, bit for bit."""
import numpy as np
import pytest

from cross_checks.engines import get_adapter
from cross_checks.fuzz import drivers, generate, pybullet_batch
from cross_checks.fuzz.pipeline import scenario_of

pytest.importorskip("pybullet")


def _cases(n=12):
    scs = [scenario_of(generate.draw(47, i).spec(0.004 * (1 + i % 3), 8)) for i in range(n)]
    kinds = {f for i in range(n) for f in generate.draw(47, i).kinds["forces"]}
    assert len(kinds) >= 7 and any(not sc.problem.body.is_diagonal() for sc in scs)
    return scs


@pytest.mark.parametrize("variant", ["multibody", "maximal"])
def test_free_runs_are_the_adapters_bit_for_bit_whatever_ran_before(variant):
    scs = _cases()
    adapter = get_adapter("pybullet")
    for sc in scs + scs[::-1]:   # each run after a different previous body in the same world
        for h, n in ((sc.dt_s, 8), (sc.dt_s / 4, 32)):
            got = pybullet_batch.simulate(sc, variant, h, n)
            want = adapter.simulate(sc, variant, h, n)
            assert want.diverged_at_s is None and np.array_equal(got, np.asarray(want.y)), sc.name


@pytest.mark.parametrize("variant", ["multibody", "maximal"])
def test_one_steps_are_the_adapters_bit_for_bit(variant):
    scs = _cases()
    rng = np.random.default_rng(3)
    adapter = get_adapter("pybullet")
    for sc in scs:
        y = sc.problem.initial_packed() + 0.05 * rng.standard_normal((4, 13))
        y[:, 6:10] /= np.linalg.norm(y[:, 6:10], axis=1, keepdims=True)
        assert np.array_equal(pybullet_batch.one_step(sc, variant, sc.dt_s, y), adapter.one_step(sc, variant, sc.dt_s, y))


def test_a_run_that_blows_up_is_left_to_the_adapter_and_its_message():
    from tests.helpers.scenarios import with_initial
    # beyond BLOWUP_LIMIT after one step (past the parser's physical ranges: set on the parsed case)
    sc = with_initial(scenario_of(generate.draw(47, 0).spec(0.004, 8)), v_W=[1e9, 0.0, 0.0])
    assert pybullet_batch.simulate(sc, "multibody", sc.dt_s, 8) is None
    ladder = drivers.run_ladder("pybullet:multibody", [sc], [sc.dt_s], 8)
    assert ladder[0].status[0] == "diverged" and ladder[0].message[0].startswith("diverged at t = ")


@pytest.mark.parametrize("variant", ["multibody", "maximal"])
def test_a_body_kept_for_the_runs_of_its_case_gives_the_adapters_runs(variant):
    """The world keeps the previous run's body when the next run is of the same case and variant (a ladder
    and the one-step rungs of a case): free runs and one steps at other steps, in any order, interleaved,
    are still the adapter's bit for bit."""
    scs = _cases()
    rng = np.random.default_rng(5)
    adapter = get_adapter("pybullet")
    for sc in scs:
        B = None
        for kind, h in (("run", sc.dt_s), ("step", sc.dt_s / 8), ("run", sc.dt_s / 2), ("step", sc.dt_s),
                        ("run", sc.dt_s / 4), ("run", sc.dt_s)):
            if kind == "run":
                n = int(round(8 * sc.dt_s / h))
                got, want = pybullet_batch.simulate(sc, variant, h, n), np.asarray(adapter.simulate(sc, variant, h, n).y)
            else:
                y = sc.problem.initial_packed() + 0.05 * rng.standard_normal((3, 13))
                y[:, 6:10] /= np.linalg.norm(y[:, 6:10], axis=1, keepdims=True)
                got, want = pybullet_batch.one_step(sc, variant, h, y), adapter.one_step(sc, variant, h, y)
            assert np.array_equal(got, want), (sc.name, kind, h)
            assert B is None or pybullet_batch._WORLD["body"] is B   # the same body all along
            B = pybullet_batch._WORLD["body"]
    pybullet_batch.release()
    assert pybullet_batch._WORLD["b"] is None
