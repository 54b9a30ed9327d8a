"""QoS profiles of DESIGN section 3."""
from typing import Any, Callable

from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

# Control path (imu, odom, ee_wrench, actuators/*): reliable, depth 10.
CONTROL = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                     history=HistoryPolicy.KEEP_LAST)
# Camera: published reliable, subscribed best effort depth 1 (REP-2003). The publisher
# keeps a third of a second of frames for reliable readers (the recorder) to catch up.
CAMERA_PUB = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                        history=HistoryPolicy.KEEP_LAST)
CAMERA_SUB = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT,
                        history=HistoryPolicy.KEEP_LAST)
# Status and other low-rate topics.
STATUS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
# Latched: the last message reaches late joiners (ground_truth/target).
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
# /clock: a reliable publisher serves the best-effort subscription of rclpy's TimeSource
# (which keeps the newest) and a recorder's reliable one (which needs them all). It keeps
# a third of a second of ticks, as the camera keeps of frames: with 10, a recorder that
# fell 33 ms behind on a loaded CPU lost ticks (0.7% of a mission's once).
CLOCK = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                   history=HistoryPolicy.KEEP_LAST)


def quiet_publisher(node: Node, msg_type: type, topic: str, qos: QoSProfile) -> Any:
    """A publisher without QoS-event handlers: each handler is one more waitable that the
    executor re-checks on every wake-up, which costs the 300 Hz loop dearly in Python."""
    return node.create_publisher(
        msg_type, topic, qos,
        event_callbacks=PublisherEventCallbacks(use_default_callbacks=False))


def quiet_subscription(node: Node, msg_type: type, topic: str, callback: Callable[[Any], None],
                       qos: QoSProfile, raw: bool = False) -> Any:
    """A subscription without QoS-event handlers (see :func:`quiet_publisher`); ``raw``:
    the callback gets the serialized message (bytes)."""
    return node.create_subscription(
        msg_type, topic, callback, qos, raw=raw,
        event_callbacks=SubscriptionEventCallbacks(use_default_callbacks=False))
