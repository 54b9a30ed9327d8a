"""uav-tilt report on synthetic recordings: exact summary values, plots, missing topics,
files the recorder did not finish."""
import json
import math
import shutil
import tracemalloc

import numpy as np
import pytest
from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped
from mcap.writer import MCAP0_MAGIC
from rclpy.serialization import serialize_message
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import CameraInfo

from uav_tilt_common import names, ros_msgs
from uav_tilt_common.state import VehicleState
from uav_tilt_common.vehicle import VehicleParams
from uav_tilt_control.controller_core import ControllerConfig, ControllerCore
from uav_tilt_control.controller_node import _loop_stats
from uav_tilt_common.modes import Mode
from uav_tilt_tools import cli
from uav_tilt_tools.bag import reader as recording
from uav_tilt_tools.bag.writer import McapBag
from uav_tilt_tools.campaign import summary as campaign_summary
from uav_tilt_tools.metrics import tasks as task_metrics
from uav_tilt_tools.report import summary as report
from uav_tilt_tools.report.plots import plot_vision, write_plots

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


RTF = 0.5


def wall_ns(t):
    """Log time: the run goes at half real time, starting at 1000 s."""
    return int(1e12 + t / RTF * 1e9)


def controller_status(contact_force_n):
    """What controller_node publishes: a tick's status from the real ControllerCore with the
    node's loop statistics, a tick each 1/300 s of sim time at RTF (the mission keys, and
    the ticks and wall time, are set per sample by :func:`status`)."""
    core = ControllerCore(VehicleParams(), ControllerConfig(contact_force=contact_force_n))
    core.on_odometry(VehicleState(0.0, np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]),
                                  np.zeros(3), np.zeros(3)))
    _, values = core.tick(0.0, np.zeros(3), 1.0 / 300)
    period_s = 1.0 / (300 * RTF)
    values.update(_loop_stats([period_s] * 10, [1e-4] * 10, 1.0 / 300))
    return values


def status(t, base, **values):
    """controller/status at sim time ``t``: its ticks so far and its wall time (the node
    started 3 s before the plant's first tick)."""
    values = dict(dict(ticks=round(300 * t), wall_time_s=3.0 + t / RTF), **values)
    return ros_msgs.diagnostics_msg('controller', dict(base, **values), stamp(t))


def plant_statuses(t_end, rtf):
    """plant/status every 0.5 s of sim time: sim_time_s and wall_time_s at ``rtf``."""
    return [(wall_ns(t), ros_msgs.diagnostics_msg(
        'plant', dict(sim_time_s=t, wall_time_s=3.0 + t / rtf), stamp(t)))
        for t in np.arange(0.0, t_end, 0.5)]


def synthetic_recording(push_n, contact_force_n=6.0, tip_offset=TIP_OFFSET, contact_lost=1):
    """Vehicle facing +x with its tool tip at POI + ``tip_offset``, pushing ``push_n[k]``;
    the controller was asked for ``contact_force_n`` and counted ``contact_lost``."""
    t = np.arange(N) * DT
    p_body = POI + tip_offset - np.array([TOOL_X, 0.0, 0.0])
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
    modes = [(0.0, Mode.IDLE), (0.1, Mode.TAKEOFF), (0.3, Mode.CONTACT), (HOLD_FIRST, Mode.HOLD),
             (1.0, Mode.HOLD), (HOLD_LAST, Mode.HOLD), (1.7, Mode.RETREAT), (1.9, Mode.IDLE)]
    base = controller_status(contact_force_n)
    rec[names.CONTROLLER_STATUS] = [
        (wall_ns(tc), status(tc, base, mode=mode.value, success=tc >= 1.9,
                             contact_lost=contact_lost))
        for tc, mode in modes]
    rec[names.PLANT_STATUS] = plant_statuses(2.0, RTF)
    return rec, t


