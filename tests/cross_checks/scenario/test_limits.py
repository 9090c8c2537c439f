"""Resource limits decided up front from the scenario: exit 2 naming the field and the limit, never a
MemoryError or an hour-long solve; the catalog stays far inside every limit. (Time limits while running:
tests/cross_checks/sweep/test_lifecycle.py.)"""
import numpy as np
import pytest

from cross_checks.cli import main
from cross_checks.core import tolerances as tol
from cross_checks.scenario import ScenarioError, catalog_names, load_scenario, parse_scenario
from cross_checks.scenario.limits import MAX_STEPS_PER_RUN, reference_evals, run_memory_bytes
from cross_checks.scenario.references import reference_solution

BASE = """
name = "{name}"
duration = {duration}
dt = {dt}
{extra}
[body]
mass = 1.0
inertia = [1.0, 2.0, 3.0]
[initial]
angular_velocity = [0.3, 1.0, 0.2]
"""

STIFF_PENDULUM = load_scenario("spring_pendulum").raw


def scenario_text(name="s", duration=1.0, dt=0.01, extra=""):
    return BASE.format(name=name, duration=duration, dt=dt, extra=extra)


@pytest.mark.parametrize("kwargs, field, words", [
    (dict(duration=1e12, dt=1e-3), "dt", "1e+15 steps"),
    (dict(dt=1e-15), "dt", "1e+15 steps"),
    (dict(dt=1e-320), "dt", "more than 1e308 steps"),
    (dict(extra="dt_ladder = [0.01, 1e-7]"), "dt_ladder[1]", "1e+07 steps"),
    (dict(extra="dt_ladder = [0.01, 0.010000000000000002]"),
     "dt_ladder[1]", "too close to dt_ladder[0] = 0.01"),
    (dict(extra="dt_ladder = [0.01, 0.009]"), "dt_ladder[1]", "at least 1.2"),
    (dict(name="a" * 300), "name", "at most 100 characters"),
])
def test_unbounded_work_is_refused_naming_the_field_and_the_limit(kwargs, field, words):
    with pytest.raises(ScenarioError) as info:
        parse_scenario(scenario_text(**kwargs), "big.toml")
    assert info.value.field == field and words in info.value.reason
    assert str(info.value).startswith(f"big.toml: {field}: ")


def test_the_step_limit_is_the_memory_budget_at_the_measured_cost_per_step():
    assert MAX_STEPS_PER_RUN == tol.JOB_MEMORY_LIMIT_BYTES // tol.BYTES_PER_RECORDED_STEP
    n_ok = int(MAX_STEPS_PER_RUN * 0.9)
    parse_scenario(scenario_text(duration=n_ok * 1e-4, dt=1e-4), "ok.toml")  # just inside: accepted
    with pytest.raises(ScenarioError, match="steps per run"):
        parse_scenario(scenario_text(duration=MAX_STEPS_PER_RUN * 1.1e-4, dt=1e-4), "big.toml")


def test_deeply_nested_toml_is_a_located_error_not_a_recursion_error():
    with pytest.raises(ScenarioError, match="nested too deeply"):
        parse_scenario("x = " + "[" * 5000 + "]" * 5000 + "\n", "deep.toml")
    with pytest.raises(ScenarioError, match="nested too deeply"):
        parse_scenario("x = " + "{a = " * 3000 + "1" + "}" * 3000 + "\n", "deep.toml")


def test_a_stiff_spring_is_refused_before_its_reference_runs_for_hours():
    text = load_scenario("spring_pendulum").source
    toml = open_catalog("spring_pendulum").replace("stiffness = 40.0", "stiffness = 1e9")
    import scipy.integrate

    def no_solve(*a, **k):
        raise AssertionError("the reference was solved before the scenario was refused")
    with pytest.MonkeyPatch.context() as mp:   # refused from the scenario alone: no solve started
        mp.setattr(scipy.integrate, "solve_ivp", no_solve)
        mp.setattr("reference_sim.ground_truth.solve_ivp", no_solve)
        with pytest.raises(ScenarioError) as info:
            parse_scenario(toml, "stiff.toml")
    assert text and info.value.field == "forces.spring[0].stiffness"
    assert "right-hand-side evaluations; the limit is 1.2e+06" in info.value.reason


def open_catalog(name):
    from cross_checks.scenario import catalog_path
    return catalog_path(name).read_text()


def _counted_evals(monkeypatch, sc) -> int:
    """Right-hand-side evaluations of the scenario's real DOP853 reference solve (SciPy's own count)."""
    import reference_sim.ground_truth as gt
    counts = []

    def counting(*a, **k):
        sol = scipy_solve_ivp(*a, **k)
        counts.append(sol.nfev)
        return sol
    from scipy.integrate import solve_ivp as scipy_solve_ivp
    monkeypatch.setattr(gt, "solve_ivp", counting)
    reference_solution(sc, np.linspace(0.0, sc.duration_s, 101))
    assert len(counts) == 1
    return counts[0]


@pytest.mark.parametrize("stiffness, duration", [(40.0, 5.0), (4000.0, 0.5), (4e5, 0.05)])
def test_reference_evaluation_estimate_is_within_a_few_times_of_scipys_count(
        monkeypatch, stiffness, duration):
    # The estimate counts operations (SciPy's nfev), so the test holds on any machine: within 4x both ways
    # (the margin the limit keeps) over four orders of magnitude of stiffness.
    sc = parse_scenario(open_catalog("spring_pendulum")
                        .replace("stiffness = 40.0", f"stiffness = {stiffness}")
                        .replace("duration = 5.0", f"duration = {duration}").replace(
                            "dt_ladder = [0.008, 0.004, 0.002, 0.001, 0.0005]", "dt_ladder = [0.0005]")
                        .replace("dt = 0.001", "dt = 0.0005"),
                        "stiffer.toml")
    counted = _counted_evals(monkeypatch, sc)
    assert counted / 4 < reference_evals(sc) < counted * 4, (counted, reference_evals(sc))


@pytest.mark.parametrize("name", catalog_names())
def test_the_catalog_is_far_inside_every_limit(name):
    sc = load_scenario(name)
    assert run_memory_bytes(sc) < tol.JOB_MEMORY_LIMIT_BYTES / 20
    assert reference_evals(sc) < tol.REFERENCE_EVALS_LIMIT / 20
    assert max(sc.n_steps(d) for d in sc.dt_ladder_s) < MAX_STEPS_PER_RUN / 20


def test_rbcheck_run_refuses_an_override_beyond_the_step_limit(tmp_path, capsys):
    out = tmp_path / "t.csv"
    assert main(["run", "projectile", "--engine", "reference:course",
                 "--dt", "1e-300", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--dt: 1e-300 s makes" in err and "steps per run" in err
    assert not out.exists()
