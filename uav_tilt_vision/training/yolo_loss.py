"""YOLOv3 training loss: objectness BCE, class BCE and CIoU box loss.

Box loss choice: 1 - CIoU on the decoded boxes (YOLOv4) rather than the original
MSE on (tx, ty, tw, th). CIoU is scale invariant (small and large objects weigh
the same), it also pulls centres together when boxes do not overlap, and with the
bounded decode of ``boxes.decode`` (sigmoid for both xy and wh) its gradients stay
bounded, so small models train quickly at a high learning rate without exp() blow-ups.
The objectness target of a positive cell is its detached, clamped CIoU (YOLOv5), which
makes the score reflect localisation quality, useful for NMS and mAP.

Target assignment: each ground truth box goes to the grid cell holding its centre
for every anchor (over all scales) whose shape IoU with it exceeds ``anchor_iou``,
and always to its single best anchor, as in YOLOv3. Ignore regions (target rows of class
``IGNORE_CLASS``: objects in view but too little visible to label) take no part in the
assignment; the cells that could predict them, those whose centre lies inside one and the
one holding its centre, are left out of the objectness loss unless a label is assigned to
them, so that a partly visible object is neither taught as one nor as background.

``distill_loss`` adds what a teacher detector outputs as a second, soft target (used to
fine-tune a pruned model against the unpruned one).
"""

import math
from typing import Any, Sequence

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from uav_tilt_vision.boxes import cell_xywh, head_view, wh_iou, xywh_to_xyxy
from uav_tilt_vision.detector import STRIDES
from uav_tilt_vision.training.yolo_data import IGNORE_CLASS


def ciou(a: torch.Tensor, b: torch.Tensor, eps: float = 1e-9) -> torch.Tensor:
    """Element-wise complete IoU of (N, 4) xywh boxes ``a`` and ``b`` (Zheng et al. 2020)."""
    a1, b1 = xywh_to_xyxy(a), xywh_to_xyxy(b)
    inter = ((torch.minimum(a1[:, 2], b1[:, 2]) - torch.maximum(a1[:, 0], b1[:, 0])).clamp(0)
             * (torch.minimum(a1[:, 3], b1[:, 3]) - torch.maximum(a1[:, 1], b1[:, 1])).clamp(0))
    union = a[:, 2] * a[:, 3] + b[:, 2] * b[:, 3] - inter + eps
    iou = inter / union
    cw = torch.maximum(a1[:, 2], b1[:, 2]) - torch.minimum(a1[:, 0], b1[:, 0])
    ch = torch.maximum(a1[:, 3], b1[:, 3]) - torch.minimum(a1[:, 1], b1[:, 1])
    rho2 = ((a[:, :2] - b[:, :2]) ** 2).sum(1)
    v = (4 / math.pi ** 2) * (torch.atan(b[:, 2] / (b[:, 3] + eps))
                              - torch.atan(a[:, 2] / (a[:, 3] + eps))) ** 2
    with torch.no_grad():
        # (1 - iou) first: 1 + eps rounds to 1 in float32 and a perfect box would give 0/0
        alpha = v / ((1 - iou) + v + eps)
    return iou - rho2 / (cw ** 2 + ch ** 2 + eps) - alpha * v


def assign(targets: torch.Tensor, anchors: torch.Tensor, anchor_iou: float) -> torch.Tensor:
    """Match targets to anchors over all scales.

    ``targets``: (n, 6) [image, class, cx, cy, w, h] in input pixels; ``anchors``:
    (S, A, 2). Returns a bool (n, S, A) mask of positive (target, scale, anchor).
    """
    s, a = anchors.shape[:2]
    iou = wh_iou(targets[:, 4:6], anchors.reshape(-1, 2))
    mask = iou > anchor_iou
    if len(targets):
        mask[torch.arange(len(targets)), iou.argmax(1)] = True
    return mask.view(-1, s, a)


def ignored_cells(regions: torch.Tensor, shape: Sequence[int], stride: float) -> torch.Tensor:
    """Bool (B, H, W) grid: cells that could predict one of the ``regions`` ((n, 6) target
    rows [image, class, cx, cy, w, h], input pixels), whose centre lies inside one or that
    holds its centre."""
    out = torch.zeros(shape, dtype=torch.bool, device=regions.device)
    for b, _, cx, cy, w, h in regions.tolist():
        lo = [min(math.floor(c / stride), math.ceil((c - d / 2) / stride - 0.5))
              for c, d in ((cx, w), (cy, h))]
        hi = [max(math.floor(c / stride), math.floor((c + d / 2) / stride - 0.5))
              for c, d in ((cx, w), (cy, h))]
        out[int(b), max(lo[1], 0):hi[1] + 1, max(lo[0], 0):hi[0] + 1] = True
    return out


