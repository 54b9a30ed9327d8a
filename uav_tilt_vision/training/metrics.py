"""COCO-style detection mAP.

``mean_ap`` uses pycocotools (the reference implementation) when it is importable and
falls back to ``coco_map``, a self-contained re-implementation of COCOeval's bbox
protocol with maxDets = 100: greedy matching of detections in descending score order to
the unmatched ground truth of highest IoU >= t, a monotone precision envelope sampled at
101 recall points, averaged over the IoU thresholds 0.50:0.05:0.95 and over the classes
that have ground truth. Both also give AP@0.5 per class and by COCO's object-area ranges
(small < 32^2 px <= medium < 96^2 px <= large): ground truth outside a range is ignored,
and so are the detections matched to it or, unmatched, outside the range themselves.

Inputs: ``preds`` one (N, 6) array [x1, y1, x2, y2, score, class] per image, ``gts``
one (M, 5) array [x1, y1, x2, y2, class] per image, in the same pixel frame; optionally
``ignores``, one (K, 5) array of the same kind per image: regions whose objects are in view
but not labelled (too little of them visible). They are COCO's crowd regions: never counted,
and a detection of their class that matches no label but lies inside one at the IoU
threshold (overlap measured as the share of the detection inside the region) is ignored.

``bootstrap`` resamples the images (or their worlds) to give these metrics' sampling
spread: a set of a few hundred scenes decides a goal one point wide only with its interval.
"""

import contextlib
import io
from dataclasses import dataclass
from typing import Any, Iterable, Sequence

import numpy as np
from numpy.typing import ArrayLike

from uav_tilt_vision.boxes import box_area, box_iou

# per-image arrays as callers pass them (numpy arrays or nested lists), or None
Rows = Iterable[ArrayLike] | None

IOU_THRESHOLDS = np.linspace(0.5, 0.95, 10)
RECALL_POINTS = np.linspace(0.0, 1.0, 101)
MAX_DETS = 100
AREA_RANGES = {'small': (0.0, 32.0 ** 2), 'medium': (32.0 ** 2, 96.0 ** 2),
               'large': (96.0 ** 2, 1e10)}   # px^2, COCO's, bounds inclusive as in COCOeval


def mean_ap(preds: Rows, gts: Rows, ignores: Rows = None) -> dict[str, Any]:
    """``coco_map``'s result plus 'backend', with pycocotools if available."""
    try:
        import pycocotools  # noqa: F401
    except ImportError:
        return {**coco_map(preds, gts, ignores),
                'backend': 'uav_tilt_vision.training.metrics.coco_map'}
    return {**pycocotools_map(preds, gts, ignores), 'backend': 'pycocotools'}


def as_rows(arrays: Rows, width: int, n: int = 0) -> list[np.ndarray]:
    """Per-image float arrays reshaped to (-1, width); ``n`` empty ones for None."""
    if arrays is None:
        return [np.zeros((0, width))] * n
    return [np.asarray(a, dtype=np.float64).reshape(-1, width) for a in arrays]


@dataclass(frozen=True)
class ClassMatches:
    """One class's detections over a set, matched image by image and sorted by descending
    score: what COCOeval's accumulate step reads."""

    tp: np.ndarray        # (thresholds, D) bool: matched a ground truth at IoU >= t
    ignored: np.ndarray   # (thresholds, D) bool: neither true nor false positive
    image: np.ndarray     # (D,) int: the image of each detection
    n_gt: np.ndarray      # (images,) int: counted ground truth of each image


def coco_map(preds: Rows, gts: Rows, ignores: Rows = None) -> dict[str, Any]:
    """COCO bbox mAP (101-point interpolated AP).

    {'map50', 'map50_95', 'ap50_per_class': {class id: AP@0.5}, 'map50_by_area': {range:
    mAP@0.5}}; nan (None for a range) where there is no ground truth to average over.
    """
    return summarize(set_matches(preds, gts, ignores))