def test_force_and_poi_metrics_are_exact_over_hold():
    push = 6.0 + np.where(np.arange(N) % 2 == 0, 0.5, -1.5)   # mean 5.5, errors +-
    push[100] = 12.0       # a spike outside HOLD: only max_force sees it
    rec, t = synthetic_recording(push)
    summary = report.summarize(rec, TOOL_X)
    held = push[(t >= HOLD_FIRST) & (t <= HOLD_LAST)]
    assert summary['force_setpoint_n'] == 6.0
    assert summary['force_mean_n'] == pytest.approx(held.mean(), abs=1e-9)
    assert summary['force_rms_error_n'] == pytest.approx(
        math.sqrt(np.mean((held - 6.0) ** 2)), abs=1e-9)
    # The push along the normal, not |F| (the 0.3 N of friction is along the wall).
    assert summary['max_force_n'] == pytest.approx(12.0, abs=1e-9)
    assert summary['poi_error_m'] == pytest.approx(0.05, abs=1e-9)
    assert summary['poi_error_max_m'] == pytest.approx(0.05, abs=1e-9)
    assert summary['hold_time_s'] == pytest.approx(HOLD_LAST - HOLD_FIRST, abs=1e-9)
    assert summary['success'] is True
    assert summary['contact_lost'] == 1
    assert summary['mission_time_s'] == pytest.approx(1.8, abs=1e-9)
    assert summary['rtf'] == pytest.approx(RTF, abs=1e-9)
    assert summary['controller_rate_hz'] == pytest.approx(300 * RTF)
    assert set(summary) == set(report.SUMMARY_KEYS)
    # completed, but 5 cm from the point of interest by the truth
    assert summary['failure'] == {'reason': 'off_target', 'mode': 'HOLD', 'phase': ''}


def test_failure_judges_the_recorded_run_on_the_truth_as_the_campaign_does():
    """summary.json ``failure`` is null only for a completed run within the inspection bar:
    the tip within 1 cm of the POI, the push within 0.1 N mean and 0.2 N RMS of the
    setpoint; a failsafe is named with the mode it fired in."""
    rng = np.random.default_rng()
    angle = rng.uniform(0.0, 2.0 * math.pi)
    along_wall = np.array([0.0, math.cos(angle), math.sin(angle)])
    steady = np.full(N, 6.0 + rng.uniform(-0.09, 0.09))
    rec, _ = synthetic_recording(steady, tip_offset=along_wall * rng.uniform(0.0, 0.0095))
    assert report.summarize(rec, TOOL_X)['failure'] is None
    rec, _ = synthetic_recording(steady, tip_offset=along_wall * rng.uniform(0.0105, 0.1))
    assert report.summarize(rec, TOOL_X)['failure']['reason'] == 'off_target'
    # off the setpoint by more than the bar (not off the steady push, which may lie on
    # the other side of it)
    off = np.full(N, 6.0 + rng.choice([-1.0, 1.0]) * rng.uniform(0.11, 1.0))
    rec, _ = synthetic_recording(off, tip_offset=np.zeros(3))
    assert report.summarize(rec, TOOL_X)['failure']['reason'] == 'force_off_setpoint'
    # the force limit trips in HOLD at 1.0 s: not completed, whatever the touch measured
    base = controller_status(6.0)
    rec[names.CONTROLLER_STATUS] = [
        (wall_ns(tc), status(tc, base, mode=mode.value, phase='', success=False,
                             failsafe_reason='force_limit' if tc > 1.0 else ''))
        for tc, mode in [(0.3, Mode.CONTACT), (HOLD_FIRST, Mode.HOLD), (1.0, Mode.HOLD),
                         (1.2, Mode.RETREAT), (1.9, Mode.IDLE)]]
    assert report.summarize(rec, TOOL_X)['failure'] == {
        'reason': 'force_limit', 'mode': 'HOLD', 'phase': ''}
    # a slide's task failure, then a retreat held on its way: the failsafe that ended the
    # run, as fly names it (the controller's last failsafe reason), not the task's
    reasons = ['', 'off_line', 'off_line', 'unreachable', 'unreachable']
    rec[names.CONTROLLER_STATUS] = [
        (wall_ns(tc), status(tc, base, mode=mode.value, phase='', success=False,
                             failsafe_reason=reason))
        for (tc, mode), reason in zip([(0.3, Mode.SLIDE), (0.6, Mode.RETREAT),
                                       (1.0, Mode.RETREAT), (1.2, Mode.LAND),
                                       (1.9, Mode.IDLE)], reasons)]
    assert report.summarize(rec, TOOL_X)['failure'] == {
        'reason': 'unreachable', 'mode': 'RETREAT', 'phase': ''}


