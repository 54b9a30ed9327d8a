"""Pruning, ONNX export, int8 quantization and the backend loader on small models."""

import json

import cv2
import numpy as np
import onnx
import onnxruntime as ort
import pytest
import torch

from uav_tilt_vision.training import compress
from uav_tilt_vision.backends import load_detector
from uav_tilt_vision.detector import Detector, load_model, save_model

torch.set_num_threads(2)


def trained_like(seed=0, scales=2):
    """A small Detector with non-trivial BN statistics (so BN folding is exercised)."""
    torch.manual_seed(seed)
    model = Detector(3, 0.25, scales=scales)
    for m in model.modules():
        if isinstance(m, torch.nn.BatchNorm2d):
            m.running_mean.uniform_(-0.2, 0.2)
            m.running_var.uniform_(0.5, 2.0)
            m.weight.data.uniform_(0.5, 1.5)
    return model.eval()


@pytest.fixture(scope='module')
def images_dir(tmp_path_factory):
    """A YOLO-format folder of 8 random-texture images (calibration only needs images)."""
    root = tmp_path_factory.mktemp('calib')
    (root / 'images').mkdir()
    (root / 'labels').mkdir()
    rng = np.random.default_rng(0)
    for i in range(8):
        img = cv2.resize(rng.integers(0, 256, (30, 40, 3), dtype=np.uint8), (320, 240))
        cv2.imwrite(str(root / 'images' / f'{i}.png'), img)
    return root


@pytest.mark.parametrize('scales', [2, 3, 4])
def test_pruning_shrinks_and_round_trips(tmp_path, scales, half_rounded):
    model = trained_like(scales=scales)
    before = compress.size_stats(model)
    compress.prune(model, 0.5)
    after = compress.size_stats(model)
    assert after['params'] < 0.35 * before['params'] and after['macs'] < 0.7 * before['macs']
    x = torch.rand(2, 3, 256, 320)
    heads = half_rounded(model)(x)     # the weights save_model stores
    assert [h.shape for h in heads] == [(2, 24, 8, 10), (2, 24, 16, 20), (2, 24, 32, 40),
                                        (2, 24, 64, 80)][:scales]
    save_model(tmp_path / 'p.pt', model)
    reloaded = load_model(tmp_path / 'p.pt')
    assert reloaded.channels() == model.channels() != Detector(3, 0.25, scales=scales).channels()
    for a, b in zip(reloaded(x), heads):
        torch.testing.assert_close(a, b)


@pytest.mark.parametrize('scales', [2, 3, 4])
def test_onnx_export_matches_torch_and_int8_stays_close(tmp_path, images_dir, scales):
    model = trained_like(1, scales)
    fp32, int8 = tmp_path / 'm.onnx', tmp_path / 'm_int8.onnx'
    compress.export_onnx(model, fp32, 'm.pt')
    x = next(compress.calibration_images(images_dir, 1, model.img_size))
    with torch.no_grad():
        ref = [h.numpy() for h in model(torch.from_numpy(x))]
    out = ort.InferenceSession(str(fp32), providers=['CPUExecutionProvider']).run(
        None, {'images': x})
    assert len(out) == len(ref) == scales
    for a, b in zip(out, ref):
        np.testing.assert_allclose(a, b, atol=1e-3, rtol=1e-3)
    assert 'BatchNormalization' not in {n.op_type for n in onnx.load(str(fp32)).graph.node}
    compress.quantize_int8(fp32, int8, images_dir, 8, model.img_size)
    graph = onnx.load(str(int8))
    ops = [n.op_type for n in graph.graph.node]
    assert ops.count('QuantizeLinear') > 10 and ops.count('DequantizeLinear') > 10
    # per-channel weights: the weight scales are vectors (one per output channel)
    inits = {i.name: i for i in graph.graph.initializer}
    w_scales = [inits[n.input[1]] for n in graph.graph.node
                if n.op_type == 'DequantizeLinear' and n.input[1] in inits
                and n.input[0] in inits and inits[n.input[0]].data_type == onnx.TensorProto.INT8]
    assert w_scales and all(len(s.dims) == 1 and s.dims[0] > 1 for s in w_scales)
    # int8 weights for every conv but the heads and the two stem convs (stride 1 and 2)
    stem = compress.float_stem(onnx.load(str(fp32)))
    assert [n.split('/')[1] for n in stem] == ['backbone.0'] * 2 + ['pool'] + \
        ['backbone.1'] * 2 + ['pool_1']
    assert len(w_scales) == len(model.channels()) - 2
    q = ort.InferenceSession(str(int8), providers=['CPUExecutionProvider']).run(
        None, {'images': x})
    for a, b in zip(q, ref):
        # int8 keeps the logits within a few percent of their spread
        assert np.abs(a - b).mean() < 0.05 * b.std()
    assert json.loads({p.key: p.value for p in graph.metadata_props}['detector'])['source'] \
        == 'm.pt'


def test_backends_agree_and_fall_back(tmp_path, images_dir):
    model = trained_like(2, scales=3)
    save_model(tmp_path / 'm.pt', model)
    compress.export_onnx(model, tmp_path / 'm.onnx', 'm.pt')
    rgb = cv2.imread(str(next((images_dir / 'images').iterdir())))[:, :, ::-1].copy()
    torch_det = load_detector(tmp_path / 'm.pt')
    onnx_det = load_detector(tmp_path / 'm.onnx')
    assert (torch_det.backend, onnx_det.backend) == ('torch', 'onnxruntime')
    a, b = torch_det.predict(rgb, 0.01), onnx_det.predict(rgb, 0.01)
    assert a.shape[1] == 6 and a.shape == b.shape
    np.testing.assert_allclose(a, b, atol=1e-2)
    assert isinstance(onnx_det.predict([rgb, rgb]), list)
    fallback = load_detector(tmp_path / 'm.onnx', 'torch')
    assert fallback.backend == 'torch' and 'm.pt' in fallback.note
    assert load_detector(tmp_path / 'm.pt', 'onnxruntime').backend == 'torch'
    with pytest.raises(ValueError, match='backend'):
        load_detector(tmp_path / 'm.pt', 'tensorrt')


def test_onnxruntime_missing_falls_back_to_source(tmp_path, monkeypatch):
    model = trained_like(3)
    save_model(tmp_path / 'm.pt', model)
    compress.export_onnx(model, tmp_path / 'm.onnx', 'm.pt')
    monkeypatch.setitem(__import__('sys').modules, 'onnxruntime', None)
    det = load_detector(tmp_path / 'm.onnx', 'onnxruntime')
    assert det.backend == 'torch' and 'onnxruntime unavailable' in det.note
