"""YOLO-format data set reader, light augmentation, collate and k-means anchors.

Layout: ``DIR/images/<name>.png`` and ``DIR/labels/<name>.txt`` with one
``class cx cy w h`` line per object (normalised to the image size); optional
``DIR/ignore/<name>.txt`` in the same format give the regions of objects in view but too
little visible to label, which evaluation ignores (COCO's crowd regions); an optional
``DIR/meta.json`` may give ``seed`` and ``classes`` (list of names).
"""

import json
import os
from pathlib import Path
from typing import Any, Iterable, Sequence

import cv2
import numpy as np
import torch
from numpy.typing import ArrayLike, NDArray

from uav_tilt_common.config import ConfigError
from uav_tilt_vision.boxes import letterbox, wh_iou, xywh_to_xyxy, xyxy_to_xywh
from uav_tilt_vision.detector import IMG_SIZE

IMG_EXTS = ('.png', '.jpg', '.jpeg', '.bmp')
# Class of the target rows that are ignore regions, not labels: the loss does not score
# objectness there (``yolo_loss``).
IGNORE_CLASS = -1
# Hue, saturation and value jitter (fractions): the value range reaches well below the
# rendered exposures, so that dimmer lighting than any seen in training stays familiar.
HSV_GAINS = (0.015, 0.5, 0.5)


def read_meta(root: str | os.PathLike[str]) -> dict[str, Any]:
    """``DIR/meta.json`` as a dict ({} when absent)."""
    path = Path(root) / 'meta.json'
    return json.loads(path.read_text()) if path.is_file() else {}


def read_labels(path: str | os.PathLike[str], num_classes: int | None = None
                ) -> NDArray[np.float64]:
    """(n, 5) float array [class, cx, cy, w, h] (normalised) from a label file; missing = empty.

    ConfigError naming the file and line unless every line holds an integer class (below
    ``num_classes`` when given) and four finite numbers.
    """
    path = Path(path)
    text = path.read_text() if path.is_file() else ''
    rows = []
    for n, line in enumerate(text.splitlines(), 1):
        if line.strip():
            rows.append(_label_row(line, num_classes, f'{path}:{n}'))
    return np.array(rows, dtype=np.float64).reshape(-1, 5)


def _label_row(line: str, num_classes: int | None, where: str) -> list[float]:
    fields = line.split()
    try:
        row = [float(v) for v in fields]
    except ValueError:
        row = []
    if len(fields) != 5 or len(row) != 5 or not np.all(np.isfinite(row)):
        raise ConfigError(f'{where}: expected a label "class cx cy w h" (5 numbers), '
                          f'got {line.strip()!r}')
    cls = row[0]
    if not (cls.is_integer() and 0 <= cls < (num_classes or np.inf)):
        known = f'0 to {num_classes - 1}' if num_classes else 'an integer of at least 0'
        raise ConfigError(f'{where}: class {fields[0]!r} is not a known class ({known})')
    return row


def hsv_jitter(img: np.ndarray, gains: Sequence[float], rng: np.random.Generator) -> np.ndarray:
    """Random hue/saturation/value gains (fractions, YOLOv5 style) on a uint8 RGB image."""
    r = rng.uniform(-1, 1, 3) * np.asarray(gains) + 1
    hue, sat, val = cv2.split(cv2.cvtColor(img, cv2.COLOR_RGB2HSV))
    x = np.arange(256, dtype=np.float64)
    luts = [((x * r[0]) % 180).astype(np.uint8), np.clip(x * r[1], 0, 255).astype(np.uint8),
            np.clip(x * r[2], 0, 255).astype(np.uint8)]
    hsv = cv2.merge([cv2.LUT(c, lut) for c, lut in zip((hue, sat, val), luts)])
    return cv2.cvtColor(hsv, cv2.COLOR_HSV2RGB)


