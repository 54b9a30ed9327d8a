"""Inference backends behind one interface: ``load_detector(model_path, backend)``.

'torch' runs a ``Detector`` checkpoint (fp32 or pruned ``.pt``); 'onnxruntime' runs the
int8 QDQ ``.onnx`` written by ``compress`` (raw heads; decoding and NMS are shared with
the torch path). When the asked backend cannot run (onnxruntime not installed, or a
``.pt`` asked of it), the loader falls back to torch on the ONNX model's source
checkpoint and says so in ``backend`` and ``note``, so a node logs one honest line.
"""

import json
import os
from pathlib import Path
from typing import Sequence

import numpy as np

from uav_tilt_vision.detector import detections, input_batch, load_model

# The deployed detector, relative to the package's files (uav_tilt_common.resources).
DEPLOYED_MODEL = 'models/detector_int8.onnx'

BACKENDS = ('torch', 'onnxruntime')


def _as_list(images: np.ndarray | Sequence[np.ndarray]) -> tuple[list[np.ndarray], bool]:
    if isinstance(images, np.ndarray) and images.ndim == 3:
        return [images], True
    return list(images), False


class TorchDetector:
    """A ``Detector`` checkpoint on CPU."""

    backend = 'torch'

    def __init__(self, model_path: str | os.PathLike[str], note: str = '') -> None:
        self.model = load_model(model_path)
        self.model_path, self.note = str(model_path), note
        self.num_classes = self.model.num_classes

    def predict(self, images: np.ndarray | Sequence[np.ndarray], conf_thres: float = 0.25,
                iou_thres: float = 0.45) -> np.ndarray | list[np.ndarray]:
        """(N, 6) [x1, y1, x2, y2, score, class] in image pixels; a list in -> a list out."""
        batch, single = _as_list(images)
        out = self.model.predict(batch, conf_thres, iou_thres)
        return out[0] if single else out


class OnnxDetector:
    """An ONNX model of the raw detector heads in ONNX Runtime (CPU)."""

    backend = 'onnxruntime'

    def __init__(self, model_path: str | os.PathLike[str], threads: int = 0) -> None:
        import onnxruntime as ort
        opts = ort.SessionOptions()
        opts.intra_op_num_threads = threads
        # ONNX Runtime's workers spin between runs by default: on two cores shared with the
        # physics and control loops that took 2.5x the CPU of the runs themselves (and made
        # them slower); idle workers sleep instead.
        opts.add_session_config_entry('session.intra_op.allow_spinning', '0')
        self.session = ort.InferenceSession(str(model_path), opts,
                                            providers=['CPUExecutionProvider'])
        meta = json.loads(self.session.get_modelmeta().custom_metadata_map['detector'])
        self.anchors = np.asarray(meta['anchors'], dtype=np.float32)
        self.img_size = tuple(meta['img_size'])
        self.num_classes = meta['num_classes']
        self.model_path, self.note = str(model_path), ''
        self.input_name = self.session.get_inputs()[0].name

    def predict(self, images: np.ndarray | Sequence[np.ndarray], conf_thres: float = 0.25,
                iou_thres: float = 0.45) -> np.ndarray | list[np.ndarray]:
        """(N, 6) [x1, y1, x2, y2, score, class] in image pixels; a list in -> a list out."""
        batch, single = _as_list(images)
        x, frames = input_batch(batch, self.img_size)
        heads = self.session.run(None, {self.input_name: x})
        out = detections(heads, self.anchors, frames, batch, conf_thres, iou_thres)
        return out[0] if single else out


def onnx_source(model_path: str | os.PathLike[str]) -> Path:
    """The checkpoint an ONNX model was exported from (recorded in its metadata)."""
    import onnx
    props = {p.key: p.value for p in onnx.load(str(model_path)).metadata_props}
    return Path(model_path).parent / json.loads(props['detector'])['source']


def load_detector(model_path: str | os.PathLike[str], backend: str = 'auto',
                  threads: int = 0) -> 'TorchDetector | OnnxDetector':
    """A detector with ``predict(rgb) -> (N, 6)``, ``backend`` (the one used) and ``note``.

    ``backend``: 'torch', 'onnxruntime', or 'auto' (by the file suffix). ``threads``: the
    size of ONNX Runtime's intra-op pool, or torch's (process-wide); 0 keeps the default.
    """
    detector = _load(model_path, backend, threads)
    if threads and detector.backend == 'torch':
        import torch
        torch.set_num_threads(threads)
    return detector


def _load(model_path: str | os.PathLike[str], backend: str,
          threads: int) -> 'TorchDetector | OnnxDetector':
    path = Path(model_path)
    is_onnx = path.suffix == '.onnx'
    if backend == 'auto':
        backend = 'onnxruntime' if is_onnx else 'torch'
    if backend not in BACKENDS:
        raise ValueError(f'unknown backend {backend!r}; expected one of {BACKENDS}')
    if backend == 'onnxruntime' and is_onnx:
        try:
            return OnnxDetector(path, threads)
        except ImportError as exc:
            reason = f'onnxruntime unavailable ({exc})'
    elif backend == 'onnxruntime':
        reason = f'{path.name} is not an ONNX model'
    elif not is_onnx:
        return TorchDetector(path)
    else:
        reason = 'torch cannot run an ONNX model'
    source = onnx_source(path) if is_onnx else path
    return TorchDetector(source, note=f'{reason}: fell back to torch on {source.name}')
