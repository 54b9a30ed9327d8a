"""Detector compression: structured channel pruning + fine-tuning, then int8 ONNX.

1. ``prune``: torch-pruning removes whole conv output channels of lowest group L2
   magnitude (the dependency graph keeps the c4 -> c10 route and BN consistent); the
   heads keep their outputs. The result is still a ``Detector`` with irregular channel
   counts, saved with ``save_model``.
2. Fine-tuning with ``train.train(model=...)`` recovers the accuracy, distilled from the
   unpruned model (``train.train(teacher=...)``) unless ``distill_gain`` is 0.
3. ``export_onnx`` + ``quantize_int8``: ONNX Runtime static quantization, QDQ format,
   per-channel int8 weights, uint8 activations calibrated (99.999th percentile) on
   training images. BatchNorm is folded into the convs by the exporter. The graph outputs
   the raw heads; the head convs stay float (they hold box offsets, sizes and logits
   of very different ranges, which one int8 scale per tensor cannot; they are 1x1 convs, a
   few percent of the MACs), and so does the stem at full and half input resolution (the
   first two conv blocks and their pools: with 3-12 channels per pixel ONNX Runtime's int8
   convolutions run slower than its float ones there, see ``bench vision``). Decoding and
   NMS run outside the graph (``backends``).
"""

import contextlib
import json
import os
import sys
import tempfile
from pathlib import Path
from typing import Any, Callable, Iterator, Sequence

import numpy as np
import torch

from uav_tilt_common.config import ConfigError
from uav_tilt_vision.detector import Detector, input_batch, load_model
from uav_tilt_vision.training.profile import profile_model
from uav_tilt_vision.training.train import card_path, check_crop, evaluate, git_commit, \
    train
from uav_tilt_vision.training.yolo_data import YoloDataset

ONNX_OPSET = 17
HEAD_OUTPUTS = ('head0', 'head1', 'head2', 'head3')
CALIB_PERCENTILE = 99.999
# torch-pruning leaves a conv whole when pruning would leave it fewer than round_to (8)
# channels: above 0.75 it skips the 32-channel convs and, near 1, prunes nothing at all.
MAX_PRUNING_RATIO = 0.75
FLOAT_STEM_POOLS = 2   # the float stem ends with the second maxpool (stride 4)
QUANTIZATION = ('onnxruntime static QDQ, per-channel int8 weights, uint8 activations, '
                f'{CALIB_PERCENTILE} percentile calibration, head convs and the stride 1-2 '
                'stem float')


def prune(model: Detector, ratio: float, round_to: int = 8) -> Detector:
    """Remove ``ratio`` of the channels of every conv except the heads, in place; ConfigError
    when no conv is wide enough to lose any (see ``MAX_PRUNING_RATIO``)."""
    import torch_pruning as tp
    example = torch.zeros(1, 3, model.img_size[1], model.img_size[0])
    before = model.channels()
    pruner = tp.pruner.MetaPruner(
        model, example, importance=tp.importance.GroupMagnitudeImportance(p=2),
        pruning_ratio=ratio, ignored_layers=model.heads, round_to=round_to)
    pruner.step()
    if model.channels() == before:
        raise ConfigError(f'pruning ratio {ratio} removes no channel: each conv keeps at '
                          f'least {round_to} of its {before}')
    return model


def export_onnx(model: Detector, path: str | os.PathLike[str], source: str) -> None:
    """Export the raw heads of ``model`` (eval mode, dynamic batch) to ONNX.

    ``source``: file name of the checkpoint, recorded (with anchors, input size and class
    count) in the 'detector' metadata entry for ``backends``.
    """
    model.eval()
    w, h = model.img_size
    torch.onnx.export(model, (torch.zeros(1, 3, h, w),), str(path), input_names=['images'],
                      output_names=list(HEAD_OUTPUTS[:len(model.strides)]),
                      dynamic_axes={'images': {0: 'batch'}},
                      opset_version=ONNX_OPSET, dynamo=False)
    set_metadata(path, {'anchors': model.anchors.tolist(), 'img_size': list(model.img_size),
                        'num_classes': model.num_classes, 'source': source})


def set_metadata(path: str | os.PathLike[str], detector_meta: dict[str, Any]) -> None:
    """Write the 'detector' JSON metadata entry of an ONNX file."""
    import onnx
    proto = onnx.load(str(path))
    del proto.metadata_props[:]
    proto.metadata_props.add(key='detector', value=json.dumps(detector_meta))
    onnx.save(proto, str(path))


def calibration_images(data_dir: str | os.PathLike[str], n: int,
                       img_size: Sequence[int]) -> Iterator[np.ndarray]:
    """The first ``n`` images of a set (sorted names: deterministic) as detector input."""
    ds = YoloDataset(data_dir, img_size)
    for i in range(min(n, len(ds))):
        yield input_batch([ds.read_rgb(i)], img_size)[0]