def set_matches(preds: Rows, gts: Rows, ignores: Rows = None
                ) -> dict[tuple[str | None, int], ClassMatches]:
    """``class_matches`` of every class with ground truth, over all areas (key (None,
    class)) and in each of ``AREA_RANGES`` (key (range name, class))."""
    preds, gts = as_rows(preds, 6), as_rows(gts, 5)
    ignores = as_rows(ignores, 5, len(gts))
    classes = np.unique(np.concatenate([g[:, 4] for g in gts])).astype(int)
    ranges: list[tuple[str | None, tuple[float, float]]] = [(None, (0.0, np.inf))]
    ranges += AREA_RANGES.items()
    return {(name, int(c)): class_matches(preds, gts, ignores, c, rng)
            for name, rng in ranges for c in classes}


def summarize(matches: dict[tuple[str | None, int], ClassMatches],
              weights: np.ndarray | None = None) -> dict[str, Any]:
    """``coco_map``'s result from ``set_matches``, each image counted ``weights[i]`` times
    (once without)."""
    ap = {c: a for (name, c), m in matches.items() if name is None
          if (a := matches_ap(m, weights)) is not None}   # classes with ground truth
    if not ap:
        return {'map50': float('nan'), 'map50_95': float('nan'), 'ap50_per_class': {},
                'map50_by_area': dict.fromkeys(AREA_RANGES)}
    by_area = {}
    for name in AREA_RANGES:
        ap50 = [a[0] for (n, _), m in matches.items() if n == name
                if (a := matches_ap(m, weights, thresholds=1)) is not None]
        by_area[name] = float(np.mean(ap50)) if ap50 else None
    table = np.array(list(ap.values()))   # (classes, thresholds)
    return {'map50': float(table[:, 0].mean()), 'map50_95': float(table.mean()),
            'ap50_per_class': {c: float(a[0]) for c, a in ap.items()},
            'map50_by_area': by_area}


def outside(boxes: np.ndarray, area_rng: Sequence[float]) -> np.ndarray:
    """(N,) bool: the area (px^2) of an xyxy box is outside the inclusive ``area_rng``."""
    area = box_area(boxes)
    return (area < area_rng[0]) | (area > area_rng[1])


def class_matches(preds: Sequence[np.ndarray], gts: Sequence[np.ndarray],
                  ignores: Sequence[np.ndarray], cls: int,
                  area_rng: Sequence[float] = (0.0, np.inf)) -> ClassMatches:
    """Match one class's detections image by image; only ground truth whose area is in
    ``area_rng`` counts."""
    scores, matched, ignored, n_gt = [], [], [], []
    for p, g, ig in zip(preds, gts, ignores):
        p = p[p[:, 5] == cls]
        p = p[np.argsort(-p[:, 4], kind='mergesort')][:MAX_DETS]
        g, ig = g[g[:, 4] == cls], ig[ig[:, 4] == cls]
        g_ignored = outside(g[:, :4], area_rng)
        n_gt.append(int((~g_ignored).sum()))
        crowd = np.r_[np.zeros(len(g), bool), np.ones(len(ig), bool)]
        tp, d_ignored = match(p[:, :4], np.r_[g[:, :4], ig[:, :4]],
                              np.r_[g_ignored, np.ones(len(ig), bool)], crowd)
        scores.append(p[:, 4])
        matched.append(tp)
        ignored.append(d_ignored | (~tp & outside(p[:, :4], area_rng)))
    image = np.repeat(np.arange(len(scores)), [len(s) for s in scores])
    order = np.argsort(-np.concatenate(scores), kind='mergesort')
    return ClassMatches(np.concatenate(matched, 1)[:, order],
                        np.concatenate(ignored, 1)[:, order], image[order], np.array(n_gt))


