"""Planning a sweep: every (scenario, engine variant, Δt) job, with a rough cost so the longest run first."""
from __future__ import annotations

from cross_checks.analysis.expectations import judged_ladder_s
from cross_checks.sweep.jobs import Job, job_dts

__all__ = ["plan_jobs", "job_cost_s", "inexpressible"]

#: Rough cost per step (µs) of each variant, (forces constant, forces state-dependent), from results.csv's
#: wall_s / steps. Used to run the longest jobs first and to estimate the time left; an engine not listed
#: (e.g. an engine file) counts _COST_DEFAULT_US.
_COST_US = {
    "reference:course": (11, 13), "reference:course_gyro": (12, 15), "reference:expmap_gyro": (13, 16),
    "reference:explicit_euler": (13, 16), "reference:midpoint": (22, 29), "reference:rk4": (34, 44),
    "reference:leapfrog": (35, 37), "reference:implicit_euler": (36, 44),
    "mujoco:euler": (5, 18), "mujoco:implicitfast": (6, 18), "mujoco:implicit": (7, 20),
    "mujoco:discrete": (6, 18), "mujoco:rk4": (14, 58),
    "pybullet:maximal": (12, 42), "pybullet:multibody": (12, 44),
    "drake:semi_explicit_euler": (21, 62), "drake:runge_kutta2": (29, 91), "drake:runge_kutta3": (37, 127),
    "drake:implicit_euler": (126, 382),
    # the eight gyroscopic variants step by their definition in NumPy (no compiled kernel:
    # docs/gyro_integrators.md)
    "reference:implicit_gyro_body": (380, 420), "reference:implicit_gyro_world": (410, 450),
    "reference:explicit_gyro_clamped": (340, 380), "reference:jolt_gyro": (350, 390),
    "reference:buss_augmented": (530, 580), "reference:dlm_splitting": (950, 1050),
    "reference:lp_midpoint": (850, 950), "reference:moser_veselov": (970, 1070),
}
_COST_DEFAULT_US = (5, 75)


def job_cost_s(scenario, variant: str, dt: float) -> float:
    """Estimated wall time (s) of one run: its steps times the variant's measured cost per step."""
    us = _COST_US.get(variant, _COST_DEFAULT_US)[1 if scenario.problem.forces.state_dependent else 0]
    return scenario.n_steps(dt) * us * 1e-6


def inexpressible(scenarios, variants) -> dict:
    """``{(scenario name, variant): the engine's sentence}`` (``variants``: Resolved) of every pair whose
    engine cannot take the scenario's physics (EngineAdapter.expressible): the sweep runs nothing for them
    and says so."""
    out = {}
    for sc in scenarios:
        for v in variants:
            why = v.cannot_express(sc)
            if why:
                out[(sc.name, v)] = why
    return out


def plan_jobs(scenarios, variants, leave_out=()) -> list:
    """Every (scenario, variant, Δt) job, longest first, except those of the (scenario name, variant) pairs
    in ``leave_out``."""
    jobs = []
    for i, sc in enumerate(scenarios):
        for v in variants:
            if (sc.name, v) in leave_out:
                continue
            ladder = judged_ladder_s(sc, v)
            for dt in job_dts(sc, (v,)):
                jobs.append(Job(i, sc.name, v, dt, any(d == dt for d in ladder),
                                dt == sc.dt_s, job_cost_s(sc, v, dt)))
    jobs.sort(key=lambda j: -j.cost)
    return jobs
