"""`rbcheck check`: every planted mistake is caught (exit 1) and named, every correct scheme passes.

The broken simulators are student_sim.py (beside this file) — a per-body plain-Python loop written
from the course equations with one bug flag each, independent of the checker's own catalog
(cross_checks/gates/check/mistakes.py). Correct schemes: the student's own correct variants, every
reference variant, MuJoCo and PyBullet trajectories written by `rbcheck run`; on catalog scenarios
(shortened to keep the default run fast) and on the three scenarios in check_scenarios/ that the
catalog does not have, with Δt from 1e-3 to 1e-2. The full grid runs under ``-m slow``
(test_check_grid.py).
"""
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from cross_checks.cli import main
from cross_checks.core.trajectory import COLUMNS, Trajectory
from cross_checks.scenario import catalog_path, load_scenario

from . import student_sim as S

HERE = Path(__file__).parent / "check_scenarios"


def scenario_file(tmp_path, name, duration=None) -> Path:
    """A catalog (or check_scenarios/) scenario as a file, its duration shortened when given."""
    src = HERE / f"{name}.toml"
    text = src.read_text() if src.exists() else catalog_path(name).read_text()
    if duration is not None:
        text = re.sub(r"^duration = .*$", f"duration = {duration}", text, count=1, flags=re.M)
    path = tmp_path / f"{name}.toml"
    path.write_text(text)
    return path


def check(capsys, *args):
    rc = main(["check", *map(str, args)])
    out, err = capsys.readouterr()
    return rc, out, err


def student_file(tmp_path, scen_path, dt, fmt="repr", columns=COLUMNS, name="student.csv", **kw):
    rows = S.run(load_scenario(scen_path), dt, **kw)
    return S.write_csv(tmp_path / name, rows, fmt=fmt, columns=columns)


# --- the zoo: every planted mistake is caught and named ------------------------------------------------

#: (bug, scenario, Δt, shortened duration or None): each bug where its physics matters; chaotic
#: (tumbling_box, tennis_racket, fast_tensor_spin) and coarse (Δt = 1e-2) cases included.
ZOO = [
    ("gyro_sign", "tumbling_box", 0.01, 3.0),
    ("gyro_sign", "symmetric_top", 0.001, 0.5),
    ("quat_right", "symmetric_top", 0.01, 1.0),
    ("omega_body", "particle_body", 0.005, 1.0),
    ("inertia_body", "tennis_racket", 0.01, 2.0),
    ("inertia_transposed", "tumbling_box", 0.002, 0.5),
    ("torque_order", "applied_torque", 0.01, 1.0),
    ("lever_body", "thruster_box", 0.005, None),
    ("no_point_torque", "applied_torque", 0.001, 0.5),
    ("torque_world", "thruster_box", 0.01, None),
    ("attach_body", "spring_pendulum", 0.005, 1.0),
    ("no_half", "constant_spin", 0.01, 1.0),
    ("no_normalise", "tennis_racket", 0.005, 2.0),
    ("decay_twice", "velocity_decay", 0.01, 1.0),
    ("no_decay", "damped_spring_top", 0.005, None),
    ("drag_sign", "linear_drag", 0.01, 1.0),
    ("gravity_y", "thruster_box", 0.002, 0.5),
    ("dt_mismatch", "fast_tensor_spin", 0.002, 1.0),
]


@pytest.mark.parametrize("bug, scen, dt, duration", ZOO, ids=[f"{b}-{s}-{d:g}" for b, s, d, _ in ZOO])
def test_every_planted_mistake_is_caught_and_named(tmp_path, capsys, bug, scen, dt, duration):
    sc = scenario_file(tmp_path, scen, duration)
    rc, out, err = check(capsys, student_file(tmp_path, sc, dt, bug=bug), "--scenario", sc)
    assert rc == 1, out
    assert out.startswith("FAIL: ")
    causes = [line for line in out.splitlines() if line.startswith("likely cause:")]
    assert causes and S.BUGS[bug] in causes[0], out