def matches_ap(m: ClassMatches, weights: np.ndarray | None = None,
               thresholds: int = len(IOU_THRESHOLDS)) -> np.ndarray | None:
    """AP at the first ``thresholds`` IoU thresholds, image i counted ``weights[i]`` times
    (its detections repeated in score order, as in a set that holds it that often); None
    without counted ground truth."""
    tp, ignored = m.tp[:thresholds], m.ignored[:thresholds]
    n_gt = int(m.n_gt.sum())
    if weights is not None:
        n_gt = int(m.n_gt @ weights)
        tp, ignored = (np.repeat(a, weights[m.image], axis=1) for a in (tp, ignored))
    if n_gt == 0:
        return None
    return np.array([interpolated_ap(t[~i], n_gt) for t, i in zip(tp, ignored)])


def match(det: np.ndarray, gt: np.ndarray, gt_ignored: np.ndarray, crowd: np.ndarray
          ) -> tuple[np.ndarray, np.ndarray]:
    """Greedy COCO matching of score-sorted detections to ground truth.

    ``gt_ignored`` and ``crowd`` are (M,) bool; a crowd region is ignored, overlaps as the
    share of the detection inside it, and may match any number of detections.
    Returns (matched, ignored), each (thresholds, n_det) bool: the detection matched a
    ground truth at IoU >= t, and that ground truth was an ignored one.
    """
    tp = np.zeros((len(IOU_THRESHOLDS), len(det)), dtype=bool)
    ignored = np.zeros_like(tp)
    if len(det) == 0 or len(gt) == 0:
        return tp, ignored
    iou = box_iou(det, gt, crowd)
    for ti, t in enumerate(IOU_THRESHOLDS):
        taken = np.zeros(len(gt), dtype=bool)
        for d in range(len(det)):
            cand = np.where(taken, -1.0, iou[d])
            # a counted ground truth wins over an ignored one whatever their IoUs
            counted = np.where(gt_ignored, -1.0, cand)
            # COCOeval compares against min(t, 1 - 1e-10) with '<', so IoU == t matches
            thr = min(t, 1 - 1e-10)
            g = int(counted.argmax()) if counted.max() >= thr else int(cand.argmax())
            if cand[g] >= thr:
                taken[g] = not crowd[g]
                tp[ti, d] = True
                ignored[ti, d] = gt_ignored[g]
    return tp, ignored


def interpolated_ap(tp: np.ndarray, n_gt: int) -> float:
    """101-point interpolated AP from score-sorted true-positive flags and the gt count."""
    if len(tp) == 0:
        return 0.0
    tps = np.cumsum(tp)
    recall = tps / n_gt
    precision = tps / np.arange(1, len(tp) + 1)
    precision = np.maximum.accumulate(precision[::-1])[::-1]
    idx = np.searchsorted(recall, RECALL_POINTS, side='left')
    # recall levels never reached contribute precision 0
    sampled = np.where(idx < len(tp), precision[np.minimum(idx, len(tp) - 1)], 0.0)
    return float(sampled.mean())


