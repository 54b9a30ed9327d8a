"""Recordings of a sensible size: the camera images a recording keeps (all, thin: the frames
at the detector's rate, none), the same rule in the recorder node and in `fly --record`;
a frame no one takes is not drawn, and the frames drawn after it are the ones they would
have been."""
import collections

import numpy as np
import pytest
from mcap.reader import make_reader

from ros_graph import REPO
from uav_tilt_common import names, ros_msgs
from uav_tilt_control.controller_core import ControllerConfig
from uav_tilt_sim.camera import CameraConfig
from uav_tilt_sim.plant import Plant, PlantCoreConfig
from uav_tilt_sim.scenario import load_scenario
from uav_tilt_tools import cli
from uav_tilt_tools.bag import images
from uav_tilt_tools.bag.flight_bag import FlightBag
from uav_tilt_tools.runner.inprocess import Flight
from uav_tilt_vision.pipeline import VisionConfig

CAMERA_HZ = CameraConfig().rate_hz
EVERY = VisionConfig().detect_every


def frame_stamps_ns(n):
    """The stamps of the plant's first ``n`` camera frames, as it stamps them."""
    config = PlantCoreConfig()
    dt_tick = config.substeps / config.physics_hz
    every = round(config.control_hz / CAMERA_HZ)
    return [ros_msgs.stamp_ns(ros_msgs.to_stamp(k * every * dt_tick)) for k in range(n)]


def test_thin_is_the_detectors_rate():
    assert images.THIN_RATE_HZ == CAMERA_HZ / EVERY


def test_thin_keeps_every_detector_frame_of_the_camera():
    stamps = frame_stamps_ns(3000)          # 100 s of frames
    thinning = images.Thinning()
    kept = [k for k, stamp in enumerate(stamps) if thinning.keep(stamp)]
    assert kept == list(range(0, 3000, EVERY))


def test_thin_keeps_the_colour_and_the_depth_of_the_same_frames_when_one_is_lost():
    stamps = frame_stamps_ns(60)
    thinning = images.Thinning()
    kept = collections.defaultdict(set)
    for k, stamp in enumerate(stamps):
        for topic in (names.CAMERA_COLOR, names.CAMERA_DEPTH):
            lost = (topic, k) in ((names.CAMERA_COLOR, 5), (names.CAMERA_DEPTH, 20),
                                  (names.CAMERA_COLOR, 21))
            if not lost and thinning.keep(stamp):
                kept[topic].add(k)
    # frame 5's colour was lost: its depth is kept, and no later frame of that period
    assert kept[names.CAMERA_DEPTH] - kept[names.CAMERA_COLOR] == {5}
    # frame 20's depth was lost before its colour came: the colour (first) is kept
    assert kept[names.CAMERA_COLOR] - kept[names.CAMERA_DEPTH] == {20}
    both = set(range(0, 60, EVERY)) - {5, 20}
    assert kept[names.CAMERA_COLOR] & kept[names.CAMERA_DEPTH] == both


def test_a_skipped_frame_leaves_the_next_one_as_it_would_have_been():
    """The plant draws no frame no one takes; the depth noise of the frames drawn later is
    what it would have been had every frame been drawn."""
    scenario = load_scenario(None)
    scenario.noise.depth_m = 0.01
    drawn, skipped = (Plant(PlantCoreConfig(), scenario) for _ in range(2))
    try:
        drawn.render()
        skipped.skip_frame()
        rgb_a, depth_a, _ = drawn.render()
        rgb_b, depth_b, _ = skipped.render()
        np.testing.assert_array_equal(rgb_a, rgb_b)
        np.testing.assert_array_equal(depth_a, depth_b)
        # and a frame drawn without that skip is not: the noise moved on
        fresh = Plant(PlantCoreConfig(), scenario)
        try:
            assert not np.array_equal(fresh.render()[1], depth_b)
        finally:
            fresh.close()
    finally:
        drawn.close()
        skipped.close()


def fly_recorded(folder, profile, seconds=1.0):
    """``seconds`` of the inspection flown in-process with the target from ground truth,
    recorded with the ``profile``'s images; returns {topic: messages} of the file."""
    config = ControllerConfig(target_source='ground_truth')
    plant_config = PlantCoreConfig()
    bag = FlightBag(str(folder / 'recording.mcap'), config, plant_config.camera, None,
                    own_folder=True, images=profile)
    flight = Flight(load_scenario(None), config, plant_config=plant_config, recorder=bag)
    try:
        flight.core.inspect()
        flight.run(seconds)
    finally:
        bag.close()
        flight.close()
    counts = collections.Counter()
    with open(folder / 'recording.mcap', 'rb') as stream:
        for _, channel, _ in make_reader(stream).iter_messages():
            counts[channel.topic] += 1
    return counts


@pytest.mark.parametrize('profile, kept', [('all', 30), ('thin', 30 // EVERY), ('none', 0)])
def test_fly_record_keeps_the_images_its_profile_says_and_the_report_reads_it(
        tmp_path, capsys, profile, kept):
    counts = fly_recorded(tmp_path, profile)
    for topic in (names.CAMERA_COLOR, names.CAMERA_DEPTH):
        assert counts['/uav/' + topic] == kept, counts
    # drawn for the recording alone (ground truth: no vision): camera_info of every frame
    # drawn, none when none is
    assert counts['/uav/' + names.CAMERA_INFO] == (0 if profile == 'none' else 30)
    assert counts['/uav/' + names.PLANT_SCENARIO] == 1
    # a second of a mission: reported (not completed: exit 1), its world drawn
    assert cli.main(['report', str(tmp_path)]) == 1
    assert (tmp_path / 'summary.json').is_file() and (tmp_path / 'trajectory.png').is_file()
    capsys.readouterr()


def test_fly_record_images_needs_record(capsys):
    code = cli.main(['fly', '--scenario', f'{REPO}/config/scenarios/default.yaml',
                     '--record-images', 'thin'])
    assert code == 2
    assert '--record-images goes with --record' in capsys.readouterr().err
