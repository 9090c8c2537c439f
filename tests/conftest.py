"""Fixtures shared by the whole test tree. Helpers that are not fixtures live in tests/helpers/."""
import os

import matplotlib
import pytest

from tests.helpers.scenarios import GRAVITY, scenario_toml
from tests.helpers.sweeps import built_once, private_cache

matplotlib.use("Agg")
os.environ.setdefault("MPLBACKEND", "Agg")


def pytest_collection_modifyitems(config, items):
    """Tests marked ``first`` ahead of the others, each group in its collected order (a stable sort).

    pytest-xdist's default scheduling (``-n 2``, ``--dist load``) hands the first quarter of the collected
    tests out in turn, one to each worker, and the rest to whichever worker runs short. Collected in file
    order, the longest test and the longest shared build (tests/test_gates.py's sweep) came last: one worker
    built while the other waited for it. Marked, they start at once, one worker each, and the short tests
    fill in around them."""
    items.sort(key=lambda item: item.get_closest_marker("first") is None)


@pytest.fixture(autouse=True)
def _no_job_summary(monkeypatch):
    """No test appends to the job summary of the CI run that runs the tests ($GITHUB_STEP_SUMMARY: sweep and
    compare append to it); a test of that sets its own file."""
    monkeypatch.delenv("GITHUB_STEP_SUMMARY", raising=False)


@pytest.fixture
def isolated_cache(tmp_path, monkeypatch):
    """A private, empty rbcheck cache for this test (RBCHECK_CACHE_DIR = tmp_path/cache, restored after):
    nothing is served from, or stored into, another test's or the developer's cache."""
    monkeypatch.setenv("RBCHECK_CACHE_DIR", str(tmp_path / "cache"))
    return tmp_path / "cache"


#: The scenario of ``tiny_results``: a short tumble under gravity (translation and rotation both move).
TINY_RESULTS_SCENARIO = scenario_toml("tiny", 0.2, 0.01, (0.02, 0.01), forces=GRAVITY,
                                      initial="velocity = [0.0, 0.0, 1.0]\n"
                                              "angular_velocity = [0.3, 1.0, 0.2]")


def _tiny_sweep(folder):
    import reports
    from cross_checks.scenario import parse_scenario
    from cross_checks.sweep import run_sweep
    with private_cache(folder / "cache"):
        run_sweep([parse_scenario(TINY_RESULTS_SCENARIO, "tiny.toml")], ["reference:course", "reference:rk4"],
                  folder / "res", jobs=1, progress=False, finish=lambda d: reports.render(d, jobs=1))


@pytest.fixture(scope="session")
def tiny_results(tmp_path_factory):
    """One small results directory written by a real sweep (marker, series, plots, pages), built once per
    test run and shared by the xdist workers; tests copy it before changing anything."""
    return built_once(tmp_path_factory, "tiny_results", _tiny_sweep) / "res"
