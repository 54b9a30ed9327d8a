"""The mission beyond the easy world, in-process with vision in the loop (the nodes' cores
and the deployed detector): a target out of view at takeoff, a target 4.5-5 m away, two
bolt plates 1 m apart (with and without a hint), a 50,000 N/m wall, gusts, a target seen
more than 70 degrees off its normal from wherever the search turns. Every run must
meet the demo's bar: tool tip within 1 cm of the point of interest along the surface, the
push within 0.1 N mean and 0.2 N RMS of the setpoint over the hold, contact never lost.

The worlds' geometry is fixed per behaviour; their seeds (textures, wind, sensor noise)
are drawn fresh for every run of the suite and printed with any failure.
"""
import multiprocessing
import os
import pathlib

import numpy as np
import pytest

from uav_tilt_common.config import from_dict
from uav_tilt_common.geometry import wall_point, wall_rotation
from uav_tilt_control.mission import MissionConfig
from uav_tilt_sim.scenario import Scenario, check_scenario
from uav_tilt_sim.world import PANEL_THICKNESS_M
from uav_tilt_tools.runner.fly import fly
from uav_tilt_tools.runner.site_params import site_overrides

MODEL = pathlib.Path(__file__).resolve().parent.parent / 'models' / 'detector_int8.onnx'
SETPOINT_N = 5.0
SEEDS = np.random.default_rng().integers(0, 2**31 - 1, size=9)
NOISE = dict(imu_gyro_rad_s=0.003, imu_accel_m_s2=0.05, odom_pos_m=0.001, ft_force_n=0.05,
             depth_m=0.002)


def _scenario(seed, wall, objects, **extra):
    data = dict(seed=int(seed), wall=wall, objects=objects, noise=NOISE, **extra)
    return check_scenario(from_dict(Scenario, data))


def _worlds():
    """name -> (scenario, hint) of each behaviour."""
    plates_wall = dict(position_m=[2.6, 0.0], width_m=6.0)
    two_plates = [dict(cls='bolt_plate', u_m=0.5, v_m=1.5, target=True),
                  dict(cls='bolt_plate', u_m=-0.5, v_m=1.5),
                  dict(cls='gauge', u_m=0.0, v_m=2.1)]
    rng = np.random.default_rng(SEEDS[0])
    return {
        'out_of_view': (_scenario(SEEDS[1], dict(position_m=[2.6, 0.3], yaw_deg=5.0), [
            dict(cls='bolt_plate', u_m=0.1, v_m=1.4, target=True),
            dict(cls='gauge', u_m=-0.7, v_m=1.3), dict(cls='hazard_sign', u_m=0.8, v_m=1.7)],
            start_yaw_deg=float(rng.choice([-1, 1]) * rng.uniform(70, 110))), None),
        # the camera starts 0.12 m ahead of the start point: 4.5-5 m from the plate
        'far': (_scenario(SEEDS[2], dict(position_m=[float(rng.uniform(4.62, 5.1)), 0.0],
                                         width_m=8.0), [
            dict(cls='bolt_plate', u_m=float(rng.uniform(-0.5, 0.5)), v_m=1.6, target=True),
            dict(cls='hazard_sign', u_m=-1.0, v_m=1.4)]), None),
        'lookalike_hint': (_scenario(SEEDS[3], plates_wall, two_plates),
                           [0.5 + rng.uniform(-0.3, 0.3), 1.5 + rng.uniform(-0.3, 0.3)]),
        'lookalike': (_scenario(SEEDS[4], plates_wall, two_plates), None),
        'stiff': (_scenario(SEEDS[5], dict(position_m=[2.5, 0.0], stiffness_n_per_m=50000.0,
                                           friction=0.9), [
            dict(cls='bolt_plate', u_m=0.0, v_m=1.5, target=True),
            dict(cls='gauge', u_m=-0.7, v_m=1.3)]), None),
        'gusts': (_scenario(SEEDS[6], dict(position_m=[2.5, 0.0]), [
            dict(cls='bolt_plate', u_m=0.2, v_m=1.4, target=True),
            dict(cls='hazard_sign', u_m=-0.6, v_m=1.6)],
            wind=dict(mean_m_s=[0.7, 1.87, 0.0], gust_std_m_s=1.2, gust_tau_s=1.0)), None),
        # a wall 0.9 m from the start, the plate 1.5-2 m to its side
        'side': (_scenario(SEEDS[7], dict(position_m=[2.0, 0.5],
                                          yaw_deg=float(rng.uniform(-55.0, -45.0))), [
            dict(cls='bolt_plate', u_m=float(rng.uniform(-2.0, -1.5)), v_m=0.8, target=True),
            dict(cls='hazard_sign', u_m=0.0, v_m=1.0)],
            start_yaw_deg=float(rng.uniform(-180.0, 180.0))), None),
    }


def _fly(item):
    name, (scenario, hint) = item
    overrides = {'contact_force': SETPOINT_N}
    if hint is not None:
        overrides.update(site_overrides(scenario, hint))
    return name, fly(scenario, 'vision', overrides, model_path=MODEL)