@pytest.mark.parametrize("scen, dt, bug", [
    ("tumbling_box", 0.001, "gyro_sign"),             # the scenario's default Δt: once allowed 3.38 rad
    ("symmetric_top", 0.01, "gyro_sign"),             # once allowed 11.4 rad ...
    ("symmetric_top", 0.01, "quat_right"),
    ("symmetric_top", 0.01, "inertia_body"),
])
def test_the_false_passes_reported_in_issue_10_now_fail(tmp_path, capsys, scen, dt, bug):
    sc = scenario_file(tmp_path, scen, 1.0)
    rc, out, _ = check(capsys, student_file(tmp_path, sc, dt, bug=bug), "--scenario", sc)
    assert rc == 1 and S.BUGS[bug] in out


def test_a_step_without_the_gyroscopic_term_that_is_not_the_course_scheme_fails_and_says_why(
        tmp_path, capsys):
    sc = scenario_file(tmp_path, "tumbling_box", 2.0)
    rc, out, _ = check(capsys, student_file(tmp_path, sc, 0.01, bug="no_gyro", scheme="expmap"),
                       "--scenario", sc)
    assert rc == 1
    cause = next(line for line in out.splitlines() if line.startswith("likely cause:"))
    assert "reference:course" in cause and "gyroscopic" in cause


def test_the_course_scheme_fails_by_default_where_its_step_is_wrong_and_passes_when_asked_for(
        tmp_path, capsys):
    """Two questions: "a correct simulation?" (default) FAILS a faithful course implementation on a tumbling
    asymmetric body, in one sentence; "is it exactly reference:course?" (--scheme) PASSES, saying what the
    course gets wrong there."""
    sc = scenario_file(tmp_path, "tennis_racket", 2.0)
    path = student_file(tmp_path, sc, 0.01, bug="no_gyro")
    rc, out, _ = check(capsys, path, "--scenario", sc)
    first, second = out.splitlines()[:2]
    assert (rc == 1 and first.startswith("FAIL: it reproduces the course's update exactly; the course "
                                         "omits the gyroscopic term −ω × (I ω)")
            and "so on this body the motion is wrong" in first)
    assert second.startswith("likely cause: the rotational update has no gyroscopic torque")
    rc, out, _ = check(capsys, path, "--scenario", sc, "--scheme", "reference:course")
    assert rc == 0 and out.startswith("PASS: is reference:course")
    assert "caveat:" in out and "gyroscopic" in out
    rc, out, _ = check(capsys, path, "--scenario", sc, "--scheme", "reference:course_gyro")
    assert rc == 1 and out.startswith("FAIL: it is not reference:course_gyro")


ISOTROPIC_TUMBLE = """
name = "isotropic_tumble"
duration = 0.5
dt = 0.01
[body]
mass = 2.0
inertia = [0.3, 0.3, 0.3]
[initial]
angular_velocity = [1.0, -2.0, 3.0]
[[forces.torque]]
torque = [0.1, 0.2, -0.05]
frame = "body"
"""


@pytest.mark.parametrize("scen", ["isotropic_tumble", "constant_spin", "projectile"])
def test_where_the_course_step_is_right_it_passes_both_questions(tmp_path, capsys, scen):
    """An isotropic body tumbling under a torque (ω × Iω = 0 always), a spin about a principal axis, no
    rotation: the course's step is physically right there."""
    if scen == "isotropic_tumble":
        sc = tmp_path / "isotropic_tumble.toml"
        sc.write_text(ISOTROPIC_TUMBLE)
    else:
        sc = scenario_file(tmp_path, scen, 0.5)
    path = student_file(tmp_path, sc, 0.01, bug="no_gyro")
    for extra in ([], ["--scheme", "reference:course"]):
        rc, out, _ = check(capsys, path, "--scenario", sc, *extra)
        assert rc == 0 and out.startswith("PASS: is reference:course"), out[:400]
        assert "caveat:" not in out


def test_a_ladder_of_the_course_on_a_tumbling_body_fails_by_default_and_passes_as_the_scheme(
        tmp_path, capsys):
    sc = scenario_file(tmp_path, "tennis_racket", 1.0)
    files = [student_file(tmp_path, sc, dt, bug="no_gyro", name=f"c{i}.csv")
             for i, dt in enumerate((0.01, 0.005))]
    rc, out, _ = check(capsys, *files, "--scenario", sc)
    assert rc == 1 and out.startswith("FAIL: 2 of 2 files fail their own check")
    rc, out, _ = check(capsys, *files, "--scenario", sc, "--scheme", "reference:course")
    assert rc == 0 and out.startswith("PASS: every file passes")