def pycocotools_map(preds: Rows, gts: Rows, ignores: Rows = None) -> dict[str, Any]:
    """The same metrics computed by pycocotools' COCOeval (its default area ranges)."""
    from pycocotools.coco import COCO
    from pycocotools.cocoeval import COCOeval

    preds, gts = as_rows(preds, 6), as_rows(gts, 5)
    ignores = as_rows(ignores, 5, len(gts))
    classes = sorted({int(c) for g in gts for c in g[:, 4]})
    anns: list[dict[str, Any]] = []
    dets: list[dict[str, Any]] = []
    for i, (p, g, ig) in enumerate(zip(preds, gts, ignores)):
        for rows, crowd in ((g, 0), (ig, 1)):
            for x1, y1, x2, y2, c in rows:
                anns.append({'id': len(anns) + 1, 'image_id': i, 'category_id': int(c),
                             'bbox': [x1, y1, x2 - x1, y2 - y1],
                             'area': (x2 - x1) * (y2 - y1), 'iscrowd': crowd})
        for x1, y1, x2, y2, s, c in p:
            dets.append({'image_id': i, 'category_id': int(c),
                         'bbox': [x1, y1, x2 - x1, y2 - y1], 'score': s})
    if not classes or not dets:
        # COCOeval cannot load an empty result list; coco_map gives the same numbers
        return coco_map(preds, gts, ignores)
    with contextlib.redirect_stdout(io.StringIO()):  # COCO prints progress and a table
        gt = COCO()
        gt.dataset = {'images': [{'id': i} for i in range(len(gts))], 'annotations': anns,
                      'categories': [{'id': c} for c in classes]}
        gt.createIndex()
        ev = COCOeval(gt, gt.loadRes(dets), 'bbox')
        ev.evaluate()
        ev.accumulate()
        ev.summarize()
    # precision[threshold, recall, class, area range, max dets]; -1 where no ground truth
    ap50 = ev.eval['precision'][0, :, :, :, ev.params.maxDets.index(MAX_DETS)]
    by_area = {}
    for name in AREA_RANGES:
        a = ap50[:, :, ev.params.areaRngLbl.index(name)]
        by_area[name] = float(a[a > -1].mean()) if (a > -1).any() else None
    return {'map50': float(ev.stats[1]), 'map50_95': float(ev.stats[0]),
            'ap50_per_class': {c: float(ap50[:, k, 0].mean()) for k, c in enumerate(classes)},
            'map50_by_area': by_area}


def bootstrap(preds: Rows, gts: Rows, ignores: Rows = None, resamples: int = 100,
              seed: int = 0, groups: ArrayLike | None = None) -> list[dict[str, Any]]:
    """``coco_map``'s metrics of ``resamples`` draws of the images with replacement.

    Images, not objects, are resampled: objects of one scene share its camera and light.
    ``groups`` (one label per image) resamples whole groups instead: images of one world
    share its wall, textures and lighting, so a set of a few worlds varies as a few. The
    draws depend only on ``seed`` and the groups (or image count), so two models scored
    on one set with one seed are paired draw by draw. Detections are matched once; a draw
    only counts each image as often as it was drawn.
    """
    gts = as_rows(gts, 5)
    matches = set_matches(preds, gts, ignores)
    labels = np.arange(len(gts)) if groups is None else np.asarray(groups)
    keys, group_of = np.unique(labels, return_inverse=True)
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(resamples):
        drawn = np.bincount(rng.integers(0, len(keys), len(keys)), minlength=len(keys))
        out.append(summarize(matches, drawn[group_of]))
    return out


def percentile_interval(values: Iterable[float | None], level: float = 0.95
                        ) -> list[float] | None:
    """[low, high]: the central ``level`` of ``values`` (None entries and nan dropped)."""
    v = np.array([x for x in values if x is not None], dtype=np.float64)
    v = v[np.isfinite(v)]
    if len(v) == 0:
        return None
    q = 50.0 * (1.0 - level)
    return [float(np.percentile(v, q)), float(np.percentile(v, 100.0 - q))]


def confidence_intervals(samples: Sequence[dict[str, Any]], level: float = 0.95
                         ) -> dict[str, Any]:
    """Percentile-bootstrap intervals of ``bootstrap``'s metrics, keyed as ``mean_ap``'s."""
    classes = sorted({c for s in samples for c in s['ap50_per_class']})
    return {
        'level': level,
        'map50': percentile_interval((s['map50'] for s in samples), level),
        'map50_95': percentile_interval((s['map50_95'] for s in samples), level),
        'ap50_per_class': {c: percentile_interval(
            (s['ap50_per_class'].get(c) for s in samples), level) for c in classes},
        'map50_by_area': {a: percentile_interval(
            (s['map50_by_area'][a] for s in samples), level) for a in AREA_RANGES}}
