"""EngineAdapter.simulate_many, the one batched seam of the sweep and the fuzz: a bug planted in an adapter
(tests/mutants.py) reaches its runs of many requests in one call, which are its ``simulate``'s with the bug
(that an engine's batched runs are its single ones: test_contract.py's
test_many_runs_in_one_call_are_its_single_runs, for every installed engine)."""
import numpy as np
import pytest

from cross_checks.engines import available_variants, get_adapter, split_variant
from cross_checks.engines.base import EngineError, RunRequest
from cross_checks.scenario import load_scenario
from tests.mutants import MUTANTS


def _requests(names, steps=60):
    scs = [load_scenario(n) for n in names]
    return [RunRequest(sc, h, min(steps, sc.n_steps(h))) for sc in scs for h in (sc.dt_s, sc.dt_s / 2)]


def _same(a, b) -> bool:
    if isinstance(a, EngineError) or isinstance(b, EngineError):
        return type(a) is type(b) and str(a) == str(b)
    return (a.diverged_at_s == b.diverged_at_s and a.message == b.message and np.array_equal(a.t_s, b.t_s)
            and np.array_equal(a.y, b.y))


def _simulated(adapter, var, r):
    try:
        return adapter.simulate(r.scenario, var, r.dt_s, r.n_steps)
    except EngineError as exc:
        return exc


@pytest.mark.parametrize("mutant", [m for m in MUTANTS if not m.variant.startswith("reference:")],
                         ids=lambda m: m.name)
def test_a_bug_planted_in_an_adapter_reaches_its_batched_runs(mutant, monkeypatch):
    if mutant.variant not in available_variants():
        pytest.skip(f"{mutant.variant} unavailable here")
    engine, var = split_variant(mutant.variant)
    adapter = get_adapter(engine)
    requests = _requests(mutant.exposed_by)
    clean = adapter.simulate_many(var, requests)
    mutant.apply(monkeypatch)
    planted = adapter.simulate_many(var, requests)
    assert all(_same(p, _simulated(adapter, var, r)) for r, p in zip(requests, planted))  # the bug's own runs
    assert not all(_same(c, p) for c, p in zip(clean, planted)), (
        f"{mutant.name} did not reach the batched runs")
