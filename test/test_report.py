"""uav-tilt report on synthetic recordings: exact summary values, plots, missing topics."""
import argparse
import json
import math

import numpy as np
import pytest
from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import CameraInfo

from uav_tilt_common import names, ros_msgs
from uav_tilt_common.state import VehicleState
from uav_tilt_common.vehicle import VehicleParams
from uav_tilt_tools import report
from uav_tilt_tools.mcap_bag import McapBag
from uav_tilt_tools.report_plots import write_plots

TOOL_X = VehicleParams().tool_tip_x_m
DT = 1.0 / 300
N = 600                       # 2 s of 300 Hz samples
HOLD_FIRST, HOLD_LAST = 0.5, 1.5
WALL_X = 2.0
POI = np.array([WALL_X, 0.0, 1.5])
# Target frame: z_t = -x_map (normal out of the wall towards the vehicle).
Q_TARGET = np.array([0.5, -0.5, -0.5, 0.5])
TIP_OFFSET = np.array([0.0, 0.03, -0.04])    # tool tip - POI while holding: 5 cm


def stamp(t):
    return ros_msgs.to_stamp(t)


def wall_ns(t):
    """Log time: the run goes at half real time, starting at 1000 s."""
    return int(1e12 + t * 2e9)


def status(t, **values):
    return ros_msgs.diagnostics_msg('controller', values, stamp(t))


def synthetic_recording(push_n):
    """Vehicle facing +x with its tool tip at POI + TIP_OFFSET, pushing ``push_n[k]``."""
    t = np.arange(N) * DT
    p_body = POI + TIP_OFFSET - np.array([TOOL_X, 0.0, 0.0])
    rec = {names.GROUND_TRUTH_ODOM: [], names.EE_WRENCH: [], names.CLOCK: []}
    for k, tk in enumerate(t):
        state = VehicleState(tk, p_body, np.array([0.0, 0.0, 0.0, 1.0]), np.zeros(3),
                             np.zeros(3))
        rec[names.GROUND_TRUTH_ODOM].append((wall_ns(tk), ros_msgs.odometry_msg(
            state, stamp(tk))))
        # The wall pushes the tool back along -x (the normal); some lateral friction.
        rec[names.EE_WRENCH].append((wall_ns(tk), ros_msgs.wrench_msg(
            [-push_n[k], 0.3, 0.0], [0.0, 0.0, 0.0], stamp(tk))))
        rec[names.CLOCK].append((wall_ns(tk), Clock(clock=stamp(tk))))
    target = PoseStamped()
    target.pose.position.x, target.pose.position.y, target.pose.position.z = POI
    o = target.pose.orientation
    o.x, o.y, o.z, o.w = Q_TARGET
    rec[names.GROUND_TRUTH_TARGET] = [(wall_ns(0.0), target)]
    modes = [(0.0, 'IDLE'), (0.1, 'TAKEOFF'), (0.3, 'CONTACT'), (HOLD_FIRST, 'HOLD'),
             (1.0, 'HOLD'), (HOLD_LAST, 'HOLD'), (1.7, 'RETREAT'), (1.9, 'IDLE')]
    rec[names.CONTROLLER_STATUS] = [
        (wall_ns(tc), status(tc, mode=mode, success=tc >= 1.9, contact_lost=1,
                             contact_force=6.0, loop_rate_hz=298.5))
        for tc, mode in modes]
    return rec, t


def test_force_and_poi_metrics_are_exact_over_hold():
    push = 6.0 + np.where(np.arange(N) % 2 == 0, 0.5, -1.5)   # mean 5.5, errors +-
    push[100] = 12.0       # a spike outside HOLD: only max_force sees it
    rec, t = synthetic_recording(push)
    summary = report.summarize(rec, TOOL_X)
    held = push[(t >= HOLD_FIRST) & (t <= HOLD_LAST)]
    assert summary['force_mean_n'] == pytest.approx(held.mean(), abs=1e-9)
    assert summary['force_rms_error_n'] == pytest.approx(
        math.sqrt(np.mean((held - 6.0) ** 2)), abs=1e-9)
    assert summary['max_force_n'] == pytest.approx(math.hypot(12.0, 0.3), abs=1e-9)
    assert summary['poi_error_m'] == pytest.approx(0.05, abs=1e-9)
    assert summary['success'] is True
    assert summary['contact_lost'] == 1
    assert summary['mission_time_s'] == pytest.approx(1.8, abs=1e-9)
    assert summary['rtf'] == pytest.approx(0.5, abs=1e-6)
    assert summary['controller_rate_hz'] == pytest.approx(298.5)
    assert set(summary) == set(report.SUMMARY_KEYS)


def test_default_setpoint_is_5_newton_without_contact_force_in_status():
    rec, _ = synthetic_recording(np.full(N, 5.0))
    for _, msg in rec[names.CONTROLLER_STATUS]:
        msg.status[0].values = [kv for kv in msg.status[0].values if kv.key != 'contact_force']
    assert report.summarize(rec, TOOL_X)['force_rms_error_n'] == pytest.approx(0.0, abs=1e-12)


