"""VisionPipeline on frames rendered by the plant, with a ground-truth box detector stub.

The stub returns the target's box from the segmentation image, so these tests check the
POI, the pose and the detect/track scheduling, not the CNN.
"""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from uav_tilt_sim.plant import Plant, PlantCoreConfig
from uav_tilt_sim.scenario import load_scenario
from uav_tilt_common.targets import OBJECT_CLASSES
from uav_tilt_vision.pipeline import VisionConfig, VisionPipeline, check_frame, draw_debug
from uav_tilt_vision.target_pose import CameraIntrinsics

TARGET_CLASS = OBJECT_CLASSES.index('bolt_plate')
FRAME_TICKS = 10    # 300 Hz control ticks per 30 Hz camera frame


class SegBoxDetector:
    """Detector stub: the target's box from the latest segmentation, plus a decoy box of
    another class and a weaker one of the target class (the pipeline must pick right)."""

    def __init__(self, body):
        self.body = body
        self.seg = None
        self.calls = 0

    def predict(self, rgb, conf_thres=0.25, iou_thres=0.45):
        self.calls += 1
        ys, xs = np.nonzero(self.seg == self.body)
        if len(xs) == 0:
            return np.zeros((0, 6), np.float32)
        box = [xs.min(), ys.min(), xs.max() + 1, ys.max() + 1]
        return np.array([[0, 0, 40, 40, 0.95, (TARGET_CLASS + 1) % len(OBJECT_CLASSES)],
                         [*box, 0.9, TARGET_CLASS],
                         [200, 150, 240, 190, 0.3, TARGET_CLASS]], np.float32)


def make_plant(start_xyz, yaw_deg):
    scenario = load_scenario()
    scenario.start_xyz_m = list(start_xyz)
    scenario.start_yaw_deg = float(yaw_deg)
    plant = Plant(PlantCoreConfig(), scenario)
    cam = plant.config.camera
    K = CameraIntrinsics(cam.fx, cam.fy, cam.cx, cam.cy, cam.width, cam.height)
    target = next(o for o in plant.world.objects if o.target)
    return plant, K, SegBoxDetector(target.body)


def facing_start(rng, distance_m, yaw=None):
    """Vehicle start (xyz, yaw) with the camera ``distance_m`` in front of the default
    scenario's target (wall x = 2.5 m, POI at 1.5 m height), small offsets and yaw."""
    yaw = rng.uniform(-15.0, 15.0) if yaw is None else yaw
    cam_xyz = np.array([2.5 - distance_m, rng.uniform(-0.1, 0.1), 1.5 + rng.uniform(-0.08, 0.08)])
    # The camera sits at (0.12, 0, 0.07) in base_link (VehicleParams.camera_xyz_m).
    base = cam_xyz - Rotation.from_euler('z', yaw, degrees=True).apply([0.12, 0.0, 0.07])
    return base, yaw


def truth_in_camera(plant):
    p_cam_map, R_map_cam = plant.camera_pose()
    world = plant.world
    return (R_map_cam.T @ (world.target_poi_map - p_cam_map),
            R_map_cam.T @ world.R_map_target[:, 2])


def errors(result, plant):
    p_true, n_true = truth_in_camera(plant)
    n = Rotation.from_quat(result.q_cam).as_matrix()[:, 2]
    return (np.linalg.norm(result.p_cam - p_true),
            np.degrees(np.arccos(np.clip(n @ n_true, -1.0, 1.0))))


def test_poi_and_pose_on_held_out_frames_at_half_to_one_and_a_half_metres():
    rng = np.random.default_rng(2024)
    pos_err, normal_err = [], []
    for distance in np.linspace(0.5, 1.5, 12):
        plant, K, detector = make_plant(*facing_start(rng, distance))
        try:
            rgb, depth, detector.seg = plant.render(segmentation=True)
            result = VisionPipeline(detector, K).process(rgb, depth, 1.0)
            assert result.found and result.detected and not result.tracked
            e_p, e_n = errors(result, plant)
            pos_err.append(e_p)
            normal_err.append(e_n)
            # The covariance is a valid 6x6 and says the position is known to centimetres.
            cov = result.covariance
            assert cov.shape == (6, 6) and np.allclose(cov, cov.T)
            assert np.all(np.linalg.eigvalsh(cov) > -1e-12)
            assert np.sqrt(np.trace(cov[:3, :3])) < 0.05
        finally:
            plant.close()
    assert np.median(pos_err) <= 0.01
    assert np.median(normal_err) <= 3.0