def test_a_trajectory_that_blows_up_is_a_fail_never_an_internal_error(tmp_path, capsys):
    """ω growing to 1e7 rad/s (the attitude following it) and then non-finite: FAIL "diverged at t = …"."""
    from reference_sim.quaternion import quat_mul
    sc = scenario_file(tmp_path, "tennis_racket", 1.0)
    traj = Trajectory.read(_run(tmp_path, sc, "reference:course", 0.01))
    n = len(traj.t_s)
    traj.y[:, 10:13] *= np.exp(np.linspace(0.0, math.log(1e7), n))[:, None]
    for i in range(n - 1):   # the attitude turned by the huge ω, as the simulator would
        w = traj.y[i, 10:13]
        th = float(np.linalg.norm(w)) * 0.01
        dq = np.r_[math.cos(th / 2), math.sin(th / 2) * w / np.linalg.norm(w)]
        traj.y[i + 1, 6:10] = quat_mul(dq, traj.y[i, 6:10])
    traj.y[-5:, 10:13] = np.inf
    path = tmp_path / "blow.csv"
    traj.write(path)
    capsys.readouterr()
    rc, out, err = check(capsys, path, "--scenario", sc)
    assert rc == 1 and out.startswith(f"FAIL: diverged at t = {traj.t_s[-5]:.6g} s"), (out[:300], err)
    assert "internal error" not in err


def _reference_course_applies_the_per_step_factor(dt=0.005):
    """True on a branch where reference:course multiplies v by the course's γ per step whatever Δt is
    (frame-rate dependent) rather than by e^(−kΔt): probed on velocity_decay (no forces, γ = 0.99 at
    dt = 0.01, v0 = (1, 0.5, 0))."""
    from cross_checks.engines import get_adapter
    sc = load_scenario("velocity_decay")
    y0 = sc.problem.initial_packed()[None, :]
    y1 = get_adapter("reference").one_step(sc, "course", dt, y0)
    return math.isclose(float(y1[0, 3] / y0[0, 3]), sc.problem.forces.velocity_decay, rel_tol=1e-12)


def test_a_per_step_decay_at_another_dt_is_never_a_silent_pass(tmp_path, capsys):
    """γ applied per step at Δt ≠ dt is another physical damping. Where reference:course itself does
    that it IS that scheme (PASS, with the frame-rate caveat); otherwise it is a caught mistake."""
    sc_path = scenario_file(tmp_path, "velocity_decay", 1.0)
    rc, out, _ = check(capsys, student_file(tmp_path, sc_path, 0.005, bug="decay_per_step"),
                       "--scenario", sc_path)
    if _reference_course_applies_the_per_step_factor(0.005):
        assert rc == 0 and "PASS: is reference:course" in out and "frame-rate dependent" in out
    else:
        assert rc == 1 and "decay per step at another Δt" in out


# --- correct schemes pass ------------------------------------------------------------------------------

#: (scheme of the student, scenario, Δt, duration, writer options)
STUDENTS = [
    ("course", "damped_spring_top", 0.005, None, {"fmt": "%.6f"}),
    ("expmap", "fast_tensor_spin", 0.01, None, {}),
    ("explicit", "thruster_box", 0.002, 0.5, {}),
    ("course", "tumbling_box", 0.001, 0.5, {"float32": True, "fmt": "%.9g"}),
]


@pytest.mark.parametrize("scheme, scen, dt, duration, opts", STUDENTS,
                         ids=[f"{s}-{c}-{d:g}" for s, c, d, _, _ in STUDENTS])
def test_a_students_correct_simulator_passes(tmp_path, capsys, scheme, scen, dt, duration, opts):
    sc = scenario_file(tmp_path, scen, duration)
    opts = dict(opts)
    fmt = opts.pop("fmt", "repr")
    rc, out, _ = check(capsys, student_file(tmp_path, sc, dt, fmt=fmt, scheme=scheme, **opts),
                       "--scenario", sc)
    assert rc == 0, out
    assert out.startswith("PASS: ")


