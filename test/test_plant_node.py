"""plant_node through ROS: lockstep with a driver in another process, timeouts, bad input."""
import json
import math

import pytest
from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import JointState

from ros_graph import Probe, start, status_values, stop
from uav_tilt_common import names, ros_msgs, ros_qos

TIMEOUT_S = 0.3


@pytest.fixture
def probe():
    probe = Probe()
    yield probe
    probe.close()


def latest_status(probe):
    msgs = probe.messages[names.PLANT_STATUS]
    return status_values(msgs[-1]) if msgs else {}


def test_lockstep_driver_timeout_bad_commands_and_clean_shutdown(tmp_path, probe):
    plant = start('uav_tilt_sim.plant_node', log_path=tmp_path / 'plant.log',
                  params={'camera_enabled': 'false', 'lockstep_timeout_s': TIMEOUT_S,
                          'status_rate_hz': 10.0})
    report = tmp_path / 'driver.json'
    driver = start('uav_tilt_tools.hover_driver', '--ticks', '300', '--stay',
                   '--out', str(report), log_path=tmp_path / 'driver.log')
    try:
        probe.record(names.PLANT_STATUS, DiagnosticArray, ros_qos.STATUS)
        assert probe.spin_until(report.exists, 60.0), (tmp_path / 'plant.log').read_text()
        result = json.loads(report.read_text())
        assert result['ticks'] == 300
        assert result['complete_sets'] == 300
        assert result['strictly_increasing']
        # Consecutive ticks: the last answered stamp is 299 ticks after the first.
        assert result['last_stamp_ns'] - result['first_stamp_ns'] == round(299e9 / 300)

        # The controller is gone: the plant must time out, fail safe and keep running.
        driver.kill()
        driver.wait()
        assert probe.spin_until(
            lambda: int(latest_status(probe).get('lockstep_timeouts', 0)) >= 1,
            TIMEOUT_S + 3.0)
        sim_time = float(latest_status(probe)['sim_time_s'])
        assert probe.spin_until(
            lambda: float(latest_status(probe)['sim_time_s']) > sim_time + 0.1, 3.0)

        # Bad commands are rejected and counted; the plant still answers.
        pub = probe.node.create_publisher(JointState, names.ACTUATORS_CMD, ros_qos.CONTROL)
        stamp = ros_msgs.to_stamp(0.0)
        nan_cmd = ros_msgs.actuator_msg([math.nan, 1.0, 1.0, 1.0], (0.0, 0.0), stamp)
        wrong_names = ros_msgs.actuator_msg([1.0] * 4, (0.0, 0.0), stamp)
        wrong_names.name = ['a', 'b', 'c', 'd', 'e', 'f']
        huge = ros_msgs.actuator_msg([1e9] * 4, (0.0, 0.0), stamp)
        probe.spin_until(lambda: pub.get_subscription_count() > 0, 5.0)
        for msg in (nan_cmd, wrong_names, huge):
            pub.publish(msg)
        assert probe.spin_until(
            lambda: int(latest_status(probe).get('rejected_commands', 0)) == 3, 5.0)
        status = latest_status(probe)
        assert int(status['rejected_non_finite']) == 1
        assert int(status['rejected_names']) == 1
        assert int(status['rejected_range']) == 1
        sim_time = float(status['sim_time_s'])
        assert probe.spin_until(
            lambda: float(latest_status(probe)['sim_time_s']) > sim_time + 0.1, 3.0)
    finally:
        stop(driver)
        code, seconds = stop(plant)
    assert code == 0, (tmp_path / 'plant.log').read_text()
    assert seconds < 5.0


def test_bad_parameter_stops_the_node_with_one_clear_line(tmp_path):
    plant = start('uav_tilt_sim.plant_node', log_path=tmp_path / 'plant.log',
                  params={'rtf': -2.0})
    assert plant.wait(timeout=30) == 2
    lines = [line for line in (tmp_path / 'plant.log').read_text().splitlines()
             if 'FATAL' in line]
    assert len(lines) == 1 and "'rtf'" in lines[0] and '-2.0' in lines[0]
