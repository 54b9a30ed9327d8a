"""Tests of the YOLOv3-tiny family detector, save/load, predict mapping and the profiler."""

import json
import math

import numpy as np
import pytest
import torch
from torch import nn

from uav_tilt_vision.training import cli as vision_cli
from uav_tilt_vision.detector import REF_CHANNELS, Detector, load_model, save_model
from uav_tilt_vision.training.profile import profile_model

torch.set_num_threads(2)

INPUT = (1, 3, 256, 320)


@pytest.mark.parametrize('scales', [2, 3, 4])
def test_head_shapes_for_camera_input(scales):
    model = Detector(num_classes=3, width_mult=0.25, scales=scales)
    heads = model(torch.zeros(2, 3, 256, 320))
    # 3 anchors * (5 + 3 classes) = 24 channels; grids 320/s x 256/s for s = 32, 16 (, 8, 4)
    expect = [(2, 24, 8, 10), (2, 24, 16, 20), (2, 24, 32, 40), (2, 24, 64, 80)][:scales]
    assert [tuple(h.shape) for h in heads] == expect
    assert model.strides == (32, 16, 8, 4)[:scales] and len(model.heads) == scales


def test_reference_yolov3_tiny_architecture():
    model = Detector(num_classes=80, width_mult=1.0)
    assert model.channels() == list(REF_CHANNELS)
    n = sum(p.numel() for p in model.parameters())
    assert abs(n - 8.7e6) / 8.7e6 < 0.02
    # the stride-8 branch of yolov3-tiny_3l.cfg: 1x1 256->128, 3x3 (128+128)->128, head
    three = Detector(num_classes=80, width_mult=1.0, scales=3)
    assert three.channels() == list(REF_CHANNELS) + [128, 128]
    extra = 256 * 128 + 256 * 128 * 9 + 128 * 255 + 255 + 4 * 128
    assert sum(p.numel() for p in three.parameters()) == n + extra
    # the stride-4 branch, built the same way on the stride-4 route (c2, 64 channels)
    four = Detector(num_classes=80, width_mult=1.0, scales=4)
    assert four.channels() == list(REF_CHANNELS) + [128, 128, 64, 64]
    extra4 = 128 * 64 + (64 + 64) * 64 * 9 + 64 * 255 + 255 + 4 * 64
    assert sum(p.numel() for p in four.parameters()) == n + extra + extra4


def test_deployed_width_cuts_macs_at_least_4x():
    ref = profile_model(Detector(3, 1.0), INPUT)
    small = profile_model(Detector(3, 0.25), INPUT)
    assert small['macs'] * 4 <= ref['macs']


def test_wrong_channel_list_or_scales_are_rejected():
    with pytest.raises(ValueError):
        Detector(3, channels=[8] * 10)
    with pytest.raises(ValueError):
        Detector(3, channels=[8] * 11, scales=3)
    with pytest.raises(ValueError):
        Detector(3, scales=5)


@pytest.mark.parametrize('scales', [2, 3, 4])
def test_save_load_round_trip_with_irregular_channels(tmp_path, scales, half_rounded):
    torch.manual_seed(0)
    channels = [5, 11, 13, 29, 37, 45, 70, 21, 33, 9, 27, 12, 14, 7, 6][:7 + 2 * scales]
    anchors = [[[40, 30], [60, 70], [100, 90]], [[8, 9], [15, 20], [25, 27]],
               [[4, 5], [6, 7], [8, 8]], [[2, 3], [3, 3], [4, 4]]][:scales]
    model = Detector(num_classes=2, channels=channels, anchors=anchors, img_size=(320, 256),
                     scales=scales)
    model.train()
    model(torch.rand(4, 3, 256, 320))  # move BN running statistics away from their defaults
    model.eval()
    path = tmp_path / 'pruned.pt'
    save_model(path, model, {'note': 'pruned'})
    loaded = load_model(path)
    assert loaded.channels() == channels and loaded.meta == {'note': 'pruned'}
    assert all(v.dtype == torch.float32 for v in loaded.state_dict().values()
               if v.is_floating_point())
    half_rounded(model)     # the weights are stored in half precision
    x = torch.rand(2, 3, 256, 320)
    with torch.no_grad():
        for a, b in zip(model(x), loaded(x)):
            assert torch.equal(a, b)


