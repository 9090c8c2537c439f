"""The resolved scenario (`rbcheck show`): every alternative resolved, checked against numbers derived by
hand from the scenario files (not from rbcheck's own conversions)."""
import json
import math

import pytest

from cross_checks.cli import main
from cross_checks.scenario import parse_scenario
from cross_checks.scenario.resolved import resolved_scenario

H = math.sqrt(0.5)

UNITY = """
name = "unity_style"
description = "Unity Euler angles and a body-frame angular velocity"
duration = 2.0
dt = 0.01
dt_ladder = [0.02, 0.01, 0.005]
[body]
mass = 2.0
inertia = [[2.0, 0.1, 0.0], [0.1, 3.0, 0.0], [0.0, 0.0, 4.0]]
[initial]
position = [1.0, 2.0, 3.0]
euler_zxy_deg = [0.0, 90.0, 90.0]
angular_velocity_body = [1.0, 0.0, 0.0]
[forces]
gravity = [0.0, -9.81, 0.0]
velocity_decay = 0.99
angular_velocity_decay = 0.98
[[forces.torque]]
torque = [0.0, 0.0, 0.5]
frame = "body"
"""

PARTICLES = """
name = "particles"
duration = 1.0
dt = 0.01
[body]
particles = [[1.0, 1.0, 0.0, 0.0], [1.0, 3.0, 0.0, 0.0], [2.0, 2.0, 1.0, 0.0]]
[initial]
angular_velocity = [0.0, 0.0, 1.0]
[[forces.spring]]
anchor = [0.0, 0.0, 5.0]
attach = [3.0, 0.5, 0.0]
stiffness = 10.0
rest_length = 1.0
[[forces.point]]
force = [0.0, 0.0, 1.0]
point = [2.0, 0.5, 1.0]
frame = "body"
"""


def test_unity_euler_angles_and_body_rates_are_resolved_to_a_quaternion_and_world_rates():
    r = resolved_scenario(parse_scenario(UNITY))
    # Unity Z-X-Y: R = R_y(90°) R_x(0) R_z(90°), q = q_y q_z = (H, 0, H, 0)(H, 0, 0, H) = (½, ½, ½, ½):
    # the 120° turn about (1, 1, 1) that maps x -> y, so body x spin is world y spin.
    assert r["initial"]["orientation"] == pytest.approx([0.5, 0.5, 0.5, 0.5], abs=1e-15)
    assert r["initial"]["angular_velocity"] == pytest.approx([0.0, 1.0, 0.0], abs=1e-15)
    assert r["initial"]["angular_velocity_body"] == pytest.approx([1.0, 0.0, 0.0], abs=1e-15)
    assert r["initial"]["position"] == [1.0, 2.0, 3.0] and r["initial"]["velocity"] == [0.0, 0.0, 0.0]
    assert r["body"] == {"mass": 2.0, "inertia": [[2.0, 0.1, 0.0], [0.1, 3.0, 0.0], [0.0, 0.0, 4.0]],
                         "principal_moments": pytest.approx([2.5 - math.sqrt(0.26),
                                                             2.5 + math.sqrt(0.26), 4.0])}
    assert r["forces"]["torque"] == [{"torque": [0.0, 0.0, 0.5], "frame": "body"}]
    assert ((r["name"], r["duration"], r["dt"], r["steps"], r["scenario_dt"])
            == ("unity_style", 2.0, 0.01, 200, 0.01))