#: (variant, scenario, Δt, duration): each reference variant on two scenarios, round robin so every
#: listed catalog scenario and every new one appears; coarse and fine Δt.
REFERENCE_GRID = [
    ("course", "constant_spin", 0.01, 1.0), ("course_gyro", "velocity_decay", 0.01, 1.0),
    ("expmap_gyro", "symmetric_top", 0.001, 0.5), ("explicit_euler", "tumbling_box", 0.01, 3.0),
    ("implicit_euler", "tennis_racket", 0.005, 1.0), ("midpoint", "constant_spin", 0.01, 1.0),
    ("leapfrog", "particle_body", 0.005, 1.0), ("rk4", "constant_spin", 0.01, 1.0),
    ("rk4", "thruster_box", 0.01, None), ("implicit_euler", "applied_torque", 0.01, 1.0),
    ("midpoint", "spring_pendulum", 0.002, 0.5), ("leapfrog", "fast_tensor_spin", 0.002, 1.0),
]


def _run(tmp_path, sc, engine, dt, name="run.csv"):
    out = tmp_path / name
    assert main(["run", str(sc), "--engine", engine, "--dt", str(dt), "--out", str(out)]) == 0
    return out


@pytest.mark.parametrize("variant, scen, dt, duration", REFERENCE_GRID,
                         ids=[f"{v}-{s}-{d:g}" for v, s, d, _ in REFERENCE_GRID])
def test_every_reference_variant_passes_and_is_recognised(tmp_path, capsys, variant, scen, dt, duration):
    sc = scenario_file(tmp_path, scen, duration)
    traj = _run(tmp_path, sc, f"reference:{variant}", dt)
    capsys.readouterr()
    rc, out, _ = check(capsys, traj, "--scenario", sc)
    assert rc == 0, out
    assert out.startswith("PASS: is ") and f"reference:{variant}" in out.splitlines()[0]


ENGINE_GRID = [
    ("mujoco:euler", "tumbling_box", 0.01, 3.0), ("mujoco:rk4", "constant_spin", 0.01, 1.0),
    ("mujoco:implicit", "thruster_box", 0.005, None), ("mujoco:implicitfast", "tennis_racket", 0.001, 0.5),
    ("pybullet:multibody", "applied_torque", 0.01, 1.0),
    ("pybullet:maximal", "damped_spring_top", 0.005, None),
]


@pytest.mark.parametrize("engine, scen, dt, duration", ENGINE_GRID,
                         ids=[f"{e}-{s}-{d:g}" for e, s, d, _ in ENGINE_GRID])
def test_mujoco_and_pybullet_trajectories_pass(tmp_path, capsys, engine, scen, dt, duration):
    sc = scenario_file(tmp_path, scen, duration)
    traj = _run(tmp_path, sc, engine, dt)
    capsys.readouterr()
    rc, out, _ = check(capsys, traj, "--scenario", sc)
    assert rc == 0, out
    if engine == "mujoco:euler":   # MuJoCo Euler is semi-implicit Euler + explicit gyroscopic term + exp map
        assert out.startswith("PASS: is reference:expmap_gyro")


# --- input as people write it ---------------------------------------------------------------------------

def test_columns_in_another_order_with_extra_columns_are_read_by_name(tmp_path, capsys):
    sc = scenario_file(tmp_path, "tumbling_box", 1.0)
    cols = ("qx", "qy", "qz", "qw", "t", "wz", "wy", "wx", "x", "y", "z", "vz", "vy", "vx")
    rows = S.run(load_scenario(sc), 0.01)
    path = S.write_csv(tmp_path / "cols.csv", rows, columns=cols)
    text = path.read_text().splitlines()
    path.write_text("\n".join([text[0] + ",frame"] + [r + f",{i}" for i, r in enumerate(text[1:])]) + "\n")
    rc, out, _ = check(capsys, path, "--scenario", sc)
    assert rc == 0 and "is reference:course_gyro" in out


def test_single_precision_times_from_a_unity_clock_are_mapped_to_steps(tmp_path, capsys):
    """10 000 steps of t += 0.001 in float32 drift by 0.4 ms (0.4 steps): a correct run still passes."""
    sc = scenario_file(tmp_path, "symmetric_top")
    traj = Trajectory.read(_run(tmp_path, sc, "reference:rk4", 0.001))
    t32 = np.zeros(len(traj.t_s), dtype=np.float32)
    for k in range(1, len(t32)):
        t32[k] = t32[k - 1] + np.float32(0.001)
    traj.t_s = t32.astype(float)
    assert np.max(np.abs(traj.t_s - 0.001 * np.arange(len(t32)))) > 3e-4      # the drift is real
    traj.write(tmp_path / "unity.csv")
    capsys.readouterr()
    rc, out, _ = check(capsys, tmp_path / "unity.csv", "--scenario", sc)
    assert rc == 0 and "is reference:rk4" in out
    assert "single-precision accumulation allows" in out


