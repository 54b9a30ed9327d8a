"""recorder_node against a live plant: every topic with its type, rates, complete on SIGINT,
readable up to its last flush after SIGKILL. Read back with the mcap/mcap_ros2 readers. And
where its `output` goes."""
import collections
import os
import time

import pytest
from diagnostic_msgs.msg import DiagnosticArray
from std_msgs.msg import String
from mcap.exceptions import McapError
from mcap.reader import NonSeekingReader, make_reader
from mcap_ros2.decoder import DecoderFactory
from rclpy.duration import Duration
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosbags.interfaces import QosDurability, QosReliability
from rosbags.rosbag2 import Reader

from ros_graph import Probe, start, stop
from uav_tilt_common import names, ros_qos
from uav_tilt_tools.bag.recorder_node import output_path

pytestmark = pytest.mark.alone   # rates in real time
RTF = 0.25              # slow enough that plant, camera and two recorders keep up on 2 cores
RECORD_WALL_S = 8.0
EXPECTED_TYPES = {
    '/clock': 'rosgraph_msgs/msg/Clock',
    '/uav/imu': 'sensor_msgs/msg/Imu',
    '/uav/odom': 'nav_msgs/msg/Odometry',
    '/uav/ee_wrench': 'geometry_msgs/msg/WrenchStamped',
    '/uav/actuators/state': 'sensor_msgs/msg/JointState',
    '/uav/ground_truth/odom': 'nav_msgs/msg/Odometry',
    '/uav/ground_truth/target': 'geometry_msgs/msg/PoseStamped',
    '/uav/camera/color/image_raw': 'sensor_msgs/msg/Image',
    '/uav/camera/depth/image_raw': 'sensor_msgs/msg/Image',
    '/uav/camera/camera_info': 'sensor_msgs/msg/CameraInfo',
    '/uav/plant/status': 'diagnostic_msgs/msg/DiagnosticArray',
}
RELIABLE_HZ = {'/clock': 300, '/uav/imu': 300, '/uav/odom': 300, '/uav/ee_wrench': 300,
               '/uav/actuators/state': 300, '/uav/ground_truth/odom': 300}
# Subscribed best effort (REP-2003): frames may be lost on a loaded machine, never invented.
BEST_EFFORT_HZ = {'/uav/camera/color/image_raw': 30, '/uav/camera/depth/image_raw': 30,
                  '/uav/camera/camera_info': 30}
OFFER_TOPIC = '/uav/probe/offer'
OFFER_QOS = QoSProfile(depth=3, reliability=ReliabilityPolicy.BEST_EFFORT,
                       deadline=Duration(seconds=2))
CAMERA = ('camera/color/image_raw,camera/depth/image_raw,camera/camera_info,'
          'vision/debug_image')


@pytest.fixture(scope='module')
def recordings(tmp_path_factory):
    """(complete file, its recorder's exit code, file of a SIGKILLed recorder, log)."""
    tmp = tmp_path_factory.mktemp('recorder')
    plant = start('uav_tilt_sim.plant_node', log_path=tmp / 'plant.log',
                  params={'mode': 'realtime', 'rtf': RTF, 'status_rate_hz': 10.0})
    probe = Probe()
    try:
        probe.record(names.PLANT_STATUS, DiagnosticArray, ros_qos.STATUS)
        assert probe.spin_until(lambda: probe.messages[names.PLANT_STATUS], 60.0), \
            (tmp / 'plant.log').read_text()
        # a topic outside the contract, found by discovery with the QoS its publisher offers
        probe.node.create_publisher(String, OFFER_TOPIC, OFFER_QOS)
        recorder = start('uav_tilt_tools.bag.recorder_node', log_path=tmp / 'recorder.log',
                         params={'output': str(tmp)})
        killed = start('uav_tilt_tools.bag.recorder_node', log_path=tmp / 'killed.log',
                       params={'output': str(tmp / 'killed' / 'killed.mcap'),
                               'exclude': CAMERA,
                               'flush_period_s': 0.5})
        # the recording window starts once both recorders subscribe (their start-up, a few
        # seconds on a loaded machine, would otherwise eat into it)
        assert probe.spin_until(lambda: probe.node.count_subscribers(names.CLOCK) >= 2, 60.0)
        time.sleep(RECORD_WALL_S)
        killed.kill()
        code, _ = stop(recorder, timeout_s=20.0)
        killed.wait()
    finally:
        probe.close()
        stop(plant)
    return tmp / 'recording.mcap', code, tmp / 'killed' / 'killed.mcap', (tmp / 'recorder.log')


def read_all(path):
    """{topic: [(publish_ns, log_ns, decoded)]}, schemas by topic, and the file summary."""
    messages, types = collections.defaultdict(list), {}
    with open(path, 'rb') as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for schema, channel, message, msg in reader.iter_decoded_messages():
            messages[channel.topic].append((message.publish_time, message.log_time, msg))
            types[channel.topic] = (schema.name, schema.encoding, channel.message_encoding)
        summary = reader.get_summary()
    return messages, types, summary