@pytest.fixture(scope='module')
def flights():
    """The summary of every behaviour's mission, flown two at a time, the longest first
    ('side' flies about 146 s of sim time, the others 46-63 s): last, it kept one worker
    busy alone for 90 s."""
    worlds = _worlds()
    order = sorted(worlds.items(), key=lambda item: item[0] != 'side')
    with multiprocessing.get_context('spawn').Pool(min(2, os.cpu_count() or 1)) as pool:
        results = dict(pool.imap_unordered(_fly, order))
    return {name: (worlds[name][0], results[name]) for name in worlds}


def _meets_the_bar(result, what):
    details = f'{what} (seeds {SEEDS.tolist()}): {result}'
    assert result['success'], details
    assert result['poi_error_max_m'] <= 0.01, details
    assert result['force_mean_n'] == pytest.approx(SETPOINT_N, abs=0.1), details
    assert result['force_rms_error_n'] <= 0.2, details
    assert result['contact_lost'] == 0, details


def _plate_pois(scenario):
    """The points of interest (plate centres, front face) of the scenario's bolt plates."""
    wall = scenario.wall
    normal = wall_rotation(wall.yaw_deg, wall.inclination_deg)[:, 2]
    return [wall_point(wall.position_m, wall.yaw_deg, wall.inclination_deg, o.u_m, o.v_m)
            + normal * PANEL_THICKNESS_M for o in scenario.objects if o.cls == 'bolt_plate']


pytestmark = [pytest.mark.skipif(not MODEL.is_file(), reason='no committed detector weights'),
              pytest.mark.slow]     # minutes of missions: handed out first


def test_a_target_out_of_view_at_takeoff_is_searched_for_and_inspected(flights):
    scenario, result = flights['out_of_view']
    _meets_the_bar(result, f'start yaw {scenario.start_yaw_deg:.0f} deg')
    modes = [m for _, m in result['mode_history']]
    assert modes.index('SEARCH') < modes.index('APPROACH')


def test_a_target_5_m_away_is_found_and_inspected(flights):
    scenario, result = flights['far']
    _meets_the_bar(result, f'wall {scenario.wall.position_m[0]:.2f} m away')


def test_the_hinted_plate_is_inspected_among_look_alikes(flights):
    _, result = flights['lookalike_hint']
    _meets_the_bar(result, 'hint')


def test_without_a_hint_the_first_confirmed_plate_is_kept(flights):
    scenario, result = flights['lookalike']
    assert result['success'], result
    pois = _plate_pois(scenario)
    confirmed = np.argmin([np.linalg.norm(p - result['confirmed_target_map']) for p in pois])
    offsets = [np.asarray(result['hold_tip_map']) - p for p in pois]
    touched = np.argmin([np.linalg.norm(o) for o in offsets])
    assert touched == confirmed, result
    wall = scenario.wall
    normal = wall_rotation(wall.yaw_deg, wall.inclination_deg)[:, 2]
    along_surface = offsets[touched] - (offsets[touched] @ normal) * normal
    assert np.linalg.norm(along_surface) <= 0.01, result


def test_a_50000_n_per_m_wall_is_touched_gently_and_held(flights):
    _, result = flights['stiff']
    _meets_the_bar(result, 'stiff wall')
    assert result['first_touch_peak_n'] <= 1.5 * SETPOINT_N


def test_gusts_do_not_move_the_tool_off_the_point(flights):
    _, result = flights['gusts']
    _meets_the_bar(result, 'gusts 1.2 m/s std, mean 2 m/s')


def _seen_off_normal_deg(scenario):
    """How far off its normal the plate is seen from the start, at each altitude the
    search turns at."""
    poi = _plate_pois(scenario)[0]
    wall = scenario.wall
    normal = wall_rotation(wall.yaw_deg, wall.inclination_deg)[:, 2]
    cfg = MissionConfig()
    sights = [np.array([0.0, 0.0, z]) - poi for z in (
        cfg.flight.takeoff_altitude_m, cfg.flight.takeoff_altitude_m + cfg.search.climb_m,
        cfg.flight.takeoff_altitude_m - cfg.search.descend_m)]
    return [np.degrees(np.arccos(s @ normal / np.linalg.norm(s))) for s in sights]


def test_a_target_seen_far_off_its_normal_is_found_from_in_front_of_the_wall(flights):
    # the detector is trained on views up to 45 degrees off; beside a vertical wall nothing
    # touches the search, and the plate is confirmed only after the search's three turns,
    # when it faces the wall
    scenario, result = flights['side']
    assert min(_seen_off_normal_deg(scenario)) > 70.0
    _meets_the_bar(result, f'wall yaw {scenario.wall.yaw_deg:.0f} deg')
    modes = dict((m, t) for t, m in reversed(result['mode_history']))
    cfg = MissionConfig()
    turns_s = 3 * 2.0 * np.pi / min(cfg.search.yaw_rate_rad_s, cfg.flight.yaw_rate_rad_s)
    assert modes['APPROACH'] - modes['SEARCH'] > turns_s, result