def test_vision_rate_and_latency_from_frames():
    rec = {names.CAMERA_INFO: [], names.TARGET_POSE: []}
    for k in range(31):               # 30 Hz sim, 10 ms image -> pose on the wall clock
        tk = k / 30
        info, pose = CameraInfo(), PoseWithCovarianceStamped()
        info.header.stamp = pose.header.stamp = stamp(tk)
        pose.pose.covariance[0] = -1.0 if k % 3 == 0 else 0.01
        rec[names.CAMERA_INFO].append((int(tk * 1e9), info))
        rec[names.TARGET_POSE].append((int(tk * 1e9) + 10_000_000, pose))
    summary = report.summarize(rec, TOOL_X)
    assert summary['vision_fps'] == pytest.approx(30.0, rel=1e-6)
    assert summary['vision_latency_ms_p95'] == pytest.approx(10.0, abs=1e-6)
    t, seen = report.detections(rec)
    assert seen.sum() == 20


def test_missing_topics_give_nulls_and_no_plots(tmp_path):
    summary = report.summarize({}, TOOL_X)
    assert set(summary) == set(report.SUMMARY_KEYS)
    assert all(v is None for v in summary.values())
    assert write_plots({}, str(tmp_path), TOOL_X) == []


def test_report_command_reads_the_mcap_and_writes_summary_and_plots(tmp_path):
    """Through a real MCAP file: what the recorder writes, the report reads."""
    from rclpy.serialization import serialize_message
    rec, _ = synthetic_recording(np.full(N, 5.5))
    bag = McapBag(tmp_path / 'recording.mcap')
    types = {names.GROUND_TRUTH_ODOM: 'nav_msgs/msg/Odometry',
             names.EE_WRENCH: 'geometry_msgs/msg/WrenchStamped',
             names.CLOCK: 'rosgraph_msgs/msg/Clock',
             names.GROUND_TRUTH_TARGET: 'geometry_msgs/msg/PoseStamped',
             names.CONTROLLER_STATUS: 'diagnostic_msgs/msg/DiagnosticArray'}
    for topic, type_name in types.items():
        absolute = topic if topic.startswith('/') else '/uav/' + topic
        bag.add_topic(absolute, type_name)
        for log_ns, msg in rec[topic]:
            bag.write(absolute, serialize_message(msg), log_ns)
    bag.close()
    assert report.run(argparse.Namespace(run_dir=str(tmp_path))) == 0
    summary = json.loads((tmp_path / 'summary.json').read_text())
    assert summary == report.summarize(rec, TOOL_X)
    assert summary['force_mean_n'] == pytest.approx(5.5)
    for plot in ('trajectory.png', 'force.png', 'poi_error.png'):
        assert (tmp_path / plot).stat().st_size > 1000
    # No actuator or vision topics were recorded: those plots are left out.
    assert not (tmp_path / 'actuators.png').exists()
    assert not (tmp_path / 'vision.png').exists()


def _plan_message(tasks):
    from std_msgs.msg import String
    return String(data=json.dumps({'tasks': tasks, 'wall': None}))


def test_per_task_results_from_the_recorded_plan(tmp_path):
    """A touch (HOLD_FIRST..HOLD_LAST) and a slide window over the same synthetic run: the
    touch's keys as the top level's, the slide's path error is the tip's distance from its
    line in the wall's plane (the normal part, the push's depth, left out)."""
    push = 5.0 + np.where(np.arange(N) % 2 == 0, 0.2, -0.2)
    rec, t = synthetic_recording(push)
    tip = POI + TIP_OFFSET
    line = [(tip + [0.03, 0.02, z]).tolist() for z in (-0.5, 0.5)]   # 3 cm deep, 2 cm aside
    rec[names.CONTROLLER_PLAN] = [(wall_ns(0.0), _plan_message([
        dict(index=0, kind='touch', target='', force_n=6.0, success=True, reason='',
             contact_lost=0, t_contact_s=[HOLD_FIRST, HOLD_LAST]),
        dict(index=1, kind='slide', force_n=5.0, success=False, reason='off_line',
             contact_lost=2, t_contact_s=[0.2, 0.4], points_map=line,
             normal_map=[-1.0, 0.0, 0.0], length_m=1.0, points_uv=[[0.0, 1.0], [0.0, 2.0]])]))]
    tasks = report.summarize(rec, TOOL_X)['tasks']
    touch, slide = tasks
    held = push[(t >= HOLD_FIRST) & (t < HOLD_LAST)]
    assert touch['success'] and touch['target'] == ''
    assert touch['poi_error_m'] == pytest.approx(0.05, abs=1e-9)
    assert touch['force_mean_n'] == pytest.approx(held.mean(), abs=1e-9)
    assert touch['force_rms_error_n'] == pytest.approx(np.sqrt(np.mean((held - 6.0) ** 2)))
    slid = push[(t >= 0.2) & (t < 0.4)]
    assert (slide['success'], slide['reason'], slide['contact_lost']) == (False, 'off_line', 2)
    assert slide['path_rms_error_m'] == pytest.approx(0.02, abs=1e-9)
    assert slide['path_max_error_m'] == pytest.approx(0.02, abs=1e-9)
    assert slide['length_m'] == pytest.approx(0.0, abs=1e-12)          # it did not move
    assert slide['duration_s'] == pytest.approx(0.2 - DT, abs=DT / 2)
    assert slide['force_rms_error_n'] == pytest.approx(np.sqrt(np.mean((slid - 5.0) ** 2)))
    written = write_plots(rec, str(tmp_path), TOOL_X)
    assert str(tmp_path / 'slides.png') in written