def test_every_topic_recorded_with_its_type_and_rate(recordings):
    path, code, _, log = recordings
    assert code == 0, log.read_text()
    messages, types, summary = read_all(path)
    assert summary is not None       # finished: the index is there
    for topic, type_name in EXPECTED_TYPES.items():
        assert types[topic] == (type_name, 'ros2msg', 'cdr')
    # Every message up to the last one decodes, and the statistics count them all.
    assert sum(map(len, messages.values())) == summary.statistics.message_count
    # Each topic against its own span of stamps: the recorder subscribes topic by topic as
    # it discovers them, so on a loaded machine one may start a second of wall time (a
    # quarter second of sim time) before another.
    for topic, rate in {**RELIABLE_HZ, **BEST_EFFORT_HZ}.items():
        stamps = [ns for ns, _, _ in messages[topic]]
        span_s = (stamps[-1] - stamps[0]) * 1e-9
        assert span_s > 1.0, topic
        if topic in RELIABLE_HZ:
            assert len(stamps) == pytest.approx(rate * span_s + 1, rel=0.1), topic
        else:
            assert 0.5 * rate * span_s < len(stamps) < 1.1 * rate * span_s + 1, topic
    assert len(messages['/uav/ground_truth/target']) == 1    # latched, sent before we came


def test_publish_time_is_the_header_stamp_and_log_time_the_wall_clock(recordings):
    messages, _, _ = read_all(recordings[0])
    for publish_ns, log_ns, msg in messages['/uav/imu']:
        assert publish_ns == msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
    for publish_ns, _, msg in messages['/clock']:
        assert publish_ns == msg.clock.sec * 10**9 + msg.clock.nanosec
    # Log time is when the recorder got it: the wall clock of this run, not sim time.
    assert abs(messages['/uav/imu'][-1][1] * 1e-9 - time.time()) < 600


def test_its_folder_opens_as_a_rosbag2_bag_with_the_qos_the_plant_offered(recordings):
    """As `ros2 bag play DIR` opens it (through metadata.yaml), with each topic's offered QoS
    so that a replay latches what the plant latched."""
    path, _, _, _ = recordings
    messages, _, _ = read_all(path)
    with Reader(path.parent) as reader:         # the folder: metadata.yaml
        assert {c.topic: c.msgcount for c in reader.connections} == {
            topic: len(messages.get(topic, ())) for topic in
            {c.topic for c in reader.connections}}
        qos = {c.topic: c.ext.offered_qos_profiles for c in reader.connections}
    assert set(EXPECTED_TYPES) <= set(qos)
    # discovered: what its publisher offered (DDS does not carry the history depth)
    (offered,) = qos[OFFER_TOPIC]
    assert (offered.reliability, offered.durability) == (QosReliability.BEST_EFFORT,
                                                         QosDurability.VOLATILE)
    assert (offered.deadline.sec, offered.deadline.nsec) == (2, 0)
    for topic in EXPECTED_TYPES:
        # the plant publishes every topic reliable (the camera too: REP-2003 readers
        # subscribe best effort), and latches the target's truth
        latched = topic == '/uav/ground_truth/target'
        assert [(q.reliability, q.durability) for q in qos[topic]] == [
            (QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL if latched
             else QosDurability.VOLATILE)], topic


def test_a_killed_recorder_leaves_its_flushed_chunks_readable(recordings):
    complete, _, killed, _ = recordings
    imu = []
    with open(killed, 'rb') as stream:
        try:
            for _, channel, message in NonSeekingReader(stream).iter_messages(
                    log_time_order=False):
                if channel.topic == '/uav/imu':
                    imu.append(message.publish_time)
        except (McapError, EOFError, ValueError):
            pass        # the chunk that was being written when it died
    full, _, _ = read_all(complete)
    last_full = full['/uav/imu'][-1][0]
    assert imu and all(b > a for a, b in zip(imu, imu[1:]))
    # Chunks are flushed every 0.5 s of wall time: at most ~1 s wall (RTF s sim) is lost.
    assert (last_full - imu[-1]) * 1e-9 < 2.0 * RTF


@pytest.mark.parametrize('output, path', [
    ('runs/a', 'runs/a/recording.mcap'), ('runs/b/', 'runs/b/recording.mcap'),
    ('runs/c/run.mcap', 'runs/c/run.mcap'), ('run.mcap', 'run.mcap')])
def test_the_output_is_a_folder_unless_it_names_an_mcap_file(tmp_path, monkeypatch, output,
                                                             path):
    monkeypatch.chdir(tmp_path)
    got, own_folder = output_path(output)
    assert os.path.normpath(got) == os.path.normpath(path)
    assert own_folder == (not output.endswith('.mcap'))
    assert (tmp_path / path).parent.is_dir() and not (tmp_path / path).exists()
