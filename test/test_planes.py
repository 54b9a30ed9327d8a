"""Tests for the planes of a depth image (uav_tilt_vision.planes) and their wire format
(uav_tilt_common.planes, vision/planes)."""
import numpy as np
import pytest

from uav_tilt_common import ros_msgs
from uav_tilt_common.planes import Plane, planes_from_array, planes_to_array
from uav_tilt_vision.planes import PlaneConfig, find_planes
from uav_tilt_vision.target_pose import CameraIntrinsics

K = CameraIntrinsics(277.0, 277.0, 160.0, 120.0, 320, 240)   # the plant's camera
FRESH = np.random.SeedSequence().entropy     # new worlds every run


def _rays():
    vv, uu = np.mgrid[0:K.height, 0:K.width]
    return np.stack([(uu - K.cx) / K.fx, (vv - K.cy) / K.fy, np.ones(uu.shape)], axis=-1)


def _render(planes_cam, k_noise, rng, max_m=np.inf):
    """Depth (optical z) of the nearest of ``planes_cam`` ((n, offset): n.x = offset, n
    towards the camera) hit by each pixel's ray; which plane each pixel sees (-1: none)."""
    rays = _rays()
    depth = np.full(rays.shape[:2], np.inf)
    which = np.full(rays.shape[:2], -1)
    for i, (n, offset) in enumerate(planes_cam):
        nd = rays @ n
        with np.errstate(divide='ignore', invalid='ignore'):
            t = np.where(nd < -1e-9, offset / nd, np.inf)
        nearer = (t > 0) & (t < depth) & (t <= max_m)
        depth[nearer], which[nearer] = t[nearer], i
    seen = np.isfinite(depth)
    depth[seen] += k_noise * depth[seen] ** 2 * rng.standard_normal(int(seen.sum()))
    return depth.astype(np.float32), which


def _wall_and_ground(rng):
    """A camera 0.8-2.5 m above the ground looking level at a wall 2-5 m ahead, yawed up to
    40 degrees, leaning up to 25 degrees either way (camera optical frame: y down)."""
    yaw, lean = np.radians(rng.uniform(-40, 40)), np.radians(rng.uniform(-25, 25))
    n_wall = np.array([np.sin(yaw) * np.cos(lean), np.sin(lean), -np.cos(yaw) * np.cos(lean)])
    distance = rng.uniform(2.0, 5.0)
    n_ground = np.array([0.0, -1.0, 0.0])
    height = rng.uniform(0.8, 2.5)
    # n.x = offset for the plane's points x; the camera (origin) is on the side n points to
    return [(n_wall, -distance), (n_ground, -height)]


@pytest.mark.parametrize('draw', range(6))
def test_the_wall_and_the_ground_are_found_with_their_shares(draw):
    rng = np.random.default_rng([FRESH, draw])
    truth = _wall_and_ground(rng)
    k_noise = rng.uniform(0.0, 0.003)       # the campaign's depth noise
    depth, which = _render(truth, k_noise, rng, max_m=PlaneConfig().max_range_m)
    cfg = PlaneConfig()
    found = find_planes(depth, K, cfg)
    g = slice(cfg.stride_px // 2, None, cfg.stride_px)
    grid, z, rays = which[g, g], depth[g, g].astype(float), _rays()[g, g]
    shares = np.array([np.mean(grid == i) for i in range(len(truth))])
    # a sample within the depth band of both planes (where they meet) may go to either
    band = cfg.band_m + cfg.band_per_m2 * z ** 2
    with np.errstate(invalid='ignore'):
        near = [np.abs((rays * z[..., None]) @ n - offset) <= band for n, offset in truth]
    either = float(np.mean(near[0] & near[1] & (grid >= 0)))
    matched = set()
    for plane in found:
        angles = [np.degrees(np.arccos(min(plane.normal_cam @ n, 1.0))) for n, _ in truth]
        i = int(np.argmin(angles))
        n, offset = truth[i]
        # the normal within 2 degrees, the centroid on the plane within the noise band
        assert angles[i] < 2.0 and i not in matched, (FRESH, draw)
        matched.add(i)
        zc = plane.point_cam[2]
        assert abs(plane.point_cam @ n - offset) < cfg.band_m + cfg.band_per_m2 * zc ** 2
        assert plane.share == pytest.approx(shares[i], abs=either + 0.01), (FRESH, draw)
    missed = [shares[i] for i in range(len(truth)) if i not in matched]
    assert all(share < cfg.min_share + either + 0.01 for share in missed), (FRESH, draw)
    assert [p.share for p in found] == sorted((p.share for p in found), reverse=True)


def test_nothing_in_view_or_in_range_gives_no_plane():
    assert find_planes(np.full((K.height, K.width), np.inf, np.float32), K) == []
    far = [(np.array([0.0, 0.0, -1.0]), -20.0)]
    depth, _ = _render(far, 0.0, np.random.default_rng(0))
    assert find_planes(depth, K) == []
    assert len(find_planes(depth, K, PlaneConfig(max_range_m=30.0))) == 1


def test_a_small_plane_is_not_a_plane():
    # a panel filling 5% of the frame in front of nothing
    depth = np.full((K.height, K.width), np.inf, np.float32)
    depth[100:130, 140:180] = 1.5
    assert find_planes(depth, K) == []
    assert len(find_planes(depth, K, PlaneConfig(min_share=0.01))) == 1


def test_planes_cross_the_wire_and_bad_ones_are_refused():
    planes = [Plane(np.array([0.1, -0.2, 3.0]), np.array([0.0, 0.6, -0.8]), 0.4),
              Plane(np.array([0.0, 1.5, 4.0]), np.array([0.0, -1.0, 0.0]), 0.25)]
    back = ros_msgs.planes_of_msg(ros_msgs.planes_msg(planes, ros_msgs.to_stamp(1.5)))
    assert len(back) == 2
    for a, b in zip(planes, back):
        np.testing.assert_allclose(b.point_cam, a.point_cam, rtol=1e-6)
        np.testing.assert_allclose(b.normal_cam, a.normal_cam, rtol=1e-6)
        assert b.share == pytest.approx(a.share)
    assert ros_msgs.planes_of_msg(ros_msgs.planes_msg([], ros_msgs.to_stamp(0.0))) == []
    rows = planes_to_array(planes)
    for bad in ({0: np.nan}, {3: 0.5}, {6: 1.5}):
        broken = rows.copy()
        for col, value in bad.items():
            broken[0, col] = value
        with pytest.raises(ValueError):
            planes_from_array(broken)
    candidates = ros_msgs.candidates_msg([], ros_msgs.to_stamp(0.0))
    with pytest.raises(ValueError, match='layout'):
        ros_msgs.planes_of_msg(candidates)
    # the right fields at other offsets (a reader by name would take them in another order)
    shuffled = ros_msgs.planes_msg(planes, ros_msgs.to_stamp(1.5))
    for field, offset in zip(shuffled.fields, reversed([f.offset for f in shuffled.fields])):
        field.offset = offset
    with pytest.raises(ValueError, match='offsets'):
        ros_msgs.planes_of_msg(shuffled)
