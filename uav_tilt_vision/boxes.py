"""Box geometry for the detector: letterbox, box formats, IoU, NMS and YOLO head decoding.

Boxes are ``xyxy`` (x1, y1, x2, y2) in pixels unless a name says ``xywh`` (centre x,
centre y, width, height). Functions accept numpy arrays; ``xywh_to_xyxy``,
``xyxy_to_xywh``, ``box_iou`` and ``wh_iou`` also accept torch tensors.
"""

from typing import Sequence, TypeVar

import cv2
import numpy as np
import torch
from numpy.typing import ArrayLike, NDArray

# boxes as numpy arrays or torch tensors; a function returns the kind it was given
Boxes = TypeVar('Boxes', np.ndarray, torch.Tensor)

PAD_VALUE = 114  # darknet/ultralytics grey: padding stays neutral for the normalised input


def letterbox(img: np.ndarray, size: Sequence[int], pad_value: int = PAD_VALUE
              ) -> tuple[np.ndarray, float, tuple[int, int]]:
    """Resize ``img`` (H, W, C) into ``size`` = (width, height) keeping aspect, padding evenly.

    Returns ``(out, scale, (pad_x, pad_y))``; a point maps as ``p_out = p * scale + pad``.
    """
    h, w = img.shape[:2]
    out_w, out_h = size
    scale = min(out_w / w, out_h / h)
    new_w, new_h = int(round(w * scale)), int(round(h * scale))
    if (new_w, new_h) != (w, h):
        img = cv2.resize(img, (new_w, new_h), interpolation=cv2.INTER_LINEAR)
    pad_x, pad_y = (out_w - new_w) // 2, (out_h - new_h) // 2
    out = cv2.copyMakeBorder(img, pad_y, out_h - new_h - pad_y, pad_x, out_w - new_w - pad_x,
                             cv2.BORDER_CONSTANT, value=(pad_value,) * 3)
    return out, scale, (pad_x, pad_y)


def scale_boxes(boxes: ArrayLike, scale: float, pad: Sequence[float]) -> NDArray[np.float64]:
    """Map xyxy boxes from original image pixels into the letterboxed image."""
    out = np.asarray(boxes, dtype=np.float64).copy()
    out[..., [0, 2]] = out[..., [0, 2]] * scale + pad[0]
    out[..., [1, 3]] = out[..., [1, 3]] * scale + pad[1]
    return out


def unscale_boxes(boxes: ArrayLike, scale: float, pad: Sequence[float],
                  orig_shape: Sequence[int]) -> NDArray[np.float64]:
    """Map xyxy boxes from the letterboxed image back to the original (H, W), clipped."""
    out = np.asarray(boxes, dtype=np.float64).copy()
    out[..., [0, 2]] = ((out[..., [0, 2]] - pad[0]) / scale).clip(0, orig_shape[1])
    out[..., [1, 3]] = ((out[..., [1, 3]] - pad[1]) / scale).clip(0, orig_shape[0])
    return out


def xywh_to_xyxy(b: Boxes) -> Boxes:
    """(cx, cy, w, h) -> (x1, y1, x2, y2); numpy or torch, any leading shape."""
    cat = torch.stack if isinstance(b, torch.Tensor) else np.stack
    cx, cy, w, h = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    return cat([cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2], -1)


def xyxy_to_xywh(b: Boxes) -> Boxes:
    """(x1, y1, x2, y2) -> (cx, cy, w, h); numpy or torch, any leading shape."""
    cat = torch.stack if isinstance(b, torch.Tensor) else np.stack
    x1, y1, x2, y2 = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    return cat([(x1 + x2) / 2, (y1 + y2) / 2, x2 - x1, y2 - y1], -1)


def box_area(b: Boxes) -> Boxes:
    """Areas of (N, 4) xyxy boxes; numpy or torch."""
    return (b[:, 2] - b[:, 0]) * (b[:, 3] - b[:, 1])


