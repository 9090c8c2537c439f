"""Mutation tests: a sweep's gates catch every bug planted in a copy of a scheme or an adapter
(tests/mutants.py), and pass the correct variants on the same scenarios.

The default run plants a few bugs, each swept on the scenario that exposes it; ``-m slow`` sweeps the
whole catalog for every mutant and reports the mutation score.
"""
import numpy as np
import pytest

from cross_checks.cli.sweep import _gate_failures
from cross_checks.engines import available_variants
from cross_checks.scenario import catalog_names, load_scenario
from cross_checks.sweep import run_sweep

from .mutants import MUTANTS

#: a private cache for every test: a mutant's runs must neither be served from nor stored into a shared cache
pytestmark = pytest.mark.usefixtures("isolated_cache")

BY_NAME = {m.name: m for m in MUTANTS}
#: The default run: one bug per kind (a stage weight, the gyroscopic sign, decay twice, a frame mix-up in
#: each engine adapter), each on the one scenario that exposes it.
QUICK = ["rk4_wrong_stage_weight", "gyroscopic_sign_flipped", "course_decay_twice",
         "mujoco_world_omega_as_body", "pybullet_principal_axes_dropped", "drake_omega_in_body_axes"]


def _gate_failures_of_sweep(tmp_path, scenarios, variant, jobs=1):
    summary = run_sweep([load_scenario(s) for s in scenarios], [variant], tmp_path / "out", jobs=jobs,
                        use_cache=False, progress=False)
    return _gate_failures(summary)


def _need(variant):
    if variant not in available_variants():
        pytest.skip(f"{variant} unavailable here")


def test_mutants_are_distinct_and_name_real_variants():
    assert len(BY_NAME) == len(MUTANTS) and set(QUICK) <= set(BY_NAME)
    from cross_checks.engines import split_variant
    for m in MUTANTS:
        split_variant(m.variant)
        assert set(m.exposed_by) <= set(catalog_names())


@pytest.mark.parametrize("name", QUICK)
def test_the_gates_catch_a_planted_bug(name, tmp_path, monkeypatch):
    m = BY_NAME[name]
    _need(m.variant)
    m.apply(monkeypatch)
    _need(m.swept)
    fails = _gate_failures_of_sweep(tmp_path, m.exposed_by, m.swept)
    assert fails, f"{m.name} ({m.bug}) was not caught on {m.exposed_by}"


@pytest.mark.slow
@pytest.mark.parametrize("variant", sorted({m.variant for m in MUTANTS}))
def test_the_correct_variants_pass_where_the_mutants_are_exposed(variant, tmp_path, monkeypatch):
    _need(variant)
    scenarios = sorted({s for m in MUTANTS if m.variant == variant for s in m.exposed_by})
    assert _gate_failures_of_sweep(tmp_path, scenarios, variant, jobs=2) == []


@pytest.mark.slow
@pytest.mark.parametrize("name", [m.name for m in MUTANTS])
def test_every_planted_bug_is_caught_by_a_catalog_sweep(name, tmp_path, monkeypatch):
    m = BY_NAME[name]
    _need(m.variant)
    m.apply(monkeypatch)
    _need(m.swept)
    fails = _gate_failures_of_sweep(tmp_path, catalog_names(), m.swept, jobs=2)
    assert fails, f"{m.name} ({m.bug}) was not caught by a sweep of the catalog"


def test_mutants_run_batched_as_they_run_alone():
    """A sweep hands a reference mutant a ladder at once (MutantAdapter.simulate_many, mutants.batched, one
    batch as the reference adapter's own); every run of it is the run alone, bit for bit, for every reference
    mutant (its broken step or knob) and the long-run mutants: rungs of different lengths on each scenario
    that exposes it, and two scenarios in one batch."""
    from cross_checks.engines.base import RunRequest

    from .mutants import LongRunMutant
    adapters = [(m.adapter, m.exposed_by) for m in MUTANTS if m.adapter is not None]
    adapters.append((LongRunMutant("planted", None, "a batch"), ("tennis_racket", "spring_pendulum")))
    for adapter, exposed in adapters:
        (variant,) = adapter.variants
        scs = [load_scenario(s) for s in exposed] + [load_scenario("spring_pendulum")]
        reqs = [RunRequest(sc, dt, min(sc.n_steps(dt), 20 + 9 * k))
                for sc in scs for k, dt in enumerate(sc.dt_ladder_s[:3])]
        for r, run in zip(reqs, adapter.simulate_many(variant, reqs)):
            alone = adapter.simulate(r.scenario, variant, r.dt_s, r.n_steps)
            assert run.message == alone.message and run.diverged_at_s == alone.diverged_at_s
            assert np.array_equal(run.t_s, alone.t_s) and np.array_equal(run.y, alone.y), (adapter.name, r)