def test_output_written_every_tenth_step_is_judged_with_dt(tmp_path, capsys):
    sc = scenario_file(tmp_path, "tumbling_box", 1.0)
    good = student_file(tmp_path, sc, 0.001, write_every=10, name="good.csv")
    rc, out, _ = check(capsys, good, "--scenario", sc, "--dt", "0.001")
    assert rc == 0 and "is reference:course_gyro" in out and "every row spans 10 steps" in out
    bad = student_file(tmp_path, sc, 0.001, write_every=10, bug="gyro_sign", name="bad.csv")
    rc, out, _ = check(capsys, bad, "--scenario", sc, "--dt", "0.001")
    assert rc == 1 and S.BUGS["gyro_sign"] in out


def test_pose_only_files_are_judged_on_what_they_hold(tmp_path, capsys):
    sc = scenario_file(tmp_path, "particle_body", 1.0)
    pose = ("t", "x", "y", "z", "qw", "qx", "qy", "qz")
    rc, out, _ = check(capsys, student_file(tmp_path, sc, 0.005, columns=pose, name="p.csv"),
                       "--scenario", sc)
    assert rc == 0, out
    assert "cannot tell: the file has no velocity, angular velocity columns" in out
    rc, out, _ = check(capsys, student_file(tmp_path, sc, 0.005, columns=pose, bug="gyro_sign", name="q.csv"),
                       "--scenario", sc)
    assert rc == 1 and "acceleration residual" in out


def test_a_run_that_ends_early_fails_and_says_so(tmp_path, capsys):
    sc = scenario_file(tmp_path, "projectile")
    rc, out, _ = check(capsys, student_file(tmp_path, sc, 0.01, duration=0.5), "--scenario", sc)
    assert rc == 1 and out.startswith("FAIL: the run ends at t = 0.5 s, before the scenario's duration 1 s")


def test_a_longer_run_is_compared_over_the_scenarios_duration(tmp_path, capsys):
    sc = scenario_file(tmp_path, "projectile")
    rc, out, _ = check(capsys, student_file(tmp_path, sc, 0.01, duration=1.5), "--scenario", sc)
    assert rc == 0 and "beyond the scenario's duration 1 s: it is compared up to t = 1 s" in out


def _tamper(tmp_path, sc, edit, dt=0.01):
    traj = Trajectory.read(_run(tmp_path, sc, "reference:course", dt))
    edit(traj)
    path = tmp_path / "tampered.csv"
    traj.write(path)
    return path


@pytest.mark.parametrize("edit, words", [
    (lambda tr: tr.t_s.__setitem__(slice(1, None), tr.t_s[1:] + 1e9), "t jumps from 0 s to 1e+09 s"),
    (lambda tr: tr.t_s.__setitem__(-1, 1e9), "t jumps from 0.99 s to 1e+09 s"),
    (lambda tr: tr.y.__setitem__((slice(None), slice(6, 10)), 0.0), "the quaternion is zero"),
    (lambda tr: tr.t_s.__setitem__(5, tr.t_s[3]), "times must strictly increase"),
    (lambda tr: tr.t_s.__setitem__(slice(None), tr.t_s + 1.0), "must start at 0"),
], ids=["second-row-at-1e9", "last-row-at-1e9", "all-quaternions-zero", "time-goes-back", "late-start"])
def test_absurd_files_exit_2_naming_the_line(tmp_path, capsys, edit, words):
    sc = scenario_file(tmp_path, "projectile")
    path = _tamper(tmp_path, sc, edit)
    capsys.readouterr()
    rc, out, err = check(capsys, path, "--scenario", sc, "--json", tmp_path / "r.json")
    assert rc == 2 and words in err and "Traceback" not in err and err.count("\n") == 1
    assert not (tmp_path / "r.json").exists()


