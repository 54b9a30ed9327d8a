"""Tests of box geometry, NMS and head decoding against hand-computed values."""

import math

import numpy as np
import pytest
import torch

from uav_tilt_vision.boxes import (PAD_VALUE, box_iou, decode, letterbox, nms, scale_boxes,
                                   unscale_boxes, wh_iou, xywh_to_xyxy, xyxy_to_xywh)


def test_letterbox_camera_frame_is_padded_not_scaled():
    img = np.random.default_rng(0).integers(0, 255, (240, 320, 3), dtype=np.uint8)
    out, scale, pad = letterbox(img, (320, 256))
    assert out.shape == (256, 320, 3) and scale == 1.0 and pad == (0, 8)
    np.testing.assert_array_equal(out[8:248], img)
    assert np.all(out[:8] == PAD_VALUE) and np.all(out[248:] == PAD_VALUE)


def test_letterbox_tall_image_and_box_round_trip():
    img = np.zeros((200, 100, 3), np.uint8)
    out, scale, pad = letterbox(img, (320, 256))
    # scale = min(320/100, 256/200) = 1.28 -> 128x256 content, (320-128)/2 = 96 px each side
    assert out.shape == (256, 320, 3) and scale == pytest.approx(1.28) and pad == (96, 0)
    box = np.array([[10.0, 20.0, 60.0, 180.0]])
    inside = scale_boxes(box, scale, pad)
    np.testing.assert_allclose(inside, [[96 + 12.8, 25.6, 96 + 76.8, 230.4]])
    np.testing.assert_allclose(unscale_boxes(inside, scale, pad, img.shape), box)


def test_unscale_clips_to_image():
    out = unscale_boxes(np.array([[-5.0, 0.0, 330.0, 300.0]]), 1.0, (0, 8), (240, 320))
    np.testing.assert_allclose(out, [[0, 0, 320, 240]])


@pytest.mark.parametrize('lib', [np.asarray, torch.tensor])
def test_box_format_conversions(lib):
    xywh = lib([[10.0, 20.0, 4.0, 6.0]])
    xyxy = xywh_to_xyxy(xywh)
    np.testing.assert_allclose(np.asarray(xyxy), [[8, 17, 12, 23]])
    np.testing.assert_allclose(np.asarray(xyxy_to_xywh(xyxy)), np.asarray(xywh))


@pytest.mark.parametrize('lib', [np.asarray, torch.tensor])
def test_box_iou_hand_cases(lib):
    a = lib([[0.0, 0.0, 2.0, 2.0]])
    b = lib([[1.0, 1.0, 3.0, 3.0], [0.0, 0.0, 2.0, 2.0], [5.0, 5.0, 6.0, 6.0],
             [0.0, 0.0, 1.0, 2.0]])
    # overlap 1 / union 7; identical; disjoint; half-contained 2 / 4
    np.testing.assert_allclose(np.asarray(box_iou(a, b)), [[1 / 7, 1, 0, 0.5]], atol=1e-9)
    # as crowd regions: the share of a inside each, 1 / 4, 1, 0 and 2 / 4
    crowd = lib([True, True, True, True])
    np.testing.assert_allclose(np.asarray(box_iou(a, b, crowd)), [[0.25, 1, 0, 0.5]],
                               atol=1e-9)


def test_wh_iou_hand_case():
    # (2, 2) vs (1, 4): intersection 1 * 2 = 2, union 4 + 4 - 2 = 6
    np.testing.assert_allclose(wh_iou(np.array([[2.0, 2.0]]), np.array([[1.0, 4.0]])), [[1 / 3]])


def brute_force_nms(boxes, scores, classes, thr):
    def iou(p, q):
        iw = max(0.0, min(p[2], q[2]) - max(p[0], q[0]))
        ih = max(0.0, min(p[3], q[3]) - max(p[1], q[1]))
        inter = iw * ih
        return inter / ((p[2] - p[0]) * (p[3] - p[1]) + (q[2] - q[0]) * (q[3] - q[1]) - inter)

    keep = []
    for i in sorted(range(len(boxes)), key=lambda k: -scores[k]):
        if all(classes[k] != classes[i] or iou(boxes[k], boxes[i]) <= thr for k in keep):
            keep.append(i)
    return keep


@pytest.mark.parametrize('seed', range(5))
def test_nms_matches_brute_force(seed):
    rng = np.random.default_rng(seed)
    n = 200
    xy = rng.uniform(0, 100, (n, 2))
    boxes = np.concatenate([xy, xy + rng.uniform(5, 40, (n, 2))], 1)
    scores = rng.uniform(size=n)
    classes = rng.integers(0, 3, n)
    for thr in (0.3, 0.5, 0.7):
        assert nms(boxes, scores, thr, classes).tolist() == \
            brute_force_nms(boxes, scores, classes, thr)
    assert nms(boxes, scores, 0.5).tolist() == brute_force_nms(boxes, scores, [0] * n, 0.5)


def test_nms_class_aware_and_empty():
    boxes = np.array([[0, 0, 10, 10], [1, 1, 10, 10], [1, 1, 10, 10.0]])
    scores = np.array([0.9, 0.8, 0.7])
    assert nms(boxes, scores, 0.5, [0, 0, 1]).tolist() == [0, 2]
    assert nms(np.zeros((0, 4)), np.zeros(0), 0.5).tolist() == []


def logit(p):
    return math.log(p / (1 - p))


def test_decode_hand_case():
    a, c, h, w, stride = 2, 1, 2, 3, 8
    anchors = [[10.0, 20.0], [4.0, 4.0]]
    head = np.zeros((a * (5 + c), h, w), np.float32)
    # anchor 1, row 1, col 2: sig(tx) = 0.75 -> offset 2*0.75 - 0.5 = 1.0 cell;
    # sig(tw) = 0.25 -> w = (2*0.25)^2 * 4 = 1; sig(th) = 0.75 -> h = 1.5^2 * 4 = 9
    head[6 + 0, 1, 2] = logit(0.75)
    head[6 + 2, 1, 2] = logit(0.25)
    head[6 + 3, 1, 2] = logit(0.75)
    head[6 + 4, 1, 2] = logit(0.9)
    out = decode(head, anchors, stride)
    assert out.shape == (a * h * w, 5 + c)
    # all-zero logits: centre = (cell + 0.5) * stride, size = anchor; anchor 0, row 1, col 2
    np.testing.assert_allclose(out[1 * w + 2], [15, 2, 25, 22, 0.5, 0.5], atol=1e-5)
    cx, cy = (2 + 1.0) * 8, (1 + 0.5) * 8
    expected = [cx - 0.5, cy - 4.5, cx + 0.5, cy + 4.5, 0.9, 0.5]
    np.testing.assert_allclose(out[h * w + 1 * w + 2], expected, atol=1e-5)
    # an objectness threshold keeps exactly the cells above it (here the one at 0.9)
    np.testing.assert_allclose(decode(head, anchors, stride, min_obj=0.6), [expected],
                               atol=1e-5)


def test_decode_threshold_keeps_the_rows_above_it_in_order():
    rng = np.random.default_rng(3)
    anchors = [[10.0, 20.0], [4.0, 4.0], [30.0, 25.0]]
    head = rng.normal(0, 3, (3 * 8, 5, 7)).astype(np.float32)
    full = decode(head, anchors, 16)
    for min_obj in (0.1, 0.5, 0.95):
        np.testing.assert_array_equal(decode(head, anchors, 16, min_obj),
                                      full[full[:, 4] > min_obj])
