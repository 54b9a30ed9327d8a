"""YOLOv3-tiny family detector (PyTorch) with explicit per-conv channel counts.

Architecture (darknet ``yolov3-tiny.cfg``): eleven conv-BN-leaky(0.1) layers
``c0..c10`` and two 1x1 detection heads::

    c0..c4 3x3, each followed by maxpool/2  (c4's output is also the route to scale 2)
    c5 3x3, maxpool 2x2 stride 1 (zero-pad right/bottom), c6 3x3
    c7 1x1 -> c8 3x3 -> head0 (stride 32)
    c7 -> c9 1x1 -> upsample x2 -> concat(c4) -> c10 3x3 -> head1 (stride 16)

With ``scales=3`` (darknet ``yolov3-tiny_3l.cfg``) a third branch serves small objects,
and ``scales=4`` adds a fourth in the same way for the smallest (a 0.2 m plate 5 m away
spans about 11 px of the 320x240 image):

    c10 -> c11 1x1 -> upsample x2 -> concat(c3) -> c12 3x3 -> head2 (stride 8)
    c12 -> c13 1x1 -> upsample x2 -> concat(c2) -> c14 3x3 -> head3 (stride 4)

The reference channel list is 16-32-64-128-256-512-1024-256-512-128-256 (-128-128 (-64-64));
``width_mult`` scales it, and ``channels`` gives every conv explicitly so that a
structurally pruned model (irregular counts) can be rebuilt by ``load_model``.

Input size: the 320x240 camera image is letterboxed to 320x256 (8 px grey bands
top and bottom, scale 1): both dimensions must be multiples of the largest
stride 32, and 256 is the smallest such height that keeps the full image
unscaled. Grids are 10x8 (stride 32), 20x16 (stride 16), 40x32 (stride 8) and 80x64
(stride 4).
"""

import os
from typing import Any, Sequence, cast

import numpy as np
import torch
from numpy.typing import ArrayLike
from torch import nn

from uav_tilt_vision.boxes import decode, letterbox, nms, unscale_boxes
from uav_tilt_vision.exposure import normalize_exposure

REF_CHANNELS = (16, 32, 64, 128, 256, 512, 1024, 256, 512, 128, 256)
# the extra (1x1, 3x3) pair of each further scale
EXTRA_SCALE_CHANNELS = ((128, 128), (64, 64))
STRIDES = (32, 16, 8, 4)
IMG_SIZE = (320, 256)
# Per-scale anchors (w, h) in input pixels, [stride 32, stride 16, stride 8]; sized for the
# objects of 320-px inspection images (train.py replaces them by k-means on the labels).
DEFAULT_ANCHORS = {2: (((48, 40), (72, 80), (128, 112)), ((10, 12), (18, 22), (30, 32))),
                   3: (((60, 60), (90, 90), (128, 124)), ((26, 28), (36, 38), (46, 48)),
                       ((9, 10), (13, 15), (18, 20))),
                   4: (((70, 70), (100, 100), (140, 130)), ((36, 38), (46, 48), (56, 58)),
                       ((18, 20), (23, 25), (28, 30)), ((7, 8), (10, 11), (13, 15)))}
SCALES = tuple(DEFAULT_ANCHORS)


def reference_channels(scales: int = 2) -> list[int]:
    """The darknet channel list of the ``scales``-head YOLOv3-tiny."""
    return list(REF_CHANNELS) + [c for pair in EXTRA_SCALE_CHANNELS[:scales - 2] for c in pair]


def scaled_channels(width_mult: float, scales: int = 2) -> list[int]:
    """Reference channel list times ``width_mult``, rounded to multiples of 8 (>= 8)."""
    return [max(8, int(round(c * width_mult / 8)) * 8) for c in reference_channels(scales)]


