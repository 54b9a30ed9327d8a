"""McapBag's files as a ROS user opens them with rosbags (rosbag2's format, read without
ROS): the folder as a bag through its metadata.yaml, the file alone through the MCAP's own
records; each topic with its type, count and the QoS its publishers offered."""
import numpy as np
import pytest
from rclpy.duration import Duration
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.serialization import serialize_message
from rosbags.interfaces import QosDurability, QosReliability
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore

from uav_tilt_common import names, ros_msgs, ros_qos
from uav_tilt_tools.bag.folder import METADATA_FILE
from uav_tilt_tools.bag.writer import McapBag

# a second publisher of odometry that offers best effort and a deadline
BEST_EFFORT = QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT,
                         deadline=Duration(seconds=1, nanoseconds=500))
TOPICS = {'/clock': ('rosgraph_msgs/msg/Clock', [ros_qos.CLOCK]),
          '/uav/ground_truth/target': ('geometry_msgs/msg/PoseStamped', [ros_qos.LATCHED]),
          '/uav/controller/plan': ('std_msgs/msg/String', [ros_qos.LATCHED]),
          '/uav/odom': ('nav_msgs/msg/Odometry', [ros_qos.CONTROL, BEST_EFFORT]),
          '/uav/unheard': ('std_msgs/msg/String', [])}


def written(path, own_folder):
    """A bag of TOPICS with a random number of messages each, at random log times; the
    (topic, log ns, message) written."""
    from geometry_msgs.msg import PoseStamped
    from nav_msgs.msg import Odometry
    from rosgraph_msgs.msg import Clock
    from std_msgs.msg import String
    rng = np.random.default_rng()
    make = {'/clock': lambda t: Clock(clock=ros_msgs.to_stamp(t)),
            '/uav/ground_truth/target': lambda t: PoseStamped(),
            '/uav/controller/plan': lambda t: String(data=f'{{"t": {t}}}'),
            '/uav/odom': lambda t: Odometry(child_frame_id=f'base_{t:.3f}')}
    bag = McapBag(path, own_folder=own_folder)
    for topic, (type_name, offered) in TOPICS.items():
        bag.add_topic(topic, type_name, offered)
    messages = []
    t_s = rng.uniform(0.0, 1e4)
    for _ in range(int(rng.integers(50, 200))):
        topic = str(rng.choice(sorted(make)))
        t_s += rng.uniform(1e-3, 0.1)
        messages.append((topic, int(t_s * 1e9), make[topic](t_s)))
        bag.write(topic, serialize_message(messages[-1][2]), messages[-1][1])
    bag.close()
    return messages


def test_the_folder_and_the_file_open_as_a_rosbag2_bag(tmp_path):
    messages = written(tmp_path / 'recording.mcap', own_folder=True)
    assert (tmp_path / METADATA_FILE).exists()
    store = get_typestore(Stores.ROS2_JAZZY)
    for opened in (tmp_path, tmp_path / 'recording.mcap'):
        with Reader(opened) as reader:
            if opened == tmp_path:      # the metadata's span (the file's counts are the same)
                assert reader.start_time == min(ns for _, ns, _ in messages)
                assert reader.duration == (max(ns for _, ns, _ in messages)
                                           - reader.start_time + 1)
            assert reader.message_count == len(messages)
            connections = {c.topic: c for c in reader.connections}
            assert {t: (c.msgtype, c.msgcount) for t, c in connections.items()} == {
                t: (type_name, sum(1 for m in messages if m[0] == t))
                for t, (type_name, _) in TOPICS.items()}
            for topic, (_, offered) in TOPICS.items():
                qos = connections[topic].ext.offered_qos_profiles
                assert [(q.reliability, q.durability, q.depth) for q in qos] == [
                    (QosReliability[o.reliability.name], QosDurability[o.durability.name],
                     o.depth) for o in offered], topic
            # latched as the nodes latch it: a replay latches it again
            assert connections['/uav/ground_truth/target'].ext.offered_qos_profiles[
                0].durability == QosDurability.TRANSIENT_LOCAL
            deadline = connections['/uav/odom'].ext.offered_qos_profiles[1].deadline
            assert (deadline.sec, deadline.nsec) == (1, 500)
            read = [(c.topic, ns, store.deserialize_cdr(raw, c.msgtype))
                    for c, ns, raw in reader.messages()]
        assert [(t, ns) for t, ns, _ in read] == [(t, ns) for t, ns, _ in messages]
        for (topic, _, got), (_, _, sent) in zip(read, messages):
            if topic == '/uav/controller/plan':
                assert got.data == sent.data
            elif topic == '/uav/odom':
                assert got.child_frame_id == sent.child_frame_id


def test_a_file_that_does_not_have_its_folder_to_itself_gets_no_metadata(tmp_path):
    written(tmp_path / 'flight.mcap', own_folder=False)
    assert not (tmp_path / METADATA_FILE).exists()
    with Reader(tmp_path / 'flight.mcap') as reader:
        assert {c.topic for c in reader.connections} == set(TOPICS)


@pytest.mark.parametrize('relative, offered', [
    (names.GROUND_TRUTH_TARGET, ros_qos.LATCHED), (names.CONTROLLER_PLAN, ros_qos.LATCHED),
    (names.ground_truth_target('plate_a'), ros_qos.LATCHED), (names.CLOCK, ros_qos.CLOCK),
    (names.ODOM, ros_qos.CONTROL), (names.CAMERA_COLOR, ros_qos.CAMERA_PUB),
    (names.CONTROLLER_STATUS, ros_qos.STATUS)])
def test_the_contract_offer_is_what_the_nodes_publish_with(relative, offered):
    """What a bag records for a topic before its publisher is heard from."""
    from uav_tilt_tools.graph.topics import contract_offer
    got = contract_offer(relative)
    assert (got.reliability, got.durability, got.depth) == (
        offered.reliability, offered.durability, offered.depth)