def test_the_controller_rate_is_its_ticks_over_its_wall_time():
    """As fly counts it: a loop that slowed for a while counts with the ticks it missed (a
    median of the statuses' windows would give the unloaded rate), and the statuses sent
    before the first tick (waiting for sensors) do not count."""
    rng = np.random.default_rng()
    rate_hz, slow_hz = rng.uniform(250.0, 300.0), rng.uniform(50.0, 150.0)
    # 10 Hz statuses over 12 s of wall time: 2 s waiting, then 6 s at rate_hz, 4 s at slow_hz
    walls_s = 0.1 * np.arange(121)
    hz = np.where(walls_s <= 2.0, 0.0, np.where(walls_s <= 8.0, rate_hz, slow_hz))
    ticks = np.floor(np.cumsum(hz * 0.1)).astype(int)
    rec, _ = synthetic_recording(np.full(N, 5.0))
    base = controller_status(5.0)
    rec[names.CONTROLLER_STATUS] = [
        (wall_ns(w), status(w, base, mode=Mode.HOVER.value, ticks=int(n), wall_time_s=w))
        for w, n in zip(walls_s, ticks)]
    first = np.argmax(ticks > 0)
    assert walls_s[first] == pytest.approx(2.1)
    rate = report.summarize(rec, TOOL_X)['controller_rate_hz']
    assert rate == pytest.approx((ticks[-1] - ticks[first]) / (12.0 - 2.1), rel=1e-9)
    assert rate == pytest.approx((5.9 * rate_hz + 4.0 * slow_hz) / 9.9, abs=0.2)


@pytest.mark.parametrize('asked_n', [4.0, 7.5])
def test_the_push_is_scored_against_what_the_controller_was_asked(asked_n):
    rec, _ = synthetic_recording(np.full(N, 5.0), contact_force_n=asked_n)
    summary = report.summarize(rec, TOOL_X)
    assert summary['force_setpoint_n'] == asked_n
    assert summary['force_rms_error_n'] == pytest.approx(abs(5.0 - asked_n), abs=1e-9)


def test_no_setpoint_in_the_status_gives_no_error_score():
    rec, _ = synthetic_recording(np.full(N, 5.0))
    for _, msg in rec[names.CONTROLLER_STATUS]:
        msg.status[0].values = [kv for kv in msg.status[0].values
                                if kv.key != 'contact_force_n']
    summary = report.summarize(rec, TOOL_X)
    assert summary['force_setpoint_n'] is None and summary['force_rms_error_n'] is None
    assert summary['force_mean_n'] == pytest.approx(5.0)


def test_vision_rate_and_latency_come_from_vision_status():
    rec = {names.CAMERA_INFO: [], names.TARGET_POSE: [], names.VISION_STATUS: []}
    for k in range(31):               # 30 Hz sim, 10 ms image -> pose on the recorder clock
        tk = k / 30
        info, pose = CameraInfo(), PoseWithCovarianceStamped()
        info.header.stamp = pose.header.stamp = stamp(tk)
        pose.pose.covariance[0] = -1.0 if k % 3 == 0 else 0.01
        rec[names.CAMERA_INFO].append((int(tk * 1e9), info))
        rec[names.TARGET_POSE].append((int(tk * 1e9) + 10_000_000, pose))
    # over the run: none while the detector loads, then 29-31 fps, then two statuses sent
    # as the graph stops, over part of a window
    rates = [(0.0, 0.0)] + [(30.0 + k % 3 - 1, 20.0 + k % 3) for k in range(20)] + \
        [(2.0, 90.0), (0.0, 0.0)]
    for k, (fps, p95) in enumerate(rates):
        rec[names.VISION_STATUS].append((0, ros_msgs.diagnostics_msg(
            'vision', dict(fps=fps, latency_ms_p95=p95, frames_processed=10),
            stamp(0.5 * k))))
    summary = report.summarize(rec, TOOL_X)
    assert summary['vision_fps'] == 30.0 and summary['vision_latency_ms_p95'] == 21.0
    t, seen = recording.detections(rec)
    assert seen.sum() == 20
    _, latency = recording.frame_latencies_ms(rec)
    assert np.allclose(latency, 10.0)


