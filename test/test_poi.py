"""find_poi on bolt plates rendered in perspective over random walls."""
import cv2
import numpy as np
import pytest

from uav_tilt_sim.textures import POI_UV, object_texture, wall_texture
from uav_tilt_vision.poi import find_poi

W, H = 320, 240
F_PX = 277.0
SS = 4  # render supersampling, then area-downsampled like a camera's pixel integration


def _rot(yaw, pitch):
    cy, sy, cp, sp = np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch)
    r_y = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    r_x = np.array([[1, 0, 0], [0, cp, -sp], [0, sp, cp]])
    return r_y @ r_x


def _render(rng, cls, side_px, yaw, pitch, offset_px=(0.0, 0.0)):
    """Panel texture seen by a pinhole camera; returns image, panel bbox, projected POI."""
    tex = object_texture(cls, rng, 256)
    s = tex.shape[0]
    side_m = 0.2
    z_m = F_PX * side_m / side_px
    cx, cy = (W - 1) / 2.0 + offset_px[0], (H - 1) / 2.0 + offset_px[1]
    k_ss = np.array([[F_PX * SS, 0, (cx + 0.5) * SS - 0.5],
                     [0, F_PX * SS, (cy + 0.5) * SS - 0.5], [0, 0, 1]])
    # Panel frame: x right, y up, z out of the wall; the camera looks at its centre.
    r_cam_panel = np.diag([1.0, -1.0, -1.0]) @ _rot(yaw, pitch)
    t = np.array([0.0, 0.0, z_m])
    # Texture pixel index (c, r) -> panel metres (x right, y up).
    a = np.array([[side_m / s, 0, side_m * (0.5 / s - 0.5)],
                  [0, -side_m / s, side_m * (0.5 - 0.5 / s)], [0, 0, 1]])
    h_ss = k_ss @ np.column_stack([r_cam_panel[:, 0], r_cam_panel[:, 1], t]) @ a
    size = (W * SS, H * SS)
    warped = cv2.warpPerspective(tex, h_ss, size, flags=cv2.INTER_LINEAR)
    inside = cv2.warpPerspective(np.full(tex.shape[:2], 255, np.uint8), h_ss, size)
    wall = cv2.resize(wall_texture(rng, 512), size, interpolation=cv2.INTER_LINEAR)
    img_ss = np.where(inside[..., None] > 127, warped, wall)
    img = cv2.resize(img_ss, (W, H), interpolation=cv2.INTER_AREA).astype(np.float32)
    img = cv2.GaussianBlur(img, (0, 0), 0.7) + rng.normal(0, 3.0, img.shape)
    img = np.clip(img, 0, 255).astype(np.uint8)
    corners = np.array([[-0.5, -0.5, 1], [s - 0.5, -0.5, 1], [s - 0.5, s - 0.5, 1],
                        [-0.5, s - 0.5, 1]]).T
    proj = h_ss @ corners
    proj = (proj[:2] / proj[2] + 0.5) / SS - 0.5
    box = np.array([proj[0].min(), proj[1].min(), proj[0].max(), proj[1].max()])
    poi_tex = np.array([POI_UV.get(cls, (0.5, 0.5))[0] * s - 0.5,
                        POI_UV.get(cls, (0.5, 0.5))[1] * s - 0.5, 1.0])
    p = h_ss @ poi_tex
    poi = (p[:2] / p[2] + 0.5) / SS - 0.5
    return img, box, poi


# 18 px (frontal): a 0.25 m plate 4 m away, its bolt head under 3 px across
CASES = [(side, yaw, pitch) for side in (22, 30, 60, 120, 200)
         for yaw, pitch in ((0.0, 0.0), (45.0, 0.0), (-30.0, 25.0), (20.0, -40.0))] + [
    (18, 0.0, 0.0)]


@pytest.mark.parametrize('side_px,yaw_deg,pitch_deg', CASES)
def test_poi_on_bolt_plate_within_1p5_px(side_px, yaw_deg, pitch_deg):
    rng = np.random.default_rng(side_px * 1000 + int(yaw_deg) * 10 + int(pitch_deg))
    offset = rng.uniform(-20, 20, 2)
    img, box, poi_true = _render(rng, 'bolt_plate', side_px, np.deg2rad(yaw_deg),
                                 np.deg2rad(pitch_deg), offset)
    # A detector box is a little loose or tight around the panel.
    box = box + rng.uniform(-0.05, 0.05, 4) * (box[2] - box[0])
    found = find_poi(img, box)
    assert found is not None
    u, v, score = found
    assert np.hypot(u - poi_true[0], v - poi_true[1]) < 1.5
    assert 0.0 < score <= 1.0


@pytest.mark.parametrize('seed', range(8))
def test_no_poi_on_gauge_or_hazard_sign(seed):
    rng = np.random.default_rng(100 + seed)
    cls = 'gauge' if seed % 2 == 0 else 'hazard_sign'
    img, box, _ = _render(rng, cls, [18, 40, 80, 160][seed % 4], np.deg2rad(rng.uniform(-40, 40)),
                          np.deg2rad(rng.uniform(-20, 20)))
    assert find_poi(img, box) is None


@pytest.mark.parametrize('family', ['concrete', 'bricks', 'painted_panels', 'stripes'])
def test_no_poi_on_plain_wall(family):
    rng = np.random.default_rng(7)
    for _ in range(5):
        wall = cv2.resize(wall_texture(rng, 512, family), (W, H), interpolation=cv2.INTER_AREA)
        side = rng.uniform(15, 150)
        x0, y0 = rng.uniform(0, W - side), rng.uniform(0, H - side)
        assert find_poi(wall, (x0, y0, x0 + side, y0 + side)) is None


def test_degenerate_box_gives_none():
    img = np.full((H, W, 3), 128, np.uint8)
    assert find_poi(img, (10, 10, 12, 12)) is None
    assert find_poi(img, (W + 5, H + 5, W + 50, H + 50)) is None
    assert find_poi(img, (W - 10, H - 10, W + 100, H + 100)) is None
