"""Plan files: the shipped plan resolves on its scenario's wall; bad plans are refused at
start with one line naming the task (index and kind) and the field; the controller takes a
plan only with ``autostart: plan`` (or the inspect service), and ``inspect`` stays the
one-touch plan."""
import pathlib
import subprocess
import sys

import numpy as np
import pytest
import yaml

from uav_tilt_common.config import ConfigError, from_dict
from uav_tilt_common.vehicle import VehicleParams
from uav_tilt_control.controller_core import ControllerConfig, ControllerCore, plan_of
from uav_tilt_control.impedance import ImpedanceConfig
from uav_tilt_control.mission import MissionConfig
from uav_tilt_control.plan import LineProgress, Slide, Touch, load_plan, parse_plan
from uav_tilt_common.targets import HINT_ERROR_M
from uav_tilt_control.site import SiteConfig
from uav_tilt_sim.scenario import load_scenario
from uav_tilt_tools.runner.fly import DURATION_S, default_duration_s
from uav_tilt_tools.runner.site_params import ros_arguments, site_overrides

REPO = pathlib.Path(__file__).resolve().parent.parent
SCENARIO = REPO / 'config' / 'scenarios' / 'plan.yaml'
PLAN = REPO / 'config' / 'plans' / 'inspection.yaml'
FORCES = (MissionConfig().contact.threshold_n, MissionConfig().failsafe.force_limit_n,
          'mission.contact.threshold_n, mission.failsafe.force_limit_n')


def _site():
    values = {k.split('.', 1)[1]: v for k, v in site_overrides(load_scenario(SCENARIO)).items()}
    return from_dict(SiteConfig, values)


def _touch(**fields):
    return {'touch': {'target': 'plate_a', 'near_uv_m': [-0.4, 1.5], **fields}}


def _slide(**fields):
    return {'slide': {'from_uv_m': [1.3, 1.0], 'to_uv_m': [1.3, 2.0], **fields}}


def test_the_shipped_plan_resolves_on_its_wall():
    site = _site()
    tasks = load_plan(PLAN, site, FORCES)
    assert [t.kind for t in tasks] == ['touch', 'touch', 'slide']
    assert [t.target for t in tasks[:2]] == ['plate_a', 'plate_b']
    scenario = load_scenario(SCENARIO)
    plates = {o.id: (o.u_m, o.v_m) for o in scenario.objects if o.id}
    for task in tasks[:2]:
        # the plan's prior is within the issue's +-0.3 m of the plate
        assert np.abs(np.subtract(task.near_uv_m, plates[task.target])).max() <= 0.3
        np.testing.assert_allclose(task.hint_map, site.point_map(task.near_uv_m))
    slide = tasks[2]
    assert isinstance(slide, Slide) and slide.length_m == pytest.approx(1.0)
    # the line lies on the wall's surface: along it, normal to the normal
    np.testing.assert_allclose(np.diff(slide.points_map, axis=0) @ slide.normal_map, 0.0,
                               atol=1e-12)