def test_missing_topics_give_nulls_and_no_plots(tmp_path):
    summary = report.summarize({}, TOOL_X)
    assert set(summary) == set(report.SUMMARY_KEYS)
    # without the controller's status the run is not shown to have completed
    assert summary.pop('failure') == {'reason': 'not_completed', 'mode': 'none', 'phase': ''}
    assert all(v is None for v in summary.values())
    assert write_plots({}, str(tmp_path), TOOL_X) == []


TYPES = {names.GROUND_TRUTH_ODOM: 'nav_msgs/msg/Odometry',
         names.EE_WRENCH: 'geometry_msgs/msg/WrenchStamped',
         names.CLOCK: 'rosgraph_msgs/msg/Clock',
         names.GROUND_TRUTH_TARGET: 'geometry_msgs/msg/PoseStamped',
         names.CONTROLLER_STATUS: 'diagnostic_msgs/msg/DiagnosticArray',
         names.PLANT_STATUS: 'diagnostic_msgs/msg/DiagnosticArray'}


def in_time_order(rec):
    """(log_ns, topic, msg) of every message, in the order a recorder gets them."""
    return sorted(((log_ns, topic, msg) for topic in TYPES for log_ns, msg in rec[topic]),
                  key=lambda item: item[0])


def open_bag(path, chunk_bytes=1 << 20):
    bag = McapBag(path, chunk_bytes=chunk_bytes)
    for topic, type_name in TYPES.items():
        bag.add_topic(topic if topic.startswith('/') else '/uav/' + topic, type_name)
    return bag


def write(bag, topic, msg, log_ns):
    bag.write(topic if topic.startswith('/') else '/uav/' + topic, serialize_message(msg),
              log_ns)


def test_report_command_reads_the_mcap_and_writes_summary_and_plots(tmp_path, capsys):
    """Through a real MCAP file: what the recorder writes, the report reads."""
    rec, _ = synthetic_recording(np.full(N, 5.5))
    bag = open_bag(tmp_path / 'recording.mcap')
    for log_ns, topic, msg in in_time_order(rec):
        write(bag, topic, msg, log_ns)
    bag.close()
    # the tool tip off the point of interest: the run missed the bar, exit 1 (as fly)
    assert cli.main(['report', str(tmp_path)]) == 1
    assert 'incomplete' not in capsys.readouterr().out
    summary = json.loads((tmp_path / 'summary.json').read_text())
    assert summary == report.summarize(rec, TOOL_X)
    assert summary['failure']['reason'] == 'off_target'
    assert summary['force_mean_n'] == pytest.approx(5.5)
    for plot in ('trajectory.png', 'force.png', 'poi_error.png'):
        assert (tmp_path / plot).stat().st_size > 1000
    # No actuator or vision topics were recorded: those plots are left out.
    assert not (tmp_path / 'actuators.png').exists()
    assert not (tmp_path / 'vision.png').exists()


