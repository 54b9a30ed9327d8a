"""The report draws the world that was flown: a plan (two touches on two plates named by id,
then a slide) flown in-process on a wall yawed 25 degrees and inclined 12 degrees, recorded
with `fly --record` and reported; the figures' data (not their pixels) against the
scenario: the wall's extent, yaw and inclination, each target where its truth is, each
task's setpoint and target its own, and the hold's POI error on an axis where a millimetre
shows. The summary answers each question once (the hold time, the setpoint)."""
import json
import math
import subprocess
import sys

import numpy as np
import pytest
import yaml

from ros_graph import REPO
from uav_tilt_common.vehicle import VehicleParams
from uav_tilt_tools.bag import reader
from uav_tilt_tools.report import task_plots, world_plots

pytestmark = pytest.mark.slow       # a minute and a half of flight, in-process

TOOL_X = VehicleParams().tool_tip_x_m
WALL = dict(position_m=[2.2, 0.8], yaw_deg=25.0, inclination_deg=12.0, width_m=4.0,
            height_m=3.0)
SCENARIO = dict(seed=3, wall=WALL, objects=[
    dict(cls='bolt_plate', id='plate_a', u_m=-0.5, v_m=1.3, target=True),
    dict(cls='bolt_plate', id='plate_b', u_m=0.5, v_m=1.7, target=True),
    dict(cls='gauge', u_m=0.0, v_m=0.9)])
PLAN = dict(tasks=[
    dict(touch=dict(target='plate_a', near_uv_m=[-0.45, 1.35], force_n=4.0, hold_s=2.0)),
    dict(touch=dict(target='plate_b', near_uv_m=[0.45, 1.65], force_n=6.0, hold_s=2.0)),
    dict(slide=dict(from_uv_m=[1.2, 1.1], to_uv_m=[1.2, 1.5], speed_m_s=0.1, force_n=5.0))])
FORCES_N = (4.0, 6.0, 5.0)
TARGETS = (('touch', 'plate_a'), ('touch', 'plate_b'), ('slide', ''))
# DPI of the saved plots (plots.write_plots): a millimetre of the hold's error axis spans
# at least this many pixels of them
DPI = 100
MM_PX = 5.0


@pytest.fixture(scope='module')
def run(tmp_path_factory):
    """(flight summary, report summary, the recording read back, its folder)."""
    tmp = tmp_path_factory.mktemp('world')
    (tmp / 'scenario.yaml').write_text(yaml.safe_dump(SCENARIO))
    (tmp / 'plan.yaml').write_text(yaml.safe_dump(PLAN))
    command = [sys.executable, '-m', 'uav_tilt_tools.cli']
    flown = subprocess.run(command + [
        'fly', '--scenario', str(tmp / 'scenario.yaml'), '--plan', str(tmp / 'plan.yaml'),
        '--target-source', 'ground_truth', '--record', str(tmp / 'run')],
        cwd=REPO, capture_output=True, text=True, timeout=900)
    assert flown.returncode == 0, flown.stderr[-3000:]
    reported = subprocess.run(command + ['report', str(tmp / 'run')], cwd=REPO,
                              capture_output=True, text=True, timeout=300)
    assert reported.returncode == 0, reported.stderr[-3000:]
    rec = reader.load_recording(str(tmp / 'run'))
    return json.loads(flown.stdout), json.loads(reported.stdout), rec, tmp / 'run'


def by_gid(fig, gid):
    """The artists of ``fig`` whose gid is ``gid``, with their axes."""
    return [(ax, a) for ax in fig.axes for a in ax.get_children() if a.get_gid() == gid]


def expected_corners():
    """The wall's corners by the scenario's numbers (its ground line through position_m,
    facing along yaw, the top leaning away by the inclination), independently of the
    plant's geometry."""
    yaw, inc = math.radians(WALL['yaw_deg']), math.radians(WALL['inclination_deg'])
    facing = np.array([math.cos(yaw), math.sin(yaw), 0.0])
    right = np.array([math.sin(yaw), -math.cos(yaw), 0.0])    # seen from in front
    up = math.sin(inc) * facing + np.array([0.0, 0.0, math.cos(inc)])
    origin = np.array([*WALL['position_m'], 0.0])
    half, height = WALL['width_m'] / 2, WALL['height_m']
    return np.array([origin + right * u + up * v for u, v in
                     ((-half, 0.0), (half, 0.0), (half, height), (-half, height))])


def test_the_recording_carries_the_world_the_plant_flew(run):
    _, _, rec, _ = run
    world = reader.world(rec)
    assert world['scenario']['wall']['yaw_deg'] == WALL['yaw_deg']
    assert [o['id'] for o in world['objects']] == ['plate_a', 'plate_b', '']
    np.testing.assert_allclose(world['wall']['corners_map'], expected_corners(), atol=1e-9)


