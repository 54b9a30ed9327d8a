"""Box tracking between detections with pyramidal KLT (article sec. 3.2), no rclpy."""
import dataclasses
from typing import Any

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from uav_tilt_common.config import param


@dataclasses.dataclass
class KltConfig:
    """KLT box tracker parameters."""

    max_corners: int = param(80, lo=8, hi=1000)
    quality_level: float = param(0.01, lo=1e-4, hi=0.5)
    min_distance_px: float = param(4.0, lo=1.0, hi=50.0)
    win_size_px: int = param(21, lo=5, hi=61)
    pyramid_levels: int = param(3, lo=0, hi=6)
    fb_max_error_px: float = param(1.0, lo=0.05, hi=10.0)   # forward-backward check
    ransac_threshold_px: float = param(2.0, lo=0.1, hi=20.0)
    min_points: int = param(8, lo=3, hi=500)                # fewer inliers: lost
    min_inlier_ratio: float = param(0.3, lo=0.0, hi=1.0)    # of the points tracked
    reseed_ratio: float = param(0.5, lo=0.0, hi=1.0)        # of the points picked at init
    max_scale_step: float = param(1.5, lo=1.01, hi=10.0)    # per update, either way


class KltBoxTracker:
    """Tracks an axis-aligned box with KLT feature points and a similarity transform."""

    def __init__(self, config: KltConfig | None = None) -> None:
        self.config = config or KltConfig()
        self._gray: np.ndarray = np.zeros((0, 0), np.uint8)   # set with the box by init
        self._pts: np.ndarray = np.zeros((0, 2), np.float32)
        self._n_seeded = 0
        self.box_xyxy: NDArray[np.float64] | None = None

    @property
    def lost(self) -> bool:
        """True until init and after an update that lost the target."""
        return self.box_xyxy is None

    @property
    def points(self) -> np.ndarray:
        """(N, 2) feature points being tracked; empty when lost."""
        return np.zeros((0, 2), np.float32) if self.lost else self._pts.copy()

    def init(self, gray: np.ndarray, box_xyxy: ArrayLike) -> bool:
        """Start tracking ``box_xyxy`` in ``gray``; returns False when it has too few features."""
        self.box_xyxy = np.asarray(box_xyxy, np.float64).copy()
        self._gray = gray
        self._pts = self._seed(gray, self.box_xyxy)
        self._n_seeded = len(self._pts)
        if self._n_seeded < self.config.min_points:
            self.box_xyxy = None
        return not self.lost

    def update(self, gray: np.ndarray) -> tuple[NDArray[np.float64] | None, float]:
        """Track into ``gray``: ``(box_xyxy, quality)``, or ``(None, 0.0)`` when lost.

        quality = inliers / points tracked into this frame, in [0, 1].
        """
        box = self.box_xyxy
        if box is None:
            return None, 0.0
        cfg = self.config
        prev = self._pts.reshape(-1, 1, 2)
        lk: dict[str, Any] = dict(
            winSize=(cfg.win_size_px, cfg.win_size_px), maxLevel=cfg.pyramid_levels,
            criteria=(cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01))
        # OpenCV 4's stubs require nextPts, which the function allocates when given None
        fwd, st_f, _ = cv2.calcOpticalFlowPyrLK(
            self._gray, gray, prev, None, **lk)  # type: ignore[call-overload, unused-ignore]
        back, st_b, _ = cv2.calcOpticalFlowPyrLK(
            gray, self._gray, fwd, None, **lk)  # type: ignore[call-overload, unused-ignore]
        fb_err = np.linalg.norm((back - prev).reshape(-1, 2), axis=1)
        ok = (st_f.ravel() == 1) & (st_b.ravel() == 1) & (fb_err < cfg.fb_max_error_px)
        src, dst = prev.reshape(-1, 2)[ok], fwd.reshape(-1, 2)[ok]
        n_tracked = len(prev)
        if len(src) < cfg.min_points:
            return self._lose()
        m, inl = cv2.estimateAffinePartial2D(src, dst, method=cv2.RANSAC,
                                             ransacReprojThreshold=cfg.ransac_threshold_px)
        if m is None:
            return self._lose()
        inl = inl.ravel().astype(bool)
        scale = float(np.hypot(m[0, 0], m[1, 0]))
        quality = inl.sum() / n_tracked
        if (inl.sum() < cfg.min_points or quality < cfg.min_inlier_ratio
                or not 1.0 / cfg.max_scale_step <= scale <= cfg.max_scale_step):
            return self._lose()
        self.box_xyxy = box = _move_box(box, m, scale)
        self._gray = gray
        self._pts = dst[inl]
        if len(self._pts) < cfg.reseed_ratio * self._n_seeded:
            self._pts = self._seed(gray, box)
            self._n_seeded = len(self._pts)
        return box.copy(), float(quality)

    def _lose(self) -> tuple[None, float]:
        self.box_xyxy = None
        return None, 0.0

    def _seed(self, gray: np.ndarray, box_xyxy: NDArray[np.float64]) -> np.ndarray:
        h, w = gray.shape[:2]
        x0, y0 = max(int(np.floor(box_xyxy[0])), 0), max(int(np.floor(box_xyxy[1])), 0)
        x1, y1 = min(int(np.ceil(box_xyxy[2])), w), min(int(np.ceil(box_xyxy[3])), h)
        if x1 - x0 < 3 or y1 - y0 < 3:
            return np.zeros((0, 2), np.float32)
        mask = np.zeros((h, w), np.uint8)
        mask[y0:y1, x0:x1] = 255
        cfg = self.config
        pts = cv2.goodFeaturesToTrack(gray, cfg.max_corners, cfg.quality_level,
                                      cfg.min_distance_px, mask=mask)
        return np.zeros((0, 2), np.float32) if pts is None else pts.reshape(-1, 2)


def _move_box(box_xyxy: NDArray[np.float64], m: NDArray[np.float64],
              scale: float) -> NDArray[np.float64]:
    """Move the box centre with the similarity ``m`` and scale its sides; rotation is
    not representable by an axis-aligned box and is ignored."""
    c = np.array([(box_xyxy[0] + box_xyxy[2]) / 2.0, (box_xyxy[1] + box_xyxy[3]) / 2.0])
    c_new = m[:, :2] @ c + m[:, 2]
    half = scale * np.array([box_xyxy[2] - box_xyxy[0], box_xyxy[3] - box_xyxy[1]]) / 2.0
    return np.concatenate([c_new - half, c_new + half])
