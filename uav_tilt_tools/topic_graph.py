"""ROS graph helpers shared by recorder_node and `uav-tilt topic`: names, types, QoS."""
import importlib

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from uav_tilt_common import names

# Sensor data is subscribed best effort (REP-2003, DESIGN section 3).
BEST_EFFORT_TYPES = frozenset(('sensor_msgs/msg/Image', 'sensor_msgs/msg/CompressedImage',
                               'sensor_msgs/msg/CameraInfo'))


def resolve(topic, namespace=names.NAMESPACE):
    """Absolute name of ``topic``; relative names are taken inside ``namespace``."""
    if topic.startswith('/'):
        return topic
    return namespace.rstrip('/') + '/' + topic


def message_class(type_name):
    """Python class of ``pkg/msg/Type`` (ImportError/AttributeError if not installed)."""
    package, _, name = type_name.split('/')
    return getattr(importlib.import_module(f'{package}.msg'), name)


def topic_types(node):
    """{absolute topic: type} of the graph as this node sees it (first type if several)."""
    return {topic: types[0] for topic, types in node.get_topic_names_and_types() if types}


def subscription_qos(node, topic, type_name, depth):
    """A QoS that matches the publishers of ``topic`` as they are now: best effort for
    sensor data or when any publisher is best effort, transient local when every
    publisher is (latched topics), else reliable and volatile."""
    offered = [info.qos_profile for info in node.get_publishers_info_by_topic(topic)]
    best_effort = type_name in BEST_EFFORT_TYPES or any(
        q.reliability == ReliabilityPolicy.BEST_EFFORT for q in offered)
    latched = bool(offered) and all(
        q.durability == DurabilityPolicy.TRANSIENT_LOCAL for q in offered)
    return QoSProfile(
        depth=depth, history=HistoryPolicy.KEEP_LAST,
        reliability=ReliabilityPolicy.BEST_EFFORT if best_effort else ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)