def test_the_camera_images_are_not_held_in_memory_while_reading(tmp_path):
    """A recording is mostly camera images, which the report does not read: they pass
    through one chunk at a time, so reading peaks at a few chunks, not at the file's size.
    (Iterating a whole file in file order through the MCAP library's seeking reader queues
    every message of the file before the first is yielded.)"""
    rec, _ = synthetic_recording(np.full(N, 5.5))
    image_bytes, chunk_bytes = 1 << 19, 1 << 20
    images = {int(k * N / 64): k for k in range(64)}      # 64 images of 0.5 MiB: 32 MiB
    rng = np.random.default_rng()
    bag = open_bag(tmp_path / 'recording.mcap', chunk_bytes=chunk_bytes)
    bag.add_topic('/uav/' + names.CAMERA_COLOR, 'sensor_msgs/msg/Image')
    for i, (log_ns, topic, msg) in enumerate(in_time_order(rec)):
        write(bag, topic, msg, log_ns)
        if i in images:     # random pixels: zstd cannot shrink them
            pixels = rng.integers(0, 256, (256, 683, 3), np.uint8)       # >= 0.5 MiB
            write(bag, names.CAMERA_COLOR, ros_msgs.image_msg(pixels, stamp(0.0)), log_ns)
    bag.close()
    assert (tmp_path / 'recording.mcap').stat().st_size > 64 * image_bytes
    tracemalloc.start()
    try:
        loaded = recording.load_recording(str(tmp_path))
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert names.CAMERA_COLOR not in loaded and names.CLOCK not in loaded   # not read
    assert {t: len(m) for t, m in loaded.items()} == {t: len(m) for t, m in rec.items()
                                                      if t != names.CLOCK}
    # the decoded messages (a few MiB) and a chunk or two in flight; the file is 32 MiB
    assert peak < 12 * chunk_bytes, peak


def test_the_report_exits_0_only_for_a_run_that_met_the_bar(tmp_path, capsys):
    # met; pushing half the force asked; the tool tip 5 cm off the point of interest
    for tip_offset, push_n, code in ((np.zeros(3), 6.0, 0), (np.zeros(3), 3.0, 1),
                                     (TIP_OFFSET, 6.0, 1)):
        rec, _ = synthetic_recording(np.full(N, push_n), tip_offset=tip_offset,
                                     contact_lost=0)
        run = tmp_path / f'run_{len(list(tmp_path.iterdir()))}'
        run.mkdir()
        bag = open_bag(run / 'recording.mcap')
        for log_ns, topic, msg in in_time_order(rec):
            write(bag, topic, msg, log_ns)
        bag.close()
        assert cli.main(['report', str(run)]) == code
        summary = json.loads(capsys.readouterr().out)
        assert (summary['failure'] is None) == (code == 0), summary['failure']


def test_a_file_without_its_end_is_read_to_its_last_complete_chunk(tmp_path, capsys):
    """As a killed recorder leaves it: flushed chunks, then a torn one, no summary. (The
    run is 5 cm off its point of interest: each report exits 1.)"""
    rec, _ = synthetic_recording(np.full(N, 5.5))
    live = tmp_path / 'live'
    live.mkdir()
    bag = open_bag(live / 'recording.mcap', chunk_bytes=1 << 30)   # chunks only by flush
    messages = in_time_order(rec)
    cut = next(i for i, (log_ns, _, _) in enumerate(messages) if log_ns > wall_ns(1.8))
    for log_ns, topic, msg in messages[:cut]:
        write(bag, topic, msg, log_ns)
    bag.flush()
    flushed = (live / 'recording.mcap').stat().st_size
    for log_ns, topic, msg in messages[cut:]:
        write(bag, topic, msg, log_ns)
    bag.flush()
    run = tmp_path / 'run'
    run.mkdir()
    with open(live / 'recording.mcap', 'rb') as src, open(run / 'recording.mcap', 'wb') as dst:
        data = src.read()
        dst.write(data[:flushed + 100])     # the second chunk torn, no footer
    bag.close()
    assert cli.main(['report', str(run)]) == 1
    out, err = capsys.readouterr()
    read = sum(topic in recording.REPORT_TOPICS for _, topic, _ in messages[:cut])
    assert 'incomplete (no footer' in err and f'read {read} messages' in err
    summary = json.loads((run / 'summary.json').read_text())
    assert json.loads(out) == summary           # stdout: the JSON alone, as fly prints it
    kept = {topic: [(log_ns, m) for log_ns, m in msgs if log_ns <= wall_ns(1.8)]
            for topic, msgs in rec.items()}
    assert summary == report.summarize(kept, TOOL_X)
    assert summary['force_mean_n'] == pytest.approx(5.5) and summary['success'] is False
    # The finished file reads completely.
    shutil.copy(live / 'recording.mcap', run / 'recording.mcap')
    assert cli.main(['report', str(run)]) == 1
    assert 'incomplete' not in capsys.readouterr().err
    assert json.loads((run / 'summary.json').read_text()) == report.summarize(rec, TOOL_X)
    # a file torn within its first record (shorter than MCAP's footer) is an empty run
    for size in (len(MCAP0_MAGIC), 20):
        (run / 'recording.mcap').write_bytes(data[:size])
        assert cli.main(['report', str(run)]) == 1
        out, err = capsys.readouterr()
        assert 'read 0 messages' in err and json.loads(out)['success'] is None   # no data
    # the file itself, as well as its folder; the summary goes beside it
    shutil.copy(live / 'recording.mcap', run / 'recording.mcap')
    (run / 'summary.json').unlink()
    assert cli.main(['report', str(run / 'recording.mcap')]) == 1
    assert json.loads((run / 'summary.json').read_text()) == report.summarize(rec, TOOL_X)