@pytest.mark.parametrize('tasks, words', [
    ([], ["'tasks'", 'at least one task']),
    ([_touch(target='plate_c')], ['tasks[0] (touch)', "'target' = 'plate_c'", 'plate_a']),
    # the message states the range enforced, the mission's (contact threshold, force limit)
    ([_touch(), _slide(force_n=-5.0)], ['tasks[1] (slide)', "'force_n' = -5.0",
                                        f'({FORCES[0]:g}, {FORCES[1]:g})']),
    ([_touch(force_n=0.5)], ['tasks[0] (touch)', f'({FORCES[0]:g}, {FORCES[1]:g})']),
    # a touch is scored by its push over the hold: a hold of 0 s has none
    ([_touch(hold_s=0.0)], ['tasks[0] (touch)', "'hold_s' = 0.0", 'more than 0']),
    ([_touch(force_n=15.0)], ['tasks[0] (touch)', "'force_n' = 15.0", 'force_limit_n']),
    ([_slide(to_uv_m=[3.0, 2.0])], ['tasks[0] (slide)', "'to_uv_m' = [3.0, 2.0]",
                                    'off the wall']),
    ([_slide(via_uv_m=[[1.3, 1.5], [1.3, 4.0]])], ['tasks[0] (slide)', "'via_uv_m[1]'",
                                                   'off the wall']),
    ([_slide(speed_m_s=0.0)], ['tasks[0].slide.speed_m_s', 'range']),
    ([_slide(to_uv_m=[1.3, 1.0])], ['tasks[0] (slide)', 'repeats']),
    # a tool tip that never moved would be within the tolerance of the end of a line so short
    ([_slide(to_uv_m=[1.33, 1.0])], ['tasks[0] (slide)', '0.03 m long',
                                     'slide.path_tolerance_m']),
    ([{'touch': {'target': 'plate_a'}}], ['tasks[0] (touch)', "'near_uv_m' is required"]),
    ([{'drill': {}}], ['tasks[0]', 'touch', 'slide']),
    ([_touch(hold=3.0)], ["unknown parameter 'tasks[0].touch.hold'"]),
])
def test_a_bad_plan_is_refused_with_one_line(tasks, words):
    with pytest.raises(ConfigError) as err:
        parse_plan({'tasks': tasks}, _site(), FORCES,
                   tolerance_m=MissionConfig().slide.path_tolerance_m)
    message = str(err.value)
    assert '\n' not in message
    for word in words:
        assert word in message, message


def test_a_plan_below_the_lowest_the_mission_works_at_is_refused(tmp_path):
    """A slide along the foot of the wall ended in flight with the failsafe 'unreachable';
    a touch's plate may lie the hint's error above its hint."""
    mission = MissionConfig()
    lowest_m = mission.lowest_hover_m()       # the wall of plan.yaml stands on z = 0
    margin_m = float(np.random.default_rng().uniform(0.01, 0.1))
    refused = [_slide(from_uv_m=[1.3, lowest_m - margin_m], to_uv_m=[1.3, 2.0]),
               _touch(near_uv_m=[-0.4, lowest_m - HINT_ERROR_M - margin_m])]
    # each message states the limit applied to its kind of task
    for task, limit_m in zip(refused, (lowest_m, lowest_m - HINT_ERROR_M)):
        with pytest.raises(ConfigError, match=f'below {limit_m:g} m: the lowest the mission '
                                              f'works at, {lowest_m:g} m'):
            parse_plan({'tasks': [task]}, _site(), FORCES, lowest_m)
    kept = [_slide(from_uv_m=[1.3, lowest_m + margin_m], to_uv_m=[1.3, 2.0]),
            _touch(near_uv_m=[-0.4, lowest_m - HINT_ERROR_M + margin_m])]
    assert len(parse_plan({'tasks': kept}, _site(), FORCES, lowest_m)) == 2
    # the controller checks its plan file so, with its own mission's ground
    with pytest.raises(ConfigError, match='below .* the lowest the mission works at'):
        plan_of(_config(tmp_path, refused[:1]))
    assert plan_of(_config(tmp_path, refused[:1], **{'mission.land.ground_z_m': -1.0}))


def test_the_default_time_limit_covers_what_the_plan_pushes():
    # a long hold and a long, slow slide: each task keeps the flight and search time a
    # default task has, on top of its own pushing
    rng = np.random.default_rng()
    hold_s, speed_m_s = rng.uniform(200.0, 600.0), rng.uniform(0.005, 0.01)
    tasks = parse_plan({'tasks': [_touch(hold_s=hold_s),
                                  _slide(from_uv_m=[1.3, 0.7], to_uv_m=[1.3, 2.5],
                                         speed_m_s=speed_m_s)]}, _site(), FORCES)
    flight_s = DURATION_S - MissionConfig().contact.hold_time_s
    assert default_duration_s(tasks) >= hold_s + 1.8 / speed_m_s + 2 * flight_s - 1e-9
    # the plan of the defaults keeps the per-task limit
    assert default_duration_s(load_plan(PLAN, _site(), FORCES)) == pytest.approx(
        3 * DURATION_S + 1.0 / 0.1 - MissionConfig().contact.hold_time_s)


