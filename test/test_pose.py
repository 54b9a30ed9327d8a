"""The pose type: composition, inverse and application agree with the matrices they stand
for, on random poses."""
import numpy as np
from scipy.spatial.transform import Rotation

from uav_tilt_common.pose import Pose


def _random_pose(rng):
    return Pose(Rotation.random(random_state=rng).as_matrix(), rng.normal(size=3) * 5)


def _matrix(pose):
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = pose.R, pose.p
    return T


def test_compose_inverse_and_apply_match_homogeneous_matrices():
    rng = np.random.default_rng()
    for _ in range(50):
        a_b, b_c = _random_pose(rng), _random_pose(rng)
        np.testing.assert_allclose(_matrix(a_b @ b_c), _matrix(a_b) @ _matrix(b_c), atol=1e-12)
        np.testing.assert_allclose(_matrix(a_b.inverse()), np.linalg.inv(_matrix(a_b)),
                                   atol=1e-10)
        x = rng.normal(size=3)
        np.testing.assert_allclose(a_b.apply(x), (_matrix(a_b) @ [*x, 1.0])[:3], atol=1e-12)
        np.testing.assert_allclose(a_b.rotate(x), a_b.R @ x, atol=1e-12)
        np.testing.assert_allclose((a_b @ a_b.inverse()).R, np.eye(3), atol=1e-12)
        np.testing.assert_allclose((a_b @ a_b.inverse()).p, np.zeros(3), atol=1e-12)


def test_from_quat_is_scipys_rotation():
    rng = np.random.default_rng()
    q = Rotation.random(random_state=rng).as_quat()
    pose = Pose.from_quat(q, [1.0, 2.0, 3.0])
    np.testing.assert_allclose(pose.R, Rotation.from_quat(q).as_matrix(), atol=1e-12)
    np.testing.assert_allclose(Pose.identity().apply(pose.p), [1.0, 2.0, 3.0])