@pytest.mark.parametrize("dt, gamma_v, gamma_w, steps", [
    (0.01, 0.99, 0.98, 200),                                   # the scenario's own dt: its factors exactly
    (0.005, math.sqrt(0.99), math.sqrt(0.98), 400),            # half the step: e^(-k dt/2) = sqrt(gamma)
    (0.02, 0.99 ** 2, 0.98 ** 2, 100),                         # twice the step: gamma squared
])
def test_decay_factors_are_per_step_at_the_run_s_dt(dt, gamma_v, gamma_w, steps):
    f = resolved_scenario(parse_scenario(UNITY), dt)
    assert f["dt"] == dt and f["steps"] == steps
    assert f["forces"]["velocity_decay"] == pytest.approx(gamma_v, rel=1e-15)
    assert f["forces"]["angular_velocity_decay"] == pytest.approx(gamma_w, rel=1e-15)
    assert f["forces"]["velocity_decay_rate"] == pytest.approx(-math.log(0.99) / 0.01, rel=1e-15)
    if dt == 0.01:
        assert f["forces"]["velocity_decay"] == 0.99  # bit for bit


def test_particles_are_resolved_to_mass_inertia_about_the_com_and_body_points_from_the_com():
    r = resolved_scenario(parse_scenario(PARTICLES))
    # COM = (1·(1,0,0) + 1·(3,0,0) + 2·(2,1,0)) / 4 = (2, ½, 0); about it the particles sit at (−1, −½, 0),
    # (1, −½, 0), (0, ½, 0): I = Σ m (|r|² 1 − r rᵀ) = diag(1, 2, 3) (worked by hand).
    assert r["body"]["mass"] == 4.0
    assert r["body"]["inertia"] == [[1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 3.0]]
    assert r["forces"]["spring"] == [{"anchor": [0.0, 0.0, 5.0], "attach": [1.0, 0.0, 0.0], "stiffness": 10.0,
                                      "rest_length": 1.0}]
    assert r["forces"]["point"] == [{"force": [0.0, 0.0, 1.0], "point": [0.0, 0.0, 1.0], "frame": "body"}]
    assert r["forces"]["gravity"] == [0.0, 0.0, 0.0] and r["forces"]["velocity_decay"] == 1.0


def test_show_json_is_the_contract_with_every_key_and_exact_floats(tmp_path, capsys):
    path = tmp_path / "u.toml"
    path.write_text(UNITY)
    assert main(["show", str(path), "--json", "--dt", "0.005"]) == 0
    r = json.loads(capsys.readouterr().out)
    for key in ("name", "description", "duration", "dt", "steps", "body", "initial", "forces"):
        assert key in r
    assert set(r["body"]) >= {"mass", "inertia"}
    assert set(r["initial"]) >= {"position", "velocity", "orientation", "angular_velocity"}
    assert set(r["forces"]) >= {"gravity", "linear_drag", "velocity_decay", "angular_velocity_decay",
                                "spring", "point", "torque"}
    assert r == json.loads(json.dumps(resolved_scenario(parse_scenario(UNITY, source=str(path)), 0.005)))
    assert r["csv_columns"] == "t,x,y,z,vx,vy,vz,qw,qx,qy,qz,wx,wy,wz".split(",")


def test_show_prints_the_initial_conditions_a_student_needs(tmp_path, capsys):
    path = tmp_path / "u.toml"
    path.write_text(UNITY)
    assert main(["show", str(path)]) == 0
    out = capsys.readouterr().out
    for words in ("orientation       [0.5, 0.5, 0.5, 0.5] (body→world quaternion w, x, y, z)",
                  "= Unity Euler angles (x, y, z) [0, 90, 90]° (rotation order Z, X, Y)",
                  "angular velocity  [0, 1, 0] rad/s (WORLD axes)", "mass      2 kg",
                  "torque            [0, 0, 0.5] N m (body axes)",
                  "velocity decay    v ← 0.99 v after each velocity update (per step of 0.01 s"):
        assert words in out, out


@pytest.mark.parametrize("argv, words", [
    (["show", "nope_not_there"], "no catalog scenario of that name"),
    (["show", "projectile", "--dt", "5"], "--dt 5: must be <= the duration (1 s)"),
    (["show", "projectile", "--dt", "-1"], "must be a positive finite number"),
])
def test_show_bad_input_exits_2_with_one_line(capsys, argv, words):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert words in err and "Traceback" not in err
