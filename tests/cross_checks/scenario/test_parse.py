"""Scenario files: every catalog entry loads; every kind of bad input names file, field and reason."""
import numpy as np
import pytest

from cross_checks.scenario import ScenarioError, catalog_names, load_scenario, parse_scenario
from cross_checks.scenario.references import analytic_available
from reference_sim.quaternion import geodesic_angle, quat_from_euler_zxy, rotate

GOOD = """
name = "demo"
description = "demo"
duration = 1.0
dt = 0.01
dt_ladder = [0.02, 0.01]

[body]
mass = 1.0
inertia = [1.0, 2.0, 3.0]

[initial]
position = [0.0, 0.0, 0.0]
velocity = [0.0, 0.0, 0.0]
orientation = [1.0, 0.0, 0.0, 0.0]
angular_velocity = [0.01, 2.0, 0.01]

[forces]
gravity = [0.0, 0.0, -9.81]
linear_drag = 0.0
velocity_decay = 1.0

[[forces.spring]]
anchor = [0.0, 1.0, 0.0]
attach = [0.1, 0.0, 0.0]
stiffness = 40.0
rest_length = 0.5

[[forces.point]]
force = [1.0, 0.0, 0.0]
point = [0.0, 0.1, 0.0]
frame = "world"

[[forces.torque]]
torque = [0.0, 0.0, 0.2]
frame = "body"
"""

#: (old text, new text, field named in the message, words of the reason)
BAD = [
    ("mass = 1.0", "mass = -1.0", "body.mass", "> 0"),
    ("mass = 1.0", "mass = 0", "body.mass", "> 0"),
    ("mass = 1.0", 'mass = "heavy"', "body.mass", "number"),
    ("mass = 1.0", "mass = nan", "body.mass", "finite"),
    ("mass = 1.0", "mass = inf", "body.mass", "finite"),
    ("mass = 1.0\n", "", "body.mass", "missing"),
    ("inertia = [1.0, 2.0, 3.0]", "inertia = [1.0, 1.0, 3.0]", "body.inertia", "triangle"),
    ("inertia = [1.0, 2.0, 3.0]", "inertia = [1.0, -2.0, 3.0]", "body.inertia", "positive definite"),
    ("inertia = [1.0, 2.0, 3.0]", "inertia = [[1, 0.5, 0], [0, 2, 0], [0, 0, 3]]",
     "body.inertia", "symmetric"),
    ("inertia = [1.0, 2.0, 3.0]", "inertia = [1.0, 2.0]", "body.inertia", "3 numbers"),
    ("inertia = [1.0, 2.0, 3.0]", "inertia = [1.0, 2.0, inf]", "body.inertia[2]", "finite"),
    ("inertia = [1.0, 2.0, 3.0]", "inertia = [[1, 0, 0], [0, 1, 0]]", "body.inertia", "3 principal moments"),
    ("orientation = [1.0, 0.0, 0.0, 0.0]",
     "orientation = [0.0, 0.0, 0.0, 0.0]", "initial.orientation", "zero"),
    ("orientation = [1.0, 0.0, 0.0, 0.0]",
     "orientation = [1.0, 0.0, 0.0]", "initial.orientation", "4 numbers"),
    ("position = [0.0, 0.0, 0.0]", "position = [0.0, nan, 0.0]", "initial.position[1]", "finite"),
    ("velocity = [0.0, 0.0, 0.0]", 'velocity = "fast"', "initial.velocity", "list of 3"),
    ("dt = 0.01", "dt = 0.0", "dt", "> 0"),
    ("dt = 0.01", "dt = -0.01", "dt", "> 0"),
    ("dt = 0.01", "dt = 2.0", "dt", "<= duration"),
    ("duration = 1.0", "duration = 0", "duration", "> 0"),
    ("dt_ladder = [0.02, 0.01]", "dt_ladder = [0.02, 5.0]", "dt_ladder[1]", "<= duration"),
    ("dt_ladder = [0.02, 0.01]", "dt_ladder = []", "dt_ladder", "non-empty"),
    ("stiffness = 40.0", "stiffness = -40.0", "forces.spring[0].stiffness", ">= 0"),
    ("rest_length = 0.5", "rest_length = -0.5", "forces.spring[0].rest_length", ">= 0"),
    ('frame = "world"', 'frame = "wrold"', "forces.point[0].frame", "one of"),
    ('frame = "body"', 'frame = "local"', "forces.torque[0].frame", "one of"),
    ("linear_drag = 0.0", "linear_drag = -1.0", "forces.linear_drag", ">= 0"),
    ("velocity_decay = 1.0", "velocity_decay = 1.5", "forces.velocity_decay", "(0, 1]"),
    ("velocity_decay = 1.0", "velocity_decay = 0.0", "forces.velocity_decay", "(0, 1]"),
    ("gravity = [0.0, 0.0, -9.81]", "gravty = [0.0, 0.0, -9.81]", "forces.gravty", "did you mean 'gravity'"),
    ("mass = 1.0", "mass = 1.0\nmas = 2.0", "body.mas", "unknown key"),
    ('name = "demo"', 'name = "Demo Case"', "name", "[a-z0-9_]+"),
    ('name = "demo"', 'name = "../../etc"', "name", "[a-z0-9_]+"),
    ('name = "demo"\n', "", "name", "missing"),
    ("[body]", "[bodies]", "bodies", "unknown key"),
    ("[initial]\n", "[start]\n", "start", "unknown key"),
    ("stiffness = 40.0", "stiffness = 40.0\nstiff = 1", "forces.spring[0].stiff", "unknown key"),
    ("anchor = [0.0, 1.0, 0.0]\n", "", "forces.spring[0].anchor", "missing"),
    ("torque = [0.0, 0.0, 0.2]", "torque = [0.0, 0.2]", "forces.torque[0].torque", "3 numbers"),
    ("dt = 0.01", "dt = 0.01\ndt = 0.02", "", "TOML syntax error"),
    ("mass = 1.0", "mass = = 1", "", "line"),
    ("mass = 1.0\ninertia = [1.0, 2.0, 3.0]", "particles = [[1.0, 0, 0, -1], [1.0, 0, 0, 1]]",
     "body.particles", "positive definite"),
    ("mass = 1.0\ninertia = [1.0, 2.0, 3.0]", "particles = [[-1.0, 0, 0, -1], [1.0, 0, 1, 1]]",
     "body.particles[0]", "mass"),
    ("orientation = [1.0, 0.0, 0.0, 0.0]", "orientation = [1.0, 0.0, 0.0, 0.0]\neuler_zxy_deg = [0, 0, 0]",
     "initial.orientation", "exactly one"),
    ('description = "demo"', 'description = 3', "description", "string"),
    ('description = "demo"', 'description = "x"\nreference = "exact"', "reference", "one of"),
]


