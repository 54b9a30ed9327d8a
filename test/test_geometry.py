"""The first-principles rotor wrench reproduces the article's eq. (1)-(2); the rotation
helpers match scipy's Rotation."""
import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from uav_tilt_common.geometry import (article_wrench_p, cross3, euler_zyx_to_matrix, flu_to_p,
                                      matrix_to_euler_zyx, matrix_to_quat, p_to_flu,
                                      quat_multiply, quat_slerp, quat_to_matrix,
                                      quat_to_rotvec, rotor_wrench_flu, rotvec_to_quat)


def test_rotor_wrench_equals_article_equations_for_random_inputs():
    rng = np.random.default_rng(0)
    for _ in range(500):
        thrusts = rng.uniform(0.0, 9.0, 4)
        alpha, beta = rng.uniform(-1.2, 1.2, 2)
        l1, l2, k = rng.uniform(0.05, 0.4), rng.uniform(0.05, 0.4), rng.uniform(0.0, 0.05)
        force, torque = rotor_wrench_flu(thrusts, alpha, beta, l1, l2, k)
        f_y, f_z, tau_x, tau_y, tau_z = article_wrench_p(thrusts, alpha, beta, l1, l2, k)
        assert np.allclose(flu_to_p(force), [0.0, f_y, f_z], atol=1e-12)
        assert np.allclose(flu_to_p(torque), [tau_x, tau_y, tau_z], atol=1e-12)


def test_frame_conversion_is_a_proper_rotation():
    v = np.array([0.3, -1.2, 2.0])
    assert np.allclose(flu_to_p(p_to_flu(v)), v)
    # x_P is right = -y_FLU; y_P is forward = x_FLU.
    assert np.allclose(p_to_flu([1, 0, 0]), [0, -1, 0])
    assert np.allclose(p_to_flu([0, 1, 0]), [1, 0, 0])
    M = np.column_stack([p_to_flu(e) for e in np.eye(3)])
    assert np.isclose(np.linalg.det(M), 1.0)


def _random_rotations(n=200, seed=1):
    return Rotation.random(n, random_state=seed)


def test_cross3_matches_numpy():
    rng = np.random.default_rng(2)
    for a, b in rng.normal(size=(200, 2, 3)):
        assert np.allclose(cross3(a, b), np.cross(a, b), rtol=0.0, atol=1e-12)


def test_matrix_to_quat_matches_scipy():
    rotations = _random_rotations()
    # the branch on the largest of (diagonal, trace) is taken for every case
    special = Rotation.from_rotvec([[np.pi, 0, 0], [0, np.pi, 0], [0, 0, np.pi], [0, 0, 0]])
    for R in np.concatenate([rotations.as_matrix(), special.as_matrix()]):
        assert np.allclose(matrix_to_quat(R), Rotation.from_matrix(R).as_quat(), rtol=0.0,
                           atol=1e-12)


def test_quat_multiply_matches_scipy_composition():
    a, b = _random_rotations(seed=3), _random_rotations(seed=4)
    for ra, rb in zip(a, b):
        assert np.allclose(quat_multiply(ra.as_quat(), rb.as_quat()), (ra * rb).as_quat(),
                           rtol=0.0, atol=1e-12)


def test_rotvec_conversions_match_scipy():
    rng = np.random.default_rng(5)
    # large, small (Taylor branch) and zero angles, and quaternions with w < 0 or w = 0
    vectors = np.vstack([rng.uniform(-3.0, 3.0, (200, 3)), rng.uniform(-4e-4, 4e-4, (50, 3)),
                         np.zeros((1, 3))])
    for v in vectors:
        r = Rotation.from_rotvec(v)
        assert np.allclose(rotvec_to_quat(v), r.as_quat(), rtol=0.0, atol=1e-12)
        assert np.allclose(quat_to_rotvec(-r.as_quat()), r.as_rotvec(), rtol=0.0, atol=1e-12)
    for q in ([0.0, -1.0, 0.0, 0.0], [0.0, 0.0, -1.0, 0.0], [-0.6, 0.8, 0.0, 0.0]):
        assert np.allclose(quat_to_rotvec(q), Rotation.from_quat(q).as_rotvec(), rtol=0.0,
                           atol=1e-12)


def test_quat_slerp_matches_scipy_slerp():
    a, b = _random_rotations(seed=6), _random_rotations(seed=7)
    rng = np.random.default_rng(8)
    for ra, rb, u in zip(a, b, rng.uniform(0.0, 1.0, len(a))):
        expected = Slerp([0.0, 1.0], Rotation.concatenate([ra, rb]))(u).as_matrix()
        got = quat_to_matrix(quat_slerp(ra.as_quat(), rb.as_quat(), u))
        assert np.allclose(got, expected, rtol=0.0, atol=1e-12)


def test_euler_zyx_conversions_match_scipy():
    rng = np.random.default_rng(9)
    for angles in rng.uniform([-np.pi, -1.5, -np.pi], [np.pi, 1.5, np.pi], (200, 3)):
        r = Rotation.from_euler('ZYX', angles)
        assert np.allclose(euler_zyx_to_matrix(*angles), r.as_matrix(), rtol=0.0, atol=1e-12)
        assert np.allclose(matrix_to_euler_zyx(r.as_matrix()), angles, rtol=0.0, atol=1e-12)
    for r in _random_rotations(seed=10):
        assert np.allclose(matrix_to_euler_zyx(r.as_matrix()), r.as_euler('ZYX'), rtol=0.0,
                           atol=1e-12)


def test_euler_zyx_at_gimbal_lock_keeps_the_rotation():
    for pitch in (np.pi / 2, -np.pi / 2):
        R = euler_zyx_to_matrix(0.7, pitch, -0.4)
        yaw, pitch_got, roll = matrix_to_euler_zyx(R)
        assert roll == 0.0 and np.isclose(pitch_got, pitch)
        assert np.allclose(euler_zyx_to_matrix(yaw, pitch_got, roll), R, atol=1e-7)