def hovering_plant_drifting_sideways():
    # Square to the wall: at some yaws TinyRenderer draws the large wall quad as aliased
    # stripes that change from frame to frame, and the KLT rightly loses the box there.
    plant, K, detector = make_plant(*facing_start(np.random.default_rng(5), 1.0, yaw=0.0))
    hover = np.full(4, plant.mass_kg * 9.80665 / 4)
    plant.set_actuator_state(hover, 0.0, 0.0)
    # A slow lateral push (~0.1 m/s after a second) moves the target across the image.
    plant.external_force_map = np.array([0.0, 0.15 * plant.mass_kg, 0.0])
    return plant, K, detector


def test_detects_one_frame_in_five_and_tracks_in_between_while_moving():
    plant, K, detector = hovering_plant_drifting_sideways()
    pipeline = VisionPipeline(detector, K, VisionConfig(detect_every=5))
    pos_err, boxes_u, planes_at = [], [], []
    try:
        for frame in range(30):
            for _ in range(FRAME_TICKS):
                plant.step()
            rgb, depth, detector.seg = plant.render(segmentation=True)
            result = pipeline.process(rgb, depth, plant.t_s)
            assert result.detected == (frame % 5 == 0)
            assert result.tracked == (frame % 5 != 0)
            if result.planes is not None:
                # the wall 1 m ahead fills the view
                planes_at.append(frame)
                assert result.planes[0].share > 0.9 and result.timings_ms['planes'] > 0.0
            assert result.found
            pos_err.append(errors(result, plant)[0])
            boxes_u.append(result.box_xyxy[0])
            assert result.timings_ms['detector' if result.detected else 'tracker'] > 0.0
    finally:
        plant.close()
    assert detector.calls == 6
    # the plane search every fifth frame too, between the detector's
    assert np.diff(planes_at).tolist() == [5] * 5 and not set(planes_at) & {0, 5, 10}
    assert np.median(pos_err) <= 0.01
    assert abs(boxes_u[-1] - boxes_u[0]) > 5.0     # the target did move in the image


def test_redetects_on_the_frame_the_track_is_lost():
    plant, K, detector = hovering_plant_drifting_sideways()
    pipeline = VisionPipeline(detector, K, VisionConfig(detect_every=5))
    try:
        rgb, depth, detector.seg = plant.render(segmentation=True)
        assert pipeline.process(rgb, depth, 0.0).detected
        blank = np.full_like(rgb, 128)
        detector.seg = np.full_like(detector.seg, -1)
        lost = pipeline.process(blank, depth, 0.1)
        # 1 m away: no magnified second look (zoom_beyond_m)
        assert lost.detected and not lost.found and detector.calls == 2
        # Nothing to track: the next frame is detected again, and the target comes back.
        detector.seg = plant.render(segmentation=True)[2]
        back = pipeline.process(rgb, depth, 0.2)
        assert back.detected and back.found and detector.calls == 3
    finally:
        plant.close()


class SmallBlindDetector:
    """Detector stub that, like the CNN, misses objects under ``min_side_px``: it boxes the
    red squares of the image it is given (whatever its scale) when large enough."""

    def __init__(self, min_side_px):
        self.min_side_px = min_side_px

    def predict(self, rgb, conf_thres=0.25, iou_thres=0.45):
        red = (rgb[..., 0] > 200) & (rgb[..., 1] < 60)
        ys, xs = np.nonzero(red)
        if len(xs) == 0 or min(xs.max() - xs.min(), ys.max() - ys.min()) + 1 < self.min_side_px:
            return np.zeros((0, 6), np.float32)
        return np.array([[xs.min(), ys.min(), xs.max() + 1, ys.max() + 1, 0.9, TARGET_CLASS]],
                        np.float32)


