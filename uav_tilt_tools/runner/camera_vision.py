"""Vision in the loop of an in-process flight: the plant's camera rendered at its rate and
the deployed detector's pipeline, as the vision node runs them (the callable ``vision`` of
:class:`uav_tilt_tools.runner.inprocess.Flight`).

Imports the vision stack (torch, OpenCV): a flight with the target from ground truth does
without this module.
"""
import collections
import time
from typing import Any, NamedTuple

import cv2

from uav_tilt_common.resources import resolve
from uav_tilt_sim.plant import Plant, PlantCoreConfig
from uav_tilt_vision.backends import DEPLOYED_MODEL, load_detector
from uav_tilt_vision.pipeline import STATS_WINDOW, FrameResult, VisionConfig, VisionPipeline
from uav_tilt_vision.target_pose import CameraIntrinsics


class Frame(NamedTuple):
    """The newest frame: its stamp, the pipeline's result, the wall clock (ns) when the
    image was ready and when the pipeline was done with it, and the images (for a
    recording that keeps them)."""

    stamp_s: float
    result: FrameResult
    rendered_ns: int
    processed_ns: int
    rgb: Any = None
    depth: Any = None


class CameraVision:
    """Vision in the loop without ROS: renders the eye-in-hand camera at its rate and runs
    the VisionPipeline; each frame gives its target candidates and planes stamped with the
    frame time (as vision_node stamps target/candidates and vision/planes), an empty list
    included. ``last_frame`` is the newest :class:`Frame`, or None;
    ``latency_ms`` the last frames' times from one to the other, the window of
    vision/status's latency."""

    def __init__(self, pipeline: VisionPipeline, camera_rate_hz: float,
                 control_rate_hz: float) -> None:
        self.pipeline = pipeline
        self.every = max(1, int(round(control_rate_hz / camera_rate_hz)))
        self.frames = 0
        self.found = 0
        self.last_frame: Frame | None = None
        self.latency_ms: collections.deque[float] = collections.deque(maxlen=STATS_WINDOW)

    def __call__(self, plant: Plant, t_s: float) -> tuple[float, Any, Any] | None:
        """(stamp_s, candidates, planes) of this tick's frame, or None when none is
        rendered."""
        if plant.tick % self.every:
            return None
        rgb, depth, _ = plant.render()
        rendered_ns = time.time_ns()
        result = self.pipeline.process(rgb, depth, t_s)
        self.last_frame = Frame(t_s, result, rendered_ns, time.time_ns(), rgb, depth)
        self.latency_ms.append((self.last_frame.processed_ns - rendered_ns) * 1e-6)
        self.frames += 1
        self.found += int(result.found)
        return t_s, result.candidates, result.planes


def camera_vision(plant_config: PlantCoreConfig, model_path: str = '', backend: str = 'auto',
                  vision_config: VisionConfig | None = None, threads: int = 0) -> CameraVision:
    """A :class:`CameraVision` with the detector at ``model_path`` (found like the vision
    node's: the working directory, then the package's files; '' the deployed detector) and
    the plant's camera; ``threads`` (0: the libraries' defaults) sizes the detector's thread
    pool and OpenCV's (process-wide), e.g. to the one CPU a campaign run gets."""
    if threads:
        cv2.setNumThreads(threads)
    cam = plant_config.camera
    intrinsics = CameraIntrinsics(cam.fx, cam.fy, cam.cx, cam.cy, cam.width, cam.height)
    detector = load_detector(resolve(model_path or DEPLOYED_MODEL, 'model_path'), backend,
                             threads)
    pipeline = VisionPipeline(detector, intrinsics, vision_config)
    return CameraVision(pipeline, cam.rate_hz, plant_config.control_hz)
