"""Forces: each yields the force and the torque about the COM, τ = (R r) × f, in world axes."""
import numpy as np
import pytest

from reference_sim.body import RigidBody
from reference_sim.forces import ForceModel, PointForce, Spring, Torque
from reference_sim.quaternion import matrix_from_quat, quat_normalize

BODY = RigidBody(2.0, [1.0, 2.0, 3.0])
Q = quat_normalize(np.array([0.9, 0.1, -0.3, 0.2]))
R = matrix_from_quat(Q)
X, V = np.array([0.1, -0.2, 0.3]), np.array([1.0, 2.0, -0.5])


def test_gravity_acts_at_com_without_torque():
    f, tau = ForceModel(gravity_W=np.array([0, 0, -9.81])).force_torque(BODY, X, V, Q)
    np.testing.assert_array_equal(f, [0, 0, -19.62])
    np.testing.assert_array_equal(tau, 0.0)


def test_linear_drag_opposes_velocity():
    f, tau = ForceModel(linear_drag_N_s_per_m=0.5).force_torque(BODY, X, V, Q)
    np.testing.assert_allclose(f, -0.5 * V)
    np.testing.assert_array_equal(tau, 0.0)


def test_spring_force_and_torque_about_com():
    s = Spring(np.array([0.0, 1.0, 0.0]), np.array([0.1, 0.0, 0.0]), 40.0, 0.5)
    f, tau = ForceModel(springs=(s,)).force_torque(BODY, X, V, Q)
    r = R @ s.attach_B
    d = X + r - s.anchor_W
    expected = -40.0 * (np.linalg.norm(d) - 0.5) * d / np.linalg.norm(d)
    np.testing.assert_allclose(f, expected, rtol=1e-14)
    np.testing.assert_allclose(tau, np.cross(r, expected), rtol=1e-14)
    U = ForceModel(springs=(s,)).potential_energy_J(BODY, X, Q)
    assert abs(U - 0.5 * 40.0 * (np.linalg.norm(d) - 0.5) ** 2) < 1e-14


def test_spring_force_is_minus_gradient_of_its_potential():
    s = Spring(np.array([0.0, 1.0, 0.0]), np.zeros(3), 40.0, 0.5)
    fm = ForceModel(springs=(s,))
    f, _ = fm.force_torque(BODY, X, V, Q)
    h = 1e-6
    grad = np.array([(fm.potential_energy_J(BODY, X + h * e, Q)
                      - fm.potential_energy_J(BODY, X - h * e, Q)) / (2 * h) for e in np.eye(3)])
    np.testing.assert_allclose(f, -grad, rtol=1e-8)


def test_point_force_world_and_body_frames():
    pw = PointForce(np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.1, 0.0]), "world")
    pb = PointForce(np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.1, 0.0]), "body")
    f, tau = ForceModel(point_forces=(pw,)).force_torque(BODY, X, V, Q)
    np.testing.assert_allclose(f, [1.0, 0, 0])
    np.testing.assert_allclose(tau, np.cross(R @ [0, 0.1, 0], [1.0, 0, 0]))
    f, tau = ForceModel(point_forces=(pb,)).force_torque(BODY, X, V, Q)
    np.testing.assert_allclose(f, R @ [1.0, 0, 0])
    np.testing.assert_allclose(tau, np.cross(R @ [0, 0.1, 0], R @ [1.0, 0, 0]))


def test_pure_torques_world_and_body():
    f, tau = ForceModel(torques=(Torque(np.array([0, 0, 0.2]), "body"),
                                 Torque(np.array([0.1, 0, 0]), "world"))
                        ).force_torque(BODY, X, V, Q)
    np.testing.assert_array_equal(f, 0.0)
    np.testing.assert_allclose(tau, R @ [0, 0, 0.2] + [0.1, 0, 0])


def test_batched_evaluation_equals_single():
    fm = ForceModel(gravity_W=np.array([0, 0, -9.81]), linear_drag_N_s_per_m=0.3,
                    springs=(Spring(np.array([0.0, 1.0, 0.0]), np.array([0.1, 0.0, 0.0]), 40.0, 0.5),),
                    point_forces=(PointForce(np.array([0.0, 0.5, 0.0]), np.array([0.0, 0.0, 0.2]), "body"),),
                    torques=(Torque(np.array([0, 0, 0.2]), "body"),))
    rng = np.random.default_rng(3)
    xs, vs, qs = rng.normal(size=(5, 3)), rng.normal(size=(5, 3)), quat_normalize(rng.normal(size=(5, 4)))
    fb, tb = fm.force_torque(BODY, xs, vs, qs)
    for i in range(5):
        f, t = fm.force_torque(BODY, xs[i], vs[i], qs[i])
        np.testing.assert_allclose(fb[i], f, rtol=1e-15, atol=1e-16)
        np.testing.assert_allclose(tb[i], t, rtol=1e-15, atol=1e-16)


def test_classification_flags():
    assert ForceModel(gravity_W=np.ones(3)).torque_free
    assert not ForceModel(torques=(Torque(np.ones(3), "world"),)).torque_free
    assert ForceModel(linear_drag_N_s_per_m=1.0).state_dependent
    assert not ForceModel(point_forces=(PointForce(np.ones(3), np.zeros(3), "world"),)).state_dependent
    fm = ForceModel(velocity_decay=0.99, decay_dt_s=0.01)
    assert fm.has_decay and not fm.conservative


def test_decay_factor_is_the_course_gamma_exactly_at_its_own_step_and_exponential_elsewhere():
    fm = ForceModel(velocity_decay=0.99, angular_velocity_decay=0.995, decay_dt_s=0.01)
    assert fm.decay_factors(0.01) == (0.99, 0.995)           # bit for bit: the course's own factors
    k_v, k_w = fm.decay_rates_per_s()
    assert (k_v == pytest.approx(-np.log(0.99) / 0.01, rel=1e-15)
            and k_w == pytest.approx(-np.log(0.995) / 0.01, rel=1e-15))
    for dt in (0.02, 0.005, 0.00125, 0.003):                  # e^{-k dt}: one physical damping rate
        gv, gw = fm.decay_factors(dt)
        assert (gv == pytest.approx(np.exp(-k_v * dt), rel=1e-14)
                and gw == pytest.approx(np.exp(-k_w * dt), rel=1e-14))
    gv, gw = fm.decay_factors(np.array([0.01, 0.005]))         # arrays of steps (batched integrators)
    np.testing.assert_allclose(gv, [0.99, np.sqrt(0.99)], rtol=1e-15)
    assert ForceModel().decay_factors(0.3) == (1.0, 1.0) and ForceModel().decay_rates_per_s() == (0.0, 0.0)


@pytest.mark.parametrize("kwargs", [dict(velocity_decay=0.99), dict(velocity_decay=0.99, decay_dt_s=0.0),
                                    dict(velocity_decay=1.5, decay_dt_s=0.01),
                                    dict(angular_velocity_decay=0.0, decay_dt_s=0.01)])
def test_decay_needs_a_factor_in_0_1_and_the_step_it_is_given_at(kwargs):
    with pytest.raises(ValueError):
        ForceModel(**kwargs)
