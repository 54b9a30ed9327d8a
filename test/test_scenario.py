"""Scenario files: every shipped scenario loads and builds; bad ones fail with one line."""
import pathlib

import numpy as np
import pytest

from uav_tilt_common.config import ConfigError, from_dict
from uav_tilt_common.geometry import wall_rotation
from uav_tilt_sim.plant import Plant, PlantCoreConfig
from uav_tilt_sim.scenario import Scenario, check_scenario, load_scenario, target_ids
from uav_tilt_sim.vehicle_body import HUB_HALF_EXTENTS_M
from uav_tilt_sim.world import WALL_THICKNESS_M

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


def test_targets_without_ids_or_of_another_class_are_rejected():
    with pytest.raises(ConfigError, match='targets'):
        check_scenario(from_dict(Scenario, {'objects': [
            {'cls': 'bolt_plate', 'target': True}, {'cls': 'bolt_plate', 'target': True}]}))
    with pytest.raises(ConfigError, match=r"objects\[0\]\.cls.*bolt_plate"):
        check_scenario(from_dict(Scenario, {'objects': [{'cls': 'gauge', 'target': True}]}))
    with pytest.raises(ConfigError, match=r"objects\[0\]\.cls"):
        from_dict(Scenario, {'objects': [{'cls': 'teapot'}]})
    for bad, words in (([{'id': 'a'}, {'id': 'a'}], 'not unique'),
                       ([{'id': '1st'}], 'a letter')):
        objects = [{'cls': 'bolt_plate', 'target': True, **o} for o in bad]
        with pytest.raises(ConfigError, match=words):
            check_scenario(from_dict(Scenario, {'objects': objects}))


def test_a_start_behind_the_wall_or_an_object_off_it_is_rejected():
    rng = np.random.default_rng()
    for _ in range(20):
        yaw_deg, inclination_deg = rng.uniform(-180, 180), rng.uniform(-30, 30)
        width_m, height_m = rng.uniform(1.0, 8.0), rng.uniform(1.0, 6.0)
        heading = np.radians(yaw_deg + rng.uniform(-80, 80))  # the wall seen ahead
        position_m = (rng.uniform(0.5, 6.0) * np.array([np.cos(heading), np.sin(heading)])
                      + rng.uniform(-5, 5, 2))
        start = [*(position_m - rng.uniform(0.5, 6.0) * np.array(
            [np.cos(heading), np.sin(heading)])), 0.0]

        def scenario(start_xyz_m, u_m=0.0, v_m=height_m / 2):
            return from_dict(Scenario, {
                'start_xyz_m': [float(x) for x in start_xyz_m],
                'wall': {'position_m': position_m.tolist(), 'yaw_deg': float(yaw_deg),
                         'inclination_deg': float(inclination_deg),
                         'width_m': float(width_m), 'height_m': float(height_m)},
                'objects': [{'cls': 'gauge', 'u_m': float(u_m), 'v_m': float(v_m)}]})

        # start positions are drawn around the wall, not along its normal: the check has
        # to find the face's side from the wall's yaw, whatever the bearing
        check_scenario(scenario(start))
        behind = 2 * position_m - np.asarray(start[:2])
        with pytest.raises(ConfigError, match=r"'start_xyz_m' .* behind the wall's face"):
            check_scenario(scenario([*behind, 0.0]))
        edge_u = rng.choice([-1, 1]) * width_m / 2
        check_scenario(scenario(start, u_m=0.98 * edge_u, v_m=0.99 * height_m))
        with pytest.raises(ConfigError, match=r"'objects\[0\]\.u_m' .* off the wall"):
            check_scenario(scenario(start, u_m=1.02 * edge_u))
        with pytest.raises(ConfigError, match=r"'objects\[0\]\.v_m' .* above the wall"):
            check_scenario(scenario(start, v_m=1.02 * height_m))


def test_a_start_in_the_wall_is_refused_and_one_clear_of_it_is_built():
    """The vehicle collides with the wall through its hub (a box about base_link) and its
    tool's tip sphere, tool_tip_x_m ahead. A start that puts either into the wall, or the
    tool through it, is refused with one line (PyBullet would throw the vehicle out, or it
    could not take off); one clear of it is built. Vertical walls, any heading."""
    rng = np.random.default_rng()
    vehicle = PlantCoreConfig().vehicle
    hx, hy, _ = HUB_HALF_EXTENTS_M
    seen = {'clear': 0, 'in': 0, 'through': 0}     # through: the tip behind the wall's back
    while min(seen.values()) < 3:
        wall_yaw_deg = rng.uniform(-180, 180)
        # the heading off the wall's normal: often straight at it
        off_rad = rng.choice([rng.uniform(-0.3, 0.3), rng.uniform(-np.pi, np.pi)])
        distance_m = rng.uniform(0.02, 0.7)         # base_link to the wall's face
        reach_m = max((vehicle.tool_tip_x_m - vehicle.tool_tip_radius_m) * np.cos(off_rad)
                      + vehicle.tool_tip_radius_m,
                      hx * abs(np.cos(off_rad)) + hy * abs(np.sin(off_rad)))
        if abs(reach_m - distance_m) < 2e-3:
            continue                                # within PyBullet's contact margin
        heading = np.radians(wall_yaw_deg)
        facing = np.array([np.cos(heading), np.sin(heading)])
        position_m = rng.uniform(-3, 3, 2)
        start = position_m - distance_m * facing + rng.uniform(-1, 1) * facing[::-1] * [-1, 1]
        scenario = from_dict(Scenario, {
            'start_xyz_m': [*map(float, start), 0.0],
            'start_yaw_deg': float(np.degrees(np.arctan2(np.sin(heading + off_rad),
                                                         np.cos(heading + off_rad)))),
            'wall': {'position_m': position_m.tolist(), 'yaw_deg': float(wall_yaw_deg),
                     'width_m': 4.0}})
        inside = reach_m > distance_m
        through = (vehicle.tool_tip_x_m * np.cos(off_rad) - distance_m
                   > WALL_THICKNESS_M + 2 * vehicle.tool_tip_radius_m)
        if inside:
            with pytest.raises(ConfigError, match=r"'start_xyz_m' .* puts the vehicle in the "
                                                  r"wall"):
                Plant(PlantCoreConfig(), scenario)
        else:
            Plant(PlantCoreConfig(), scenario).close()
        seen['through' if through else 'in' if inside else 'clear'] += 1


def test_several_targets_each_have_their_ground_truth():
    scenario = load_scenario(SCENARIOS[0].parent / 'plan.yaml')
    assert target_ids(scenario) == ['plate_a', 'plate_b']
    plant = Plant(PlantCoreConfig(), scenario)
    try:
        world = plant.world
        assert set(world.targets) == {'plate_a', 'plate_b'}
        for o in scenario.objects:
            if o.target:
                poi, R = world.targets[o.id]
                # on the wall, at the object's (u, v), one panel in front of the surface
                uvn = world.R_map_wall.T @ (poi - world.wall_origin_map)
                np.testing.assert_allclose(uvn, [o.u_m, o.v_m, 0.01], atol=1e-9)
        # the first target stays the scenario's target (ground_truth/target)
        np.testing.assert_allclose(world.target_poi_map, world.targets['plate_a'][0])
    finally:
        plant.close()