def test_good_scenario_loads():
    sc = parse_scenario(GOOD, "good.toml")
    assert sc.name == "demo" and sc.dt_ladder_s == (0.02, 0.01)
    assert len(sc.problem.forces.springs) == 1


@pytest.mark.parametrize("old, new, field, reason", BAD,
                         ids=[f"{b[2] or 'syntax'}-{i}" for i, b in enumerate(BAD)])
def test_bad_input_names_file_field_reason(old, new, field, reason):
    assert old in GOOD
    with pytest.raises(ScenarioError) as info:
        parse_scenario(GOOD.replace(old, new, 1), "user/bad.toml")
    msg = str(info.value)
    assert msg.startswith("user/bad.toml: "), msg
    assert info.value.field == field, msg
    assert reason in msg, msg


def test_toml_syntax_error_names_the_line():
    with pytest.raises(ScenarioError, match=r"line 9"):
        parse_scenario(GOOD.replace("mass = 1.0", "mass = = 1"), "x.toml")


@pytest.mark.parametrize("name", catalog_names())
def test_catalog_scenario_loads_and_names_its_reference(name):
    sc = load_scenario(name)
    assert sc.name == name
    assert len(sc.dt_ladder_s) >= 4
    assert sc.reference in ("analytic", "ground_truth")
    if sc.reference == "analytic":
        assert analytic_available(sc)[0]


def test_catalog_has_the_required_scenarios():
    required = {"projectile", "linear_drag", "velocity_decay", "spring_oscillator", "spring_pendulum",
                "constant_spin", "symmetric_top", "tennis_racket", "tumbling_box", "applied_torque",
                "particle_body"}
    assert required <= set(catalog_names())


def test_tumbling_box_is_the_gazebo_case():
    sc = load_scenario("tumbling_box")
    a, b, c, m = 0.1, 0.4, 0.9, 10.0
    np.testing.assert_allclose(np.diag(sc.problem.body.inertia_B),
                               m / 12 * np.array([b*b + c*c, a*a + c*c, a*a + b*b]))
    np.testing.assert_allclose(sc.problem.initial.v_W, [-2, 2, 8])
    np.testing.assert_allclose(sc.problem.initial.w_W, [0.1, 5, 0.1])  # identity orientation: body = world
    assert sc.duration_s == 10.0