@pytest.mark.parametrize('content, why', [(None, 'no *.mcap in'),
                                          (b'garbage', 'is not an MCAP file'),
                                          (b'', 'is not an MCAP file'),
                                          ('two', '2 MCAP files in'),
                                          ('missing', 'no such folder or file')])
def test_a_folder_without_an_mcap_recording_is_refused_with_one_line(tmp_path, capsys,
                                                                     content, why):
    """Bad input: exit 2, one line on stderr, no summary (unlike a file torn at its end);
    two runs in one folder are not merged into one."""
    run_dir = tmp_path / 'no_such_run' if content == 'missing' else tmp_path
    if content == 'two':
        for name in ('a.mcap', 'b.mcap'):
            (tmp_path / name).write_bytes(MCAP0_MAGIC)
    elif content not in (None, 'missing'):
        (tmp_path / 'recording.mcap').write_bytes(content)
    assert cli.main(['report', str(run_dir)]) == 2
    out, err = capsys.readouterr()
    assert err.startswith('uav-tilt report: ') and why in err and err.count('\n') == 1
    assert out == '' and not (tmp_path / 'summary.json').exists()


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
    summary = report.summarize(rec, TOOL_X)
    touch, slide = summary['tasks']
    for key in ('poi_error_m', 'force_setpoint_n', 'force_mean_n', 'force_rms_error_n'):
        assert summary[key] == touch[key], key          # the first touch's, at 6 N
    held = push[(t >= HOLD_FIRST) & (t < HOLD_LAST)]
    # completed by the controller, 5 cm from the point of interest by the truth
    assert (touch['success'], touch['reason'], touch['target']) == (False, 'off_target', '')
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


def test_a_slide_that_comes_back_on_itself_is_measured_along_its_line():
    """Up 0.5 m and back down 0.4 m: 0.9 m of its 1 m line covered, though the tip ends
    0.1 m from where it began; the plot's axis along the line does not fold either."""
    start = np.array([WALL_X, 1.3, 1.0])
    line = [start, start + [0.0, 0.0, 0.5], start]
    heights = np.concatenate((np.linspace(0.0, 0.5, 151), np.linspace(0.5, 0.1, 121)[1:]))
    t = np.arange(len(heights)) * DT
    tips = start + np.outer(heights, [0.0, 0.0, 1.0]) + [-0.004, 0.0, 0.0]  # pushed in
    task = dict(index=0, kind='slide', force_n=5.0, success=True, reason='', contact_lost=0,
                t_contact_s=[0.0, t[-1] + DT], points_map=[p.tolist() for p in line],
                normal_map=[-1.0, 0.0, 0.0], length_m=1.0,
                points_uv=[[1.3, 1.0], [1.3, 1.5], [1.3, 1.0]])
    normal = np.array([-1.0, 0.0, 0.0])
    (slide,) = task_metrics.task_results([task], t, tips, np.outer(np.full(len(t), 5.0),
                                                                   normal))
    assert slide['length_m'] == pytest.approx(0.9, abs=1e-9)
    assert slide['path_max_error_m'] == pytest.approx(0.0, abs=1e-12)
    assert slide['force_mean_n'] == pytest.approx(5.0)
    _, along, _ = task_metrics.slide_geometry(task, tips, normal)
    assert np.all(np.diff(along) >= 0.0) and along[-1] == pytest.approx(0.9, abs=1e-9)