class YoloDataset(torch.utils.data.Dataset):
    """Letterboxed images and targets in input pixels.

    Items are ``(image (3, H, W) float in [0, 1], targets (n, 6))`` with targets
    ``[0, class, cx, cy, w, h]``; ``collate`` fills column 0 with the batch index. The
    image's ignore regions follow its labels as rows of class ``IGNORE_CLASS``.
    Augmentation draws from an RNG seeded by (seed, epoch, index), so results do not
    depend on worker processes. Enable ``hflip`` only for mirror-symmetric classes.
    ``crop`` (w, h), with ``augment``: train on a window around a random object
    (``random_crop``), at full scale: cheaper steps, same object sizes as at inference.
    """

    def __init__(self, root: str | os.PathLike[str], img_size: Sequence[int] = IMG_SIZE,
                 augment: bool = False, hflip: bool = False,
                 hsv: Sequence[float] = HSV_GAINS, seed: int = 0,
                 crop: Sequence[int] | None = None) -> None:
        self.root = Path(root)
        self.images = sorted(p for p in (self.root / 'images').iterdir()
                             if p.suffix.lower() in IMG_EXTS)
        if not self.images:
            raise FileNotFoundError(f'no images in {self.root / "images"}')
        if not (self.root / 'labels').is_dir():     # else every image reads as background
            raise ConfigError(f'{self.root}: no labels/ folder beside images/')
        self.num_classes = len(read_meta(self.root).get('classes') or ()) or None
        self.img_size = tuple(img_size)
        self.augment, self.hflip, self.hsv = augment, hflip, hsv
        self.seed, self.epoch, self.crop = seed, 0, crop

    def __len__(self) -> int:
        return len(self.images)

    def set_epoch(self, epoch: int) -> None:
        """Select the augmentation draw for this epoch."""
        self.epoch = epoch

    def read_rgb(self, i: int) -> np.ndarray:
        """Original image i as uint8 RGB."""
        bgr = cv2.imread(str(self.images[i]), cv2.IMREAD_COLOR)
        if bgr is None:
            raise ConfigError(f'{self.images[i]}: not a readable image')
        return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)

    def labels(self, i: int, folder: str = 'labels') -> NDArray[np.float64]:
        """Normalised labels of image i, (n, 5) [class, cx, cy, w, h]; ``folder='ignore'``
        gives its ignore regions instead."""
        return read_labels(self.root / folder / (self.images[i].stem + '.txt'),
                           self.num_classes)

    def ground_truth(self, i: int, shape: Sequence[int], folder: str = 'labels'
                     ) -> NDArray[np.float64]:
        """(n, 5) [x1, y1, x2, y2, class] in pixels of image i, whose (H, W, ...) is ``shape``;
        ``folder='ignore'`` gives its ignore regions instead."""
        h, w = shape[:2]
        lab = self.labels(i, folder)
        xyxy = xywh_to_xyxy(lab[:, 1:] * [w, h, w, h])
        return np.concatenate([xyxy, lab[:, :1]], 1)

    def load(self, i: int) -> tuple[np.ndarray, NDArray[np.float64]]:
        """Letterboxed uint8 RGB image and (n, 5) [class, cx, cy, w, h] in input pixels: the
        labels, then the ignore regions (class ``IGNORE_CLASS``)."""
        img = self.read_rgb(i)
        h, w = img.shape[:2]
        out, scale, pad = letterbox(img, self.img_size)
        ignore = self.labels(i, 'ignore')
        ignore[:, 0] = IGNORE_CLASS
        lab = np.concatenate([self.labels(i), ignore])
        boxes = lab[:, 1:] * [w, h, w, h] * scale + [pad[0], pad[1], 0, 0]
        return out, np.concatenate([lab[:, :1], boxes], 1)

    def __getitem__(self, i: int) -> tuple[torch.Tensor, torch.Tensor]:
        img, lab = self.load(i)
        if self.augment:
            rng = np.random.default_rng([self.seed, self.epoch, i])
            if self.crop:
                img, lab = random_crop(img, lab, self.crop, rng)
            if any(self.hsv):  # the uint8 HSV round trip is lossy: skip it when disabled
                img = hsv_jitter(img, self.hsv, rng)
            if self.hflip and rng.random() < 0.5:
                img = np.ascontiguousarray(img[:, ::-1])
                lab[:, 1] = img.shape[1] - lab[:, 1]
        # float conversion in numpy: torch's strided uint8 -> float copy is several times slower
        x = torch.from_numpy(img.transpose(2, 0, 1).astype(np.float32) / np.float32(255.0))
        t = torch.zeros((len(lab), 6))
        t[:, 1:] = torch.from_numpy(lab)
        return x, t

    def label_wh(self) -> NDArray[np.float64]:
        """All label sizes (n, 2) in input pixels (for anchor clustering)."""
        labs = (self.load(i)[1] for i in range(len(self)))
        return np.concatenate([lab[lab[:, 0] != IGNORE_CLASS, 3:5] for lab in labs], 0)


