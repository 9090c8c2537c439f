"""Quaternion algebra against scipy.spatial.transform.Rotation (scalar_first=True) and its properties."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.spatial.transform import Rotation

from reference_sim.quaternion import (
    axis_angle_from_quat,
    euler_zxy_from_quat,
    geodesic_angle,
    matrix_from_quat,
    quat_conj,
    quat_exp,
    quat_from_axis_angle,
    quat_from_euler_zxy,
    quat_from_matrix,
    quat_log,
    quat_mul,
    quat_norm,
    quat_normalize,
    rotate,
    same_side,
    sign_continuous,
)
from tests.helpers.tolerances import QUAT_ALGEBRA, QUAT_ROUND_TRIP, euler_round_trip_tol

finite = st.floats(-10, 10, allow_nan=False, allow_infinity=False)
quats = arrays(float, 4, elements=finite).filter(lambda q: np.linalg.norm(q) > 1e-3).map(quat_normalize)
vecs = arrays(float, 3, elements=finite)


@pytest.fixture
def rng():
    return np.random.default_rng(1234)


def _random_quats(rng, n=500):
    return quat_normalize(rng.normal(size=(n, 4)))


def test_product_matches_scipy(rng):
    q1, q2 = _random_quats(rng), _random_quats(rng)
    expected = (Rotation.from_quat(q1, scalar_first=True)
                * Rotation.from_quat(q2, scalar_first=True)).as_quat(scalar_first=True)
    assert np.max(geodesic_angle(expected, quat_mul(q1, q2))) < QUAT_ROUND_TRIP


def test_product_formula_is_the_course_one():
    q1, q2 = np.array([1.0, 2.0, 3.0, 4.0]), np.array([-0.5, 0.1, 0.7, -2.0])
    s1, v1, s2, v2 = q1[0], q1[1:], q2[0], q2[1:]
    expected = np.concatenate([[s1 * s2 - v1 @ v2], s1 * v2 + s2 * v1 + np.cross(v1, v2)])
    np.testing.assert_allclose(quat_mul(q1, q2), expected, rtol=QUAT_ALGEBRA)


def test_product_not_commutative():
    a, b = quat_from_axis_angle([1, 0, 0], 0.5), quat_from_axis_angle([0, 1, 0], 0.5)
    assert np.max(np.abs(quat_mul(a, b) - quat_mul(b, a))) > 0.1


def test_matrix_matches_scipy(rng):
    q = _random_quats(rng)
    np.testing.assert_allclose(matrix_from_quat(q), Rotation.from_quat(q, scalar_first=True).as_matrix(),
                               atol=QUAT_ALGEBRA)


def test_matrix_round_trip(rng):
    q = _random_quats(rng)
    assert np.max(geodesic_angle(q, quat_from_matrix(matrix_from_quat(q)))) < QUAT_ROUND_TRIP


def test_exp_matches_scipy_rotvec(rng):
    w = rng.normal(size=(200, 3)) * 2.0
    np.testing.assert_allclose(quat_exp(w), Rotation.from_rotvec(w).as_quat(scalar_first=True),
                               atol=QUAT_ALGEBRA)
    tiny = np.array([[1e-9, -2e-9, 3e-10], [0.0, 0.0, 0.0]])
    np.testing.assert_allclose(quat_exp(tiny),
                               Rotation.from_rotvec(tiny).as_quat(scalar_first=True), atol=1e-18)


def test_axis_angle_round_trip(rng):
    axis = rng.normal(size=(200, 3))
    angle = rng.uniform(0, np.pi, size=200)
    u, a = axis_angle_from_quat(quat_from_axis_angle(axis, angle))
    np.testing.assert_allclose(a, angle, atol=QUAT_ROUND_TRIP)
    np.testing.assert_allclose(u, axis / np.linalg.norm(axis, axis=1, keepdims=True), atol=1e-9)
    np.testing.assert_allclose(quat_log(quat_exp(0.5 * axis)), 0.5 * axis, atol=QUAT_ROUND_TRIP)


def test_conjugate_inverts(rng):
    q = _random_quats(rng)
    np.testing.assert_allclose(quat_mul(q, quat_conj(q)),
                               np.tile([1.0, 0, 0, 0], (len(q), 1)), atol=QUAT_ALGEBRA)


def test_normalize_rejects_zero():
    with pytest.raises(ValueError):
        quat_normalize([0.0, 0.0, 0.0, 0.0])


def test_euler_zxy_matches_scipy_extrinsic_zxy(rng):
    # Unity: rotate about Z, then X, then Y (fixed axes) == scipy extrinsic "zxy" with angles (z, x, y).
    ang = rng.uniform(-85, 85, size=(100, 3))
    expected = Rotation.from_euler("zxy", ang[:, [2, 0, 1]], degrees=True).as_quat(scalar_first=True)
    assert np.max(geodesic_angle(expected, quat_from_euler_zxy(ang))) < QUAT_ROUND_TRIP


@settings(max_examples=200, deadline=None, derandomize=True)
@given(quats)
def test_unit_norm_kept_by_product_and_exp(q):
    assert abs(quat_norm(quat_mul(q, q)) - 1.0) < QUAT_ALGEBRA
    assert abs(quat_norm(quat_mul(quat_exp(q[1:]), q)) - 1.0) < QUAT_ALGEBRA


@settings(max_examples=200, deadline=None, derandomize=True)
@given(quats)
def test_rotation_matrix_is_orthonormal(q):
    R = matrix_from_quat(q)
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=QUAT_ALGEBRA)
    assert abs(np.linalg.det(R) - 1.0) < QUAT_ALGEBRA


@settings(max_examples=200, deadline=None, derandomize=True)
@given(quats)
def test_quat_double_cover(q):
    np.testing.assert_allclose(matrix_from_quat(q), matrix_from_quat(-q), atol=0)
    assert geodesic_angle(q, -q) < QUAT_ALGEBRA


@settings(max_examples=200, deadline=None, derandomize=True)
@given(quats, vecs, vecs)
def test_rotation_preserves_distances(q, a, b):
    assert abs(np.linalg.norm(rotate(q, a) - rotate(q, b)) - np.linalg.norm(a - b)) < QUAT_ALGEBRA * (
        1 + np.linalg.norm(a - b)) * 10


@settings(max_examples=200, deadline=None, derandomize=True)
@given(quats)
def test_euler_round_trip(q):
    angles, locked = euler_zxy_from_quat(q)
    tol = euler_round_trip_tol(np.cos(np.deg2rad(angles[0])), bool(locked))
    assert geodesic_angle(q, quat_from_euler_zxy(angles)) < tol


@pytest.mark.parametrize("pitch", [90.0, -90.0])
@pytest.mark.parametrize("yaw_roll", [(30.0, 10.0), (0.0, 50.0), (-70.0, 20.0)])
def test_gimbal_lock_flagged_at_pm90_pitch(pitch, yaw_roll):
    q = quat_from_euler_zxy([pitch, *yaw_roll])
    angles, locked = euler_zxy_from_quat(q)
    assert locked
    assert angles[2] == 0.0  # z set to 0: only y ± z is defined
    assert geodesic_angle(q, quat_from_euler_zxy(angles)) < QUAT_ROUND_TRIP


def test_no_gimbal_lock_just_off_90():
    _, locked = euler_zxy_from_quat(quat_from_euler_zxy([89.999, 30.0, 10.0]))
    assert not locked


def test_sign_continuous_removes_every_jump_to_minus_q_and_keeps_the_orientations():
    rng = np.random.default_rng(3)
    q = rng.normal(size=(200, 4))
    q /= np.linalg.norm(q, axis=1)[:, None]
    q = np.cumsum(q * 0.05, axis=0) + np.array([1.0, 0, 0, 0])
    q /= np.linalg.norm(q, axis=1)[:, None]
    flips = rng.random(200) < 0.3
    jumpy = np.where(flips[:, None], -q, q)
    smooth = sign_continuous(jumpy, first=q[0])
    assert np.all(np.einsum("ij,ij->i", smooth[1:], smooth[:-1]) >= 0)     # no jump to −q
    assert np.allclose(np.abs(np.einsum("ij,ij->i", smooth, q)), 1.0)      # the same orientations
    assert np.allclose(smooth, q)                                          # and here the same signs
    assert np.allclose(sign_continuous(jumpy, first=-q[0]), -q)            # the first row follows `first`
    assert np.allclose(sign_continuous(jumpy)[0], jumpy[0])                # without it, the first is kept


def test_same_side_picks_the_sign_nearest_the_reference_and_keeps_the_orientation():
    rng = np.random.default_rng(5)
    q_ref = rng.normal(size=(300, 4))
    q_ref /= np.linalg.norm(q_ref, axis=1)[:, None]
    q = q_ref + 0.4 * rng.normal(size=(300, 4))          # a step away, some of it past a quarter turn
    q /= np.linalg.norm(q, axis=1)[:, None]
    flips = rng.random(300) < 0.5
    out = same_side(np.where(flips[:, None], -q, q), q_ref)
    by_hand = np.array([qi if np.dot(qi, ri) >= 0 else -qi for qi, ri in zip(q, q_ref)])
    assert np.array_equal(out, by_hand)
    row = same_side(np.array([np.nan, 0.0, 0.0, 1.0]), np.array([0.0, 0.0, 0.0, -1.0]))
    assert np.isnan(row[0]) and row[3] == 1.0                                   # not finite: sign kept


def test_sign_continuous_leaves_a_non_finite_row_and_an_empty_array_alone():
    q = np.array([[1.0, 0, 0, 0], [np.nan, 0, 0, 0], [-1.0, 0, 0, 0]])
    out = sign_continuous(q)
    assert out[0, 0] == 1.0 and np.isnan(out[1, 0]) and out[2, 0] == -1.0
    assert sign_continuous(np.empty((0, 4))).shape == (0, 4)


#: Angles around every branch of sin(θ/2)/θ: 0, deep in the series, both sides of its threshold, ordinary
#: and large angles, rad.
SINC_ANGLES = [0.0, 1e-300, 1e-12, 3e-7, 9.999999999999999e-05, 1e-4, 1.0000000000000002e-4, 3e-4, 0.1,
               1.0, 2.0, np.pi, 10.0, 1e6]


def test_half_angle_sinc_is_the_exp_map_coefficient_everywhere():
    from reference_sim.integrators import exp_map_times
    from reference_sim.quaternion import SINC_SERIES_BELOW_RAD, half_angle_sinc
    th = np.array(SINC_ANGLES)
    got = half_angle_sinc(th)
    assert got[0] == 0.5 and np.all(np.isfinite(got))
    # sin(θ/2)/θ where the division loses nothing; the series where it would: within a few ulps of both
    big = th >= SINC_SERIES_BELOW_RAD
    np.testing.assert_allclose(got[big], np.sin(0.5 * th[big]) / th[big], rtol=0, atol=0)
    small = (th > 0) & ~big
    np.testing.assert_allclose(got[small], np.sin(0.5 * th[small]) / th[small], rtol=4e-16)
    # the quaternion exponential and the integrators' exp-map update take it from here
    w = np.array([0.3, -0.4, 1.2])
    for h in (1e-9, 1e-5, 0.01, 1.0):
        q = exp_map_times(h, w, np.array([1.0, 0.0, 0.0, 0.0]))
        th_h = h * np.sqrt(np.sum(w * w))
        np.testing.assert_array_equal(q[1:], (h * half_angle_sinc(th_h)) * w)
        np.testing.assert_array_equal(quat_exp(h * w)[1:], half_angle_sinc(np.linalg.norm(h * w)) * (h * w))
