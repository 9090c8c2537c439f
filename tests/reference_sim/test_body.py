"""Mass properties and the course's particle-body sanity checks."""
import numpy as np
import pytest

from reference_sim.body import RigidBody, check_inertia, inertia_from_particles
from reference_sim.forces import ForceModel
from reference_sim.quaternion import matrix_from_quat, quat_normalize
from tests.helpers.tolerances import QUAT_ALGEBRA

PARTICLES = np.array([[1.0, 0.3, 0.0, 0.1], [2.0, -0.2, 0.4, 0.0],
                      [1.5, 0.0, -0.3, 0.5], [0.5, 0.1, 0.2, -0.4]])


def test_particle_inertia_is_the_course_sum():
    body, com = RigidBody.from_particles(PARTICLES)
    m, p = PARTICLES[:, 0], PARTICLES[:, 1:]
    assert body.mass_kg == pytest.approx(m.sum())
    np.testing.assert_allclose(com, (m[:, None] * p).sum(0) / m.sum())
    I = np.zeros((3, 3))
    for mi, ri in zip(m, p - com):
        I += mi * ((ri @ ri) * np.eye(3) - np.outer(ri, ri))
    np.testing.assert_allclose(body.inertia_B, I, rtol=1e-14)
    assert not body.is_diagonal()  # a full tensor: exercises principal axes in every adapter


def test_gravity_gives_no_torque_about_the_com_of_a_particle_body():
    body, _ = RigidBody.from_particles(PARTICLES)
    g = np.array([0.0, 0.0, -9.81])
    for q in quat_normalize(np.random.default_rng(0).normal(size=(20, 4))):
        R = matrix_from_quat(q)
        tau = sum(np.cross(R @ r, m * g) for m, *r in body.particles for r in [np.array(r)])
        assert np.linalg.norm(tau) < 1e-14
        _, tau_model = ForceModel(gravity_W=g).force_torque(body, np.zeros(3), np.zeros(3), q)
        assert np.all(tau_model == 0.0)


def test_body_points_keep_their_distances():
    body, _ = RigidBody.from_particles(PARTICLES)
    r = body.particles[:, 1:]
    d_body = np.linalg.norm(r[:, None] - r[None], axis=-1)
    for q in quat_normalize(np.random.default_rng(1).normal(size=(20, 4))):
        p = np.array([1.0, 2.0, 3.0]) + r @ matrix_from_quat(q).T
        np.testing.assert_allclose(np.linalg.norm(p[:, None] - p[None], axis=-1),
                                   d_body, atol=10 * QUAT_ALGEBRA)


def test_world_inertia_rotates_the_tensor():
    body = RigidBody(2.0, [1.0, 2.0, 3.0])
    R = matrix_from_quat(quat_normalize([0.3, -0.2, 0.9, 0.1]))
    np.testing.assert_allclose(body.world_inertia(R), R @ np.diag([1.0, 2.0, 3.0]) @ R.T, atol=1e-15)


def test_principal_axes_reconstruct_the_tensor():
    body, _ = RigidBody.from_particles(PARTICLES)
    moments, R = body.principal_axes()
    assert np.linalg.det(R) == pytest.approx(1.0)
    np.testing.assert_allclose(R @ np.diag(moments) @ R.T, body.inertia_B, atol=1e-15)


@pytest.mark.parametrize("inertia, reason", [
    ([1.0, 1.0, 3.0], "triangle"),
    ([[1, 0.5, 0], [0, 1, 0], [0, 0, 1]], "symmetric"),
    ([-1.0, 2.0, 2.0], "positive definite"),
    ([1.0, 2.0], "shape"),
    ([1.0, np.nan, 1.0], "finite"),
])
def test_invalid_inertia_is_rejected_with_reason(inertia, reason):
    with pytest.raises(ValueError, match=reason):
        check_inertia(inertia)


def test_triangle_equality_is_accepted():
    check_inertia([1.0, 2.0, 3.0])  # A + B = C: a flat plate, physical (MuJoCo accepts it too)


def test_inertia_from_colinear_particles_is_singular():
    _, _, I = inertia_from_particles([1.0, 1.0], [[0, 0, -1], [0, 0, 1]])
    assert np.linalg.eigvalsh(I)[0] == 0.0


def test_compose_parts_is_the_parallel_axis_theorem_by_hand():
    from reference_sim.body import BodyPart, compose_parts
    # two unit-inertia parts of 1 and 3 kg at x = 1 and x = −1: COM at −0.5; d = 1.5, −0.5; Σ m d² = 3
    mass, com, inertia = compose_parts([BodyPart(1.0, [1.0, 0.0, 0.0], np.eye(3)),
                                        BodyPart(3.0, [-1.0, 0.0, 0.0], np.eye(3))])
    assert mass == 4.0
    np.testing.assert_array_equal(com, [-0.5, 0.0, 0.0])
    np.testing.assert_allclose(inertia, np.diag([2.0, 5.0, 5.0]), atol=1e-15)


def test_origin_and_com_states_are_inverse_and_move_the_com_with_the_rotation():
    from reference_sim.body import com_state, origin_state
    from reference_sim.quaternion import quat_from_axis_angle
    c = np.array([0.3, -0.2, 0.5])
    q = quat_from_axis_angle(np.array([1.0, 2.0, 2.0]) / 3.0, 0.7)
    y = np.concatenate([[1.0, 2.0, 3.0], [0.1, 0.2, 0.3], q, [0.5, -1.0, 2.0]])
    x_o, v_o = origin_state(y, c)
    np.testing.assert_allclose(com_state(x_o, v_o, q, y[10:13], c), y, rtol=0, atol=1e-15)
    # about the z axis at 2 rad/s, a COM 1 m along x from the origin moves at 2 m/s along y (by hand)
    y2 = np.concatenate([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 2.0]])
    x_o, v_o = origin_state(y2, [1.0, 0.0, 0.0])
    np.testing.assert_array_equal(x_o, [-1.0, 0.0, 0.0])
    np.testing.assert_array_equal(v_o, [0.0, -2.0, 0.0])
