"""The generator: deterministic per (seed, case), valid over the whole schema, exact through TOML."""
import numpy as np
import pytest

from cross_checks.fuzz import generate
from cross_checks.fuzz.pipeline import scenario_of
from cross_checks.scenario import parse_scenario


def test_a_case_is_the_same_whatever_was_drawn_before_it():
    first = generate.to_toml(generate.draw(7, 5).spec(0.01, 8))
    for i in range(5):
        generate.draw(7, i)
    assert generate.to_toml(generate.draw(7, 5).spec(0.01, 8)) == first
    assert generate.to_toml(generate.draw(8, 5).spec(0.01, 8)) != first


def test_every_draw_is_a_valid_scenario_whose_toml_reads_back_exactly():
    from reference_sim.quaternion import quat_from_euler_zxy
    for i in range(60):
        d = generate.draw(3, i)
        spec = d.spec(0.01, 8)
        sc = parse_scenario(generate.to_toml(spec), source="<test>")
        assert sc.dt_s == 0.01 and sc.n_steps() == 8
        mass = spec["body"].get("mass")
        if mass is not None:
            assert sc.problem.body.mass_kg == mass
        ini = spec["initial"]
        if "orientation" in ini:
            assert np.allclose(sc.problem.initial.q_WB, ini["orientation"], rtol=0, atol=4e-16)
        if "euler_zxy_deg" in ini:
            assert np.allclose(sc.problem.initial.q_WB, quat_from_euler_zxy(ini["euler_zxy_deg"]), atol=1e-15)
        if "velocity" in ini:
            assert np.array_equal(sc.problem.initial.v_W, ini["velocity"])


def test_the_draws_cover_every_body_spin_and_force_kind_of_the_schema():
    seen = {"body": set(), "shape": set(), "spin": set(), "forces": set()}
    frames = set()
    for i in range(300):
        d = generate.draw(1, i)
        for k in ("body", "shape", "spin"):
            seen[k].add(d.kinds[k])
        seen["forces"].update(d.kinds["forces"])
        frames.update(p["frame"] for p in d.forces.get("point", []))
        frames.update("torque_" + t["frame"] for t in d.forces.get("torque", []))
    assert seen["body"] == {"moments", "tensor", "particles"}
    assert seen["shape"] == set(generate.SHAPES) | {"particles"}
    assert seen["spin"] == set(generate.SPIN_KINDS)
    assert seen["forces"] == {"gravity", "drag", "velocity_decay",
                              "angular_velocity_decay", "spring", "point", "torque"}
    assert frames == {"world", "body", "torque_world", "torque_body"}


def test_drawn_bodies_keep_their_margin_from_mujocos_triangle_inequality_check():
    """A lamina (any three particles, I1 + I2 = I3) is refused by MuJoCo when round-off lands on the wrong
    side (docs/engine_conventions.md); every drawn body keeps FUZZ_TRIANGLE_MARGIN and MuJoCo builds it."""
    from cross_checks.core import tolerances as tol
    from cross_checks.engines import mujoco_engine as me
    n_flat = 0
    for i in range(120):
        d = generate.draw(2, i)
        sc = scenario_of(d.spec(0.01, 8))
        ev = np.linalg.eigvalsh(sc.problem.body.inertia_B)
        assert ev[0] + ev[1] >= ev[2] * (1.0 + 0.999 * tol.FUZZ_TRIANGLE_MARGIN)
        n_flat += d.kinds["shape"] in ("flat", "particles")
        me.build_model(sc, "euler", 0.01)
    assert n_flat >= 20


@pytest.mark.parametrize("index", range(4))
def test_the_chosen_step_keeps_the_measured_numbers_within_their_bounds(index):
    from cross_checks.core import tolerances as tol
    from cross_checks.fuzz import pipeline
    cases = pipeline.prepare([generate.draw(11, 4 * index + k) for k in range(4)], 16)
    pipeline.measure(cases)
    for c in cases:
        n = c.numbers
        assert "skipped" not in n
        assert n["hL"] <= tol.FUZZ_HL_MAX * tol.FUZZ_BOUND_SLACK
        assert n["A_chi"] <= tol.FUZZ_LINEAR_MAX * tol.FUZZ_BOUND_SLACK