def test_a_push_beyond_what_the_vehicle_pushes_is_refused(tmp_path):
    """Without contact feedforward the impedance law pushes with the vehicle's mass times
    its commanded acceleration, whose norm is limited: on a vertical wall 14 N were asked,
    the push stopped at that product (9.6 N) and the task held on, short of its force."""
    reach_n = VehicleParams().mass_kg * ImpedanceConfig().accel_limit_mps2
    assert reach_n < MissionConfig().failsafe.force_limit_n
    for kind in (_touch, _slide):
        with pytest.raises(ConfigError) as err:
            plan_of(_config(tmp_path, [kind(force_n=reach_n + 0.05)]))
        assert f'({FORCES[0]:g}, {reach_n:g})' in str(err.value)
        assert 'accel_limit_mps2' in str(err.value)
        assert plan_of(_config(tmp_path, [kind(force_n=reach_n - 0.05)]))
    # the one-touch inspection's contact_force likewise, on the vehicle the core flies
    with pytest.raises(ConfigError, match="'contact_force'.*accel_limit_mps2"):
        ControllerCore(VehicleParams(), ControllerConfig(contact_force=reach_n + 0.05))
    heavier = VehicleParams(mass_kg=2.0 * VehicleParams().mass_kg)
    assert ControllerCore(heavier, ControllerConfig(contact_force=reach_n + 0.05))
    # a law that feeds the measured contact force forward is held by the force limit alone
    assert plan_of(_config(tmp_path, [_touch(force_n=reach_n + 0.05)],
                           **{'flight.impedance.contact_feedforward': True}))


def test_a_line_just_longer_than_the_slides_tolerance_is_taken():
    tolerance_m = MissionConfig().slide.path_tolerance_m
    (slide,) = parse_plan({'tasks': [_slide(to_uv_m=[1.3, 1.0 + tolerance_m * 1.01])]},
                          _site(), FORCES, tolerance_m=tolerance_m)
    assert slide.length_m > tolerance_m


@pytest.mark.parametrize('line, tips, along', [
    # a tip that stays where it started has come nowhere, even where the line ends there
    ([[0.0, 1.0], [0.0, 1.5], [0.0, 1.0]], [[0.0, 1.0]] * 5, 0.0),
    # nor one that stays on the line past its start
    ([[0.0, 1.0], [0.0, 2.0]], [[0.01, 1.5]] * 100, 0.5),
    # up and back: the way back counts on the way back, not as a return to the start
    ([[0.0, 1.0], [0.0, 1.5], [0.0, 1.0]],
     [[0.001, v] for v in (*np.linspace(1.0, 1.5, 101), *np.linspace(1.5, 1.1, 81))], 0.9),
    # an L, its corner cut by 1 cm: the nearest point of each leg
    ([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]],
     [[u, 0.0] for u in np.linspace(0.0, 0.99, 100)] + [[0.99, 0.01]]
     + [[1.0, v] for v in np.linspace(0.02, 0.6, 59)], 1.6),
])
def test_the_progress_along_a_line_follows_it_leg_by_leg(line, tips, along):
    progress = LineProgress(line)
    for tip in tips:
        progress.update(tip)
    assert progress.along_m == pytest.approx(along, abs=1e-9)


def test_a_touch_on_a_site_without_target_ids_says_a_target_needs_an_id():
    """A scenario whose one target has no id (default.yaml) gives the site no ids."""
    site = _site()
    site.target_ids = []
    with pytest.raises(ConfigError) as err:
        parse_plan({'tasks': [_touch()]}, site, FORCES)
    assert "target objects need" in str(err.value) and "'id'" in str(err.value)


def test_a_slide_needs_the_surveyed_wall():
    site = SiteConfig(target_ids=['plate_a'])
    with pytest.raises(ConfigError, match=r'tasks\[0\] \(slide\).*site.wall_width_m'):
        parse_plan({'tasks': [_slide()]}, site, FORCES)


def _config(tmp_path, tasks, **values):
    path = tmp_path / 'plan.yaml'
    path.write_text(yaml.safe_dump({'tasks': tasks}))
    data = {**site_overrides(load_scenario(SCENARIO)), 'plan_file': str(path), **values}
    return from_dict(ControllerConfig, data)


