"""vision_node: the onboard vision on ROS 2 (DESIGN section 3), a shell around
:class:`VisionPipeline`.

Colour and depth are paired by stamp; the newest pair is processed and older ones are
dropped, never queued (best-effort depth-1 subscriptions). Every processed frame gives
one `target/candidates` (every target-class detection with a point of interest, the
tracked one first; what the controller flies to) and one `target/pose` (the tracked
target; covariance[0] = -1: none), both stamped like the image. Without a
usable model the node keeps running and publishes "no target" for every frame.
"""
import collections
import dataclasses
import os
import time
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PoseWithCovarianceStamped
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import CameraInfo, Image, PointCloud2

from uav_tilt_common import cdr, names, resources, ros_msgs, ros_qos
from uav_tilt_common.config import param
from uav_tilt_common.rate_limit import RejectCounter
from uav_tilt_common.ros_params import declare_config, run_node
from uav_tilt_common.targets import no_target_covariance
from uav_tilt_vision.backends import BACKENDS, DEPLOYED_MODEL, OnnxDetector, TorchDetector, \
    load_detector
from uav_tilt_vision.pipeline import STAGES, STATS_WINDOW, FrameResult, VisionConfig, \
    VisionPipeline, check_frame, draw_debug
from uav_tilt_vision.target_pose import CameraIntrinsics

# Tried in this order, beside ``model_path``, when it cannot be loaded.
FALLBACK_MODELS = ('detector_int8.onnx', 'detector_pruned.pt', 'detector_fp32.pt')
# Frames before the first camera_info are dropped quietly: it travels on a topic of its own,
# so a first frame can overtake it. This many in a row mean it is not coming: said once.
NO_CAMERA_INFO_WARN_FRAMES = 30


@dataclasses.dataclass
class VisionNodeConfig(VisionConfig):
    """Parameters of vision_node (DESIGN section 7 names `model_path`, `backend`,
    `detect_every` are stable); a relative model path is looked up in the working
    directory, then in the package's files (:mod:`uav_tilt_common.resources`)."""

    model_path: str = param(DEPLOYED_MODEL,
                            doc='detector file; relative: working directory, else package')
    backend: str = param('onnxruntime', choices=BACKENDS + ('auto',),
                         doc='inference backend (auto: by file suffix)')
    status_rate_hz: float = param(2.0, lo=0.1, hi=20.0, doc='vision/status rate (wall clock)')


# Parameters a `ros2 param set` changes while vision runs (the pipeline reads them every
# frame); the others are read-only.
DYNAMIC = ('detect_every', 'conf_thres', 'iou_thres', 'zoom', 'zoom_beyond_m',
           'min_track_quality', 'pose_window_px', 'pixel_sigma_px')


def open_detector(model_path: str | os.PathLike[str], backend: str
                  ) -> tuple[TorchDetector | OnnxDetector | None, str]:
    """``(detector or None, note)``: the asked model, else the first loadable fallback
    beside it; ``note`` is one log line when anything differs from what was asked."""
    path = resources.locate(model_path)
    candidates = [(path, backend)] + [(path.parent / name, 'auto') for name in FALLBACK_MODELS
                                      if path.parent / name != path]
    problems: list[str] = []
    for candidate, kind in candidates:
        if not candidate.is_file():
            problems.append(f'{candidate.name} missing')
            continue
        try:
            detector = load_detector(candidate, kind)
        except Exception as exc:  # noqa: BLE001 - any broken model file must not stop the node
            problems.append(f'{candidate.name} unusable ({exc})')
            continue
        if candidate == path:
            return detector, detector.note
        return detector, (f'{"; ".join(problems)}: fell back to {candidate.name} on '
                          f'{detector.backend}')
    return None, f'no usable model ({"; ".join(problems)}): publishing no target'


