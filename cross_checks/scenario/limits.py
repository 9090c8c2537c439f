"""Resource limits of a scenario, decided up front from the scenario alone (before any run starts;
docs/hardening.md, "Limits decided from the scenario").

A run's memory grows with ``duration / Δt``; the DOP853 reference's CPU with ``duration × (the fastest
rate of the dynamics)``, counted in right-hand-side evaluations (never in seconds: the limits are the same
on every machine). A scenario beyond them is refused with a :class:`~cross_checks.scenario.ScenarioError`
naming the field, the estimate and the limit. The numbers, and where each comes from, are in
:mod:`cross_checks.core.tolerances` ("hardening"); the time limits that hold while the work runs are the
sweep's (``--time-limit``).
"""
from __future__ import annotations

import math

import numpy as np

from cross_checks.core import tolerances as tol

__all__ = ["LimitExceeded", "check_scenario_limits", "check_run_steps", "run_memory_bytes",
           "reference_evals", "fastest_rate", "MAX_STEPS_PER_RUN", "check_physical_ranges"]

#: Steps one run may record: the memory a job may use at the measured cost per recorded step.
MAX_STEPS_PER_RUN = int(tol.JOB_MEMORY_LIMIT_BYTES // tol.BYTES_PER_RECORDED_STEP)


class LimitExceeded(ValueError):
    """A scenario whose work would exceed a limit: ``field`` and ``reason`` as in ScenarioError."""

    def __init__(self, field_: str, reason: str):
        self.field, self.reason = field_, reason
        super().__init__(f"{field_}: {reason}")


def _gib(n_bytes: float) -> str:
    return f"{n_bytes / 2 ** 30:.3g} GiB"


def check_run_steps(duration_s: float, dt_s: float, field_: str) -> int:
    """Steps of one run of ``duration_s`` at ``dt_s``; LimitExceeded (naming ``field_``) beyond the limit.

    Works for any positive finite inputs, including Δt = 1e-320 (the ratio overflows to inf)."""
    with np.errstate(over="ignore"):
        n = float(np.float64(duration_s) / np.float64(dt_s))
    if not math.isfinite(n) or n > MAX_STEPS_PER_RUN:
        shown = "more than 1e308" if not math.isfinite(n) else f"{n:.3g}"
        raise LimitExceeded(field_,
                            f"{dt_s:g} s makes {shown} steps over the duration {duration_s:g} s; the limit "
                            f"is {MAX_STEPS_PER_RUN:.3g} steps per run ({_gib(tol.JOB_MEMORY_LIMIT_BYTES)} "
                            f"of memory at ~{tol.BYTES_PER_RECORDED_STEP} bytes per recorded step)")
    return int(round(n))


def _ladder_fields(scenario):
    """``(field, Δt)`` of every run a sweep makes of the scenario."""
    if "dt_ladder" not in scenario.raw:
        return [("dt", scenario.dt_s)]
    given = list(scenario.raw["dt_ladder"])
    out = [(f"dt_ladder[{given.index(d)}]", d) for d in scenario.dt_ladder_s]
    if not any(d == scenario.dt_s for d in scenario.dt_ladder_s):
        out.append(("dt", scenario.dt_s))
    return out


def run_memory_bytes(scenario) -> float:
    """Peak memory estimate of the scenario's largest sweep job: its own recorded steps plus the
    reference on the union of the scenario's time grids. BYTES_PER_RECORDED_STEP was measured for a
    run and its reference on the same grid (about half each), so each point counts half of it."""
    steps = [scenario.n_steps(d) for _, d in _ladder_fields(scenario)]
    union = sum(n + 1 for n in steps)  # upper bound; exact when no grid point is shared
    if union * tol.BYTES_PER_RECORDED_STEP > tol.JOB_MEMORY_LIMIT_BYTES:
        grids = [d * np.arange(n + 1) for (_, d), n in zip(_ladder_fields(scenario), steps)]
        union = np.unique(np.concatenate(grids)).size
    return float((max(steps) + 1 + union) * tol.BYTES_PER_RECORDED_STEP / 2)


def fastest_rate(scenario) -> tuple:
    """``(rate in 1/s, field)``: the fastest rate of the dynamics and the scenario field that sets it.

    Rates: spring frequencies (translation ``sqrt(Σk/m)``, rotation ``sqrt(Σ k r (r + reach) / I_min)``
    with r the attachment radius and reach how far the anchor can pull it), the spin rate (initial
    ``|ω|`` plus what the torques and off-COM forces can add over the duration), and the damping rates
    (drag ``c/m``, the course's decay ``−ln γ / dt``). DOP853 needs a fixed number of steps per unit of
    the fastest rate (measured, tolerances.DOP853_EVALS_PER_RAD)."""
    p = scenario.problem
    fm, m = p.forces, p.body.mass_kg
    i_min = float(np.linalg.eigvalsh(p.body.inertia_B)[0])
    rates = []
    if fm.springs:
        k_sum = sum(s.stiffness_N_per_m for s in fm.springs)
        rot = 0.0
        for s in fm.springs:
            r = float(np.linalg.norm(s.attach_B))
            reach = (float(np.linalg.norm(np.asarray(s.anchor_W) - np.asarray(p.initial.x_W)))
                     + r + s.rest_length_m)
            rot += s.stiffness_N_per_m * r * (r + reach)
        stiffest = max(range(len(fm.springs)), key=lambda i: fm.springs[i].stiffness_N_per_m)
        rates.append((math.sqrt(k_sum / m + rot / i_min), f"forces.spring[{stiffest}].stiffness"))
    torque = sum(float(np.linalg.norm(t.torque)) for t in fm.torques)
    torque += sum(float(np.linalg.norm(pf.force) * np.linalg.norm(pf.point_B)) for pf in fm.point_forces)
    spin = float(np.linalg.norm(p.initial.w_W)) + torque * scenario.duration_s / i_min
    rates.append((spin, "initial.angular_velocity" if torque == 0 else "forces.torque"))
    rates.append((fm.linear_drag_N_s_per_m / m, "forces.linear_drag"))
    for key, g in (("velocity_decay", fm.velocity_decay),
                   ("angular_velocity_decay", fm.angular_velocity_decay)):
        rates.append((-math.log(g) / scenario.dt_s, f"forces.{key}"))
    return max(rates, key=lambda r: r[0])


def reference_evals(scenario) -> float:
    """Estimated right-hand-side evaluations of the scenario's DOP853 reference solve (0 when a closed
    form covers it): DOP853_EVALS_PER_RAD per radian of the fastest rate over the duration. A count of
    operations, the same on every machine; what it costs in seconds depends on the machine."""
    from cross_checks.scenario.references import analytic_available
    if scenario.reference != "ground_truth" and analytic_available(scenario)[0]:
        return 0.0
    rate, _ = fastest_rate(scenario)
    return tol.DOP853_EVALS_PER_RAD * max(rate, 1.0 / scenario.duration_s) * scenario.duration_s


def _in_range(value: float, lo: float, hi: float, field_: str, what: str, unit: str) -> None:
    if not (lo <= value <= hi):
        raise LimitExceeded(field_, f"{what} {value:.3g} {unit} is outside the range rbcheck judges, "
                                    f"[{lo:g}, {hi:g}] {unit} (docs/hardening.md)".replace(" ]", "]"))


def check_physical_ranges(scenario) -> None:
    """LimitExceeded (field, reason) when a physical number of the scenario lies outside the ranges of
    :mod:`cross_checks.core.tolerances` ("physical ranges"): a mass, a principal moment, the ratio of the
    largest to the smallest moment, an initial speed, spin, position, or a force's size. Beyond them the
    engines refuse the body (MuJoCo below its mjMINVAL) or float64 round-off, not the scheme, makes the
    errors, and a verdict would not be about the simulator."""
    with np.errstate(over="ignore", invalid="ignore"):   # |ω| = 1e300 squares to inf: outside, said so
        _check_physical_ranges(scenario)


def _check_physical_ranges(scenario) -> None:
    p = scenario.problem
    parts = getattr(scenario, "body_parts", ())
    src = ("body.particles" if scenario.com_offset_B_m is not None else "body.parts" if parts
           else "body.mass")
    _in_range(p.body.mass_kg, *tol.PHYSICAL_MASS_KG, src, "the mass", "kg")
    for i, part in enumerate(parts):
        _in_range(part.mass_kg, *tol.PHYSICAL_MASS_KG, f"body.parts[{i}].mass", "the part's mass", "kg")
    body_com = getattr(scenario, "body_com_B_m", None)
    if body_com is not None:
        _in_range(float(np.linalg.norm(body_com)), 0.0, tol.PHYSICAL_MAX_DISTANCE_M,
                  "body.parts" if parts else "body.com", "the distance |c| of the COM from the body frame's "
                  "origin", "m")
        _in_range(float(np.linalg.norm(scenario.raw.get("initial", {}).get("position", [0.0, 0.0, 0.0]))),
                  0.0, tol.PHYSICAL_MAX_DISTANCE_M, "initial.position",
                  "the distance of the body frame's origin from the world origin", "m")
    moments = np.linalg.eigvalsh(p.body.inertia_B)
    where = ("body.particles" if scenario.com_offset_B_m is not None else "body.parts" if parts
             else "body.inertia")
    _in_range(float(moments[0]), *tol.PHYSICAL_INERTIA_KG_M2, where, "the smallest principal moment", "kg m²")
    _in_range(float(moments[-1]), *tol.PHYSICAL_INERTIA_KG_M2, where, "the largest principal moment", "kg m²")
    _in_range(float(moments[-1] / moments[0]), 1.0, tol.PHYSICAL_MAX_INERTIA_RATIO, where,
              "the ratio of the largest to the smallest principal moment", "")
    init = p.initial
    _in_range(float(np.linalg.norm(init.w_W)), 0.0, tol.PHYSICAL_MAX_SPIN_RAD_S, "initial.angular_velocity",
              "the initial spin |ω|", "rad/s")
    _in_range(float(np.linalg.norm(init.v_W)), 0.0, tol.PHYSICAL_MAX_SPEED_M_S, "initial.velocity",
              "the initial speed |v|", "m/s")
    _in_range(float(np.linalg.norm(init.x_W)), 0.0, tol.PHYSICAL_MAX_DISTANCE_M, "initial.position",
              "the distance from the origin |x|", "m")
    fm = p.forces
    _in_range(float(np.linalg.norm(fm.gravity_W)), 0.0, tol.PHYSICAL_MAX_ACCELERATION_M_S2, "forces.gravity",
              "the gravity |g|", "m/s²")
    for i, pf in enumerate(fm.point_forces):
        _in_range(float(np.linalg.norm(pf.force)) / p.body.mass_kg, 0.0, tol.PHYSICAL_MAX_ACCELERATION_M_S2,
                  f"forces.point[{i}].force", "the acceleration |f|/m it gives", "m/s²")
    for i, t in enumerate(fm.torques):
        _in_range(float(np.linalg.norm(t.torque)) / float(moments[0]), 0.0,
                  tol.PHYSICAL_MAX_ANGULAR_ACCELERATION, f"forces.torque[{i}].torque",
                  "the angular acceleration |τ|/I_min it gives", "rad/s²")


def check_scenario_limits(scenario) -> None:
    """LimitExceeded (field, estimate, limit) when any run of a sweep of ``scenario``, or its reference,
    would exceed a limit. Cheap: no simulation."""
    for fld, d in _ladder_fields(scenario):
        check_run_steps(scenario.duration_s, d, fld)
    mem = run_memory_bytes(scenario)
    if mem > tol.JOB_MEMORY_LIMIT_BYTES:
        raise LimitExceeded("dt_ladder",
                            "the finest run and the reference on the union of the time grids need "
                            f"~{_gib(mem)} of memory; the limit is {_gib(tol.JOB_MEMORY_LIMIT_BYTES)} "
                            "per job (use fewer or coarser rungs, or a shorter duration)")
    evals = reference_evals(scenario)
    if evals > tol.REFERENCE_EVALS_LIMIT:
        rate, fld = fastest_rate(scenario)
        raise LimitExceeded(fld,
                            f"the dynamics run at {rate:.3g} 1/s, so the DOP853 reference over the "
                            f"duration {scenario.duration_s:g} s would need ~{evals:.3g} right-hand-side "
                            f"evaluations; the limit is {tol.REFERENCE_EVALS_LIMIT:.3g} (minutes of CPU "
                            "on any machine; shorten the duration or soften the dynamics)")


