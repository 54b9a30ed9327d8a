"""Scenario files: every shipped scenario loads and builds; bad ones fail with one line."""
import pathlib

import numpy as np
import pytest

from uav_tilt_common.config import ConfigError, from_dict
from uav_tilt_common.geometry import wall_rotation
from uav_tilt_sim.plant import Plant, PlantCoreConfig
from uav_tilt_sim.scenario import Scenario, check_scenario, load_scenario

SCENARIOS = sorted((pathlib.Path(__file__).parent.parent / 'config' / 'scenarios')
                   .glob('*.yaml'))


@pytest.mark.parametrize('path', SCENARIOS, ids=lambda p: p.stem)
def test_shipped_scenarios_build_with_the_target_on_the_wall(path):
    scenario = load_scenario(path)
    plant = Plant(PlantCoreConfig(), scenario)
    try:
        world = plant.world
        poi = world.target_poi_map
        # The point of interest lies one panel thickness in front of the wall surface.
        offset = (poi - world.wall_origin_map) @ world.R_map_wall[:, 2]
        assert offset == pytest.approx(0.01, abs=1e-9)
        assert np.allclose(world.R_map_target[:, 2], world.R_map_wall[:, 2])
    finally:
        plant.close()


def test_wall_rotation_faces_the_vehicle_and_leans_away():
    R = wall_rotation(30.0, 10.0)
    assert np.allclose(R.T @ R, np.eye(3)) and np.isclose(np.linalg.det(R), 1.0)
    facing = np.array([np.cos(np.radians(30)), np.sin(np.radians(30)), 0.0])
    assert R[:, 2] @ facing < 0            # the normal points back at the vehicle
    assert R[:, 2][2] > 0                  # leaning away: the normal tilts up
    assert abs(R[:, 0][2]) < 1e-12         # the wall's x axis stays horizontal


def test_two_targets_or_unknown_class_are_rejected():
    with pytest.raises(ConfigError, match='targets'):
        check_scenario(from_dict(Scenario, {'objects': [
            {'cls': 'gauge', 'target': True}, {'cls': 'bolt_plate', 'target': True}]}))
    with pytest.raises(ConfigError, match=r"objects\[0\]\.cls"):
        from_dict(Scenario, {'objects': [{'cls': 'teapot'}]})
