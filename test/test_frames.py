"""Tests for uav_tilt_control.frames."""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from uav_tilt_common.pose import Pose
from uav_tilt_common.vehicle import VehicleParams
from uav_tilt_control import frames

TOL = 1e-12


def _assert_rotation(R):
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=TOL)
    assert np.linalg.det(R) == pytest.approx(1.0, abs=TOL)


def test_camera_axes_zero_pitch():
    vehicle = VehicleParams(camera_pitch_rad=0.0)
    camera = vehicle.camera_in_base()
    R_base_cam, p_base_cam = camera.R, camera.p
    _assert_rotation(R_base_cam)
    # columns are the optical axes expressed in FLU
    np.testing.assert_allclose(R_base_cam[:, 2], [1, 0, 0], atol=TOL)
    np.testing.assert_allclose(R_base_cam[:, 0], [0, -1, 0], atol=TOL)
    np.testing.assert_allclose(R_base_cam[:, 1], [0, 0, -1], atol=TOL)
    np.testing.assert_allclose(p_base_cam, vehicle.camera_xyz_m, atol=TOL)


def test_camera_pitched_down_looks_down():
    pitch = 0.3
    R_base_cam = VehicleParams(camera_pitch_rad=pitch).camera_in_base().R
    _assert_rotation(R_base_cam)
    np.testing.assert_allclose(R_base_cam[:, 2], [np.cos(pitch), 0, -np.sin(pitch)], atol=TOL)
    # the right axis does not change with pitch
    np.testing.assert_allclose(R_base_cam[:, 0], [0, -1, 0], atol=TOL)


@pytest.mark.parametrize('normal', [
    [-1, 0, 0], [0, 1, 0], [0.6, -0.8, 0], [-0.7, 0.1, 0.4], [0, 0, 1], [0, 0, -1],
    [1e-9, 0, 1],
])
def test_target_frame_orthonormal_and_oriented(normal):
    p_poi = np.array([3.0, -1.0, 1.5])
    R_map_t, origin = frames.target_frame_from_normal(p_poi, normal)
    _assert_rotation(R_map_t)
    np.testing.assert_allclose(R_map_t[:, 2], np.asarray(normal) / np.linalg.norm(normal),
                               atol=TOL)
    np.testing.assert_allclose(origin, p_poi)
    assert abs(R_map_t[2, 0]) < 1e-6           # x_t horizontal
    assert R_map_t[2, 1] >= -1e-12               # y_t never points down


def test_target_frame_vertical_wall_y_is_up():
    R_map_t, _ = frames.target_frame_from_normal(np.zeros(3), [-1.0, 0.0, 0.0])
    np.testing.assert_allclose(R_map_t[:, 1], [0, 0, 1], atol=TOL)


def test_target_frame_vertical_normal_is_deterministic():
    R_map_t, _ = frames.target_frame_from_normal(np.zeros(3), [0.0, 0.0, 2.0])
    np.testing.assert_allclose(R_map_t, np.eye(3), atol=TOL)


def test_target_frame_rejects_zero_normal():
    with pytest.raises(ValueError):
        frames.target_frame_from_normal(np.zeros(3), [0.0, 0.0, 0.0])


@pytest.mark.parametrize('normal', [[-1, 0, 0], [0, -1, 0], [0.6, 0.8, 0.0], [-0.5, 0.5, 0.7]])
def test_yaw_facing_points_body_x_into_wall(normal):
    n = np.asarray(normal, dtype=float)
    yaw = frames.yaw_facing(n)
    x_flu_map = Rotation.from_euler('z', yaw).apply([1.0, 0.0, 0.0])
    n_h = n.copy()
    n_h[2] = 0.0
    np.testing.assert_allclose(x_flu_map, -n_h / np.linalg.norm(n_h), atol=TOL)


def test_yaw_facing_vertical_normal_uses_default():
    assert frames.yaw_facing([0.0, 0.0, 1.0], default_rad=0.7) == 0.7


def test_pitch_facing_aligns_tool_with_inclined_normal():
    n = frames.unit([-1.0, 0.0, 0.3])
    R_map_base = Rotation.from_euler(
        'ZY', [frames.yaw_facing(n), frames.pitch_facing(n)]).as_matrix()
    np.testing.assert_allclose(R_map_base[:, 0], -n, atol=TOL)


@pytest.mark.parametrize('yaw, pitch', [(0.0, 0.0), (2.5, 0.4), (-1.2, -0.7), (3.1, 1.2)])
def test_tool_direction_is_body_x_at_that_heading_and_pitch(yaw, pitch):
    R_map_base = Rotation.from_euler('ZY', [yaw, pitch]).as_matrix()
    np.testing.assert_allclose(frames.tool_direction(yaw, pitch), R_map_base[:, 0], atol=TOL)


def test_to_frame_undoes_a_pose():
    R_a_b = Rotation.from_euler('zyx', [0.3, -0.2, 0.1]).as_matrix()
    p_a_b, x_b = np.array([1.0, 2.0, 3.0]), np.array([-0.5, 0.2, 0.1])
    x_a = Pose(R_a_b, p_a_b).apply(x_b)
    np.testing.assert_allclose(frames.to_frame(R_a_b, p_a_b, x_a), x_b, atol=TOL)


def test_wrap_angle():
    assert frames.wrap_angle(3 * np.pi / 2) == pytest.approx(-np.pi / 2)
    assert frames.wrap_angle(-0.1) == pytest.approx(-0.1)
