"""Point of interest inside a detection box by morphology (article sec. 3.2), no rclpy.

The POI is the centre of the bolt head: the darkest compact blob near the box
centre, surrounded by a lighter, fairly uniform plate.
"""
from typing import Any, Iterator, Sequence

import cv2
import numpy as np

MARGIN_FRAC = 0.10          # crop margin around the box, fraction of the box side
AREA_FRAC_RANGE = (0.006, 0.06)  # blob area / box area (a bolt head is ~0.02 of its plate)
MIN_AXIS_RATIO = 0.55       # minor/major inertia axes: a round head seen up to ~55 deg
MIN_SOLIDITY = 0.85         # blob area / convex hull area
MAX_CENTRE_DIST_FRAC = 0.35  # blob centroid to box centre, fraction of the box half-diagonal
MIN_REL_CONTRAST = 0.35     # (surround - blob) / surround mean grey
MIN_CONTRAST_OVER_STD = 2.5  # surround - blob, in standard deviations of the surround
# A box smaller than this (a plate 4-5 m away: 12-15 px) is resampled to it first: its
# bolt head is a pixel or two, too small for the area and shape tests at native size.
MIN_BOX_PX = 40


def find_poi(rgb: np.ndarray, box_xyxy: Sequence[float] | np.ndarray
             ) -> tuple[float, float, float] | None:
    """POI ``(u_px, v_px, score)`` in image pixels inside ``box_xyxy``, or None.

    ``score`` in (0, 1] grows with the blob's compactness, contrast and centrality.
    """
    h_img, w_img = rgb.shape[:2]
    x0, y0, x1, y1 = (float(c) for c in box_xyxy)
    bw, bh = x1 - x0, y1 - y0
    if bw < 4 or bh < 4:
        return None
    m = MARGIN_FRAC * max(bw, bh)
    cx0, cy0 = max(int(np.floor(x0 - m)), 0), max(int(np.floor(y0 - m)), 0)
    cx1, cy1 = min(int(np.ceil(x1 + m)), w_img), min(int(np.ceil(y1 + m)), h_img)
    if cx1 - cx0 < 4 or cy1 - cy0 < 4:
        return None
    gray = cv2.cvtColor(np.ascontiguousarray(rgb[cy0:cy1, cx0:cx1]), cv2.COLOR_RGB2GRAY)
    zoom = max(MIN_BOX_PX / min(bw, bh), 1.0)
    if zoom > 1.0:
        gray = cv2.resize(gray, None, fx=zoom, fy=zoom, interpolation=cv2.INTER_CUBIC)
        bw, bh = bw * zoom, bh * zoom
    gray = cv2.GaussianBlur(gray, (3, 3), 0)
    box_c = np.array([(x0 + x1) / 2.0 - cx0, (y0 + y1) / 2.0 - cy0]) * zoom
    mask = _dark_mask(gray, box_c, bw, bh)
    best = None
    for blob in _blobs(mask, gray, bw * bh):
        dist = np.hypot(*(blob['centroid'] - box_c)) / (0.5 * np.hypot(bw, bh))
        if dist > MAX_CENTRE_DIST_FRAC:
            continue
        score = blob['quality'] * (1.0 - dist / MAX_CENTRE_DIST_FRAC * 0.5)
        if best is None or dist < best[0]:
            best = (dist, blob['centroid'], score)
    if best is None:
        return None
    # back to source pixel indices (cv2.resize aligns pixel centres, not corners)
    u, v = (best[1] + 0.5) / zoom - 0.5
    return float(u + cx0), float(v + cy0), float(best[2])


def _dark_mask(gray: np.ndarray, box_c: np.ndarray, bw: float, bh: float) -> np.ndarray:
    """Otsu on the box's central half (plate + head, no background), opened and closed."""
    qx0, qx1 = int(box_c[0] - bw / 4), int(np.ceil(box_c[0] + bw / 4))
    qy0, qy1 = int(box_c[1] - bh / 4), int(np.ceil(box_c[1] + bh / 4))
    centre = gray[max(qy0, 0):qy1, max(qx0, 0):qx1]
    if centre.size < 16:
        return np.zeros_like(gray)  # box centre off the image: nothing to threshold
    thr, _ = cv2.threshold(centre.reshape(-1, 1), 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    mask: np.ndarray = (gray <= thr).astype(np.uint8)
    # A small kernel: it removes specks and holes but must not carve thin dark strokes
    # (needles, letters) into compact blobs that look like a bolt head.
    k = max(int(round(0.01 * min(bw, bh))), 1) * 2 + 1
    if min(bw, bh) >= 40:
        kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k))
        mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, kernel)
        mask = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, kernel)
    return mask


def _blobs(mask: np.ndarray, gray: np.ndarray, box_area: float
           ) -> Iterator[dict[str, Any]]:
    """Dark components that pass the size, shape and contrast tests, with a quality in (0, 1]."""
    n, labels, stats, centroids = cv2.connectedComponentsWithStats(mask, connectivity=8)
    h, w = mask.shape
    for i in range(1, n):
        x, y, bw, bh, area = stats[i]
        if x == 0 or y == 0 or x + bw == w or y + bh == h:
            continue  # touches the crop border: background, not a head on the plate
        if not AREA_FRAC_RANGE[0] <= area / box_area <= AREA_FRAC_RANGE[1]:
            continue
        comp = (labels == i).astype(np.uint8)
        mom = cv2.moments(comp, binaryImage=True)
        cov = np.array([[mom['mu20'], mom['mu11']], [mom['mu11'], mom['mu02']]]) / area
        ev = np.linalg.eigvalsh(cov)
        axis_ratio = np.sqrt(max(ev[0], 0.0) / ev[1]) if ev[1] > 0 else 0.0
        contours, _ = cv2.findContours(comp, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        hull_area = cv2.contourArea(cv2.convexHull(contours[0]))
        # Pixel blobs have ~half a pixel more area than their polygon contour.
        solidity = min(area / (hull_area + 0.5 * cv2.arcLength(contours[0], True) + 1.0), 1.0)
        if axis_ratio < MIN_AXIS_RATIO or solidity < MIN_SOLIDITY:
            continue
        contrast = _surround_contrast(comp, gray, area)
        if contrast is None:
            continue
        yield {'centroid': np.array([mom['m10'] / mom['m00'], mom['m01'] / mom['m00']]),
               'quality': axis_ratio * solidity * min(contrast, 1.0)}


def _surround_contrast(comp: np.ndarray, gray: np.ndarray, area: float) -> float | None:
    """Relative contrast of a blob against the annulus [1.3 r, 2 r] around it, or None."""
    r = np.sqrt(area / np.pi)
    inner = cv2.dilate(comp, _disc(0.3 * r))
    outer = cv2.dilate(comp, _disc(1.0 * r))
    ring = (outer > 0) & (inner == 0)
    if not ring.any():
        return None
    blob_mean = float(gray[comp > 0].mean())
    ring_vals = gray[ring].astype(np.float32)
    ring_mean, ring_std = float(ring_vals.mean()), float(ring_vals.std())
    diff = ring_mean - blob_mean
    if ring_mean <= 0 or diff < MIN_REL_CONTRAST * ring_mean:
        return None
    if diff < MIN_CONTRAST_OVER_STD * ring_std:
        return None
    return diff / ring_mean


def _disc(radius_px: float) -> np.ndarray:
    k = 2 * max(int(round(radius_px)), 1) + 1
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k))
