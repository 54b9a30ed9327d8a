"""COCO-style detection mAP.

``mean_ap`` uses pycocotools (the reference implementation) when it is importable and
falls back to ``coco_map``, a self-contained re-implementation of COCOeval's bbox
protocol for one area range ('all') and maxDets = 100: greedy matching of detections
in descending score order to the unmatched ground truth of highest IoU >= t, a
monotone precision envelope sampled at 101 recall points, averaged over the IoU
thresholds 0.50:0.05:0.95 and over the classes that have ground truth.

Inputs: ``preds`` one (N, 6) array [x1, y1, x2, y2, score, class] per image, ``gts``
one (M, 5) array [x1, y1, x2, y2, class] per image, in the same pixel frame.
"""

import contextlib
import io

import numpy as np

from uav_tilt_vision.boxes import box_iou

IOU_THRESHOLDS = np.linspace(0.5, 0.95, 10)
RECALL_POINTS = np.linspace(0.0, 1.0, 101)
MAX_DETS = 100


def mean_ap(preds, gts):
    """{'map50', 'map50_95', 'backend'} with pycocotools if available, else ``coco_map``."""
    try:
        import pycocotools  # noqa: F401
    except ImportError:
        return {**coco_map(preds, gts), 'backend': 'uav_tilt_vision.metrics.coco_map'}
    return {**pycocotools_map(preds, gts), 'backend': 'pycocotools'}


def coco_map(preds, gts):
    """COCO bbox mAP (101-point interpolated AP): {'map50', 'map50_95'}; nan without any gt."""
    preds = [np.asarray(p, dtype=np.float64).reshape(-1, 6) for p in preds]
    gts = [np.asarray(g, dtype=np.float64).reshape(-1, 5) for g in gts]
    classes = np.unique(np.concatenate([g[:, 4] for g in gts]))
    if len(classes) == 0:
        return {'map50': float('nan'), 'map50_95': float('nan')}
    ap = np.array([class_ap(preds, gts, c) for c in classes])  # (classes, thresholds)
    return {'map50': float(ap[:, 0].mean()), 'map50_95': float(ap.mean())}


def class_ap(preds, gts, cls):
    """AP of one class at every IoU threshold, shape (len(IOU_THRESHOLDS),)."""
    scores, matched = [], []
    n_gt = 0
    for p, g in zip(preds, gts):
        p = p[p[:, 5] == cls]
        p = p[np.argsort(-p[:, 4], kind='mergesort')][:MAX_DETS]
        g = g[g[:, 4] == cls]
        n_gt += len(g)
        scores.append(p[:, 4])
        matched.append(match(p[:, :4], g[:, :4]))
    scores = np.concatenate(scores)
    order = np.argsort(-scores, kind='mergesort')
    tp = np.concatenate(matched, 1)[:, order]
    return np.array([interpolated_ap(t, n_gt) for t in tp])


def match(det, gt):
    """(thresholds, n_det) bool: detection (score-sorted) matched a ground truth at IoU >= t."""
    tp = np.zeros((len(IOU_THRESHOLDS), len(det)), dtype=bool)
    if len(det) == 0 or len(gt) == 0:
        return tp
    iou = box_iou(det, gt)
    for ti, t in enumerate(IOU_THRESHOLDS):
        taken = np.zeros(len(gt), dtype=bool)
        for d in range(len(det)):
            cand = np.where(taken, -1.0, iou[d])
            g = int(cand.argmax())
            # COCOeval compares against min(t, 1 - 1e-10) with '<', so IoU == t matches
            if cand[g] >= min(t, 1 - 1e-10):
                taken[g] = tp[ti, d] = True
    return tp


def interpolated_ap(tp, n_gt):
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


def pycocotools_map(preds, gts):
    """The same metric computed by pycocotools' COCOeval: {'map50', 'map50_95'}."""
    from pycocotools.coco import COCO
    from pycocotools.cocoeval import COCOeval

    classes = sorted({int(c) for g in gts for c in np.asarray(g).reshape(-1, 5)[:, 4]})
    anns, dets = [], []
    for i, (p, g) in enumerate(zip(preds, gts)):
        for x1, y1, x2, y2, c in np.asarray(g, dtype=float).reshape(-1, 5):
            anns.append({'id': len(anns) + 1, 'image_id': i, 'category_id': int(c),
                         'bbox': [x1, y1, x2 - x1, y2 - y1], 'area': (x2 - x1) * (y2 - y1),
                         'iscrowd': 0})
        for x1, y1, x2, y2, s, c in np.asarray(p, dtype=float).reshape(-1, 6):
            dets.append({'image_id': i, 'category_id': int(c),
                         'bbox': [x1, y1, x2 - x1, y2 - y1], 'score': s})
    if not classes:
        return {'map50': float('nan'), 'map50_95': float('nan')}
    if not dets:
        return {'map50': 0.0, 'map50_95': 0.0}
    with contextlib.redirect_stdout(io.StringIO()):  # COCO prints progress and a table
        gt = COCO()
        gt.dataset = {'images': [{'id': i} for i in range(len(gts))], 'annotations': anns,
                      'categories': [{'id': c} for c in classes]}
        gt.createIndex()
        ev = COCOeval(gt, gt.loadRes(dets), 'bbox')
        ev.evaluate()
        ev.accumulate()
        ev.summarize()
    return {'map50': float(ev.stats[1]), 'map50_95': float(ev.stats[0])}
