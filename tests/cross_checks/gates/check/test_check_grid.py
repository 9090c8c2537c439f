"""The full `rbcheck check` grid (``-m slow``): every catalog scenario and the three new ones, Δt from
1e-2 to 1e-3, every engine variant passes; every planted mistake is caught and named wherever its
physics matters. Durations are capped at 3 s (the defect and the conserved quantities do not need
more; the free-running comparison stops being decisive sooner on the chaotic ones)."""
import re

import pytest

from cross_checks.cli import main
from cross_checks.scenario import catalog_names, load_scenario
from tests.helpers.sweeps import gated_variants

from . import student_sim as S
from .test_check import HERE, scenario_file, student_file

pytestmark = pytest.mark.slow

NEW = sorted(p.stem for p in HERE.glob("*.toml"))
SCENARIOS = catalog_names() + NEW
DTS = (0.01, 0.005, 0.002, 0.001)
CAP_S = 3.0

ROTATING = ["constant_spin", "symmetric_top", "tennis_racket", "tumbling_box", "particle_body",
            "applied_torque", "spring_pendulum", "velocity_decay", "thruster_box", "damped_spring_top",
            "fast_tensor_spin"]
OFF_COM = ["applied_torque", "spring_pendulum", "thruster_box", "damped_spring_top"]
GRAVITY_NOT_Y = ["projectile", "linear_drag", "tumbling_box", "particle_body", "applied_torque",
                 "spring_oscillator", "spring_pendulum", "thruster_box", "damped_spring_top"]
#: bug -> scenarios where its physics matters
MATTERS = {
    "gyro_sign": [s for s in ROTATING if s not in ("constant_spin", "velocity_decay")],
    "quat_right": ROTATING, "omega_body": ROTATING, "no_half": ROTATING, "no_normalise": ROTATING,
    "inertia_body": ROTATING, "inertia_transposed": ROTATING,
    "torque_order": OFF_COM, "lever_body": OFF_COM, "no_point_torque": OFF_COM,
    "torque_world": ["applied_torque", "thruster_box"],
    "attach_body": ["spring_pendulum", "damped_spring_top"], "drag_sign": ["linear_drag", "thruster_box"],
    "gravity_y": GRAVITY_NOT_Y, "dt_mismatch": SCENARIOS,
}
#: decay bugs at the scenario's own dt (where the course's γ and e^(−kΔt) agree)
DECAY = [("decay_twice", "velocity_decay"), ("no_decay", "velocity_decay"),
         ("decay_twice", "damped_spring_top"), ("no_decay", "damped_spring_top")]


def _file(tmp_path, name):
    sc = load_scenario(HERE / f"{name}.toml" if name in NEW else name)
    return scenario_file(tmp_path, name, min(sc.duration_s, CAP_S))


def _check(capsys, traj, sc, *extra):
    rc = main(["check", str(traj), "--scenario", str(sc), *extra])
    return rc, capsys.readouterr().out


def _per_step_decay_elsewhere(sc_path, dt):
    """True where the engines (and reference:course) apply the course's per-step γ at a Δt other than
    the scenario's: another physical damping, which the check rightly fails unless the file IS a
    reference scheme (then it passes with the frame-rate caveat)."""
    from .test_check import _reference_course_applies_the_per_step_factor
    sc = load_scenario(sc_path)
    return (sc.problem.forces.has_decay and abs(dt - sc.dt_s) > 1e-12
            and _reference_course_applies_the_per_step_factor(dt))


@pytest.mark.parametrize("dt", DTS)
@pytest.mark.parametrize("scen", SCENARIOS)
def test_every_engine_variant_passes_everywhere(tmp_path, capsys, scen, dt):
    sc = _file(tmp_path, scen)
    frame_rate_dependent = _per_step_decay_elsewhere(sc, dt)
    bad = []
    for v in gated_variants():
        out = tmp_path / f"{v.replace(':', '_')}.csv"
        rc = main(["run", str(sc), "--engine", v, "--dt", str(dt), "--out", str(out)])
        capsys.readouterr()
        if rc != 0:
            continue              # the engine itself diverged here (rbcheck run says so): nothing to judge
        rc, text = _check(capsys, out, sc)
        if rc != 0 and not (frame_rate_dependent and "frame-rate dependent" in text):
            bad.append(f"{v}: {text.splitlines()[0]}")
    assert not bad, "\n".join(bad)


BUG_GRID = [(b, s, dt) for b, ss in MATTERS.items() for s in ss for dt in DTS]


@pytest.mark.parametrize("bug, scen, dt", BUG_GRID, ids=[f"{b}-{s}-{d:g}" for b, s, d in BUG_GRID])
def test_every_planted_mistake_is_caught_everywhere_it_matters(tmp_path, capsys, bug, scen, dt):
    sc = _file(tmp_path, scen)
    rc, out = _check(capsys, student_file(tmp_path, sc, dt, bug=bug), sc)
    assert rc == 1, out
    causes = [line for line in out.splitlines() if line.startswith("likely cause:")]
    assert causes and S.BUGS[bug] in causes[0], out


@pytest.mark.parametrize("bug, scen", DECAY)
def test_decay_mistakes_are_caught_at_the_scenarios_dt(tmp_path, capsys, bug, scen):
    sc = _file(tmp_path, scen)
    dt = load_scenario(sc).dt_s
    rc, out = _check(capsys, student_file(tmp_path, sc, dt, bug=bug), sc)
    assert rc == 1 and S.BUGS[bug] in out, out


@pytest.mark.parametrize("scheme", ["course", "expmap", "explicit"])
@pytest.mark.parametrize("scen", SCENARIOS)
def test_a_students_correct_schemes_pass_everywhere(tmp_path, capsys, scen, scheme):
    sc = _file(tmp_path, scen)
    for dt in DTS:
        rc, out = _check(capsys, student_file(tmp_path, sc, dt, scheme=scheme), sc)
        assert rc == 0, f"Δt = {dt}: {out}"
        rc, out = _check(capsys, student_file(tmp_path, sc, dt, scheme=scheme, float32=True, fmt="%.9g"), sc)
        assert rc == 0, f"Δt = {dt}, single precision: {out}"
    assert re.match(r"^[a-z0-9_]+$", scen)
