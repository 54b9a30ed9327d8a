"""Per-frame vision pipeline of article sec. 3.2: detect, track, POI, target pose. No rclpy.

Every ``detect_every`` frames (and whenever the track is lost or its quality drops) the
CNN detector runs; of its target-class boxes the one that continues the track (the best
overlap with the tracked box) is tracked on, else the highest-scoring one; in between,
the KLT tracker carries that box. A frame without one is looked at again through a
magnified tile (a far target is a dozen pixels). Inside each box the POI (bolt head) is
found by morphology, and the depth image around it gives the 3D point, the surface normal and
their covariance in the camera optical frame. Every target-class box of a frame with a
POI is a candidate (the tracked one first), so that the controller can pick the one it
is after among look-alikes. Every ``planes.every`` frames (one without a detector run when
it can) the depth image's large planes (walls, the ground) are looked for too, for a search
that faces the wall.
"""
import contextlib
import dataclasses
import time
from typing import Any, Iterator, Protocol

import cv2
import numpy as np
from numpy.typing import NDArray

from uav_tilt_common.config import nested, param
from uav_tilt_common.planes import Plane
from uav_tilt_common.targets import OBJECT_CLASSES, TargetCandidate
from uav_tilt_vision.boxes import box_iou
from uav_tilt_vision.klt_tracker import KltBoxTracker, KltConfig
from uav_tilt_vision.planes import PlaneConfig, find_planes
from uav_tilt_vision.poi import find_poi
from uav_tilt_vision.target_pose import CameraIntrinsics, estimate_target_pose, \
    pose_quaternion_from_normal

STAGES = ('detector', 'tracker', 'poi', 'pose', 'planes')
# vision/status's latency and share statistics cover the last frames
STATS_WINDOW = 100
MAX_CANDIDATES = 6
# A detection continues the track when it overlaps the tracked box at least this much.
TRACK_IOU = 0.3


@dataclasses.dataclass
class VisionConfig:
    """Parameters of :class:`VisionPipeline`."""

    detect_every: int = param(5, lo=1, hi=1000,
                              doc='run the detector every N frames, the KLT tracker between')
    conf_thres: float = param(0.25, lo=0.0, hi=1.0, doc='detector score threshold')
    iou_thres: float = param(0.45, lo=0.0, hi=1.0, doc='non-maximum suppression IoU')
    zoom: float = param(2.0, lo=1.0, hi=4.0,
                        doc='a frame without a target-class box is looked at again, one tile '
                            'magnified this much (around the lost box, else the next of a '
                            'grid): small, far targets; 1 = off')
    zoom_beyond_m: float = param(3.0, lo=0.0, hi=100.0, unit='m',
                                 doc='the magnified look only at a tile whose median depth is '
                                     'beyond this (nearer, a target is big enough unmagnified)')
    target_class: str = param('bolt_plate', choices=OBJECT_CLASSES, doc='class to inspect')
    min_track_quality: float = param(0.5, lo=0.0, hi=1.0,
                                     doc='KLT inlier ratio below which the frame is re-detected')
    pose_window_px: int = param(10, lo=2, hi=50, doc='half side of the plane-fit window')
    pixel_sigma_px: float = param(0.5, lo=0.01, hi=10.0,
                                  doc='POI pixel noise (pose covariance)')
    klt: KltConfig = nested(KltConfig)
    planes: PlaneConfig = nested(PlaneConfig)


@dataclasses.dataclass
class FrameResult:
    """What the pipeline made of one frame (camera optical frame, metres)."""

    stamp_s: float
    found: bool = False
    p_cam: np.ndarray | None = None        # POI position
    q_cam: np.ndarray | None = None        # (x, y, z, w) of the target frame, z = normal
    covariance: np.ndarray | None = None   # 6x6: x, y, z, rot x, rot y, rot z
    box_xyxy: np.ndarray | None = None     # target box (detected or tracked), image pixels
    poi_px: tuple[float, float] | None = None   # (u, v)
    detected: bool = False          # the detector ran on this frame
    tracked: bool = False           # the box came from the tracker
    track_points: np.ndarray | None = None  # (N, 2) KLT points after this frame
    candidates: list[TargetCandidate] = dataclasses.field(
        default_factory=list)       # tracked first
    planes: list[Plane] | None = None   # None: not looked for in this frame
    timings_ms: dict[str, float] = dataclasses.field(
        default_factory=lambda: dict.fromkeys(STAGES, 0.0))


class FrameDetector(Protocol):
    """What the pipeline needs of a detector (uav_tilt_vision.backends has two)."""

    def predict(self, images: Any, conf_thres: float = ..., iou_thres: float = ...) -> Any:
        """(N, 6) [x1, y1, x2, y2, score, class] in image pixels for one RGB image."""