def test_the_controller_takes_the_plan_file_and_inspect_stays_one_touch(tmp_path):
    core = ControllerCore(VehicleParams(), _config(tmp_path, [_touch(), _slide()],
                                                   autostart='plan'))
    assert [t.kind for t in core.mission.plan] == ['touch', 'slide']
    report = core.plan_report()
    assert [t['kind'] for t in report['tasks']] == ['touch', 'slide']
    assert report['wall'] is not None
    inspect = ControllerCore(VehicleParams(), ControllerConfig(contact_force=7.0))
    (task,) = inspect.mission.plan
    assert isinstance(task, Touch) and task.target == '' and task.hint_map is None
    assert task.force_n == 7.0 and task.hold_s == MissionConfig().contact.hold_time_s
    with pytest.raises(ConfigError, match="'plan' needs 'plan_file'"):
        plan_of(ControllerConfig(autostart='plan'))
    with pytest.raises(ConfigError, match="autostart 'inspect' is the one-touch"):
        plan_of(_config(tmp_path, [_touch()], autostart='inspect'))


def test_site_arguments_keep_ids_strings():
    words = ros_arguments({'site.target_ids': ['y', 'plate_b'], 'site.wall_yaw_deg': 5.0,
                           'site.target_hint_uv_m': []})
    assert words == ['-p', "site.target_ids:=['y', 'plate_b']", '-p', 'site.wall_yaw_deg:=5.0']


def test_controller_node_stops_with_one_line_on_a_bad_plan(tmp_path):
    """Through ROS: the site as launch.sh gives it (typed list parameters) and a plan that
    names a target the site does not have."""
    path = tmp_path / 'plan.yaml'
    path.write_text(yaml.safe_dump({'tasks': [_touch(target='plate_z')]}))
    site = subprocess.run([sys.executable, '-m', 'uav_tilt_tools.runner.site_params',
                           str(SCENARIO)],
                          capture_output=True, text=True, check=True).stdout.splitlines()
    cmd = [sys.executable, '-m', 'uav_tilt_control.controller_node', '--ros-args',
           '-p', 'autostart:=plan', '-p', f'plan_file:={path}', *site]
    out = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=60)
    assert out.returncode == 2, out.stderr
    fatal = [line for line in out.stderr.splitlines() if line.startswith('[FATAL]')]
    assert len(fatal) == 1 and "'target' = 'plate_z'" in fatal[0], out.stderr
    assert "['plate_a', 'plate_b']" in fatal[0]       # the site's ids came through ROS


@pytest.mark.parametrize('argv, words', [
    (['fly', '--scenario', str(SCENARIO), '--plan', '{plan}'], ['uav-tilt fly:', 'plate_z']),
    (['campaign', '--n', '1', '--scenario', str(SCENARIO), '--plan', '{plan}'],
     ['uav-tilt campaign:', 'plate_z']),
    (['campaign', '--n', '1', '--plan', str(PLAN)], ['--plan and --scenario go together']),
])
def test_fly_and_campaign_refuse_a_bad_plan_with_one_line(tmp_path, argv, words):
    path = tmp_path / 'plan.yaml'
    path.write_text(yaml.safe_dump({'tasks': [_touch(target='plate_z')]}))
    cmd = [sys.executable, '-m', 'uav_tilt_tools.cli',
           *(a.replace('{plan}', str(path)) for a in argv)]
    out = subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True, timeout=60)
    assert out.returncode == 2 and out.stdout == '', out
    # nothing else: not even the build time pybullet's import prints (uav_tilt_sim.bullet)
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and all(w in lines[0] for w in words), out.stderr


@pytest.mark.parametrize('argv, words', [
    (['--mission', 'plan'], '--mission plan and --plan FILE go together'),
    (['--plan', str(PLAN)], '--mission plan and --plan FILE go together'),
    (['--mission', 'plan', '--plan', 'no_such_plan.yaml'], '--plan: no file'),
])
def test_launch_refuses_a_plan_without_its_mission_or_file(tmp_path, argv, words):
    out = subprocess.run([str(REPO / 'scripts' / 'launch.sh'), *argv], cwd=tmp_path,
                         capture_output=True, text=True, timeout=30)
    assert out.returncode == 2 and words in out.stderr, out.stderr
