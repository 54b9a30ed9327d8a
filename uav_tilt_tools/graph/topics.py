"""ROS graph helpers shared by recorder_node and `uav-tilt topic`: names, types, QoS."""
import importlib
from typing import Any

from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from uav_tilt_common import names, ros_qos


def resolve(topic: str, namespace: str = names.NAMESPACE) -> str:
    """Absolute name of ``topic``; relative names are taken inside ``namespace``."""
    if topic.startswith('/'):
        return topic
    return namespace.rstrip('/') + '/' + topic


def message_class(type_name: str) -> Any:
    """Python class of ``pkg/msg/Type`` (ImportError/AttributeError if not installed)."""
    package, _, name = type_name.split('/')
    return getattr(importlib.import_module(f'{package}.msg'), name)


def topic_types(node: Node) -> dict[str, str]:
    """{absolute topic: type} of the graph as this node sees it (first type if several)."""
    return {topic: types[0] for topic, types in node.get_topic_names_and_types() if types}


def contract_qos(topic: str, depth: int) -> QoSProfile:
    """The subscription QoS that matches this project's own publisher of ``topic`` (relative
    name, :data:`names.TOPIC_TYPES`): reliable, transient local for the latched ones."""
    return QoSProfile(
        depth=depth, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if names.is_latched(topic)
        else DurabilityPolicy.VOLATILE)


def contract_offer(topic: str) -> QoSProfile:
    """The QoS this project's own nodes publish ``topic`` (relative name) with: latched,
    /clock's, or the reliable volatile depth 10 of the control path, camera and statuses."""
    if names.is_latched(topic):
        return ros_qos.LATCHED
    return ros_qos.CLOCK if topic == names.CLOCK else ros_qos.CONTROL


def offered_qos(node: Node, topic: str) -> list[QoSProfile]:
    """The QoS profiles the publishers of ``topic`` (absolute) offer now, or, with none yet,
    the one the contract's publisher offers (:func:`contract_offer`, of its name relative to
    the node's namespace)."""
    prefix = node.get_namespace().rstrip('/') + '/'
    relative = topic[len(prefix):] if topic.startswith(prefix) else topic
    return ([info.qos_profile for info in node.get_publishers_info_by_topic(topic)]
            or [contract_offer(relative)])


def monitor_qos(node: Node, topic: str, depth: int) -> QoSProfile:
    """What a monitor (`uav-tilt topic echo | hz`) subscribes with: best effort, so that a
    monitor that falls behind drops messages instead of making a reliable publisher of the
    lockstep loop keep and resend them; a latched topic as :func:`subscription_qos` takes
    it (its last message reaches a late reliable reader only)."""
    qos = subscription_qos(node, topic, depth)
    if qos.durability != DurabilityPolicy.TRANSIENT_LOCAL:
        qos.reliability = ReliabilityPolicy.BEST_EFFORT
    return qos


def subscription_qos(node: Node, topic: str, depth: int) -> QoSProfile:
    """A QoS that matches the publishers of ``topic`` as they are now, as rosbag2 chooses
    it: reliable when every publisher is (so nothing they send is lost), best effort when
    any one is not (else that one would not match); transient local when every publisher
    is (latched topics), else volatile."""
    offered = [info.qos_profile for info in node.get_publishers_info_by_topic(topic)]
    best_effort = any(q.reliability == ReliabilityPolicy.BEST_EFFORT for q in offered)
    latched = bool(offered) and all(
        q.durability == DurabilityPolicy.TRANSIENT_LOCAL for q in offered)
    return QoSProfile(
        depth=depth, history=HistoryPolicy.KEEP_LAST,
        reliability=ReliabilityPolicy.BEST_EFFORT if best_effort else ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)
