"""The rendered camera follows the pinhole model of camera_info (K) to a tenth of a pixel."""
import numpy as np
import pybullet as p
import pytest

from uav_tilt_sim import camera


@pytest.fixture
def client():
    cid = p.connect(p.DIRECT)
    yield cid
    p.disconnect(cid)


def test_spheres_render_where_the_intrinsics_project_them(client):
    cam = camera.CameraConfig()
    R_map_cam = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    rng = np.random.default_rng(3)
    errors = []
    for _ in range(12):
        u, v, depth = rng.uniform(40, 280), rng.uniform(40, 200), rng.uniform(0.8, 2.0)
        p_cam = np.array([(u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, 1.0]) * depth
        visual = p.createVisualShape(p.GEOM_SPHERE, radius=0.03 * depth,
                                     physicsClientId=client)
        body = p.createMultiBody(0, -1, visual, (R_map_cam @ p_cam).tolist(),
                                 physicsClientId=client)
        _, depth_img, seg = camera.render(client, cam, np.zeros(3), R_map_cam,
                                          segmentation=True)
        rows, cols = np.nonzero(seg == body)
        errors.append((cols.mean() - u, rows.mean() - v))
        # Metric depth: the sphere's nearest point is its centre's depth minus the radius.
        assert depth_img[rows, cols].min() == pytest.approx(depth * 0.97, rel=0.01)
        p.removeBody(body, physicsClientId=client)
    assert np.all(np.abs(np.mean(errors, axis=0)) < 0.1)