@pytest.mark.parametrize('rounding_s', [-4e-10, 4e-10])
def test_a_recording_stamped_in_whole_nanoseconds_scores_the_same_samples(rounding_s):
    """fly scores a task on the controller's float times, the report on the recording's
    nanosecond stamps: a stamp rounded either way is still the sample of its tick."""
    t = 10.0 + np.arange(30) * DT
    push = np.arange(30, dtype=float)      # each sample its own push
    normal = np.array([-1.0, 0.0, 0.0])
    task = dict(index=0, kind='touch', target='', force_n=5.0, success=True, reason='',
                contact_lost=0, t_contact_s=[float(t[10]), float(t[13])],
                normal_map=normal.tolist())
    tips = np.zeros((30, 3))
    flown, recorded = (task_metrics.task_results([task], times, tips, np.outer(push, normal))[0]
                       for times in (t, t + rounding_s))
    assert flown['force_mean_n'] == pytest.approx(11.0)      # samples 10, 11 and 12
    assert recorded['force_mean_n'] == flown['force_mean_n']
    assert recorded['hold_time_s'] == pytest.approx(flown['hold_time_s'], abs=1e-9)


def test_a_touch_completed_off_the_bar_is_no_success():
    """A push the vehicle cannot reach (its rotors' tilt saturated short of 14 N): the
    controller completed the hold, the truth puts its mean more than 0.1 N off the task's
    force; one within the bar stays a success."""
    t = np.arange(300) * DT
    normal = np.array([-1.0, 0.0, 0.0])
    poi = np.array([WALL_X, 0.0, 1.5])
    targets = {'': (poi, np.column_stack([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], normal]))}
    results = []
    for mean_n in (9.6, 14.0 - 0.05):
        task = dict(index=0, kind='touch', target='', force_n=14.0, success=True, reason='',
                    contact_lost=0, t_contact_s=[0.0, 1.0], normal_map=normal.tolist())
        results += task_metrics.task_results([task], t, np.tile(poi, (300, 1)),
                                             np.outer(np.full(300, mean_n), normal), targets)
    short, within = results
    assert (short['success'], short['reason']) == (False, 'force_off_setpoint')
    assert (within['success'], within['reason']) == (True, '')


def _completed_touch(target_id='', t_contact_s=(HOLD_FIRST, HOLD_LAST)):
    return dict(index=0, kind='touch', target=target_id, force_n=6.0, success=True,
                reason='', contact_lost=0, t_contact_s=list(t_contact_s),
                normal_map=[-1.0, 0.0, 0.0])