@pytest.mark.parametrize("edit, words", [
    (lambda tr: tr.y.__setitem__((slice(50, None), 3), math.nan), "diverged at t = 0.5 s"),
    (lambda tr: tr.y.__setitem__((slice(30, None), slice(6, 10)), 0.0),
     "the quaternion is zero from t = 0.3 s"),
    (lambda tr: tr.y.__setitem__((slice(None), 0), tr.y[:, 0] + 1.0),
     "does not start at the scenario's initial state"),
], ids=["nan-from-row-50", "zero-quaternion-from-row-30", "moved"])
def test_broken_runs_fail_clearly_never_pass(tmp_path, capsys, edit, words):
    sc = scenario_file(tmp_path, "applied_torque", 1.0)
    path = _tamper(tmp_path, sc, edit)
    capsys.readouterr()
    rc, out, _ = check(capsys, path, "--scenario", sc)
    assert rc == 1 and out.startswith("FAIL: ") and words in out.splitlines()[0]


def test_a_drifting_trajectory_fails_on_position_and_rounded_times_are_fine(tmp_path, capsys):
    sc = scenario_file(tmp_path, "projectile")
    traj = Trajectory.read(_run(tmp_path, sc, "reference:rk4", 0.01))
    traj.t_s = np.round(traj.t_s, 6)
    traj.write(tmp_path / "rounded.csv")
    traj.y[:, 2] += 1.0 * traj.t_s                   # drifting upwards at 1 m/s
    traj.write(tmp_path / "drift.csv")
    capsys.readouterr()
    rc, out, _ = check(capsys, tmp_path / "rounded.csv", "--scenario", sc)
    assert rc == 0 and "reference:rk4" in out.splitlines()[0] and "Δt = 0.01 s" in out
    rc, out, _ = check(capsys, tmp_path / "drift.csv", "--scenario", sc)
    assert rc == 1 and out.startswith("FAIL: position one-step defect")


def test_a_file_without_the_needed_columns_exits_2(tmp_path, capsys):
    bad = tmp_path / "bad.csv"
    bad.write_text("t,x\n0,1\n")
    rc, _, err = check(capsys, bad, "--scenario", "projectile")
    assert rc == 2 and "header: position needs all of x,y,z" in err and "Traceback" not in err


def test_an_initial_angular_velocity_in_body_axes_is_named(tmp_path, capsys):
    from reference_sim.quaternion import quat_conj, rotate
    sc = scenario_file(tmp_path, "velocity_decay", 0.5)

    def to_body(tr):
        tr.y[:, 10:13] = rotate(quat_conj(tr.y[:, 6:10]), tr.y[:, 10:13])
    rc, out, _ = check(capsys, _tamper(tmp_path, sc, to_body), "--scenario", sc)
    assert rc == 1 and "likely cause: the angular velocity is written in body axes" in out


def test_angular_velocity_in_body_axes_is_named_from_the_identity_orientation(tmp_path, capsys):
    """The README's tennis_racket starts at the identity: the first row is the same in both frames, and the
    rows after it say that ω is written in body axes (issue 44, point 6)."""
    from reference_sim.quaternion import quat_conj, rotate
    sc = scenario_file(tmp_path, "tennis_racket", 2.0)

    traj = Trajectory.read(_run(tmp_path, sc, "reference:course_gyro", 0.002))   # a correct simulator ...
    traj.y[:, 10:13] = rotate(quat_conj(traj.y[:, 6:10]), traj.y[:, 10:13])    # ... writing ω_B as wx,wy,wz
    traj.write(tmp_path / "body_axes.csv")
    rc, out, _ = check(capsys, tmp_path / "body_axes.csv", "--scenario", sc)
    assert rc == 1
    assert "likely cause: the angular velocity is written in body axes" in out, out
    assert "no catalogued mistake" not in out
    # every scheme is as far from a file written in the wrong frame: none is named the closest (point 9)
    assert "closest scheme: none — all 16 schemes are as far from the file" in out, out


# --- output ---------------------------------------------------------------------------------------------

