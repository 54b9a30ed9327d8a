"""hold_until_recorded: whether the recorder listens to a publisher of this node."""
from rclpy.qos import QoSCompatibility, ReliabilityPolicy, qos_check_compatible

from uav_tilt_common import names


def recorder_listens(node, publisher):
    """Whether the recorder's own subscription to ``publisher``'s topic is matched: the
    graph lists a reliable subscription of the recorder node (its recording one, not the
    best-effort /clock subscription of its TimeSource), and the publisher has matched every
    compatible subscription the graph lists, so that one too. Another node's subscription
    (the controller's on /clock and the control topics) does not count: a tick sent before
    the recorder's subscription matched is lost to the recording."""
    infos = node.get_subscriptions_info_by_topic(publisher.topic_name)
    recorder = any(info.node_name == names.RECORDER_NODE
                   and info.qos_profile.reliability == ReliabilityPolicy.RELIABLE
                   for info in infos)
    offered = publisher.qos_profile
    compatible = sum(qos_check_compatible(offered, info.qos_profile)[0]
                     != QoSCompatibility.ERROR for info in infos)
    return recorder and publisher.get_subscription_count() >= compatible


def recorder_subscribes(node, publisher):
    """Whether the graph lists a subscription of the recorder to ``publisher``'s topic: the
    recorder leaves some out (its `exclude`, its `images` profile), and a tick waits only
    for what it records."""
    return any(info.node_name == names.RECORDER_NODE
               for info in node.get_subscriptions_info_by_topic(publisher.topic_name))