def pose_msg(result: FrameResult, stamp: Any) -> PoseWithCovarianceStamped:
    """target/pose of a FrameResult; covariance[0] = -1 when no target was found."""
    msg = PoseWithCovarianceStamped()
    msg.header.stamp = stamp
    msg.header.frame_id = names.FRAME_CAMERA
    pose = msg.pose.pose
    p_cam, q_cam, covariance = result.p_cam, result.q_cam, result.covariance
    if not result.found or p_cam is None or q_cam is None or covariance is None:
        pose.orientation.w = 1.0
        msg.pose.covariance = no_target_covariance()
        return msg
    pose.position.x, pose.position.y, pose.position.z = (float(v) for v in p_cam)
    o = pose.orientation
    o.x, o.y, o.z, o.w = (float(v) for v in q_cam)
    msg.pose.covariance = covariance.astype(float).ravel()
    return msg


class VisionNode(Node):
    """Thin shell: camera messages -> VisionPipeline -> target/pose, debug image, status."""

    def __init__(self) -> None:
        super().__init__('vision', parameter_overrides=[Parameter('use_sim_time', value=True)])
        self.cfg = declare_config(self, VisionNodeConfig, DYNAMIC)
        detector, note = open_detector(self.cfg.model_path, self.cfg.backend)
        self.backend = detector.backend if detector is not None else 'none'
        self.model = detector.model_path if detector is not None else ''
        self.model_note = note
        if detector is None:
            self.get_logger().error(note)
        elif note:
            self.get_logger().warn(note)
        self.pipeline = VisionPipeline(detector, None, self.cfg)
        self.pub_pose = ros_qos.quiet_publisher(self, PoseWithCovarianceStamped,
                                                names.TARGET_POSE, ros_qos.CONTROL)
        self.pub_candidates = ros_qos.quiet_publisher(self, PointCloud2,
                                                      names.TARGET_CANDIDATES, ros_qos.CONTROL)
        self.pub_planes = ros_qos.quiet_publisher(self, PointCloud2, names.VISION_PLANES,
                                                  ros_qos.CONTROL)
        self.pub_debug = self.create_publisher(Image, names.VISION_DEBUG_IMAGE,
                                               ros_qos.CAMERA_PUB)
        self.pub_status = ros_qos.quiet_publisher(self, DiagnosticArray, names.VISION_STATUS,
                                                  ros_qos.STATUS)
        sub = ros_qos.quiet_subscription
        q = ros_qos.CAMERA_SUB
        # images are taken serialized: rclpy builds a 320x240 Image message in ~2 ms
        sub(self, Image, names.CAMERA_COLOR, lambda m: self.on_image('color', m), q, raw=True)
        sub(self, Image, names.CAMERA_DEPTH, lambda m: self.on_image('depth', m), q, raw=True)
        sub(self, CameraInfo, names.CAMERA_INFO, self.on_camera_info, q)
        # (msg, wall arrival time)
        self.latest: dict[str, tuple[cdr.CdrImage, float] | None] = \
            {'color': None, 'depth': None}
        self.rejects = RejectCounter()
        self.frames_without_info = 0
        self.counts = dict(frames_received=0, frames_processed=0, targets_found=0)
        self.window: collections.deque[tuple[float, FrameResult]] = \
            collections.deque(maxlen=STATS_WINDOW)
        self.last_status = (time.monotonic(), 0)
        # Wall clock: status keeps coming when sim time stalls (the plant is gone).
        self.create_timer(1.0 / self.cfg.status_rate_hz, self.on_status,
                          clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.get_logger().info(f'vision up: backend={self.backend} '
                               f'detect_every={self.cfg.detect_every}')

    # --- inputs -------------------------------------------------------------------------
    def _reject(self, reason: str, detail: str) -> None:
        if self.rejects.reject(reason):
            self.get_logger().warn(f'rejected {detail}; {self.rejects.total} rejected so far')

    def on_camera_info(self, msg: CameraInfo) -> None:
        """Intrinsics of the frames that follow."""
        k = np.asarray(msg.k, dtype=float)
        if not (np.all(np.isfinite(k)) and k[0] > 0 and k[4] > 0 and msg.width > 0
                and msg.height > 0):
            self._reject('camera_info', f'camera_info K={list(k)} {msg.width}x{msg.height}')
            return
        self.pipeline.intrinsics = CameraIntrinsics(k[0], k[4], k[2], k[5], int(msg.width),
                                                    int(msg.height))

    def on_image(self, kind: str, data: bytes) -> None:
        """Keep the newest colour and depth (serialized); a pair with equal stamps is
        processed."""
        now = time.monotonic()
        self.counts['frames_received'] += int(kind == 'color')
        try:
            image = cdr.decode_image(data)
        except ValueError as exc:
            self._reject('malformed', f'{kind} image: {exc}')
            return
        self.latest[kind] = (image, now)
        color, depth = self.latest['color'], self.latest['depth']
        if color is None or depth is None or color[0].stamp_ns != depth[0].stamp_ns:
            return
        self.latest = {'color': None, 'depth': None}
        self.process(color[0], depth[0], min(color[1], depth[1]))

    # --- processing ---------------------------------------------------------------------
    def process(self, color_msg: cdr.CdrImage, depth_msg: cdr.CdrImage, arrival: float
                ) -> None:
        """Validate, run the pipeline, publish target/pose (and the debug image)."""
        if self.pipeline.intrinsics is None:
            self.frames_without_info += 1
            if self.frames_without_info == NO_CAMERA_INFO_WARN_FRAMES:
                self.get_logger().warn(
                    f'{NO_CAMERA_INFO_WARN_FRAMES} frames and no {names.CAMERA_INFO} yet: '
                    f'frames are dropped until it comes')
            return
        if (color_msg.encoding, depth_msg.encoding) != ('rgb8', '32FC1'):
            self._reject('encoding', f'frame encoded {color_msg.encoding!r}/'
                         f'{depth_msg.encoding!r}, expected rgb8/32FC1')
            return
        try:
            rgb, depth = ros_msgs.array_of_image(color_msg), ros_msgs.array_of_image(depth_msg)
        except ValueError as exc:
            self._reject('malformed', f'frame: {exc}')
            return
        reason = check_frame(rgb, depth, self.pipeline.intrinsics)
        if reason is not None:
            self._reject(reason, f'frame {rgb.shape[1::-1]}: {reason}')
            return
        stamp = ros_msgs.stamp_of_ns(color_msg.stamp_ns)
        result = self.pipeline.process(rgb, depth, ros_msgs.from_stamp(stamp))
        self.pub_candidates.publish(ros_msgs.candidates_msg(result.candidates, stamp))
        self.pub_pose.publish(pose_msg(result, stamp))
        latency_s = time.monotonic() - arrival      # to the target's publication (DESIGN)
        if result.planes is not None:
            self.pub_planes.publish(ros_msgs.planes_msg(result.planes, stamp))
        if self.pub_debug.get_subscription_count():
            self.pub_debug.publish(ros_msgs.image_msg(draw_debug(rgb, result), stamp))
        self.counts['frames_processed'] += 1
        self.counts['targets_found'] += int(result.found)
        self.window.append((latency_s, result))

    def on_status(self) -> None:
        """vision/status: rates, latency from image arrival to publish, shares, rejections."""
        now = time.monotonic()
        last_wall, last_count = self.last_status
        processed = self.counts['frames_processed']
        self.last_status = (now, processed)
        values = dict(backend=self.backend, model=self.model,
                      fps=(processed - last_count) / max(now - last_wall, 1e-9),
                      rejected_inputs=self.rejects.total, **self.counts)
        values.update({f'rejected_{k}': v for k, v in self.rejects.counts.items()})
        if self.window:
            latency_ms = 1e3 * np.array([lat for lat, _ in self.window])
            stage_ms = {s: sum(r.timings_ms[s] for _, r in self.window) for s in STAGES}
            total_ms = max(sum(stage_ms.values()), 1e-9)
            values.update(
                latency_ms_p50=float(np.percentile(latency_ms, 50)),
                latency_ms_p95=float(np.percentile(latency_ms, 95)),
                detector_frame_share=float(np.mean([r.detected for _, r in self.window])),
                detector_time_share=stage_ms['detector'] / total_ms,
                tracker_time_share=stage_ms['tracker'] / total_ms)
        level, message = DiagnosticStatus.OK, self.model_note or 'ok'
        if self.backend == 'none':
            level = DiagnosticStatus.ERROR
        self.pub_status.publish(ros_msgs.diagnostics_msg(
            'vision', values, self.get_clock().now().to_msg(), level, message))


def main(args: list[str] | None = None) -> int:
    """Entry point of the vision_node executable."""
    return run_node(VisionNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