class YoloLoss(nn.Module):
    """Callable ``loss(heads, targets) -> (total, {'box', 'obj', 'cls'})``."""

    anchors: torch.Tensor           # (scales, A, 2) in input pixels (a buffer)

    def __init__(self, anchors: torch.Tensor | np.ndarray, anchor_iou: float = 0.25,
                 box_gain: float = 0.05, obj_gain: float = 1.0, cls_gain: float = 0.5,
                 balance: Sequence[float] | None = None) -> None:
        super().__init__()
        self.register_buffer('anchors', torch.as_tensor(anchors, dtype=torch.float32))
        self.anchor_iou = anchor_iou
        self.gains = (box_gain, obj_gain, cls_gain)
        self.balance = balance or (1.0,) * len(self.anchors)   # objectness weight per scale
        self.bce = nn.BCEWithLogitsLoss()

    def forward(self, heads: Sequence[torch.Tensor], targets: torch.Tensor
                ) -> tuple[torch.Tensor, dict[str, float]]:
        """Total weighted loss and its detached components for one batch."""
        dev = heads[0].device
        targets = targets.to(dev)
        regions = targets[targets[:, 1] == IGNORE_CLASS]
        targets = targets[targets[:, 1] != IGNORE_CLASS]
        mask = assign(targets, self.anchors, self.anchor_iou)
        l_box = l_obj = l_cls = torch.zeros((), device=dev)
        for s, (head, stride) in enumerate(zip(heads, STRIDES)):
            p = head_view(head, self.anchors.shape[1])
            tobj = torch.zeros_like(p[..., 4])
            # objectness weight: 0 on the cells of ignore regions, 1 elsewhere and on positives
            wobj = (~ignored_cells(regions, (p.shape[0],) + p.shape[2:4], stride))[:, None]
            wobj = wobj.expand_as(tobj).to(tobj.dtype).clone()
            ti, ai = mask[:, s].nonzero(as_tuple=True)
            if len(ti):
                t = targets[ti]
                b = t[:, 0].long()
                gx = (t[:, 2] / stride).long().clamp(0, p.shape[3] - 1)
                gy = (t[:, 3] / stride).long().clamp(0, p.shape[2] - 1)
                ps = p[b, ai, gy, gx]
                xy, wh = cell_xywh(ps.sigmoid(), torch.stack([gx, gy], 1), self.anchors[s, ai],
                                   stride)
                iou = ciou(torch.cat([xy, wh], 1), t[:, 2:6])
                l_box = l_box + (1 - iou).mean()
                tobj[b, ai, gy, gx] = iou.detach().clamp(0).to(tobj.dtype)
                wobj[b, ai, gy, gx] = 1.0
                tcls = torch.zeros_like(ps[:, 5:])
                tcls[torch.arange(len(t)), t[:, 1].long()] = 1.0
                l_cls = l_cls + self.bce(ps[:, 5:], tcls)
            bce = F.binary_cross_entropy_with_logits(p[..., 4], tobj, wobj, reduction='sum')
            l_obj = l_obj + self.balance[s] * bce / wobj.sum().clamp(min=1.0)
        gb, go, gc = self.gains
        total = gb * l_box + go * l_obj + gc * l_cls
        parts = {'box': l_box, 'obj': l_obj, 'cls': l_cls}
        return total, {k: float(v.detach()) for k, v in parts.items()}


def bernoulli_kl(student_logits: torch.Tensor, teacher_logits: torch.Tensor) -> torch.Tensor:
    """Element-wise KL(teacher || student) of Bernoulli outputs given as logits (>= 0, and 0
    where they agree): the soft-target BCE less the teacher's own entropy."""
    target = teacher_logits.sigmoid()
    return (F.binary_cross_entropy_with_logits(student_logits, target, reduction='none')
            - F.binary_cross_entropy_with_logits(teacher_logits, target, reduction='none'))


def distill_loss(student_heads: Sequence[torch.Tensor], teacher_heads: Sequence[torch.Tensor],
                 num_anchors: int, eps: float = 1e-9) -> tuple[torch.Tensor, dict[str, float]]:
    """Output distillation from a teacher detector with the same heads (e.g. the unpruned
    model a pruned one came from): ``(total, {'d_obj', 'd_box', 'd_cls'})``.

    Every output of these heads is a sigmoid, so each is matched with a Bernoulli KL. The
    objectness term is averaged over all cells; the box and class terms are weighted by the
    teacher's objectness (objectness-scaled distillation, Mehta and Ozturk 2018), because
    what the teacher says about box and class in a background cell, most of the grid, is
    noise that would drown the cells holding objects.
    """
    # sums that become tensors at the first head
    l_obj: Any = 0.0
    l_box: Any = 0.0
    l_cls: Any = 0.0
    for hs, ht in zip(student_heads, teacher_heads):
        ps, pt = head_view(hs, num_anchors), head_view(ht.detach(), num_anchors)
        kl = bernoulli_kl(ps, pt)
        w = pt[..., 4].sigmoid()
        norm = w.sum() + eps
        l_obj = l_obj + kl[..., 4].mean()
        l_box = l_box + (w * kl[..., :4].sum(-1)).sum() / norm
        l_cls = l_cls + (w * kl[..., 5:].sum(-1)).sum() / norm
    parts = {'d_obj': l_obj, 'd_box': l_box, 'd_cls': l_cls}
    return l_obj + l_box + l_cls, {k: float(v.detach()) for k, v in parts.items()}
