"""cross_checks.gates.check.mistakes: the correct bases are the reference's course steps; each mistake changes
the step exactly as its sentence says (effects derived by hand here)."""
import dataclasses
import math

import numpy as np
import pytest

from cross_checks.engines import get_adapter
from cross_checks.gates.check.mistakes import BASES, CATALOG, Knobs, applicable_mistakes, course_step
from cross_checks.scenario import load_scenario
from reference_sim.quaternion import matrix_from_quat, quat_conj, quat_log, quat_mul, quat_normalize
from reference_sim.state import Q, V, W, X

H = 0.01


def _states(sc, n=20, seed=0):
    rng = np.random.default_rng(seed)
    y = np.zeros((n, 13))
    y[:, X] = sc.problem.initial.x_W + 0.3 * rng.normal(size=(n, 3))
    y[:, V] = rng.normal(size=(n, 3))
    y[:, Q] = quat_normalize(rng.normal(size=(n, 4)))
    y[:, W] = 2.0 * rng.normal(size=(n, 3))
    return y


def _knobs(**kw):
    return dataclasses.replace(Knobs(), **kw)


@pytest.mark.parametrize("scen", ["applied_torque", "spring_pendulum", "velocity_decay", "linear_drag"])
@pytest.mark.parametrize("base, variant", [("with the gyroscopic term", "course_gyro"),
                                           ("without the gyroscopic term (the course's step)", "course")])
def test_the_correct_bases_are_the_reference_course_steps(scen, base, variant):
    """At the scenario's dt the course's per-step γ and e^(−k dt) are the same factor."""
    sc = load_scenario(scen)
    y = _states(sc)
    ours = course_step(sc, y, sc.dt_s, BASES[base])
    ref = get_adapter("reference").one_step(sc, variant, sc.dt_s, y)
    np.testing.assert_allclose(ours, ref, rtol=0, atol=1e-13)


def test_a_flipped_gyroscopic_sign_adds_twice_the_gyroscopic_acceleration():
    sc = load_scenario("tennis_racket")
    y = _states(sc)
    R = matrix_from_quat(y[:, Q])
    I_W = R @ sc.problem.body.inertia_B @ np.swapaxes(R, 1, 2)
    gyro = np.cross(y[:, W], np.einsum("kij,kj->ki", I_W, y[:, W]))
    expected = 2.0 * H * np.linalg.solve(I_W, gyro[..., None])[..., 0]
    diff = course_step(sc, y, H, _knobs(gyro=1.0))[:, W] - course_step(sc, y, H, Knobs())[:, W]
    np.testing.assert_allclose(diff, expected, atol=1e-12)


def test_missing_half_turns_the_body_through_twice_the_angle():
    """q1 = (1 + h [0, ω] c) q: rotation angle 2 atan(c h |ω|) with c = ½ (correct) or 1."""
    sc = load_scenario("constant_spin")
    y = _states(sc)
    for knobs, c in ((Knobs(), 0.5), (_knobs(quat_half=1.0), 1.0)):
        y1 = course_step(sc, y, H, knobs)
        angle = np.linalg.norm(quat_log(quat_mul(y1[:, Q], quat_conj(y[:, Q]))), axis=1)
        np.testing.assert_allclose(angle, 2.0 * np.arctan(c * H * np.linalg.norm(y1[:, W], axis=1)),
                                   rtol=1e-10)


def test_without_normalisation_the_norm_grows_by_the_hand_derived_factor():
    sc = load_scenario("constant_spin")
    y = _states(sc)
    y1 = course_step(sc, y, H, _knobs(normalise=False))
    np.testing.assert_allclose(np.linalg.norm(y1[:, Q], axis=1),
                               np.sqrt(1.0 + (0.5 * H * np.linalg.norm(y1[:, W], axis=1)) ** 2), rtol=1e-12)


def test_the_wrong_side_of_the_product_rotates_about_R_omega():
    """q ⊗ [0, ω] = [0, R ω] ⊗ q: the wrong-side step turns about R ω instead of ω."""
    sc = load_scenario("constant_spin")
    y = _states(sc)
    wrong = course_step(sc, y, H, _knobs(quat="right_world"))
    y_rot = y.copy()
    w1 = course_step(sc, y, H, Knobs())[:, W]
    z = y.copy()
    z[:, W] = np.einsum("kij,kj->ki", matrix_from_quat(y[:, Q]), w1)
    q_expected = y[:, Q] + quat_mul(np.concatenate([np.zeros((len(y), 1)), 0.5 * H * z[:, W]], axis=1),
                                    y[:, Q])
    q_expected /= np.linalg.norm(q_expected, axis=1, keepdims=True)
    np.testing.assert_allclose(wrong[:, Q], q_expected, atol=1e-14)
    assert np.max(np.abs(wrong[:, Q] - y_rot[:, Q])) > 0


def test_the_cross_product_order_flips_the_torque_of_point_forces():
    sc = load_scenario("applied_torque")       # a world force (1, 0, 0) N at body point (0, 0.1, 0)
    y = _states(sc)
    R = matrix_from_quat(y[:, Q])
    r_W = R @ np.array([0.0, 0.1, 0.0])
    tau = np.cross(r_W, [1.0, 0.0, 0.0])
    I_W = R @ sc.problem.body.inertia_B @ np.swapaxes(R, 1, 2)
    expected = -2.0 * H * np.linalg.solve(I_W, tau[..., None])[..., 0]
    diff = course_step(sc, y, H, _knobs(torque_sign=-1.0))[:, W] - course_step(sc, y, H, Knobs())[:, W]
    np.testing.assert_allclose(diff, expected, atol=1e-13)


def test_decay_twice_and_missing_decay_change_the_velocity_factor():
    sc = load_scenario("velocity_decay")        # γ = 0.99 at dt = 0.01, no forces
    y = _states(sc)
    k = -math.log(0.99) / 0.01
    for power in (0.0, 1.0, 2.0):
        v1 = course_step(sc, y, H, _knobs(decay_power=power))[:, V]
        np.testing.assert_allclose(v1, math.exp(-power * k * H) * y[:, V], rtol=1e-14)
    v1 = course_step(sc, y, 0.005, _knobs(decay_per_step=True))[:, V]
    np.testing.assert_allclose(v1, 0.99 * y[:, V], rtol=1e-14)          # γ whatever the step


def test_inertia_mistakes_vanish_without_rotation_and_show_with_it():
    sc = load_scenario("tennis_racket")
    y = _states(sc)
    y_id = y.copy()
    y_id[:, Q] = [1.0, 0.0, 0.0, 0.0]
    for name in ("body", "transposed"):
        k = _knobs(inertia=name)
        np.testing.assert_allclose(course_step(sc, y_id, H, k), course_step(sc, y_id, H, Knobs()), atol=1e-15)
        assert np.max(np.abs(course_step(sc, y, H, k)[:, W] - course_step(sc, y, H, Knobs())[:, W])) > 1e-3


def test_the_catalog_offers_only_mistakes_that_can_show():
    names = lambda sc, h=0.01: {m.name for m in applicable_mistakes(load_scenario(sc), h)}   # noqa: E731
    assert names("projectile") == {"gravity axis"}
    assert "drag sign" in names("linear_drag") and "decay applied twice" not in names("linear_drag")
    assert ({"torque cross product order", "lever arm not rotated", "force or torque frame"}
            <= names("applied_torque"))
    assert "decay per step at another Δt" not in names("velocity_decay", 0.01)
    assert "decay per step at another Δt" in names("velocity_decay", 0.005)
    assert len({m.name for m in CATALOG}) == len(CATALOG) and all(m.sentence for m in CATALOG)
