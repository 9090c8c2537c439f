"""Scenario transforms (cross_checks.scenario.transforms, docs/invariance.md): each against numbers derived by
hand, refused when it would leave the physical ranges (naming the field), and against the reference itself — a
transformed reference run mapped back equals the original run to round-off, and the same run not mapped back
does not (the check can fail)."""
import math

import numpy as np
import pytest

from cross_checks.analysis.judge import judge_invariance
from cross_checks.core.quantities import QUANTITIES, quantity_scales, state_errors
from cross_checks.engines import run_requests
from cross_checks.engines.base import RunRequest
from cross_checks.scenario import parse_scenario
from cross_checks.scenario.references import error_amplification
from cross_checks.scenario.transforms import (
    BodyFrame,
    Scale,
    Transform,
    TransformRefused,
    Translation,
    WorldRotation,
    apply,
    default_transforms,
    scenario_dict,
    toml_text,
)
from reference_sim.quaternion import quat_mul
from tests.helpers.byo import PUSHED, TUMBLE

#: Every force type, on a mass + inertia body: the hand-derived cases read each field back.
ALL_FORCES = """
name = "all_forces"
duration = 0.5
dt = 0.01
[body]
mass = 2.0
inertia = [1.0, 2.0, 2.5]
[initial]
position = [1.0, 0.0, 0.5]
velocity = [1.0, 0.0, 0.0]
orientation = [0.9, 0.1, -0.2, 0.3]
angular_velocity = [0.1, 0.2, 3.0]
[forces]
gravity = [0.0, 0.0, -9.81]
linear_drag = 0.4
angular_velocity_decay = 0.999
[[forces.spring]]
anchor = [0.0, 1.0, 0.0]
attach = [1.0, 0.0, 0.0]
stiffness = 5.0
rest_length = 0.3
[[forces.point]]
force = [1.0, 0.0, 0.0]
point = [0.0, 0.1, 0.0]
frame = "world"
[[forces.point]]
force = [0.0, 2.0, 0.0]
point = [0.1, 0.0, 0.0]
frame = "body"
[[forces.torque]]
torque = [0.0, 0.0, 0.2]
frame = "world"
[[forces.torque]]
torque = [0.3, 0.0, 0.0]
frame = "body"
"""

EPS = 1e-15   # a handful of roundings of O(1) numbers


@pytest.fixture(scope="module")
def base():
    return parse_scenario(ALL_FORCES, "all_forces.toml")


def _forces(sc):
    return sc.problem.forces


def test_the_scenario_dict_round_trips(base):
    """Exactly, but for the orientation, which parsing normalises again (an ulp or two)."""
    again = parse_scenario(toml_text(scenario_dict(base)), "again")
    a, b = base.problem, again.problem
    ya, yb = a.initial_packed(), b.initial_packed()
    assert np.array_equal(np.delete(ya, range(6, 10)), np.delete(yb, range(6, 10)))
    assert np.allclose(ya[6:10], yb[6:10], rtol=0, atol=EPS)
    assert np.array_equal(a.body.inertia_B, b.body.inertia_B) and a.body.mass_kg == b.body.mass_kg
    assert np.array_equal(a.forces.springs[0].anchor_W, b.forces.springs[0].anchor_W)
    assert b.forces.angular_velocity_decay == 0.999 and b.forces.linear_drag_N_s_per_m == 0.4


def test_translation_moves_the_com_and_the_anchors_only(base):
    t = Translation((1.0, 2.0, 3.0))
    sc = apply(t, base)
    y0, y1 = base.problem.initial_packed(), sc.problem.initial_packed()
    assert np.array_equal(y1[0:3], y0[0:3] + [1.0, 2.0, 3.0])
    assert np.allclose(y1[3:], y0[3:], rtol=0, atol=EPS)
    assert np.array_equal(_forces(sc).springs[0].anchor_W, [1.0, 3.0, 3.0])
    assert np.array_equal(_forces(sc).springs[0].attach_B, [1.0, 0.0, 0.0])   # a body point: unchanged
    assert np.array_equal(_forces(sc).point_forces[0].force, [1.0, 0.0, 0.0])
    assert t.position_offset_m() == pytest.approx(math.sqrt(14.0), rel=EPS)
    assert np.allclose(t.map_back(y1[None])[0], y0, rtol=0, atol=EPS)
    assert "[invariance: translation 3.74 m]" in sc.description


