"""recorder_node: records every topic of its namespace, and /clock, into one MCAP file.

Topics are discovered periodically and subscribed raw (serialized CDR, no decoding), with a
QoS matched to their publishers (:func:`topic_graph.subscription_qos`). The file is
completed on shutdown (SIGINT/SIGTERM) and flushed chunk by chunk while recording, so even
a killed recorder leaves its flushed chunks readable.
"""
import dataclasses
import os
import signal
import sys
import time

from rclpy.clock import Clock, ClockType
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node

from uav_tilt_common import names
from uav_tilt_common.config import param
from uav_tilt_common.ros_params import declare_config, run_node
from uav_tilt_tools import topic_graph
from uav_tilt_tools.mcap_bag import McapBag

DEFAULT_FILE = 'recording.mcap'
# Deeper than the nodes' own queues: the recorder must absorb bursts, not drop them.
QUEUE_DEPTH = 100


@dataclasses.dataclass
class RecorderConfig:
    """Parameters of recorder_node."""

    output: str = param(DEFAULT_FILE)   # file, or folder that gets recording.mcap
    # Comma-separated topics not to record. The debug image is drawn only for subscribers,
    # so recording it would load the vision node it observes.
    exclude: str = param(names.VISION_DEBUG_IMAGE)
    discovery_period_s: float = param(0.5, lo=0.05, hi=10.0)
    flush_period_s: float = param(1.0, lo=0.1, hi=60.0)


def output_path(output):
    """The MCAP path of parameter ``output``: a folder gets recording.mcap inside."""
    if os.path.isdir(output) or output.endswith(os.sep):
        os.makedirs(output, exist_ok=True)
        return os.path.join(output, DEFAULT_FILE)
    os.makedirs(os.path.dirname(os.path.abspath(output)), exist_ok=True)
    return output


class RecorderNode(Node):
    """Discovers topics, subscribes raw, writes an :class:`McapBag`."""

    def __init__(self):
        super().__init__('recorder')
        self.cfg = declare_config(self, RecorderConfig)
        namespace = self.get_namespace()
        self.prefix = namespace.rstrip('/') + '/'
        self.exclude = {topic_graph.resolve(t.strip(), namespace)
                        for t in self.cfg.exclude.split(',') if t.strip()}
        self.bag = McapBag(output_path(self.cfg.output))
        self.subscriptions_by_topic = {}
        self.skipped = set()
        # Wall clock: discovery and flushing go on when sim time stalls.
        wall = Clock(clock_type=ClockType.STEADY_TIME)
        self.create_timer(self.cfg.discovery_period_s, self.discover, clock=wall)
        self.create_timer(self.cfg.flush_period_s, self.bag.flush, clock=wall)
        self.get_logger().info(f'recording {self.prefix}* and {names.CLOCK} '
                               f'to {self.bag.path}')
        self.discover()

    def wanted(self, topic):
        """Topics of this namespace and /clock, less the excluded ones."""
        return ((topic.startswith(self.prefix) or topic == names.CLOCK)
                and topic not in self.exclude)

    def discover(self):
        """Subscribe to every new wanted, published topic whose type is installed."""
        for topic, type_name in topic_graph.topic_types(self).items():
            # Wait for a publisher: its QoS decides ours (a latched topic needs
            # transient local before its one message goes by).
            if topic in self.subscriptions_by_topic or topic in self.skipped \
                    or not self.wanted(topic) or not self.count_publishers(topic):
                continue
            try:
                msg_type = topic_graph.message_class(type_name)
                self.bag.add_topic(topic, type_name)
            except (ImportError, AttributeError, LookupError) as err:
                self.skipped.add(topic)
                self.get_logger().warn(f'not recording {topic} [{type_name}]: {err}')
                continue
            qos = topic_graph.subscription_qos(self, topic, type_name, QUEUE_DEPTH)
            self.subscriptions_by_topic[topic] = self.create_subscription(
                msg_type, topic, self._writer(topic), qos, raw=True,
                event_callbacks=SubscriptionEventCallbacks(use_default_callbacks=False))
            self.get_logger().info(f'recording {topic} [{type_name}]')

    def _writer(self, topic):
        def callback(data):
            self.bag.write(topic, data, time.time_ns())
        return callback

    def destroy_node(self):
        """Complete the file with the node."""
        self.bag.close()
        # After shutdown /rosout is gone: say it on stderr.
        counts = ', '.join(f'{t}: {n}' for t, n in sorted(self.bag.counts.items()))
        print(f'[recorder] wrote {self.bag.path} ({counts})', file=sys.stderr, flush=True)
        return super().destroy_node()


def main(args=None):
    """Entry point of the recorder_node executable."""
    # rclpy's SIGINT handler shuts the context down and then calls the Python handler; a
    # no-op there keeps KeyboardInterrupt from landing inside a half-written MCAP record,
    # and spin returns between callbacks instead.
    signal.signal(signal.SIGINT, lambda *_: None)
    return run_node(RecorderNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
