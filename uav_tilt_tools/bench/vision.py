"""`uav-tilt bench vision`: detector and pipeline speed on CPU (DESIGN section 7).

reference_ms_p50: fp32 YOLOv3-tiny (reference widths, untrained: only speed matters) at
the same 320x256 input; detector_ms_p50: the deployed model on its backend, the two
timed in turns on the same frames; speedup: their ratio; pipeline_fps /
pipeline_ms_p95: the whole VisionPipeline.process on frames rendered by the plant while
the vehicle drifts past the target; planes_ms_p50: its plane search (vision/planes) on
the frames that run it. Torch and ONNX Runtime get 2 threads each (the Jetson-class
budget).
"""
import time
from typing import Any, Callable, Sequence

import numpy as np
import torch

from uav_tilt_common.vehicle import GRAVITY
from uav_tilt_sim.plant import Plant, PlantCoreConfig
from uav_tilt_sim.scenario import load_scenario
from uav_tilt_common.targets import OBJECT_CLASSES
from uav_tilt_vision.backends import OnnxDetector
from uav_tilt_vision.detector import Detector
from uav_tilt_vision.pipeline import VisionPipeline
from uav_tilt_vision.target_pose import CameraIntrinsics
from uav_tilt_vision.vision_node import VisionNodeConfig, open_detector

THREADS = 2
N_FRAMES = 60           # two seconds of camera frames
WARMUP = 3
ROUNDS = 5


def rendered_frames(n: int = N_FRAMES
                    ) -> tuple[CameraIntrinsics, list[tuple[np.ndarray, np.ndarray, float]]]:
    """(intrinsics, [(rgb, depth, t_s)]): the vehicle hovers 1 m before the default target
    and drifts sideways at ~0.1 m/s."""
    scenario = load_scenario()
    scenario.start_xyz_m = [1.38, 0.0, 1.43]
    plant = Plant(PlantCoreConfig(), scenario)
    try:
        hover = np.full(4, plant.mass_kg * GRAVITY / 4)
        plant.set_actuator_state(hover, 0.0, 0.0)
        plant.external_force_map = np.array([0.0, 0.1 * plant.mass_kg, 0.0])
        every = round(plant.config.control_hz / plant.config.camera.rate_hz)
        frames = []
        for _ in range(n):
            for _ in range(every):
                plant.step()
            rgb, depth, _ = plant.render()
            frames.append((rgb, depth, plant.t_s))
        cam = plant.config.camera
        return CameraIntrinsics(cam.fx, cam.fy, cam.cx, cam.cy, cam.width, cam.height), frames
    finally:
        plant.close()


def time_ms(fns: Sequence[Callable[[np.ndarray], Any]], inputs: Sequence[np.ndarray],
            seconds: float, rounds: int = ROUNDS) -> list[np.ndarray]:
    """Milliseconds per call of each of ``fns`` (one array each) over ``inputs`` (cycled),
    about ``seconds`` in all. The functions take turns in ``rounds`` blocks, so that a
    change of load on a shared machine reaches all of them and their ratio holds; each
    block starts with untimed warm-up calls (the thread pools of torch and ONNX Runtime
    spin for a while after a call and would slow the other down)."""
    out: list[list[float]] = [[] for _ in fns]
    k = 0
    for _ in range(rounds):
        for fn, times in zip(fns, out):
            for x in inputs[:WARMUP]:
                fn(x)
            start = time.perf_counter()
            while time.perf_counter() - start < seconds / (rounds * len(fns)):
                t0 = time.perf_counter()
                fn(inputs[k % len(inputs)])
                times.append((time.perf_counter() - t0) * 1e3)
                k += 1
    return [np.array(times) for times in out]


def bench_vision(seconds: float = 10.0, model_path: str | None = None,
                 backend: str | None = None) -> dict[str, Any]:
    """JSON-ready dict of DESIGN section 7's vision keys, plus the backend and model used."""
    torch.set_num_threads(THREADS)
    cfg = VisionNodeConfig()
    detector, note = open_detector(model_path or cfg.model_path, backend or cfg.backend)
    if isinstance(detector, OnnxDetector):
        detector = OnnxDetector(detector.model_path, threads=THREADS)
    K, frames = rendered_frames()
    images = [rgb for rgb, _, _ in frames]
    reference = Detector(num_classes=len(OBJECT_CLASSES)).eval()
    fns = [reference.predict] + ([detector.predict] if detector is not None else [])
    ref_ms, *det = time_ms(fns, images, seconds / 2.0)
    result = {'reference_ms_p50': float(np.median(ref_ms)), 'detector_ms_p50': None,
              'speedup': None, 'backend': 'none', 'model': None, 'note': note}
    if detector is not None:
        det_ms = det[0]
        result.update(detector_ms_p50=float(np.median(det_ms)),
                      speedup=float(np.median(ref_ms) / np.median(det_ms)),
                      backend=detector.backend, model=detector.model_path)
    # Each pass restarts the detect/track schedule on the same sequence.
    pipe_ms: list[float] = []
    planes_ms: list[float] = []
    start = time.perf_counter()
    while not pipe_ms or time.perf_counter() - start < seconds / 2.0:
        pipeline = VisionPipeline(detector, K, cfg)
        for rgb, depth, t_s in frames:
            t0 = time.perf_counter()
            frame = pipeline.process(rgb, depth, t_s)
            pipe_ms.append((time.perf_counter() - t0) * 1e3)
            if frame.planes is not None:
                planes_ms.append(frame.timings_ms['planes'])
    result.update(pipeline_fps=float(1e3 / np.mean(pipe_ms)),
                  pipeline_ms_p95=float(np.percentile(pipe_ms, 95)),
                  planes_ms_p50=float(np.median(planes_ms)) if planes_ms else None)
    return result