@pytest.mark.parametrize('zoom', [2.0, 3.0])
def test_a_target_too_small_for_the_detector_is_found_in_a_magnified_tile(zoom):
    rng = np.random.default_rng()
    w, h, side = 320, 240, 12
    K = CameraIntrinsics(277.0, 277.0, w / 2, h / 2, w, h)
    depth = np.full((h, w), 5.0, np.float32)
    detector = SmallBlindDetector(min_side_px=20)
    n_tiles = (int(np.ceil(2 * zoom)) - 1) ** 2
    for _ in range(4):
        rgb = np.full((h, w, 3), 120, np.uint8)
        x0, y0 = int(rng.integers(0, w - side)), int(rng.integers(0, h - side))
        rgb[y0:y0 + side, x0:x0 + side] = (230, 20, 20)
        assert not len(detector.predict(rgb))
        pipeline = VisionPipeline(detector, K, VisionConfig(detect_every=1, zoom=zoom))
        # every frame without a box looks at the next tile: one of a grid's tiles has it
        found = [pipeline.process(rgb, depth, k / 30.0).box_xyxy for k in range(n_tiles + 1)]
        first = next((k for k, b in enumerate(found) if b is not None), None)
        assert first is not None and first < n_tiles, (zoom, x0, y0)
        square = np.array([x0, y0, x0 + side, y0 + side], float)
        # in the frame's pixels, to a pixel of the magnified tile's; a tile may cut the
        # square, the next look (centred on that box) sees it whole
        tol = 1.0 / zoom + 0.5
        assert np.all(found[first][:2] >= square[:2] - tol), (found[first], square)
        assert np.all(found[first][2:] <= square[2:] + tol), (found[first], square)
        assert np.allclose(found[first + 1], square, atol=tol), (found, square)
        off = VisionPipeline(detector, K, VisionConfig(detect_every=1, zoom=1.0))
        assert all(off.process(rgb, depth, k / 30.0).box_xyxy is None for k in range(n_tiles))
        # nearer than zoom_beyond_m a target is big enough: no second look
        near = VisionPipeline(detector, K, VisionConfig(detect_every=1, zoom=zoom,
                                                        zoom_beyond_m=3.0))
        assert all(near.process(rgb, np.full_like(depth, 2.9), k / 30.0).box_xyxy is None
                   for k in range(n_tiles))


class NothingDetector:
    def predict(self, image, conf_thres=0.25, iou_thres=0.45):
        return np.zeros((0, 6))


def test_with_the_detector_on_every_frame_the_plane_search_still_runs():
    # nothing found: the detector runs on every frame, the plane search on every other
    # period of planes.every rather than never
    plant, K, _ = make_plant(*facing_start(np.random.default_rng(2), 1.0))
    try:
        rgb, depth, _ = plant.render()
        pipeline = VisionPipeline(NothingDetector(), K, VisionConfig(detect_every=5))
        results = [pipeline.process(rgb, depth, k / 30.0) for k in range(40)]
    finally:
        plant.close()
    assert all(r.detected for r in results)
    assert [k for k, r in enumerate(results) if r.planes is not None] == [9, 19, 29, 39]


def test_without_a_detector_every_frame_is_no_target():
    plant, K, _ = make_plant(*facing_start(np.random.default_rng(1), 1.0))
    try:
        rgb, depth, _ = plant.render()
        pipeline = VisionPipeline(None, K)
        for k in range(3):
            result = pipeline.process(rgb, depth, k / 30.0)
            assert not result.found and result.box_xyxy is None and result.stamp_s == k / 30.0
    finally:
        plant.close()


def test_debug_image_draws_box_points_and_poi():
    plant, K, detector = make_plant(*facing_start(np.random.default_rng(3), 0.8))
    try:
        rgb, depth, detector.seg = plant.render(segmentation=True)
        pipeline = VisionPipeline(detector, K)
        pipeline.process(rgb, depth, 0.0)
        result = pipeline.process(rgb, depth, 1 / 30)     # tracked: has KLT points
        assert result.tracked and len(result.track_points) >= 8
        img = draw_debug(rgb, result)
    finally:
        plant.close()
    assert img.shape == rgb.shape and img.dtype == np.uint8
    changed = np.any(img != rgb, axis=2)
    u, v = (int(round(c)) for c in result.poi_px)
    assert changed[v, u]
    x0, y0 = (int(round(c)) for c in result.box_xyxy[:2])
    assert changed[y0, x0 + 3]


K_TEST = CameraIntrinsics(277.0, 277.0, 160.0, 120.0, 320, 240)


@pytest.mark.parametrize('rgb,depth,reason', [
    (np.zeros((240, 320, 3), np.uint8), np.ones((240, 320), np.float32), None),
    (np.zeros((240, 320), np.uint8), np.ones((240, 320), np.float32), 'rgb_format'),
    (np.zeros((240, 320, 3), np.float32), np.ones((240, 320), np.float32), 'rgb_format'),
    (np.zeros((0, 320, 3), np.uint8), np.ones((0, 320), np.float32), 'empty'),
    (np.zeros((120, 160, 3), np.uint8), np.ones((120, 160), np.float32), 'size'),
    (np.zeros((240, 320, 3), np.uint8), np.ones((120, 160), np.float32), 'size'),
    (np.zeros((240, 320, 3), np.uint8), np.full((240, 320), np.nan, np.float32),
     'depth_invalid'),
])
def test_check_frame_names_the_problem(rgb, depth, reason):
    assert check_frame(rgb, depth, K_TEST) == reason