def random_crop(img: np.ndarray, lab: NDArray[np.float64], size: Sequence[int],
                rng: np.random.Generator, min_kept: float = 0.4
                ) -> tuple[np.ndarray, NDArray[np.float64]]:
    """A (w, h) window holding a random labelled object (anywhere, if none) and its labels.

    Boxes are clipped to the window; a label keeping less than ``min_kept`` of its area
    becomes an ignore region (like the data set's visibility rule), and boxes left with no
    area are dropped.
    """
    w, h = size
    H, W = img.shape[:2]
    labelled = np.flatnonzero(lab[:, 0] != IGNORE_CLASS)
    if len(labelled):
        cx, cy = lab[labelled[int(rng.integers(len(labelled)))], 1:3]
        x0, y0 = rng.uniform([cx - w, cy - h], [cx, cy])
    else:
        x0, y0 = rng.uniform([0, 0], [W - w, H - h])
    x0, y0 = int(np.clip(x0, 0, W - w)), int(np.clip(y0, 0, H - h))
    xyxy = xywh_to_xyxy(lab[:, 1:]) - [x0, y0, x0, y0]
    clipped = np.clip(xyxy, 0, [w, h, w, h])
    area = np.prod(clipped[:, 2:] - clipped[:, :2], 1)
    cls = np.where(area >= min_kept * lab[:, 3] * lab[:, 4], lab[:, 0], IGNORE_CLASS)
    keep = area > 0
    out = np.concatenate([cls[keep, None], xyxy_to_xywh(clipped[keep])], 1)
    return np.ascontiguousarray(img[y0:y0 + h, x0:x0 + w]), out


def collate(batch: Iterable[tuple[torch.Tensor, torch.Tensor]]
            ) -> tuple[torch.Tensor, torch.Tensor]:
    """Stack images; concatenate targets with column 0 = index in the batch."""
    images, targets = zip(*batch)
    for k, t in enumerate(targets):
        t[:, 0] = k
    return torch.stack(images), torch.cat(targets, 0)


def kmeans_anchors(wh: ArrayLike, num_scales: int = 2, per_scale: int = 3,
                   iters: int = 300) -> NDArray[np.float64]:
    """Cluster box sizes with the 1 - IoU distance (YOLOv2) into detector-ordered anchors.

    Returns (num_scales, per_scale, 2) sorted so that scale 0 holds the largest
    anchors (it is the stride-32 head) and each scale is ordered by area.
    """
    wh = np.asarray(wh, dtype=np.float64).reshape(-1, 2)
    k = num_scales * per_scale
    distinct = np.unique(wh, axis=0)
    if len(distinct) < k:
        raise ValueError(f'need at least {k} distinct box sizes, got {len(distinct)}')
    # deterministic start at area quantiles: one centre per size band, no seed needed
    distinct = distinct[np.argsort(distinct.prod(1), kind='stable')]
    centres = distinct[((np.arange(k) + 0.5) * len(distinct) / k).astype(int)]
    for _ in range(iters):
        assign = wh_iou(wh, centres).argmax(1)
        new = np.array([wh[assign == j].mean(0) if np.any(assign == j) else centres[j]
                        for j in range(k)])
        if np.allclose(new, centres):
            break
        centres = new
    centres = centres[np.argsort(centres.prod(1))]
    return centres.reshape(num_scales, per_scale, 2)[::-1].copy()