def test_the_drawn_wall_is_the_scenario_s_in_extent_yaw_and_inclination(run):
    _, _, rec, _ = run
    fig = world_plots.plot_trajectory(rec, TOOL_X, task_plots.report_tasks(rec))
    (top, outline), (face, rectangle), (side, section) = by_gid(fig, 'wall')
    assert top.get_title().startswith('top view')
    corners = expected_corners()
    np.testing.assert_allclose(outline.get_xydata()[:4], corners[:, :2], atol=1e-9)
    # the ground line runs across the heading to the wall (yaw), 4 m long
    ground = corners[1, :2] - corners[0, :2]
    assert np.linalg.norm(ground) == pytest.approx(WALL['width_m'])
    assert math.degrees(math.atan2(ground[1], ground[0])) == pytest.approx(
        WALL['yaw_deg'] - 90.0)
    assert face.get_title().startswith('the wall')
    np.testing.assert_allclose(rectangle.get_xydata()[:4], [[-2.0, 0.0], [2.0, 0.0],
                                                            [2.0, 3.0], [-2.0, 3.0]])
    # across the wall: from its ground line up to its top, leaning away by 12 degrees
    inc = math.radians(WALL['inclination_deg'])
    np.testing.assert_allclose(section.get_xydata(), [[0.0, 0.0], [-3.0 * math.sin(inc),
                                                                   3.0 * math.cos(inc)]],
                               atol=1e-9)
    truth = reader.target_poses(rec)
    for target_id in ('plate_a', 'plate_b'):
        markers = by_gid(fig, f'target:{target_id}')
        assert len(markers) == 3        # in each view, named
        (_, top_marker), = [(ax, m) for ax, m in markers if ax is top]
        np.testing.assert_allclose(top_marker.get_xydata()[0], truth[target_id][0][:2])
        assert any(text.get_text() == target_id for text in top.texts)
    # the gauge is drawn, not as a target
    assert by_gid(fig, 'object:2')


def test_each_task_is_drawn_against_its_own_setpoint_and_target(run):
    flown, reported, rec, _ = run
    tasks = task_plots.report_tasks(rec)
    assert [(task.kind, task.target) for task in tasks] == list(TARGETS)
    fig = task_plots.plot_force(rec, tasks)
    labels = fig.axes[0].get_legend_handles_labels()[1]
    assert {'task 0: touch plate_a (hold)', 'task 1: touch plate_b (hold)',
            'task 2: slide (slide)'} <= set(labels), labels
    for task, force_n, entry in zip(tasks, FORCES_N, reported['tasks']):
        (_, line), = by_gid(fig, f'setpoint:{task.index}')
        assert set(line.get_ydata()) == {force_n} == {entry['force_setpoint_n']}
        start, end = task.record['t_contact_s']
        # over its own window, to a tick (the last sample is the tick before its end)
        assert line.get_xdata()[0] == pytest.approx(start, abs=1e-6)
        assert line.get_xdata()[1] == pytest.approx(end, abs=1.5 / 300)
    fig = task_plots.plot_poi_error(rec, TOOL_X, tasks)
    axes = set()
    for task, entry in zip(tasks[:2], reported['tasks']):
        (ax, line), = by_gid(fig, f'poi_error:{task.index}')
        axes.add(ax)
        # against its own target: the summary's POI error of that task, in millimetres
        # (the other plate is a metre away)
        assert np.mean(line.get_ydata()) == pytest.approx(entry['poi_error_m'] * 1e3,
                                                          abs=1e-6)
        assert np.max(line.get_ydata()) < 10.0
    (ax,) = axes
    fig.set_dpi(DPI)
    fig.canvas.draw()
    (_, y0), (_, y1) = ax.transData.transform([[0.0, 0.0], [0.0, 1.0]])
    assert y1 - y0 >= MM_PX, (y1 - y0, ax.get_ylim())
    assert 'mm' in ax.get_ylabel()
    fig = task_plots.plot_slides(rec, TOOL_X, tasks)
    assert fig is not None and len(fig.axes) == 2


def test_one_answer_per_question(run):
    """The top-level touch keys are the first touch's, in the flight's summary and in the
    report of its recording alike: the same hold time (as sim time from the hold's first
    sample to its last), the same setpoint."""
    flown, reported, _, _ = run
    for summary in (flown, reported):
        first = summary['tasks'][0]
        for key in ('hold_time_s', 'force_setpoint_n', 'force_mean_n', 'poi_error_m',
                    'tool_normal_angle_max_deg'):
            assert summary[key] == first[key], key
        # an inclined wall too: the tool sits square, as an ultrasonic probe needs
        assert first['tool_normal_angle_max_deg'] < 2.0
        assert summary['force_setpoint_n'] == FORCES_N[0]
        assert first['hold_time_s'] == pytest.approx(2.0 - 1.0 / 300, abs=1e-6)
    for mine, theirs in zip(reported['tasks'][:2], flown['tasks'][:2]):     # the touches
        assert mine['hold_time_s'] == pytest.approx(theirs['hold_time_s'], abs=1e-6)
        # the report's samples are the F/T's, fly's every tick: the same attitudes
        assert mine['tool_normal_angle_max_deg'] == pytest.approx(
            theirs['tool_normal_angle_max_deg'], abs=0.05)
    assert reported['failure'] is None and flown['failure'] is None


def test_the_report_writes_every_plot_of_the_plan(run):
    _, _, _, folder = run
    for name in ('trajectory.png', 'force.png', 'poi_error.png', 'slides.png',
                 'actuators.png'):
        assert (folder / name).stat().st_size > 10_000, name