class ConvBNAct(nn.Sequential):
    """Conv (no bias) -> BatchNorm -> LeakyReLU(0.1), 'same' padding."""

    def __init__(self, c_in: int, c_out: int, k: int) -> None:
        super().__init__(nn.Conv2d(c_in, c_out, k, 1, k // 2, bias=False),
                         nn.BatchNorm2d(c_out), nn.LeakyReLU(0.1, inplace=True))


class Detector(nn.Module):
    """YOLOv3-tiny family: ``forward`` returns raw heads [(B, A*(5+C), H/32, W/32), (.., /16)]
    and, with ``scales`` 3 and 4, (.., /8) and (.., /4)."""

    anchors: torch.Tensor           # (scales, A, 2) anchor sizes in input pixels (a buffer)
    meta: dict[str, Any]            # what load_model read with the weights

    def __init__(self, num_classes: int = 80, width_mult: float = 1.0,
                 channels: Sequence[int] | None = None, anchors: ArrayLike | None = None,
                 img_size: Sequence[int] = IMG_SIZE, scales: int = 2) -> None:
        super().__init__()
        if scales not in SCALES:
            raise ValueError(f'scales must be one of {SCALES}, got {scales}')
        ch = list(channels) if channels is not None else scaled_channels(width_mult, scales)
        n_convs = len(reference_channels(scales))
        if len(ch) != n_convs:
            raise ValueError(f'channels must list {n_convs} convs, got {len(ch)}')
        anchors = DEFAULT_ANCHORS[scales] if anchors is None else anchors
        anchors = np.asarray(anchors, dtype=np.float64).reshape(scales, -1, 2)
        self.num_classes = int(num_classes)
        self.width_mult = float(width_mult)
        self.img_size = tuple(int(v) for v in img_size)
        self.strides = STRIDES[:scales]
        self.register_buffer('anchors', torch.tensor(anchors, dtype=torch.float32))
        n_out = anchors.shape[1] * (5 + self.num_classes)
        ins = [3] + ch[:6]
        self.backbone = nn.ModuleList(ConvBNAct(ins[i], ch[i], 3) for i in range(7))
        self.pool = nn.MaxPool2d(2, 2)
        self.pool_s1 = nn.Sequential(nn.ZeroPad2d((0, 1, 0, 1)), nn.MaxPool2d(2, 1))
        self.c7 = ConvBNAct(ch[6], ch[7], 1)
        self.c8 = ConvBNAct(ch[7], ch[8], 3)
        self.head0 = nn.Conv2d(ch[8], n_out, 1)
        self.c9 = ConvBNAct(ch[7], ch[9], 1)
        self.up = nn.Upsample(scale_factor=2, mode='nearest')
        self.c10 = ConvBNAct(ch[9] + ch[4], ch[10], 3)
        self.head1 = nn.Conv2d(ch[10], n_out, 1)
        # scale k >= 2: c(2k+7) 1x1 -> upsample -> concat(route of stride 2^(5-k)) -> c(2k+8)
        for k in range(2, scales):
            i = 2 * k + 7
            setattr(self, f'c{i}', ConvBNAct(ch[i - 1], ch[i], 1))
            setattr(self, f'c{i + 1}', ConvBNAct(ch[i] + ch[5 - k], ch[i + 1], 3))
            setattr(self, f'head{k}', nn.Conv2d(ch[i + 1], n_out, 1))
        self._init_head_bias()

    @property
    def heads(self) -> list[nn.Conv2d]:
        """The 1x1 detection convs, coarsest first."""
        return [getattr(self, f'head{k}') for k in range(len(self.strides))]

    def _convs(self) -> list[ConvBNAct]:
        extra = [getattr(self, f'c{i}') for i in range(11, 2 * len(self.strides) + 7)]
        return [cast(ConvBNAct, m) for m in self.backbone] + [self.c7, self.c8, self.c9,
                                                              self.c10] + extra

    def _init_head_bias(self) -> None:
        # Objectness prior ~1e-2 and class prior 1/C (focal-loss paper / YOLOv5) so the
        # first steps are not dominated by the huge number of background cells.
        for head in self.heads:
            b = cast(torch.Tensor, head.bias).data.view(self.anchors.shape[1], -1)
            b[:, 4] = float(np.log(0.01 / 0.99))
            b[:, 5:] = float(np.log(0.6 / max(self.num_classes - 0.99, 1.0)))

    def channels(self) -> list[int]:
        """Actual output channels of c0..c10 (read from the modules, so pruning is reflected)."""
        return [int(cast(nn.Conv2d, m[0]).out_channels) for m in self._convs()]

    def config(self) -> dict[str, Any]:
        """Constructor arguments that rebuild this architecture (JSON-serialisable)."""
        return {'num_classes': self.num_classes, 'width_mult': self.width_mult,
                'channels': self.channels(), 'anchors': self.anchors.tolist(),
                'img_size': list(self.img_size), 'scales': len(self.strides)}

    def forward(self, x: torch.Tensor) -> list[torch.Tensor]:
        """Raw head logits for a (B, 3, H, W) float input in [0, 1]."""
        routes = []
        for i in range(5):
            x = self.backbone[i](x)
            routes.append(x)
            x = self.pool(x)
        x = self.backbone[6](self.pool_s1(self.backbone[5](x)))
        x = self.c7(x)
        out = [self.head0(self.c8(x))]
        y = self.c10(torch.cat([self.up(self.c9(x)), routes[4]], 1))
        out.append(self.head1(y))
        for k in range(2, len(self.strides)):
            i = 2 * k + 7
            y = getattr(self, f'c{i + 1}')(torch.cat(
                [self.up(getattr(self, f'c{i}')(y)), routes[5 - k]], 1))
            out.append(getattr(self, f'head{k}')(y))
        return out

    @torch.no_grad()
    def predict(self, images: np.ndarray | Sequence[np.ndarray], conf_thres: float = 0.25,
                iou_thres: float = 0.45, max_det: int = 100) -> list[np.ndarray]:
        """Detect in uint8 RGB images (H, W, 3), a list or one image.

        Returns one (N, 6) float array per image: x1, y1, x2, y2 (original image
        pixels), score = objectness * class probability, class index.
        """
        if isinstance(images, np.ndarray) and images.ndim == 3:
            images = [images]
        x, frames = input_batch(images, self.img_size)
        was_training = self.training
        self.eval()
        heads = [h.float().cpu().numpy()
                 for h in self(torch.from_numpy(x).to(self.anchors.device))]
        self.train(was_training)
        return detections(heads, self.anchors.cpu().numpy(), frames, images, conf_thres,
                          iou_thres, max_det)


def input_batch(images: Sequence[np.ndarray] | np.ndarray, img_size: Sequence[int]
                ) -> tuple[np.ndarray, list[tuple[float, tuple[int, int]]]]:
    """The detector's input for uint8 RGB images: exposure-normalised, letterboxed, float
    NCHW in [0, 1]; plus each image's (scale, pad) for mapping boxes back."""
    boxes = [letterbox(normalize_exposure(img), img_size) for img in images]
    x = np.stack([b[0] for b in boxes]).transpose(0, 3, 1, 2).astype(np.float32) / 255.0
    return x, [(s, p) for _, s, p in boxes]


def detections(heads: Sequence[np.ndarray], anchors: np.ndarray,
               frames: Sequence[tuple[float, tuple[int, int]]],
               images: Sequence[np.ndarray] | np.ndarray,
               conf_thres: float, iou_thres: float, max_det: int = 100) -> list[np.ndarray]:
    """One (N, 6) detection array per image from the raw heads (numpy, coarsest first).

    ``anchors``: (scales, A, 2); ``frames``: each image's (scale, pad) from ``input_batch``.
    """
    out = []
    for b, ((scale, pad), img) in enumerate(zip(frames, images)):
        det = np.concatenate([decode(h[b], a, s, conf_thres)
                              for h, a, s in zip(heads, anchors, STRIDES)])
        out.append(postprocess(det, conf_thres, iou_thres, max_det, scale, pad, img.shape))
    return out


def postprocess(det: np.ndarray, conf_thres: float, iou_thres: float, max_det: int,
                scale: float, pad: Sequence[float], orig_shape: Sequence[int]) -> np.ndarray:
    """Score filter, class-aware NMS and mapping back to the original image for one image."""
    cls = det[:, 5:].argmax(1)
    score = det[:, 4] * det[np.arange(len(det)), 5 + cls]
    keep = score > conf_thres
    xyxy, score, cls = det[keep, :4], score[keep], cls[keep]
    idx = nms(xyxy, score, iou_thres, cls)[:max_det]
    xyxy = unscale_boxes(xyxy[idx], scale, pad, orig_shape)
    return np.concatenate([xyxy, score[idx, None], cls[idx, None]], 1).astype(np.float32)


def grow_scales(model: Detector, scales: int, extra_anchors: ArrayLike) -> Detector:
    """A ``scales``-head copy of ``model`` that keeps its weights and anchors; the new finer
    heads (anchors ``extra_anchors``, one (A, 2) set per new head) start untrained."""
    have = len(model.strides)
    extra_anchors = np.asarray(extra_anchors, dtype=np.float64).reshape(scales - have, -1, 2)
    widths = [max(8, int(round(c * model.width_mult / 8)) * 8)
              for pair in EXTRA_SCALE_CHANNELS[have - 2:scales - 2] for c in pair]
    anchors = np.concatenate([model.anchors.cpu().numpy(), extra_anchors])
    grown = Detector(model.num_classes, model.width_mult, model.channels() + widths, anchors,
                     model.img_size, scales)
    state = {k: v for k, v in model.state_dict().items() if k != 'anchors'}
    missing, unexpected = grown.load_state_dict(state, strict=False)
    new = {f'c{i}' for i in range(2 * have + 7, 2 * scales + 7)} | {
        f'head{k}' for k in range(have, scales)}
    if unexpected or any(k.split('.')[0] not in new for k in missing if k != 'anchors'):
        raise ValueError(f'cannot grow {have} to {scales} scales: {unexpected or missing}')
    return grown


def resize_input(model: Detector, img_size: Sequence[int]) -> Detector:
    """A copy of ``model`` that takes ``img_size`` (w, h) inputs. Weights and anchors are
    kept: the network is fully convolutional, and an object magnified in the input looks
    larger to it, so its boxes grow with the object in input pixels as the anchors do."""
    resized = Detector(model.num_classes, model.width_mult, model.channels(),
                       model.anchors.cpu().numpy(), img_size, len(model.strides))
    resized.load_state_dict(model.state_dict())
    return resized


def save_model(path: str | os.PathLike[str], model: Detector,
               meta: dict[str, Any] | None = None) -> None:
    """Save architecture config, weights and a JSON-like ``meta`` dict to ``path``.

    Float weights are stored in half precision (half the file; ``load_model`` restores
    float32), far finer than the int8 the deployed model runs at.
    """
    state = {k: v.half() if v.is_floating_point() else v
             for k, v in model.state_dict().items()}
    torch.save({'config': model.config(), 'state_dict': state, 'meta': dict(meta or {})}, path)


def load_model(path: str | os.PathLike[str], map_location: str = 'cpu') -> Detector:
    """Rebuild a ``Detector`` saved by ``save_model`` (pruned channel counts included).

    The saved ``meta`` dict is attached as ``model.meta``; the model is in eval mode.
    """
    ckpt = torch.load(path, map_location=map_location, weights_only=True)
    model = Detector(**ckpt['config'])
    model.load_state_dict(ckpt['state_dict'])
    model.meta = ckpt['meta']
    return model.eval()