def box_iou(a: Boxes, b: Boxes, crowd: Boxes | None = None) -> Boxes:
    """Pairwise IoU of xyxy boxes: (N, 4) x (M, 4) -> (N, M); numpy or torch.

    ``crowd``: optional (M,) bool; for those columns the union is a's area alone
    (COCO's iscrowd overlap: the share of box a inside region b).
    """
    lib = torch if isinstance(a, torch.Tensor) else np
    area_a, area_b = box_area(a), box_area(b)
    lt = lib.maximum(a[:, None, :2], b[None, :, :2])
    rb = lib.minimum(a[:, None, 2:4], b[None, :, 2:4])
    wh = (rb - lt).clip(0) if lib is np else (rb - lt).clamp(min=0)
    inter = wh[..., 0] * wh[..., 1]
    union = area_a[:, None] + area_b[None, :] - inter
    if crowd is not None:
        union = lib.where(crowd[None, :], area_a[:, None], union)
    return inter / (union + 1e-12)


def wh_iou(a: Boxes, b: Boxes) -> Boxes:
    """IoU of boxes sharing a centre: (N, 2) x (M, 2) sizes -> (N, M); numpy or torch."""
    lib = torch if isinstance(a, torch.Tensor) else np
    inter = lib.minimum(a[:, None], b[None]).prod(-1)
    return inter / (a.prod(-1)[:, None] + b.prod(-1)[None] - inter)


def nms(boxes: ArrayLike, scores: ArrayLike, iou_thres: float,
        classes: ArrayLike | None = None) -> NDArray[np.intp]:
    """Greedy non-maximum suppression; class-aware when ``classes`` is given.

    Returns the kept indices in descending score order. A box is suppressed by a
    higher-scoring kept box of the same class whose IoU with it exceeds ``iou_thres``.
    """
    boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
    scores = np.asarray(scores, dtype=np.float64).reshape(-1)
    order = np.argsort(-scores, kind='stable')
    if len(order) == 0:
        return order
    iou = box_iou(boxes[order], boxes[order])
    if classes is not None:
        cls = np.asarray(classes)[order]
        iou = np.where(cls[:, None] == cls[None, :], iou, 0.0)
    suppressed = np.zeros(len(order), dtype=bool)
    for i in range(len(order)):
        if not suppressed[i]:
            # only later (lower-score) boxes can be suppressed by box i
            suppressed[i + 1:] |= iou[i, i + 1:] > iou_thres
    return order[~suppressed]


def decode(head: np.ndarray, anchors: ArrayLike, stride: float,
           min_obj: float = 0.0) -> np.ndarray:
    """Decode one image's raw head map into boxes in input pixels (numpy).

    ``head``: (A*(5+C), H, W) logits; ``anchors``: (A, 2) anchor sizes in input pixels.
    Uses the bounded YOLOv4/v5 parametrisation (see ``yolo_loss``):
    ``xy = (2*sig(t_xy) - 0.5 + cell) * stride``, ``wh = (2*sig(t_wh))**2 * anchor``.
    Only cells whose objectness probability exceeds ``min_obj`` are decoded: a detection's
    score (objectness times class probability) cannot exceed its objectness, so a score
    threshold may be passed here and the few candidate cells are all that is computed.
    Returns (K, 5+C) in (anchor, row, column) order: xyxy, objectness, class probabilities.
    """
    anchors = np.asarray(anchors, dtype=np.float32).reshape(-1, 2)
    t = head.reshape(len(anchors), -1, *head.shape[1:])
    with np.errstate(divide='ignore'):
        min_logit = np.log(min_obj) - np.log1p(-min_obj)
    a, y, x = np.nonzero(t[:, 4] > min_logit)
    p: np.ndarray = 1.0 / (1.0 + np.exp(-t[a, :, y, x].astype(np.float32)))
    xy, wh = cell_xywh(p, np.stack([x, y], -1), anchors[a], stride)
    return np.concatenate([xywh_to_xyxy(np.concatenate([xy, wh], -1)), p[:, 4:]], -1)


def head_view(head: torch.Tensor, num_anchors: int) -> torch.Tensor:
    """Reshape (B, A*(5+C), H, W) -> (B, A, H, W, 5+C) without copying data when possible."""
    b, ch, h, w = head.shape
    return head.view(b, num_anchors, ch // num_anchors, h, w).permute(0, 1, 3, 4, 2)


def cell_xywh(p: Boxes, cell: Boxes, anchors: Boxes, stride: float
              ) -> tuple[Boxes, Boxes]:
    """The decode formula: centre and size (input pixels) from sigmoid outputs, cells, anchors
    (numpy or torch)."""
    return (p[..., :2] * 2 - 0.5 + cell) * stride, (p[..., 2:4] * 2) ** 2 * anchors