class VisionPipeline:
    """Stateful per-frame processing; ``detector.predict(rgb) -> (N, 6)`` or None (no model)."""

    def __init__(self, detector: FrameDetector | None, intrinsics: CameraIntrinsics | None,
                 config: VisionConfig | None = None) -> None:
        """``intrinsics`` may be None until they are known (the node's first camera_info);
        :meth:`process` needs them."""
        self.detector = detector
        self.intrinsics = intrinsics
        self.config = config or VisionConfig()
        self.target_class = OBJECT_CLASSES.index(self.config.target_class)
        self.tracker = KltBoxTracker(self.config.klt)
        self._since_detect = self.config.detect_every   # detect on the first frame
        self._last_box: NDArray[np.float64] | None = None   # the tracked box of the frame before
        self._track_score = 0.0     # the detector's score of the tracked box
        self._next_tile = 0         # the zoom grid's tile to look at next
        self._since_planes = 0

    def process(self, rgb: NDArray[np.uint8], depth_m: NDArray[np.floating[Any]],
                stamp_s: float) -> FrameResult:
        """One frame: uint8 RGB (H, W, 3) and depth (H, W) metres -> :class:`FrameResult`."""
        res = FrameResult(stamp_s)
        gray = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
        boxes: list[tuple[NDArray[np.float64], float]] | None = None
        if self._since_detect < self.config.detect_every:
            tracked = self._track(gray, res)
            boxes = None if tracked is None else [(tracked, self._track_score)]
        if boxes is None:
            boxes = self._detect(rgb, gray, depth_m, res)
        self._since_detect += 1
        self._look_for_planes(depth_m, res)
        if not boxes:
            return res
        res.box_xyxy = boxes[0][0]
        res.track_points = self.tracker.points
        for k, (box, score) in enumerate(boxes):
            est = self._pose_in(rgb, depth_m, box, res, k == 0)
            if est is None:
                continue
            p_cam, n_cam, cov = est
            res.candidates.append(TargetCandidate(p_cam, n_cam, cov[:3, :3], float(score),
                                                  self.target_class))
            if k == 0:
                res.p_cam, res.covariance = p_cam, cov
                res.q_cam = pose_quaternion_from_normal(n_cam)
                res.found = True
        return res

    def _look_for_planes(self, depth_m: NDArray[np.floating[Any]], res: FrameResult) -> None:
        """The depth image's planes every ``planes.every`` frames, on a frame the detector
        did not run on (their costs do not add up) unless that waits another period."""
        every = self.config.planes.every
        self._since_planes += 1
        if not every or self._since_planes < every or (
                res.detected and self._since_planes < 2 * every):
            return
        self._since_planes = 0
        with _timer(res, 'planes'):
            res.planes = find_planes(depth_m, self._camera(), self.config.planes)

    def _pose_in(self, rgb: NDArray[np.uint8], depth_m: NDArray[np.floating[Any]],
                 box: NDArray[np.float64], res: FrameResult, tracked: bool
                 ) -> tuple[NDArray[np.float64], NDArray[np.float64],
                            NDArray[np.float64]] | None:
        """(p_cam, n_cam, 6x6 covariance) of the POI in ``box``, or None."""
        with _timer(res, 'poi'):
            poi = find_poi(rgb, box)
        if poi is None:
            return None
        if tracked:
            res.poi_px = poi[:2]
        with _timer(res, 'pose'):
            return estimate_target_pose(poi[0], poi[1], depth_m, self._camera(),
                                        self.config.pose_window_px, self.config.pixel_sigma_px)

    def _camera(self) -> CameraIntrinsics:
        """The intrinsics; a frame before them is the caller's error (the node drops those)."""
        if self.intrinsics is None:
            raise ValueError('no camera intrinsics yet')
        return self.intrinsics

    def _track(self, gray: np.ndarray, res: FrameResult) -> NDArray[np.float64] | None:
        """The tracked box, or None when lost or of too low quality (then: re-detect)."""
        if self.tracker.lost:
            return None
        with _timer(res, 'tracker'):
            box, quality = self.tracker.update(gray)
        if box is None or quality < self.config.min_track_quality or not _on_image(box, gray):
            return None
        res.tracked = True
        self._last_box = box
        return box

    def _detect(self, rgb: NDArray[np.uint8], gray: np.ndarray,
                depth_m: NDArray[np.floating[Any]], res: FrameResult
                ) -> list[tuple[NDArray[np.float64], float]]:
        """Run the detector; [(box, score)] of its target-class boxes, the one to track
        first (the track's continuation, else the best); start tracking that one."""
        self._since_detect = 0
        res.detected = self.detector is not None
        boxes: list[tuple[NDArray[np.float64], float]] = []
        if self.detector is not None:
            with _timer(res, 'detector'):
                dets = self._target_boxes(np.asarray(self.detector.predict(
                    rgb, self.config.conf_thres, self.config.iou_thres)))
                if not len(dets) and self.config.zoom > 1.0:
                    dets = self._target_boxes(self._zoomed(rgb, depth_m))
            mine = dets[np.argsort(-dets[:, 4])][:MAX_CANDIDATES] if len(dets) else dets
            if len(mine):
                first = 0
                if self._last_box is not None:
                    overlap = box_iou(self._last_box[None], mine[:, :4].astype(np.float64))[0]
                    if overlap.max() >= TRACK_IOU:
                        first = int(np.argmax(overlap))
                order = [first] + [k for k in range(len(mine)) if k != first]
                boxes = [(mine[k, :4].astype(np.float64), float(mine[k, 4])) for k in order]
        self.tracker = KltBoxTracker(self.config.klt)    # nothing tracked without a box
        self._last_box = boxes[0][0] if boxes else None
        self._track_score = boxes[0][1] if boxes else 0.0
        if boxes:
            with _timer(res, 'tracker'):
                self.tracker.init(gray, boxes[0][0])
        return boxes

    def _target_boxes(self, dets: np.ndarray) -> np.ndarray:
        return dets[dets[:, 5].astype(int) == self.target_class] if len(dets) else dets

    def _zoomed(self, rgb: NDArray[np.uint8], depth_m: NDArray[np.floating[Any]]
                ) -> np.ndarray:
        """Detections in one tile of 1/zoom the frame's side, magnified to the frame's
        size and mapped back: centred on the box lost (its target is still there), else
        the next of a grid of half-overlapping tiles (every object smaller than half a
        tile lies whole in one of them). Nothing on a tile nearer than zoom_beyond_m."""
        assert self.detector is not None
        h, w = rgb.shape[:2]
        zoom = self.config.zoom
        tw, th = int(round(w / zoom)), int(round(h / zoom))
        if self._last_box is not None:
            cx, cy = (self._last_box[:2] + self._last_box[2:]) / 2.0
            x0, y0 = cx - tw / 2.0, cy - th / 2.0
        else:
            n = int(np.ceil(2.0 * zoom)) - 1          # tiles per axis
            k, self._next_tile = self._next_tile % (n * n), self._next_tile + 1
            x0, y0 = (k % n) * (w - tw) / max(n - 1, 1), (k // n) * (h - th) / max(n - 1, 1)
        x0 = int(round(min(max(x0, 0.0), w - tw)))
        y0 = int(round(min(max(y0, 0.0), h - th)))
        # a sparse median: the tile's distance, not its detail
        depth = depth_m[y0:y0 + th:4, x0:x0 + tw:4]
        depth = depth[np.isfinite(depth)]
        if not depth.size or np.median(depth) <= self.config.zoom_beyond_m:
            return np.zeros((0, 6))
        tile = cv2.resize(rgb[y0:y0 + th, x0:x0 + tw], (w, h), interpolation=cv2.INTER_LINEAR)
        dets = np.array(self.detector.predict(tile, self.config.conf_thres,
                                              self.config.iou_thres), dtype=np.float64)
        if len(dets):
            dets[:, [0, 2]] = dets[:, [0, 2]] * (tw / w) + x0
            dets[:, [1, 3]] = dets[:, [1, 3]] * (th / h) + y0
        return dets


def check_frame(rgb: np.ndarray, depth_m: np.ndarray, intrinsics: CameraIntrinsics
                ) -> str | None:
    """Why a frame cannot be processed (a short reason), or None when it can."""
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.dtype != np.uint8:
        return 'rgb_format'
    if rgb.size == 0 or depth_m.size == 0:
        return 'empty'
    size = (intrinsics.height, intrinsics.width)
    if rgb.shape[:2] != size or depth_m.shape != size:
        return 'size'
    if not np.isfinite(depth_m).any():
        return 'depth_invalid'
    return None


def draw_debug(rgb: NDArray[np.uint8], result: FrameResult) -> NDArray[np.uint8]:
    """Copy of ``rgb`` with the box (green: detected, yellow: tracked), KLT points, POI."""
    img = np.ascontiguousarray(rgb).copy()
    if result.box_xyxy is not None:
        x0, y0, x1, y1 = (int(round(c)) for c in result.box_xyxy)
        colour = (255, 220, 0) if result.tracked else (0, 230, 0)
        cv2.rectangle(img, (x0, y0), (x1, y1), colour, 1)
    if result.track_points is not None:
        for u, v in result.track_points:
            cv2.circle(img, (int(round(u)), int(round(v))), 1, (0, 160, 255), -1)
    if result.poi_px is not None:
        u, v = (int(round(c)) for c in result.poi_px)
        cv2.drawMarker(img, (u, v), (255, 0, 0), cv2.MARKER_CROSS, 9, 1)
    if result.found and result.p_cam is not None:
        cv2.putText(img, f'{result.p_cam[2]:.2f} m', (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.4,
                    (255, 0, 0), 1, cv2.LINE_AA)
    return img


def _on_image(box: NDArray[np.float64], gray: np.ndarray) -> bool:
    """The box still overlaps the image by at least half its area."""
    h, w = gray.shape
    x0, y0, x1, y1 = box
    inter = max(min(x1, w) - max(x0, 0), 0) * max(min(y1, h) - max(y0, 0), 0)
    return inter >= 0.5 * (x1 - x0) * (y1 - y0)


@contextlib.contextmanager
def _timer(res: FrameResult, stage: str) -> Iterator[None]:
    """Adds the wall time of a ``with`` block to ``res.timings_ms[stage]``."""
    t0 = time.perf_counter()
    yield
    res.timings_ms[stage] += (time.perf_counter() - t0) * 1e3
