import os

import pytest

TINY_RESULTS_SCENARIO = """
name = "tiny"
duration = 0.2
dt = 0.01
dt_ladder = [0.02, 0.01]
[body]
mass = 1.0
inertia = [1.0, 2.0, 3.0]
[initial]
velocity = [0.0, 0.0, 1.0]
angular_velocity = [0.3, 1.0, 0.2]
[forces]
gravity = [0.0, 0.0, -9.81]
"""


@pytest.fixture(scope="session")
def tiny_results(tmp_path_factory):
    """One small results directory written by a real sweep (marker, series, plots, pages), built once
    per test process; tests copy it before changing anything."""
    from cross_checks.scenario import parse_scenario
    from cross_checks.sweep import run_sweep
    tmp = tmp_path_factory.mktemp("tiny_results")
    old = os.environ.get("RBCHECK_CACHE_DIR")
    os.environ["RBCHECK_CACHE_DIR"] = str(tmp / "cache")
    try:
        import reports
        run_sweep([parse_scenario(TINY_RESULTS_SCENARIO, "tiny.toml")], ["reference:course", "reference:rk4"],
                  tmp / "res", jobs=1, progress=False, finish=lambda d: reports.render(d, jobs=1))
    finally:
        os.environ.pop("RBCHECK_CACHE_DIR") if old is None else os.environ.__setitem__("RBCHECK_CACHE_DIR", old)
    return tmp / "res"