def test_verdict_line_first_then_the_table_json_and_plot(tmp_path, capsys):
    sc = scenario_file(tmp_path, "tumbling_box", 3.0)
    path = student_file(tmp_path, sc, 0.01, bug="gyro_sign")
    rc, out, err = check(capsys, path, "--scenario", sc,
                         "--json", tmp_path / "r.json", "--plot", tmp_path / "r.png")
    lines = out.splitlines()
    assert rc == 1 and lines[0].startswith("FAIL: angular velocity one-step defect "
                                           "over its allowance from t = 0.01 s")
    assert lines[1].startswith("likely cause: ") and "gyroscopic term has the wrong sign" in lines[1]
    header = next(i for i, line in enumerate(lines) if line.strip().startswith("evidence"))
    assert "first over" in lines[header] and "allowed" in lines[header] and "value" in lines[header]
    over = [line for line in lines[header + 1:] if line.endswith("OVER") or "OVER (" in line]
    assert over and over[0].strip().startswith("one-step defect  angular velocity")  # the worst failure first
    # each row: the worst ratio with the value and the allowance at the same time
    ratio_s, value_s, allowed_s = over[0].split(")")[1].split()[:3]
    assert float(value_s) / float(allowed_s) == pytest.approx(float(ratio_s), rel=0.01)
    assert any(line.strip().startswith("free-running") and "decisive to t =" in line for line in lines)
    assert "allowances (where each comes from):" in out and "closest scheme:" in out
    assert out.index("closest scheme:") < out.index("allowances (where each comes from):")
    data = json.loads((tmp_path / "r.json").read_text(), parse_constant=pytest.fail)   # strict JSON: no NaN
    assert data["passed"] is False and data["exit_code"] == 1 and data["verdict"] == lines[0]
    worst = next(e for e in data["evidence"]
                 if e["kind"] == "one-step defect" and e["quantity"] == "angular_velocity")
    assert worst["first_over_s"] == pytest.approx(0.01) and worst["max_ratio"] > 10 and worst["source"]
    assert {s["name"] for s in data["schemes"]} >= {f"reference:{v}" for v in
                                                    ("course", "course_gyro", "expmap_gyro", "explicit_euler",
                                                     "implicit_euler", "midpoint", "leapfrog", "rk4")}
    assert "gyroscopic term has the wrong sign" in data["likely_causes"][0]
    png = (tmp_path / "r.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 20000


def test_bad_output_paths_exit_2_before_any_work(tmp_path, capsys):
    sc = scenario_file(tmp_path, "projectile")
    path = _run(tmp_path, sc, "reference:course", 0.01)
    capsys.readouterr()
    rc, _, err = check(capsys, path, "--scenario", sc, "--plot", tmp_path / "r.jpg")
    assert rc == 2 and "--plot" in err and "must end in .png" in err
    rc, _, err = check(capsys, path, "--scenario", sc, "--json", tmp_path / "missing" / "r.json")
    assert rc == 2 and "does not exist" in err


# --- the API: extra engines compared free-running -----------------------------------------------------------

def test_extra_engine_variants_are_compared_free_running(tmp_path):
    from cross_checks.gates.check import check_trajectory
    sc_path = scenario_file(tmp_path, "tennis_racket", 1.0)
    sc = load_scenario(sc_path)
    traj = Trajectory.read(_run(tmp_path, sc_path, "mujoco:euler", 0.01))
    res = check_trajectory(traj, sc, "m.csv", compare_with=["pybullet:multibody", "reference:rk4"])
    by = {e["engine"]: e for e in res.engines}
    assert by["pybullet:multibody"]["same_to_roundoff"] is True      # the same scheme: ~1e-14 rad apart
    assert by["reference:rk4"]["same_to_roundoff"] is False
    assert by["reference:rk4"]["max_difference"]["angular_velocity"] > 1e-5


@pytest.mark.parametrize("scheme", ["jolt_gyro", "lp_midpoint", "implicit_gyro_body"])
def test_check_names_the_gyroscopic_schemes_of_engines_and_the_literature(tmp_path, capsys, scheme):
    """`rbcheck check --scheme reference:jolt_gyro` (and the others of docs/gyro_integrators.md) on that
    scheme's own run of the tennis racket: PASS, the file IS that scheme; another scheme's name: FAIL."""
    sc = scenario_file(tmp_path, "tennis_racket", 2.0)
    path = tmp_path / f"{scheme}.csv"
    assert main(["run", str(sc), "--engine", f"reference:{scheme}", "--dt", "0.01", "--out", str(path)]) == 0
    capsys.readouterr()
    rc, out, _ = check(capsys, path, "--scenario", sc, "--scheme", f"reference:{scheme}")
    assert rc == 0 and out.startswith(f"PASS: is reference:{scheme}"), out[:300]
    other = "dlm_splitting" if scheme != "dlm_splitting" else "rk4"
    rc, out, _ = check(capsys, path, "--scenario", sc, "--scheme", f"reference:{other}")
    assert rc == 1 and out.startswith(f"FAIL: it is not reference:{other}"), out[:300]
