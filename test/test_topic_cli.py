"""`uav-tilt topic list|echo|hz` against a live plant (realtime, so rates are wall rates)."""
import re
import signal
import subprocess
import sys
import time

import pytest
from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import Imu

from ros_graph import REPO, Probe, start, status_values, stop
from uav_tilt_common import names, ros_qos

pytestmark = pytest.mark.alone   # `hz` measures wall rates
RTF = 0.5
IMU_HZ = 300


CLI = [sys.executable, '-m', 'uav_tilt_tools.cli']


def cli(*args):
    """Run `uav-tilt` in a fresh process (ROS_DOMAIN_ID from the test environment)."""
    done = subprocess.run([*CLI, *args], cwd=REPO, capture_output=True, text=True, timeout=60)
    return done.returncode, done.stdout


@pytest.fixture(scope='module')
def plant(tmp_path_factory):
    """A realtime plant without camera, and its last status. It is up once its IMU flows:
    a status alone may come from the plant of a test before, still shutting down."""
    log = tmp_path_factory.mktemp('topic_cli') / 'plant.log'
    proc = start('uav_tilt_sim.plant_node', log_path=log,
                 params={'mode': 'realtime', 'rtf': RTF, 'camera_enabled': 'false',
                         'status_rate_hz': 10.0})
    probe = Probe()
    probe.record(names.PLANT_STATUS, DiagnosticArray, ros_qos.STATUS)
    probe.record(names.IMU, Imu, ros_qos.CONTROL)
    assert probe.spin_until(lambda: probe.messages[names.PLANT_STATUS]
                            and probe.messages[names.IMU], 60.0), log.read_text()
    yield probe
    probe.close()
    stop(proc)


def test_list_shows_names_and_types(plant):
    code, out = cli('topic', 'list')
    assert code == 0
    lines = out.splitlines()
    assert '/uav/imu [sensor_msgs/msg/Imu]' in lines
    assert '/clock [rosgraph_msgs/msg/Clock]' in lines
    assert '/uav/ground_truth/target [geometry_msgs/msg/PoseStamped]' in lines


def test_echo_once_prints_one_message_as_yaml(plant):
    code, out = cli('topic', 'echo', 'imu', '--once')
    assert code == 0
    assert out.count('---') == 1
    assert "frame_id: 'base_link'" in out
    gravity = re.search(r'linear_acceleration:\n  x: .*\n  y: .*\n  z: (\S+)', out)
    assert float(gravity.group(1)) == pytest.approx(9.81, abs=0.5)   # resting on the ground


@pytest.mark.parametrize('option, whole', [((), True), (('-l', '10'), False),
                                           (('-l', '10', '--full-length'), None)])
def test_echo_prints_sequences_up_to_the_truncate_length(plant, option, whole):
    code, out = cli('topic', 'echo', 'odom', '--once', *option)
    if whole is None:           # the two together are refused
        assert code == 2
        return
    assert code == 0
    # a covariance is 36 values, under `ros2 topic echo`'s default length of 128
    covariance = re.search(r'\n  covariance:(.*?)\ntwist:', out, re.S).group(1)
    if whole:
        assert len(covariance.strip().splitlines()) == 36, covariance
    else:
        assert covariance.strip() == "'<sequence of 36 values>'"


def test_echo_shows_a_status_whole(plant):
    code, out = cli('topic', 'echo', 'plant/status', '--once')
    assert code == 0 and 'sequence of' not in out
    assert "key: 'sim_time_s'" in out and "key: 'lockstep_waits'" in out


def test_echo_absolute_latched_topic(plant):
    code, out = cli('topic', 'echo', '/uav/ground_truth/target', '-n', '1')
    assert code == 0 and "frame_id: 'map'" in out