def test_world_rotation_by_90_degrees_about_z(base):
    r = (math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5))    # x -> y, y -> -x, z -> z
    t = WorldRotation(r)
    sc = apply(t, base)
    y0, y1 = base.problem.initial_packed(), sc.problem.initial_packed()
    assert np.allclose(y1[0:3], [0.0, 1.0, 0.5], atol=EPS) and np.allclose(y1[3:6], [0.0, 1.0, 0.0], atol=EPS)
    assert np.allclose(y1[10:13], [-0.2, 0.1, 3.0], atol=EPS)
    assert np.allclose(y1[6:10], quat_mul(np.array(r), y0[6:10]), atol=EPS)
    fm = _forces(sc)
    assert np.allclose(fm.gravity_W, [0.0, 0.0, -9.81], atol=EPS)
    assert np.allclose(fm.springs[0].anchor_W, [-1.0, 0.0, 0.0], atol=EPS)
    assert np.allclose(fm.point_forces[0].force, [0.0, 1.0, 0.0], atol=EPS)      # world: turned
    assert np.array_equal(fm.point_forces[1].force, [0.0, 2.0, 0.0])             # body: unchanged
    assert np.allclose(fm.torques[0].torque, [0.0, 0.0, 0.2], atol=EPS)
    assert np.array_equal(fm.torques[1].torque, [0.3, 0.0, 0.0])
    assert np.allclose(t.map_back(y1[None])[0], y0, atol=EPS)
    assert t.magnitude == "90 deg"


def test_world_rotation_turns_gravity_off_its_axis():
    sc = apply(default_transforms()[3], parse_scenario(TUMBLE, "t.toml"))
    g = _forces(sc).gravity_W
    assert np.all(np.abs(g) > 0.3 * 9.81) and np.linalg.norm(g) == pytest.approx(9.81, rel=EPS)


def test_body_frame_by_90_degrees_about_z(base):
    p = (math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5))    # P e_x' = e_y: r_B' = Pᵀ r_B
    t = BodyFrame(p)
    sc = apply(t, base)
    assert np.allclose(sc.problem.body.inertia_B, np.diag([2.0, 1.0, 2.5]), atol=EPS)
    fm = _forces(sc)
    assert np.allclose(fm.springs[0].attach_B, [0.0, -1.0, 0.0], atol=EPS)
    assert np.allclose(fm.point_forces[0].point_B, [0.1, 0.0, 0.0], atol=EPS)
    assert np.array_equal(fm.point_forces[0].force, [1.0, 0.0, 0.0])             # world: unchanged
    assert np.allclose(fm.point_forces[1].force, [2.0, 0.0, 0.0], atol=EPS)      # body: rewritten
    assert np.allclose(fm.torques[1].torque, [0.0, -0.3, 0.0], atol=EPS)
    y0, y1 = base.problem.initial_packed(), sc.problem.initial_packed()
    assert np.allclose(y1[6:10], quat_mul(y0[6:10], np.array(p)), atol=EPS)
    assert np.allclose(y1[10:13], y0[10:13], atol=EPS)                           # world ω: unchanged
    assert np.allclose(t.map_back(y1[None])[0], y0, atol=EPS)


def test_the_default_body_frame_makes_the_inertia_a_full_tensor(base):
    inertia = apply(default_transforms()[4], base).problem.body.inertia_B
    assert np.all(np.abs(inertia - np.diag(np.diag(inertia))) + np.eye(3) > 0.01)
    assert np.allclose(np.linalg.eigvalsh(inertia), [1.0, 2.0, 2.5], rtol=0, atol=4 * EPS)


def test_scale_k10_mu2_by_hand(base):
    t = Scale(10.0, 2.0)
    sc = apply(t, base)
    b = sc.problem.body
    assert b.mass_kg == 4.0 and np.allclose(b.inertia_B, np.diag([200.0, 400.0, 500.0]), rtol=EPS)
    fm = _forces(sc)
    assert np.allclose(fm.gravity_W, [0.0, 0.0, -98.1], rtol=EPS) and fm.linear_drag_N_s_per_m == 0.8
    s = fm.springs[0]
    assert (np.array_equal(s.anchor_W, [0.0, 10.0, 0.0]) and np.array_equal(s.attach_B, [10.0, 0.0, 0.0])
            and s.stiffness_N_per_m == 10.0 and s.rest_length_m == pytest.approx(3.0, rel=EPS))
    assert np.array_equal(fm.point_forces[0].force, [20.0, 0.0, 0.0])
    assert np.allclose(fm.point_forces[0].point_B, [0.0, 1.0, 0.0], rtol=EPS)
    assert np.allclose(fm.torques[0].torque, [0.0, 0.0, 40.0], rtol=EPS)
    assert np.allclose(fm.torques[1].torque, [60.0, 0.0, 0.0], rtol=EPS)
    assert fm.angular_velocity_decay == 0.999
    y0, y1 = base.problem.initial_packed(), sc.problem.initial_packed()
    assert np.allclose(y1[0:3], 10 * y0[0:3], rtol=EPS) and np.allclose(y1[6:], y0[6:], rtol=0, atol=EPS)
    assert np.allclose(t.map_back(y1[None])[0], y0, rtol=EPS, atol=EPS)