def test_a_completed_run_that_nothing_can_score_is_unscored(tmp_path, capsys):
    """No designated target (no truth of it): the controller completed its touch, the
    truth cannot say where it pressed. `uav-tilt report`, `uav-tilt fly` and the campaign
    judge it by one rule (metrics.tasks): 'unscored', never a success, exit 1."""
    rec, _ = synthetic_recording(np.full(N, 6.0), tip_offset=np.zeros(3), contact_lost=0)
    assert report.summarize(rec, TOOL_X)['failure'] is None       # scored, and met
    del rec[names.GROUND_TRUTH_TARGET]
    summary = report.summarize(rec, TOOL_X)
    assert summary['success'] is True and summary['poi_error_m'] is None
    assert summary['failure'] == {'reason': 'unscored', 'mode': 'HOLD', 'phase': ''}
    # the same with the recorded plan of one touch: the task says so too
    rec[names.CONTROLLER_PLAN] = [(wall_ns(0.0), _plan_message([_completed_touch()]))]
    summary = report.summarize(rec, TOOL_X)
    assert summary['failure'] == {'reason': 'unscored', 'mode': 'HOLD', 'phase': ''}
    assert (summary['tasks'][0]['success'], summary['tasks'][0]['reason']) == (False,
                                                                               'unscored')
    bag = open_bag(tmp_path / 'recording.mcap')
    bag.add_topic('/uav/' + names.CONTROLLER_PLAN, 'std_msgs/msg/String')
    with_plan = dict(TYPES, **{names.CONTROLLER_PLAN: 'std_msgs/msg/String'})
    for log_ns, topic, msg in sorted(((log_ns, topic, msg) for topic in with_plan
                                      for log_ns, msg in rec.get(topic, ())),
                                     key=lambda item: item[0]):
        write(bag, topic, msg, log_ns)
    bag.close()
    assert cli.main(['report', str(tmp_path)]) == 1
    assert json.loads(capsys.readouterr().out)['failure']['reason'] == 'unscored'
    # fly's and the campaign's runs: the tasks of the flight, without the target's truth
    t = np.arange(N) * DT
    normal = np.array([-1.0, 0.0, 0.0])
    tasks = task_metrics.task_results([_completed_touch()], t, np.tile(POI, (N, 1)),
                                      np.outer(np.full(N, 6.0), normal), {})
    result = dict(success=True, contact_lost=0, failsafe_reason='', tasks=tasks,
                  mode_history=[(0.0, 'IDLE')])
    assert task_metrics.failure_of(result) == {'reason': 'unscored', 'mode': 'HOLD',
                                               'phase': ''}
    result['failure'] = task_metrics.failure_of(result)
    campaign = campaign_summary.summarize(1, 0, 'vision', [result])
    assert campaign['successes'] == 0 and campaign['failures'] == {'unscored in HOLD': 1}
    # with the truth, the same flight is scored and met
    scored = task_metrics.task_results(
        [_completed_touch()], t, np.tile(POI, (N, 1)), np.outer(np.full(N, 6.0), normal),
        {'': (POI, np.column_stack([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], normal]))})
    assert task_metrics.failure_of(dict(result, tasks=scored)) is None


def test_a_completed_slide_without_the_truth_is_unscored():
    task = dict(index=0, kind='slide', force_n=5.0, success=True, reason='', contact_lost=0,
                t_contact_s=[0.0, 1.0], points_map=[[WALL_X, 0.0, 1.0], [WALL_X, 0.0, 1.5]],
                normal_map=[-1.0, 0.0, 0.0], length_m=0.5)
    (slide,) = task_metrics.task_results([task], np.zeros(0), np.zeros((0, 3)),
                                         np.zeros((0, 3)))
    assert (slide['success'], slide['reason']) == (False, 'unscored')
    assert task_metrics.failure_of(dict(success=True, tasks=[slide])) == {
        'reason': 'unscored', 'mode': 'SLIDE', 'phase': ''}


def test_the_vision_plot_shows_latency_on_the_wall_clock_as_the_summary_key():
    """vision.png's latency is vision/status's (the wall clock of the vision node), the
    numbers vision_latency_ms_p95 is the median of; its axis says which clock."""
    rec = {names.TARGET_POSE: [], names.VISION_STATUS: []}
    for k in range(31):
        pose = PoseWithCovarianceStamped()
        pose.header.stamp = stamp(k / 30)
        rec[names.TARGET_POSE].append((int(k / 30 * 1e9), pose))
    p95 = [20.0 + k % 3 for k in range(6)]
    for k, value in enumerate(p95):
        rec[names.VISION_STATUS].append((0, ros_msgs.diagnostics_msg(
            'vision', dict(fps=30.0, latency_ms_p50=10.0, latency_ms_p95=value),
            stamp(0.5 * k))))
    fig = plot_vision(rec)
    (_, ax) = fig.axes
    (line,) = [a for a in ax.get_lines() if a.get_gid() == 'latency_p95']
    assert list(line.get_ydata()) == p95
    assert 'wall clock' in ax.get_ylabel()
    assert report.summarize(rec, TOOL_X)['vision_latency_ms_p95'] == np.median(p95)
