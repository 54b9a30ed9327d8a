"""Procedural textures: determinism, class distinctness, bolt head at POI_UV."""
import cv2
import numpy as np
import pytest

from uav_tilt_sim.textures import (BOLT_HEAD_DIAMETER_FRAC, OBJECT_CLASSES, POI_UV,
                                   WALL_FAMILIES, object_texture,
                                   wall_texture)


def _all(seed):
    rng = np.random.default_rng(seed)
    return ([object_texture(c, rng, 128) for c in OBJECT_CLASSES]
            + [wall_texture(rng, 128, f) for f in WALL_FAMILIES])


def test_same_seed_same_textures_and_other_seed_differs():
    a, b, c = _all(3), _all(3), _all(4)
    for ta, tb, tc in zip(a, b, c):
        assert ta.dtype == np.uint8 and ta.shape == (128, 128, 3)
        assert np.array_equal(ta, tb)
        assert not np.array_equal(ta, tc)


def test_unknown_class_rejected():
    with pytest.raises(ValueError):
        object_texture('teapot', np.random.default_rng(0))


def _features(img):
    hsv = cv2.cvtColor(img, cv2.COLOR_RGB2HSV)
    sat = hsv[..., 1] > 100
    yellow = np.mean(sat & (np.abs(hsv[..., 0].astype(int) - 27) < 8))
    gray = cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)
    return np.array([yellow, np.mean(gray < 60), gray.mean() / 255.0])


def test_classes_are_distinct_across_randomisation():
    rng = np.random.default_rng(11)
    feats = {c: np.array([_features(object_texture(c, rng)) for _ in range(10)])
             for c in OBJECT_CLASSES}
    # Hazard signs are largely saturated yellow; the others have almost none.
    assert feats['hazard_sign'][:, 0].min() > 0.15
    assert feats['bolt_plate'][:, 0].max() < 0.02 and feats['gauge'][:, 0].max() < 0.02
    # Only the gauge has a large dark ring; a plate's dark area is its head (~2 %).
    assert feats['gauge'][:, 1].min() > 2.0 * feats['bolt_plate'][:, 1].max()
    head_area = 3.0 * np.sqrt(3.0) / 2.0 * (BOLT_HEAD_DIAMETER_FRAC / 2.0) ** 2
    assert np.all(np.abs(feats['bolt_plate'][:, 1] - head_area) < 0.5 * head_area)


@pytest.mark.parametrize('seed', range(5))
def test_bolt_head_is_dark_and_centred_at_poi(seed):
    size = 256
    img = object_texture('bolt_plate', np.random.default_rng(seed), size)
    gray = cv2.cvtColor(img, cv2.COLOR_RGB2GRAY).astype(np.float32)
    u, v = POI_UV['bolt_plate']
    col, row = u * size - 0.5, v * size - 0.5
    r_px = BOLT_HEAD_DIAMETER_FRAC * size / 2.0
    yy, xx = np.mgrid[0:size, 0:size]
    dist = np.hypot(xx - col, yy - row)
    head = gray[dist < 0.8 * r_px * np.cos(np.pi / 6)]  # inside the hexagon's incircle
    plate = gray[(dist > 2.0 * r_px) & (dist < 0.3 * size)]
    assert head.mean() < 0.4 * plate.mean()
    dark = (gray < 0.5 * (head.mean() + plate.mean())) & (dist < 1.5 * r_px)
    # The dark blob is point-symmetric about the POI: its centroid is there to a tenth
    # of a pixel (anti-aliased edges and pixel noise only).
    assert abs(xx[dark].mean() - col) < 0.1 and abs(yy[dark].mean() - row) < 0.1
