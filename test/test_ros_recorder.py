"""recorder_listens on real DDS: two participants (the plant's and the other nodes'), as
two processes would have them. Only the recorder's own reliable subscription, matched,
lets a held run start; the controller's /clock and the recorder's TimeSource do not."""
import time

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock

from uav_tilt_common import names, ros_qos
from uav_tilt_common.ros_recorder import recorder_listens

SIM_TIME = [Parameter('use_sim_time', value=True)]
# Discovery on localhost takes well under a second; a missing match is waited for this long.
DISCOVERY_S = 3.0


class Participant:
    """One rclpy context (one DDS participant) with its nodes, spun together."""

    def __init__(self):
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.nodes = []

    def node(self, name, **kwargs):
        node = rclpy.create_node(name, context=self.context, **kwargs)
        self.executor.add_node(node)
        self.nodes.append(node)
        return node

    def close(self):
        self.executor.shutdown()
        for node in self.nodes:
            node.destroy_node()
        rclpy.try_shutdown(context=self.context)


def spin_for(participants, seconds, until=lambda: False):
    """Spin all participants for ``seconds`` or until ``until()``; returns ``until()``."""
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline and not until():
        for participant in participants:
            participant.executor.spin_once(timeout_sec=0.01)
    return until()


def test_only_the_recorders_matched_subscription_lets_a_held_run_start():
    plant_side, others = Participant(), Participant()
    try:
        plant = plant_side.node('plant')
        clock = plant.create_publisher(Clock, names.CLOCK, ros_qos.CLOCK)
        listens = lambda: recorder_listens(plant, clock)     # noqa: E731
        both = [plant_side, others]
        # The controller's TimeSource, then the recorder's own: subscribers, not the recorder.
        others.node('controller', parameter_overrides=SIM_TIME)
        spin_for(both, DISCOVERY_S, lambda: clock.get_subscription_count() >= 1)
        assert clock.get_subscription_count() >= 1       # the old rule would start here
        recorder = others.node(names.RECORDER_NODE, parameter_overrides=SIM_TIME)
        assert not spin_for(both, DISCOVERY_S, listens)
        # A reliable subscription of another node (a viewer) does not count either.
        viewer = others.node('viewer')
        viewer.create_subscription(Clock, names.CLOCK, lambda _: None, ros_qos.CLOCK)
        assert not spin_for(both, DISCOVERY_S, listens)
        # A subscription the publisher can never match (transient local on a volatile
        # writer) must not hold the run until the 30 s give-up.
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        viewer.create_subscription(Clock, names.CLOCK, lambda _: None, latched)
        # The recorder's recording subscription: listened to once discovered and matched.
        recorder.create_subscription(Clock, names.CLOCK, lambda _: None, ros_qos.CLOCK,
                                     raw=True)
        assert spin_for(both, DISCOVERY_S, listens)
        infos = plant.get_subscriptions_info_by_topic(names.CLOCK)
        assert sorted(info.node_name for info in infos) == sorted(
            ['controller', names.RECORDER_NODE, names.RECORDER_NODE, 'viewer', 'viewer'])
        assert clock.get_subscription_count() == 4       # all but the incompatible one
    finally:
        others.close()
        plant_side.close()