def quantize_int8(fp32_path: str | os.PathLike[str], out_path: str | os.PathLike[str],
                  data_dir: str | os.PathLike[str], n_calib: int,
                  img_size: Sequence[int]) -> None:
    """Static per-channel QDQ int8 quantization of an ONNX model (metadata kept)."""
    import onnx
    from onnxruntime.quantization import (CalibrationDataReader, CalibrationMethod,
                                          QuantFormat, QuantType, quantize_static)

    class Reader(CalibrationDataReader):
        def __init__(self) -> None:
            self.it = iter(calibration_images(data_dir, n_calib, img_size))

        def get_next(self) -> dict[str, np.ndarray] | None:
            x = next(self.it, None)
            return None if x is None else {'images': x}

    proto = onnx.load(str(fp32_path))
    meta = {p.key: p.value for p in proto.metadata_props}
    heads = [n.name for n in proto.graph.node if set(n.output) & set(HEAD_OUTPUTS)]
    # the calibrator prints its progress: keep stdout for the CLI's JSON
    with contextlib.redirect_stdout(sys.stderr):
        quantize_static(str(fp32_path), str(out_path), Reader(), quant_format=QuantFormat.QDQ,
                        per_channel=True, activation_type=QuantType.QUInt8,
                        weight_type=QuantType.QInt8, nodes_to_exclude=heads + float_stem(proto),
                        calibrate_method=CalibrationMethod.Percentile,
                        extra_options={'CalibPercentile': CALIB_PERCENTILE})
    set_metadata(out_path, json.loads(meta['detector']))


def float_stem(proto: Any, pools: int = FLOAT_STEM_POOLS) -> list[str]:
    """Names of the conv, activation and pool nodes up to the ``pools``-th maxpool."""
    names = []
    for node in proto.graph.node:   # the exporter writes nodes in execution order
        if node.op_type in ('Conv', 'LeakyRelu', 'MaxPool'):
            names.append(node.name)
            pools -= node.op_type == 'MaxPool'
            if pools == 0:
                break
    return names


def size_stats(model: Detector) -> dict[str, int]:
    """Parameters and MACs per image at the model's input size."""
    prof = profile_model(model, (1, 3, model.img_size[1], model.img_size[0]))
    return {'params': prof['params'], 'macs': prof['macs']}


def compress(model_path: str | os.PathLike[str], data_dir: str | os.PathLike[str],
             out_dir: str | os.PathLike[str], ratio: float = 0.25, finetune_epochs: int = 4,
             seed: int = 0, calib_images: int = 128,
             eval_dir: str | os.PathLike[str] | None = None, lr: float = 1e-3,
             crop: Sequence[int] | None = None, distill_gain: float = 1.0,
             bf16: bool = False, device: str = 'auto', workers: int = 0,
             log: Callable[[str], Any] = print) -> dict[str, Any]:
    """fp32 ``.pt`` -> ``detector_pruned.pt`` (+ card) and ``detector_int8.onnx`` (+ card).

    Returns a report with params, MACs and (with ``eval_dir``) mAP of every stage.
    ``crop``: fine-tune on object-centred windows (see ``train.train``).
    ``distill_gain``: weight of the distillation from the unpruned model (0: labels only).
    ``bf16``, ``device``, ``workers``: the fine-tuning's (see ``train.train``).
    ``log``: receives the fine-tuning's per-epoch lines.
    """
    model = load_model(model_path)
    check_crop(crop, model.img_size)        # before the evaluation and the pruning
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    report = {'fp32': {**size_stats(model), 'path': str(model_path)}}
    if eval_dir:
        report['fp32'].update(evaluate(model, eval_dir))
    pruned_path = out / 'detector_pruned.pt'
    pruned = prune(model, ratio)
    teacher = load_model(model_path) if distill_gain else None
    card = train(data_dir, pruned_path, finetune_epochs, seed, lr=lr, model=pruned,
                 eval_dir=eval_dir, device=device, workers=workers, crop=crop,
                 teacher=teacher, distill_gain=distill_gain, bf16=bf16, log=log,
                 card_extra={'source': str(model_path), 'pruning_ratio': ratio,
                             'teacher': str(model_path) if teacher else None})
    report['pruned'] = {**size_stats(pruned), 'path': str(pruned_path),
                        **(card['metrics'] or {})}
    report['int8'] = quantize(pruned_path, data_dir, calib_images, eval_dir)
    return report


def quantize(pruned_path: str | os.PathLike[str], data_dir: str | os.PathLike[str],
             calib_images: int = 128,
             eval_dir: str | os.PathLike[str] | None = None) -> dict[str, Any]:
    """``detector_pruned.pt`` -> ``detector_int8.onnx`` (+ card) beside it; its report.

    Calibrates on the first ``calib_images`` images of ``data_dir`` (all, if it has fewer).
    """
    from uav_tilt_vision.backends import OnnxDetector
    pruned_path = Path(pruned_path)
    pruned = load_model(pruned_path)
    # read every input before writing anything
    source_card = json.loads(card_path(pruned_path).read_text())
    calib_images = min(calib_images, len(YoloDataset(data_dir, pruned.img_size)))
    int8_path = pruned_path.parent / 'detector_int8.onnx'
    with tempfile.TemporaryDirectory() as tmp:
        fp32_onnx = Path(tmp) / 'pruned_fp32.onnx'
        export_onnx(pruned, fp32_onnx, pruned_path.name)
        quantize_int8(fp32_onnx, int8_path, data_dir, calib_images, pruned.img_size)
    report = {**size_stats(pruned), 'path': str(int8_path)}
    if eval_dir:
        report.update(evaluate(OnnxDetector(int8_path), eval_dir))
    int8_card = {'source': pruned_path.name, 'quantization': QUANTIZATION,
                 'calib_images': calib_images, 'calib_data': str(data_dir),
                 'data_seed': source_card.get('data_seed'), 'metrics': report,
                 'git_commit': git_commit()}
    card_path(int8_path).write_text(json.dumps(int8_card, indent=2))
    return report
