"""Planning a sweep: every (scenario, engine variant, Δt) job, with a rough cost so the longest run first."""
from __future__ import annotations

from cross_checks.sweep.jobs import Job, job_dts

__all__ = ["plan_jobs", "job_cost_s"]

#: Rough cost per step (µs) of each variant, measured on the catalog (2 vCPU), only to order the
#: jobs longest first. MuJoCo/PyBullet cost ~5 µs/step unless the adapter evaluates the forces in
#: Python every step (state-dependent forces): then ~75 µs (~270 µs for MuJoCo RK4's four stages).
_COST_US = {"reference:course": 7, "reference:course_gyro": 7, "reference:expmap_gyro": 7,
            "reference:explicit_euler": 7, "reference:implicit_euler": 800, "reference:midpoint": 12,
            "reference:leapfrog": 40, "reference:rk4": 22}
_COST_ENGINE_STATE_DEPENDENT = {"mujoco:rk4": 270}
_COST_ENGINE_DEFAULT_US = (5, 75)  # (forces constant, forces state-dependent)


def job_cost_s(scenario, variant: str, dt: float) -> float:
    """Estimated wall time (s) of one run: its steps times the variant's measured cost per step."""
    n = scenario.n_steps(dt)
    if variant in _COST_US:
        us = _COST_US[variant]
    elif scenario.problem.forces.state_dependent:
        us = _COST_ENGINE_STATE_DEPENDENT.get(variant, _COST_ENGINE_DEFAULT_US[1])
    else:
        us = _COST_ENGINE_DEFAULT_US[0]
    return n * us * 1e-6


def plan_jobs(scenarios, variants) -> list:
    """Every (scenario, variant, Δt) job, longest first."""
    jobs = []
    for i, sc in enumerate(scenarios):
        for v in variants:
            for dt in job_dts(sc):
                jobs.append(Job(i, sc.name, v, dt, any(d == dt for d in sc.dt_ladder_s), dt == sc.dt_s,
                                job_cost_s(sc, v, dt)))
    jobs.sort(key=lambda j: -j.cost)
    return jobs
