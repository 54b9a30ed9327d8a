"""KLT box tracker on a textured object moving over a static wall."""
import cv2
import numpy as np
import pytest

from uav_tilt_common.config import ConfigError, from_dict
from uav_tilt_sim.textures import object_texture, wall_texture
from uav_tilt_vision.klt_tracker import KltBoxTracker, KltConfig

W, H = 320, 240
SIDE_PX = 80.0


def _iou(a, b):
    ix = max(0.0, min(a[2], b[2]) - max(a[0], b[0]))
    iy = max(0.0, min(a[3], b[3]) - max(a[1], b[1]))
    inter = ix * iy
    return inter / ((a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter)


def _frames(rng, cls, shift_px, scale_step, rot_step_deg, n=11):
    """Object texture under a known similarity per frame; yields (gray, true box)."""
    tex = object_texture(cls, rng, 128)
    wall = cv2.resize(wall_texture(rng, 512, 'concrete'), (W, H))
    c0 = np.array([140.0, 110.0])
    for k in range(n):
        s = SIDE_PX / tex.shape[0] * scale_step ** k
        c = c0 + k * np.asarray(shift_px)
        m = cv2.getRotationMatrix2D((0.0, 0.0), rot_step_deg * k, s)
        m[:, 2] = c - m[:, :2] @ np.array([tex.shape[1] - 1, tex.shape[0] - 1]) / 2.0
        obj = cv2.warpAffine(tex, m, (W, H), flags=cv2.INTER_LINEAR)
        inside = cv2.warpAffine(np.full(tex.shape[:2], 255, np.uint8), m, (W, H))
        img = np.where(inside[..., None] > 127, obj, wall)
        half = SIDE_PX * scale_step ** k / 2.0
        yield cv2.cvtColor(img, cv2.COLOR_RGB2GRAY), np.r_[c - half, c + half]


@pytest.mark.parametrize('cls,shift,scale,rot', [
    ('gauge', (3.0, -2.0), 1.03, 0.8),
    ('hazard_sign', (-2.5, 1.5), 0.98, -1.0),
    ('bolt_plate', (4.0, 2.0), 1.02, 0.5),
])
def test_tracks_similarity_motion_with_iou_above_0p8(cls, shift, scale, rot):
    frames = _frames(np.random.default_rng(5), cls, shift, scale, rot)
    gray0, box0 = next(frames)
    tracker = KltBoxTracker()
    assert tracker.init(gray0, box0)
    for gray, box_true in frames:
        box, quality = tracker.update(gray)
        assert box is not None and not tracker.lost
        assert 0.0 < quality <= 1.0
        assert _iou(box, box_true) >= 0.8


def test_noise_frame_loses_target_and_stays_lost():
    rng = np.random.default_rng(1)
    frames = _frames(rng, 'gauge', (2.0, 0.0), 1.0, 0.0, n=2)
    gray0, box0 = next(frames)
    tracker = KltBoxTracker()
    assert tracker.init(gray0, box0)
    noise = rng.integers(0, 256, (H, W), dtype=np.uint8)
    assert tracker.update(noise) == (None, 0.0)
    assert tracker.lost
    assert tracker.update(next(frames)[0]) == (None, 0.0)


def test_featureless_box_cannot_init():
    tracker = KltBoxTracker()
    assert not tracker.init(np.full((H, W), 90, np.uint8), (100, 80, 180, 160))
    assert tracker.lost and tracker.update(np.full((H, W), 90, np.uint8)) == (None, 0.0)


def test_config_is_validated():
    assert from_dict(KltConfig, {'min_points': 12}).min_points == 12
    with pytest.raises(ConfigError):
        from_dict(KltConfig, {'fb_max_error_px': -1.0})