def test_unity_euler_and_body_rates_are_alternatives():
    text = GOOD.replace("orientation = [1.0, 0.0, 0.0, 0.0]", "euler_zxy_deg = [10.0, 20.0, 30.0]").replace(
        "angular_velocity = [0.01, 2.0, 0.01]", "angular_velocity_body = [1.0, 0.0, 0.0]")
    sc = parse_scenario(text, "alt.toml")
    q = quat_from_euler_zxy([10.0, 20.0, 30.0])
    assert geodesic_angle(q, sc.problem.initial.q_WB) < 1e-15
    np.testing.assert_allclose(sc.problem.initial.w_W, rotate(q, [1.0, 0.0, 0.0]))


def test_content_hash_tracks_physics_not_formatting():
    a = parse_scenario(GOOD, "a.toml")
    b = parse_scenario("# comment\n" + GOOD.replace("mass = 1.0", "mass   =   1.0"), "b.toml")
    c = parse_scenario(GOOD.replace("mass = 1.0", "mass = 1.5"), "c.toml")
    assert a.content_hash == b.content_hash != c.content_hash


def test_missing_file_and_unknown_name():
    with pytest.raises(ScenarioError, match="no catalog scenario"):
        load_scenario("no_such_scenario")
    with pytest.raises(ScenarioError, match="no such file"):
        load_scenario("/nonexistent/x.toml")


def test_analytic_requested_where_none_exists_is_rejected():
    with pytest.raises(ScenarioError, match="reference"):
        parse_scenario(GOOD.replace('name = "demo"', 'name = "demo"\nreference = "analytic"'), "r.toml")


# --- particle bodies: body points are in the particles' own coordinates -------------------------------

FAR_COM = """
name = "far_com"
duration = 1.0
dt = 0.01
reference = "ground_truth"
[body]
# COM at (2, 0.5, 0.25) in the particles' coordinates: 2.1 m from their origin
particles = [[1.0, 1.0, 0.0, 0.0], [1.0, 3.0, 0.0, 0.0], [1.0, 2.0, 1.0, 0.0], [1.0, 2.0, 1.0, 1.0]]
[initial]
position = [0.0, 0.0, 1.0]
orientation = [0.9238795325112867, 0.0, 0.0, 0.3826834323650898]
angular_velocity = [0.0, 0.0, 0.5]
[[forces.spring]]
anchor = [0.0, 2.0, 1.0]
attach = [3.0, 0.5, 0.25]
stiffness = 10.0
rest_length = 0.5
[[forces.point]]
force = [0.0, 0.0, 2.0]
point = [2.0, 0.5, 1.0]
[[forces.point]]
force = [1.0, 0.0, 0.0]
"""


def test_particle_body_points_are_shifted_by_the_com_of_the_particles():
    sc = parse_scenario(FAR_COM, "far_com.toml")
    # hand computation: COM = mean of the four unit masses = (8/4, 2/4, 1/4) = (2, 0.5, 0.25)
    np.testing.assert_allclose(sc.com_offset_B_m, [2.0, 0.5, 0.25], rtol=0, atol=1e-15)
    fm = sc.problem.forces
    # (3, .5, .25) − COM
    np.testing.assert_allclose(fm.springs[0].attach_B, [1.0, 0.0, 0.0], rtol=0, atol=1e-15)
    # (2, .5, 1) − COM
    np.testing.assert_allclose(fm.point_forces[0].point_B, [0.0, 0.0, 0.75], rtol=0, atol=1e-15)
    np.testing.assert_array_equal(fm.point_forces[1].point_B, np.zeros(3))  # no point given: at the COM


def test_particle_body_spring_force_and_torque_by_hand():
    # The body is yawed 45° about z: the attach point, 1 m from the COM along body x, is at
    # x0 + (cos 45°, sin 45°, 0) in the world; the spring pulls it towards the anchor (0, 2, 1).
    sc = parse_scenario(FAR_COM, "far_com.toml")
    p = sc.problem
    c = np.sqrt(0.5)
    r_W = np.array([c, c, 0.0])
    d = np.array([0.0, 0.0, 1.0]) + r_W - np.array([0.0, 2.0, 1.0])
    L = np.linalg.norm(d)
    f_spring = -10.0 * (L - 0.5) * d / L
    r_point_W = np.array([0.0, 0.0, 0.75])             # the body point above the COM (z is the yaw axis)
    f_expected = f_spring + np.array([0.0, 0.0, 2.0]) + np.array([1.0, 0.0, 0.0])
    tau_expected = np.cross(r_W, f_spring) + np.cross(r_point_W, [0.0, 0.0, 2.0])
    f, tau = p.forces.force_torque(p.body, p.initial.x_W, p.initial.v_W, p.initial.q_WB)
    np.testing.assert_allclose(f, f_expected, rtol=0, atol=1e-14)
    np.testing.assert_allclose(tau, tau_expected, rtol=0, atol=1e-14)


