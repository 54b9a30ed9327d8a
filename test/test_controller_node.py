"""controller_node with plant_node in lockstep: the whole inspection mission through ROS."""
import signal

import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Odometry

from ros_graph import Probe, start, status_values, stop
from uav_tilt_common import names, ros_qos

pytestmark = pytest.mark.slow     # minutes of missions or graphs: handed out first

MISSION_MODES = ['IDLE', 'TAKEOFF', 'HOVER', 'SEARCH', 'APPROACH', 'CONTACT', 'HOLD',
                 'RETREAT', 'LAND', 'IDLE']
# Status comes at 10 Hz: SEARCH lasts one tick with a ground-truth target and may be missed.
MUST_SEE = ['TAKEOFF', 'CONTACT', 'HOLD', 'RETREAT', 'LAND']
# How long a controller process is stopped (SIGSTOP) mid-flight.
STALL_S = 3.0


@pytest.fixture
def probe():
    probe = Probe()
    yield probe
    probe.close()


def test_ground_truth_inspection_mission_in_lockstep(tmp_path, probe):
    controller = start('uav_tilt_control.controller_node', log_path=tmp_path / 'controller.log',
                       params={'target_source': 'ground_truth', 'autostart': 'inspect',
                               'mission.contact.hold_time_s': 2.0})
    modes = []

    def on_status(msg):
        values = status_values(msg)
        if not modes or modes[-1] != values['mode']:
            modes.append(values['mode'])
        statuses.append(values)

    statuses = []
    plant = None
    try:
        probe.node.create_subscription(DiagnosticArray, names.CONTROLLER_STATUS, on_status,
                                       ros_qos.STATUS)
        # The mission cannot start before the lockstep plant runs: start it only once the
        # probe sees the status writer, so that no mode is published before discovery.
        assert probe.spin_until(
            lambda: probe.node.count_publishers(names.CONTROLLER_STATUS) > 0, 30.0)
        plant = start('uav_tilt_sim.plant_node', log_path=tmp_path / 'plant.log',
                      params={'camera_enabled': 'false'})
        # A setpoint in the wrong frame is rejected and counted, and changes nothing.
        pub = probe.node.create_publisher(PoseStamped, names.SETPOINT_POSE, ros_qos.CONTROL)
        assert probe.spin_until(lambda: pub.get_subscription_count() > 0, 30.0)
        bad = PoseStamped()
        bad.header.frame_id = 'odom'
        bad.pose.orientation.w = 1.0
        pub.publish(bad)
        logs = (tmp_path / 'plant.log', tmp_path / 'controller.log')
        # In flight, odometry that is no rotation (all zeros) or older than the last is
        # rejected and counted; the plant's own goes on and the mission with it.
        assert probe.spin_until(lambda: 'HOVER' in modes, 120.0), modes
        odom_pub = probe.node.create_publisher(Odometry, names.ODOM, ros_qos.CONTROL)
        assert probe.spin_until(lambda: odom_pub.get_subscription_count() > 0, 30.0)
        for w in (0.0, 1.0):
            odom = Odometry()       # stamped 0 s, at the origin
            odom.header.frame_id, odom.child_frame_id = names.FRAME_MAP, names.FRAME_BASE
            odom.pose.pose.orientation.w = w
            odom_pub.publish(odom)
        # IDLE may show before the autostart takes effect: the end is IDLE after TAKEOFF.
        done = probe.spin_until(lambda: 'TAKEOFF' in modes and modes[-1] == 'IDLE', 170.0)
        assert done, (modes, [p.read_text()[-2000:] for p in logs])
    finally:
        code_c, _ = stop(controller)
        code_p = stop(plant)[0] if plant else None
    seen = [m for m in modes if m != 'WAITING_FOR_SENSORS']
    # in the mission's order, each mode once, ending landed
    remaining = iter(MISSION_MODES)
    assert all(mode in remaining for mode in seen), seen
    assert set(MUST_SEE) <= set(seen) and seen[-1] == 'IDLE'
    final = statuses[-1]
    assert final['success'] == 'True'
    assert final['contact_lost'] == '0'
    assert final['target_source'] == 'ground_truth'
    assert int(final['rejected_frame']) == 1
    assert int(final['rejected_quaternion']) == 1 and int(final['rejected_stamp']) == 1
    assert float(final['loop_rate_hz']) > 0.0
    assert code_c == 0 and code_p == 0


def test_a_stalled_controller_only_pauses_lockstep(tmp_path, probe):
    """A controller starved of CPU for seconds (a loaded machine) is no lost controller: in
    lockstep simulated time waits for it, with no failsafe and no gap in the flight."""
    controller = start('uav_tilt_control.controller_node', log_path=tmp_path / 'controller.log',
                       params={'target_source': 'ground_truth', 'autostart': 'inspect'})
    modes = []
    probe.node.create_subscription(
        DiagnosticArray, names.CONTROLLER_STATUS,
        lambda msg: modes.append(status_values(msg)['mode']), ros_qos.STATUS)
    probe.record(names.PLANT_STATUS, DiagnosticArray, ros_qos.STATUS)

    def sim_time_s():
        return float(probe.latest_status(names.PLANT_STATUS)['sim_time_s'])
    plant = None
    try:
        # Lockstep: the flight waits for the plant. Start it once the probe sees the status
        # writer, so that discovery cannot lag behind a flight already past the modes awaited.
        assert probe.spin_until(
            lambda: probe.node.count_publishers(names.CONTROLLER_STATUS) > 0, 30.0)
        plant = start('uav_tilt_sim.plant_node', log_path=tmp_path / 'plant.log',
                      params={'camera_enabled': 'false', 'status_rate_hz': 10.0})
        assert probe.spin_until(
            lambda: bool(probe.messages[names.PLANT_STATUS])
            and ('HOVER' in modes or 'SEARCH' in modes), 120.0), modes
        # longer than a careless timeout (the default was 0.5 s), shorter than a dead node's
        controller.send_signal(signal.SIGSTOP)
        probe.spin_until(lambda: False, 0.5)          # commands in flight land
        paused_at_s = sim_time_s()
        probe.spin_until(lambda: False, STALL_S)
        assert sim_time_s() == pytest.approx(paused_at_s, abs=2.0 / 300.0)
        controller.send_signal(signal.SIGCONT)
        assert probe.spin_until(lambda: sim_time_s() > paused_at_s + 1.0, 60.0)
        status = probe.latest_status(names.PLANT_STATUS)
        assert int(status['lockstep_timeouts']) == 0, status
    finally:
        controller.send_signal(signal.SIGCONT)
        code_c, _ = stop(controller)
        code_p = stop(plant)[0] if plant is not None else None
    assert code_c == 0 and code_p == 0