def test_predict_maps_a_known_detection_to_original_pixels():
    anchors = [[[40, 30], [60, 70], [100, 90]], [[10, 12], [15, 20], [25, 27]]]
    model = Detector(num_classes=1, width_mult=0.25, anchors=anchors)
    k = 6  # 5 + 1 class
    head0 = torch.full((1, 3 * k, 8, 10), -10.0)
    head1 = torch.full((1, 3 * k, 16, 20), -10.0)
    # anchor 0 of the stride-16 head, row 5, col 7: zero box logits give centre
    # (cell + 0.5) * 16 = (120, 88) and size = anchor (10, 12) in the 320x256 input
    head1[0, 0:4, 5, 7] = 0.0
    head1[0, 4:6, 5, 7] = 10.0
    model.forward = lambda x: [head0.expand(len(x), -1, -1, -1),
                               head1.expand(len(x), -1, -1, -1)]
    img = np.zeros((480, 640, 3), np.uint8)  # letterbox: scale 0.5, 8 px band top
    dets = model.predict([img, img], conf_thres=0.5, iou_thres=0.5)
    assert len(dets) == 2
    score = (1 / (1 + math.exp(-10))) ** 2  # objectness * class probability
    for d in dets:
        assert d.shape == (1, 6)
        # centre (120 / 0.5, (88 - 8) / 0.5) = (240, 160), size (20, 24)
        np.testing.assert_allclose(d[0], [230, 148, 250, 172, score, 0], rtol=1e-5, atol=1e-3)
    assert len(model.predict(img, conf_thres=0.5)) == 1


def test_profile_hand_counted_model():
    model = nn.Sequential(nn.Conv2d(3, 4, 3, padding=1, bias=False), nn.BatchNorm2d(4),
                          nn.ReLU(), nn.Conv2d(4, 2, 1))
    prof = profile_model(model, (2, 3, 8, 8))
    bt = prof['by_type']
    # params: 4*3*9 = 108; BN 2*4 = 8; 1x1 2*4 + 2 = 10
    assert [bt[t]['params'] for t in ('conv3x3', 'bn', 'conv1x1', 'other')] == [108, 8, 10, 0]
    # per-image MACs: 64 px * 4 out * 27; 64 * 4; 64 * 2 * 4
    assert [bt[t]['macs'] for t in ('conv3x3', 'bn', 'conv1x1', 'other')] == [6912, 256, 512, 0]
    assert prof['params'] == 126 and prof['macs'] == 7680
    assert bt['conv3x3']['macs_share'] == pytest.approx(6912 / 7680)


def test_profile_totals_cover_the_whole_detector():
    model = Detector(3, 0.5)
    prof = profile_model(model, INPUT)
    assert prof['params'] == sum(p.numel() for p in model.parameters())
    assert sum(v['params_share'] for v in prof['by_type'].values()) == pytest.approx(1.0)
    assert sum(v['macs_share'] for v in prof['by_type'].values()) == pytest.approx(1.0)


def test_profile_cli_reports_the_references_and_the_given_models(tmp_path, capsys):
    path = tmp_path / 'm.pt'
    save_model(path, Detector(3, 0.25, scales=3))
    assert vision_cli.main(['profile', '--model', str(path)]) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out) == {'yolov3_tiny_ref_80cls', 'yolov3_tiny_3l_ref_80cls', str(path)}
    # 3x3 weights of yolov3-tiny counted from its channel table: c0..c6, c8 (on c7), and
    # c10 (on the upsampled c9 concatenated with c4)
    c = REF_CHANNELS
    ins = [3, *c[:6], c[7], c[9] + c[4]]
    outs = [*c[:7], c[8], c[10]]
    w3x3 = sum(9 * i * o for i, o in zip(ins, outs))
    ref = out['yolov3_tiny_ref_80cls']
    assert ref['by_type']['conv3x3']['params'] == w3x3
    assert ref['by_type']['conv3x3']['params_share'] == pytest.approx(w3x3 / ref['params'])
    for summary in out.values():
        assert sum(v['macs_share'] for v in summary['by_type'].values()) == pytest.approx(1.0)