def test_particle_body_moves_like_the_same_body_given_by_mass_and_inertia_from_its_com():
    from cross_checks.engines import run_variant
    from reference_sim.body import inertia_from_particles
    sc = parse_scenario(FAR_COM, "far_com.toml")
    P = np.array(sc.raw["body"]["particles"])
    m, com, I = inertia_from_particles(P[:, 0], P[:, 1:])
    same = FAR_COM.split("[body]")[0] + "[body]\nmass = %r\ninertia = %s\n[initial]" % (
        m, [[float(v) for v in row] for row in I]) + FAR_COM.split("[initial]")[1]
    same = same.replace("attach = [3.0, 0.5, 0.25]", "attach = [1.0, 0.0, 0.0]").replace(
        "point = [2.0, 0.5, 1.0]", "point = [0.0, 0.0, 0.75]")
    a = run_variant(sc, "reference:rk4", duration_s=0.5)
    b = run_variant(parse_scenario(same, "same.toml"), "reference:rk4", duration_s=0.5)
    np.testing.assert_allclose(a.y, b.y, rtol=0, atol=1e-13)


# --- long runs (kind = "long_run", docs/scenario.md "Long runs") -------------------------------------------

LONG = """
name = "my_long"
kind = "long_run"
duration = 100.0
dt = 0.05
[body]
mass = 1.0
inertia = [1.0, 2.0, 3.0]
[initial]
angular_velocity = [0.02, 0.02, 2.0]
"""


def test_the_catalogs_long_runs_are_thousands_of_periods_of_a_torque_free_spin():
    from cross_checks.scenario import long_run_names
    names = long_run_names()
    assert names == ["long_major_axis_spin", "long_minor_axis_spin", "long_tennis_racket"]
    assert not set(names) & set(catalog_names())          # the ladders' catalog is unchanged
    for n in names:
        sc = load_scenario(n)
        assert sc.long_run and sc.kind == "long_run" and sc.dt_ladder_s == (sc.dt_s,)
        spin = float(np.linalg.norm(sc.problem.initial.w_W))
        assert sc.duration_s * spin / (2 * np.pi) >= 1000.0 - 1e-9, n      # periods of the spin
        assert not sc.problem.forces.springs and not sc.problem.forces.torques


def test_kind_defaults_to_convergence_and_a_long_run_parses():
    assert parse_scenario(GOOD).kind == "convergence" and not parse_scenario(GOOD).long_run
    sc = parse_scenario(LONG)
    assert sc.long_run and sc.n_steps() == 2000


@pytest.mark.parametrize("extra,field", [
    ('dt_ladder = [0.1, 0.05]\n', "dt_ladder"),
    ('[forces]\nlinear_drag = 0.1\n', "forces.linear_drag"),
    ('[forces]\nangular_velocity_decay = 0.99\n', "forces.angular_velocity_decay"),
    ('[[forces.torque]]\ntorque = [0.0, 0.0, 0.1]\n', "forces.torque"),
])
def test_a_long_run_refuses_a_ladder_and_forces_that_change_what_it_measures(extra, field):
    head, rest = LONG.split("[body]")
    text = head + (extra if extra.startswith("dt_") else "") + "[body]" + rest + (
        "" if extra.startswith("dt_") else extra)
    with pytest.raises(ScenarioError) as e:
        parse_scenario(text, source="x.toml")
    assert f"x.toml: {field}:" in str(e.value)


def test_kind_must_be_known():
    with pytest.raises(ScenarioError, match="kind"):
        parse_scenario(LONG.replace('"long_run"', '"long"'))


# --- a body frame off the COM (body.com) and welded parts (body.parts) --------------------------------------

_HEAD = 'name = "b"\nduration = 1.0\ndt = 0.01\n'