def test_hz_matches_the_rate_the_plant_reports(plant):
    window_s = 3.0
    statuses = plant.messages[names.PLANT_STATUS]
    # (arrival here, the plant's wall and sim time) of its statuses
    seen, samples = len(statuses), []
    proc = subprocess.Popen([*CLI, 'topic', 'hz', 'imu', '--window', str(window_s)], cwd=REPO,
                            stdout=subprocess.PIPE, text=True)
    while proc.poll() is None:
        plant.spin_until(lambda: len(statuses) > seen, 0.05)
        for msg in statuses[seen:]:
            values = status_values(msg)
            samples.append((time.monotonic(), float(values['wall_time_s']),
                            float(values['sim_time_s'])))
        seen = len(statuses)
    end = time.monotonic()
    out = proc.stdout.read()
    assert proc.returncode == 0, out
    rate = float(re.search(r'average rate: (\S+)', out).group(1))
    # The plant's sim-time rate over the same last seconds of wall time: on a loaded machine
    # it falls behind its target rtf (most of all while the CLI process starts), and the
    # imu rate with it. Timed by the plant's own clock, as a status arrives here late when
    # this process waits for a core; the least delayed status maps one clock to the other.
    offset_s = min(arrival - wall for arrival, wall, _ in samples)
    (wall0, sim0), *_, (wall1, sim1) = [(wall, sim) for _, wall, sim in samples
                                        if wall + offset_s >= end - window_s]
    assert rate == pytest.approx(IMU_HZ * (sim1 - sim0) / (wall1 - wall0), rel=0.1)
    assert re.search(r'min: \S+s max: \S+s std dev: \S+s window: \d+', out)
    # which clock: the wall clock's rate so labelled, then the rate per second of sim time
    # (the header stamps), which is the imu's own
    assert re.search(r'average rate: \S+ Hz \(wall clock\)', out), out
    sim_rate = float(re.search(r'rate per second of sim time: (\S+) Hz', out).group(1))
    assert sim_rate == pytest.approx(IMU_HZ, rel=0.02)


def test_unknown_topic_fails_with_a_message(plant):
    code, out = cli('topic', 'echo', 'no/such/topic', '--once', '--timeout', '1')
    assert code == 1 and 'did not appear' in out and 'did you mean' not in out
    # a misspelt name: the graph's nearest (given the time to discover the graph, which a
    # monitor, niced below the graph it watches, takes longer to do on a busy machine)
    code, out = cli('topic', 'hz', 'plant/stauts', '--timeout', '4')
    assert code == 1 and out.strip() == ('topic /uav/plant/stauts did not appear within 4.0 s '
                                         '(did you mean /uav/plant/status?)')


@pytest.mark.parametrize('verb, code, words', [
    # echo goes on until Ctrl-C, which ends it as `ros2 topic echo` ends
    (['echo', 'imu'], 0, 'frame_id'),
    # hz stopped before its window prints the rate so far
    (['hz', 'imu', '--window', '60'], 0, 'average rate'),
    # Ctrl-C while waiting for a topic that never comes
    (['echo', 'no/such/topic', '--timeout', '60'], 130, ''),
])
def test_ctrl_c_ends_the_command_cleanly(plant, verb, code, words):
    proc = subprocess.Popen([*CLI, 'topic', *verb], cwd=REPO, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    time.sleep(8.0)     # started, subscribed, and messages taken
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=20)
    assert proc.returncode == code and 'Traceback' not in err, err
    assert words in out


@pytest.mark.parametrize('args', [
    ['echo', 'imu', '--timeout', 'nan'], ['echo', 'imu', '-n', '0'],
    ['hz', 'imu', '--window', '-1'], ['list', '--wait', 'inf'], ['echo', 'bad topic!'],
])
def test_a_bad_option_value_is_refused(args):
    code, _ = cli('topic', *args)
    assert code == 2


def test_a_monitor_reads_the_header_stamp_from_the_bytes_and_subscribes_best_effort():
    """`topic hz` counts serialized messages (a 300 Hz topic is not deserialized) and takes
    their header stamps from the CDR bytes; a monitor subscribes best effort to a volatile
    topic, so that falling behind drops messages instead of holding a reliable publisher
    of the lockstep loop, and reliably to a latched one (its last message)."""
    import numpy as np
    import rclpy
    from rclpy.qos import DurabilityPolicy, ReliabilityPolicy
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import Imu
    from std_msgs.msg import String

    from uav_tilt_tools.graph import topic_tool, topics

    rng = np.random.default_rng()
    sec, nanosec = int(rng.integers(0, 2 ** 31)), int(rng.integers(0, 10 ** 9))
    msg = Imu()
    msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nanosec
    msg.header.frame_id = 'base_link'
    assert topic_tool.starts_with_header(Imu) and not topic_tool.starts_with_header(String)
    assert topic_tool.cdr_header_stamp_s(serialize_message(msg)) == sec + nanosec * 1e-9
    assert topic_tool.cdr_header_stamp_s(b'\x00\x01\x00') is None
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = rclpy.create_node('monitor_qos_probe', context=context)
        node.create_publisher(Imu, 'imu_probe', ros_qos.CONTROL)
        node.create_publisher(String, 'latched_probe', ros_qos.LATCHED)
        volatile = topics.monitor_qos(node, '/imu_probe', 10)
        latched = topics.monitor_qos(node, '/latched_probe', 10)
        assert volatile.reliability == ReliabilityPolicy.BEST_EFFORT
        assert latched.reliability == ReliabilityPolicy.RELIABLE
        assert latched.durability == DurabilityPolicy.TRANSIENT_LOCAL
        node.destroy_node()
    finally:
        rclpy.shutdown(context=context)