@pytest.mark.parametrize("k, mu, field_", [(1e3, 1.0, "k"), (1.0, 1e-3, "mu"), (math.nan, 1.0, "k")])
def test_a_scale_out_of_its_range_is_refused_naming_the_factor(k, mu, field_):
    with pytest.raises(TransformRefused) as exc:
        Scale(k, mu)
    assert exc.value.field == field_ and "[0.01, 100]" in str(exc.value)


def test_a_transform_leaving_the_physical_ranges_is_refused_naming_the_field(base):
    far = parse_scenario(ALL_FORCES.replace("position = [1.0, 0.0, 0.5]", "position = [9.999e5, 0.0, 0.0]"),
                         "far.toml")
    with pytest.raises(TransformRefused) as exc:
        apply(Translation((1e4, 0.0, 0.0)), far)
    assert exc.value.field == "initial.position" and "1e+06" in exc.value.reason
    light = parse_scenario(ALL_FORCES.replace("mass = 2.0", "mass = 5e-5"), "light.toml")
    with pytest.raises(TransformRefused) as exc:
        apply(Scale(1.0, 1e-2), light)
    assert exc.value.field == "body.mass"
    assert "scale k=1 mu=0.01 of all_forces" in str(exc.value)


# --- against the reference itself ---------------------------------------------------------------------------

def _runs(variant, scenario, transforms):
    scs = [scenario] + [apply(t, scenario) for t in transforms]
    return run_requests(variant, [RunRequest(s, scenario.dt_s, scenario.n_steps()) for s in scs])


@pytest.mark.parametrize("text", [TUMBLE, PUSHED], ids=["tumble", "every_force_particles"])
def test_a_transformed_reference_run_mapped_back_is_the_original_to_round_off(text):
    sc = parse_scenario(text, "s.toml")
    # (the reference's equations are about the COM: a body frame off it or welded parts it cannot express)
    transforms = [t for t in default_transforms() if t.kind not in ("com_offset", "welded_split")]
    runs = _runs("reference:course_gyro", sc, transforms)
    scales = quantity_scales(runs[0].y)
    amp = error_amplification(sc, scales)
    for t, run in zip(transforms, runs[1:]):
        j = judge_invariance(runs[0].y, t.map_back(run.y), scales=scales, amplification=amp,
                             n_steps=sc.n_steps(), offset_m=t.position_offset_m())
        # a translation makes every position |d| larger, and its rounding with it: precision loss, expected
        allowed = ("holds", "precision loss") if t.kind == "translation" else ("holds",)
        assert j.verdict in allowed, (t.label, j.assessment)
        # the base allowance is round-off: far below anything the physics moves
        assert all(j.base[q] < 1e-9 for q in QUANTITIES), j.base


@pytest.mark.parametrize("index", [1, 3, 4, 5])   # translation 1 km, rotation, body frame, scale
def test_the_same_run_not_mapped_back_is_broken(index):
    """The mapping is what makes the runs agree: without it the judge says broken (this check can fail)."""
    sc = parse_scenario(TUMBLE, "t.toml")
    t = default_transforms()[index]
    runs = _runs("reference:course_gyro", sc, [t])
    scales = quantity_scales(runs[0].y)
    j = judge_invariance(runs[0].y, runs[1].y, scales=scales, amplification=error_amplification(sc, scales),
                         n_steps=sc.n_steps(), offset_m=t.position_offset_m())
    assert j.verdict == "broken", j.assessment


def test_map_back_undoes_each_transform_of_the_initial_state_exactly():
    sc = parse_scenario(PUSHED, "p.toml")
    y0 = sc.problem.initial_packed()
    for t in default_transforms():
        y = t.map_back(apply(t, sc).problem.initial_packed()[None])[0]
        d = state_errors(y[None], y0[None])
        assert d["position"][0] <= 4 * EPS * (1.0 + t.position_offset_m()), t.label
        rest = ("velocity", "orientation", "angular_velocity")
        assert all(d[q][0] < 4 * EPS * 10 for q in rest), (t.label, d)