def test_a_body_com_makes_the_initial_state_and_points_the_origin_s():
    sc = parse_scenario(_HEAD + """
[body]
mass = 2.0
inertia = [1.0, 2.0, 2.5]
com = [0.5, 0.0, 0.0]
[initial]
position = [1.0, 0.0, 0.0]
velocity = [0.0, 0.0, 0.0]
angular_velocity_body = [0.0, 0.0, 2.0]
euler_zxy_deg = [0.0, 0.0, 90.0]
[[forces.point]]
force = [1.0, 0.0, 0.0]
point = [0.5, 1.0, 0.0]
frame = "body"
""")
    # turned 90° about z, the COM (0.5, 0, 0) in body axes is at (0, 0.5, 0) from the origin (1, 0, 0), and
    # spinning at 2 rad/s about z it moves at ω × r = (−1, 0, 0) while the origin is at rest (by hand)
    y = sc.problem.initial_packed()
    np.testing.assert_allclose(y[0:3], [1.0, 0.5, 0.0], atol=1e-15)
    np.testing.assert_allclose(y[3:6], [-1.0, 0.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(sc.problem.forces.point_forces[0].point_B, [0.0, 1.0, 0.0], atol=0)
    np.testing.assert_array_equal(sc.body_com_B_m, [0.5, 0.0, 0.0])


def test_welded_parts_make_their_composite_body():
    sc = parse_scenario(_HEAD + """
[[body.parts]]
mass = 1.0
com = [1.0, 0.0, 0.0]
inertia = [0.1, 0.1, 0.1]
[[body.parts]]
mass = 3.0
com = [-1.0, 0.0, 0.0]
inertia = [0.2, 0.3, 0.4]
[initial]
""")
    # COM at (1·1 + 3·(−1))/4 = −0.5 on x; parts at d = 1.5 and −0.5: Σ m d² = 2.25 + 0.75 = 3 about y and z
    assert sc.problem.body.mass_kg == 4.0
    np.testing.assert_allclose(sc.body_com_B_m, [-0.5, 0.0, 0.0], atol=0)
    np.testing.assert_allclose(sc.problem.body.inertia_B, np.diag([0.3, 3.4, 3.5]), atol=1e-15)
    assert len(sc.body_parts) == 2 and sc.body_parts[1].mass_kg == 3.0


@pytest.mark.parametrize("body, field, words", [
    ("mass = 1.0\ninertia = [1.0, 1.0, 1.0]\ncom = [1.0, 2.0]", "body.com", "3"),
    ("particles = [[1.0, 0.0, 0.0, 0.0], [1.0, 1.0, 0.0, 0.0], [1.0, 0.0, 1.0, 0.0], [1.0, 0.0, 0.0, 1.0]]\n"
     "com = [0.0, 0.0, 0.0]", "body.com", "particle body"),
    ("mass = 1.0\ninertia = [1.0, 1.0, 1.0]\ncom = [2e6, 0.0, 0.0]", "body.com", "outside the range"),
    ("mass = 1.0\n[[body.parts]]\nmass = 1.0\ninertia = [1.0, 1.0, 1.0]", "body.mass", "not both"),
    ("[[body.parts]]\nmass = 1.0\ninertia = [1.0, 1.0, 3.0]", "body.parts[0].inertia", "triangle"),
    ("[[body.parts]]\nmass = -1.0\ninertia = [1.0, 1.0, 1.0]", "body.parts[0].mass", "> 0"),
    ("[[body.parts]]\nmass = 1.0\ninertia = [1.0, 1.0, 1.0]\ncolour = 1", "body.parts[0]", "colour"),
    ("[[body.parts]]\nmass = 1.0", "body.parts[0].inertia", "missing"),
])
def test_a_bad_body_form_is_refused_naming_the_field(body, field, words):
    with pytest.raises(ScenarioError) as info:
        parse_scenario(_HEAD + "[body]\n" + body + "\n[initial]\n", "f.toml")
    assert info.value.field.startswith(field) and words in str(info.value), str(info.value)


def test_more_parts_than_the_limit_are_refused():
    from cross_checks.core.tolerances import MAX_BODY_PARTS
    one = "[[body.parts]]\nmass = 1.0\ninertia = [1.0, 1.0, 1.0]\n"
    parts = one * (MAX_BODY_PARTS + 1)
    with pytest.raises(ScenarioError) as info:
        parse_scenario(_HEAD + parts + "[initial]\n", "f.toml")
    assert info.value.field == "body.parts" and f"1 to {MAX_BODY_PARTS}" in info.value.reason
