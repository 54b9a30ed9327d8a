"""The inspection mission with vision in the loop (in-process, the nodes' cores) succeeds on
the default scenario: tool tip within 1 cm of the point of interest, the push within 0.1 N
mean and 0.2 N RMS of 5 N over the hold, contact never lost."""
import pathlib

import pytest

from uav_tilt_common.config import from_dict
from uav_tilt_control.controller_core import ControllerConfig
from uav_tilt_sim.plant import PlantCoreConfig
from uav_tilt_sim.scenario import load_scenario
from uav_tilt_tools.runner.camera_vision import camera_vision
from uav_tilt_tools.runner.inprocess import run_mission

pytestmark = pytest.mark.slow     # minutes of missions or graphs: handed out first

MODEL = pathlib.Path(__file__).resolve().parent.parent / 'models' / 'detector_int8.onnx'


@pytest.mark.skipif(not MODEL.is_file(), reason='no committed detector weights')
def test_mission_with_vision_in_the_loop_on_the_default_scenario():
    plant_config = PlantCoreConfig()
    vision = camera_vision(plant_config, MODEL)
    config = from_dict(ControllerConfig, {'target_source': 'vision'})
    result = run_mission(load_scenario(), config, duration_s=120.0,
                         plant_config=plant_config, vision=vision)
    assert vision.found > 0
    assert result['success'], result
    assert result['poi_error_max_m'] <= 0.01
    assert result['force_mean_n'] == pytest.approx(5.0, abs=0.1)
    assert result['force_rms_error_n'] <= 0.2
    assert result['contact_lost'] == 0