def test_transform_is_abstract():
    with pytest.raises(TypeError):
        Transform()


# --- the body's form: its frame origin off the COM, welded parts -------------------------------------------

def test_a_com_offset_keeps_the_com_state_and_gives_the_origin_s_in_the_file():
    from cross_checks.scenario.resolved import resolved_scenario
    from cross_checks.scenario.transforms import ComOffset
    from reference_sim.quaternion import rotate
    sc = parse_scenario(PUSHED, "p.toml")
    t = ComOffset()
    out = apply(t, sc)
    # the Problem (what rbcheck compares) is the COM's: the same to one rounding of x_o + R c
    np.testing.assert_allclose(out.problem.initial_packed(), sc.problem.initial_packed(), rtol=0, atol=1e-15)
    c = out.body_com_B_m
    r_g = np.sqrt(np.linalg.eigvalsh(sc.problem.body.inertia_B)[-1] / sc.problem.body.mass_kg)
    assert np.linalg.norm(c) == pytest.approx(1.5 * r_g, rel=1e-15)
    r = resolved_scenario(out)
    y0 = sc.problem.initial_packed()
    r_W = rotate(y0[6:10], c)
    np.testing.assert_allclose(r["initial"]["position"], y0[0:3] - r_W, rtol=0, atol=1e-15)
    np.testing.assert_allclose(r["initial"]["velocity"], y0[3:6] - np.cross(y0[10:13], r_W), rtol=0,
                               atol=1e-15)
    assert r["body"]["com"] == list(c)
    np.testing.assert_allclose(r["forces"]["spring"][0]["attach"], sc.problem.forces.springs[0].attach_B + c,
                               rtol=0, atol=1e-15)
    assert "com" not in resolved_scenario(sc)["body"]   # absent means [0, 0, 0]: old engine files unchanged


def test_a_welded_split_has_the_original_s_mass_com_and_inertia_with_a_massive_child():
    from cross_checks.scenario.transforms import WeldedSplit
    from reference_sim.body import compose_parts
    for text in (TUMBLE, PUSHED):
        sc = parse_scenario(text, "s.toml")
        out = apply(WeldedSplit(), sc)
        parent, child = out.body_parts
        assert child.mass_kg == pytest.approx(3 * parent.mass_kg, rel=1e-15)   # the massive child
        assert np.linalg.norm(parent.com_B_m - child.com_B_m) > 0.1 * np.sqrt(
            np.linalg.eigvalsh(sc.problem.body.inertia_B)[0] / sc.problem.body.mass_kg)
        mass, com, inertia = compose_parts(out.body_parts)
        assert mass == pytest.approx(sc.problem.body.mass_kg, rel=1e-15)
        assert np.linalg.norm(com) < 1e-15
        np.testing.assert_allclose(inertia, sc.problem.body.inertia_B, rtol=0,
                                   atol=1e-15 * np.abs(sc.problem.body.inertia_B).max())
        for part in out.body_parts:     # each part a physical body with a full tensor (not principal)
            assert np.abs(part.inertia_B - np.diag(np.diag(part.inertia_B))).max() > 0


def test_a_flat_body_splits_in_its_plane_so_every_part_stays_physical():
    from cross_checks.scenario import load_scenario
    from cross_checks.scenario.transforms import WeldedSplit
    sc = load_scenario("tennis_racket")                    # 1 + 2 = 3 kg m²: all its mass in one plane
    out = apply(WeldedSplit(), sc)
    axis = np.linalg.eigh(sc.problem.body.inertia_B)[1][:, -1]
    for part in out.body_parts:
        assert abs(float(part.com_B_m @ axis)) < 1e-15
        a, b, c = np.linalg.eigvalsh(part.inertia_B)
        assert a + b >= c * (1 - 1e-12)


def test_a_com_offset_beyond_the_physical_ranges_is_refused_naming_the_field():
    from cross_checks.scenario.transforms import ComOffset
    sc = parse_scenario(TUMBLE, "t.toml")
    with pytest.raises(TransformRefused) as exc:
        apply(ComOffset(radii=3e6), sc)
    assert exc.value.field == "body.com" and "outside the range rbcheck judges" in exc.value.reason
