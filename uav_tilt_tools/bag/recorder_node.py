"""recorder_node: records every topic of its namespace, and /clock, into one MCAP file.

The contract's topics (:data:`names.TOPIC_TYPES`) are subscribed at start, so the recorder
listens before the plant's first tick when it starts first, as scripts/launch.sh starts it;
other topics are discovered periodically. All are subscribed raw (serialized CDR, no
decoding), with a QoS matched to their publishers as rosbag2 does
(:func:`graph.topics.subscription_qos`, resubscribed should a publisher offer less):
reliable publishers get a reliable subscription (a best-effort one loses frames under load).
A message's log time is when the recorder got it by the node's clock: sim time (/clock)
with ``use_sim_time``, as scripts/launch.sh starts it (messages that come before the first
/clock get the time of that first /clock), else the wall clock. The file is completed on
shutdown (SIGINT/SIGTERM), its size reported, and flushed chunk by chunk while recording,
so even a killed recorder leaves its flushed chunks readable. Served by rclpy's
EventsExecutor (:mod:`uav_tilt_common.ros_spin`): some 2,200 messages a second in a real-time
mission cost it 34% of a core with the default executor, 15% with this one.
"""
import dataclasses
import os
import sys
import time
from typing import Any, Callable

from rclpy.clock import Clock, ClockType
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node

from uav_tilt_common import names
from uav_tilt_common.config import param
from uav_tilt_common.ros_params import declare_config, run_node
from uav_tilt_tools.bag import images as image_profile
from uav_tilt_tools.bag.folder import RECORDING_FILE, not_recordable, recording_folder
from uav_tilt_tools.bag.writer import McapBag
from uav_tilt_tools.graph import topics

# Deeper than the nodes' own queues: the recorder must absorb bursts, not drop them.
QUEUE_DEPTH = 100


@dataclasses.dataclass
class RecorderConfig:
    """Parameters of recorder_node."""

    output: str = param(RECORDING_FILE, doc='a new MCAP file (*.mcap), or a folder that gets '
                        'recording.mcap')
    # The debug image is drawn only for subscribers, so recording it would load the vision
    # node it observes.
    exclude: str = param(names.VISION_DEBUG_IMAGE, doc='comma-separated topics not to record')
    images: str = param('all', choices=image_profile.PROFILES,
                        doc='the camera images recorded: all, thin (at images_rate_hz) or none')
    images_rate_hz: float = param(image_profile.THIN_RATE_HZ, lo=0.1, hi=120.0,
                                  doc="thin: frames kept a second of sim time (the detector's "
                                  "rate: the camera's 30 Hz over vision's detect_every 5)")
    discovery_period_s: float = param(0.5, lo=0.05, hi=10.0,
                                      doc='how often new topics are looked for (wall clock)')
    flush_period_s: float = param(1.0, lo=0.1, hi=60.0,
                                  doc='how often the chunk in progress is written out')


def output_path(output: str) -> tuple[str, bool]:
    """The MCAP path of parameter ``output`` and whether its folder is the recording's: a
    name ending in .mcap is the file, any other a folder (made when missing, like its
    parents) that gets recording.mcap, refused when it holds a recording
    (:func:`bag.folder.recording_folder`)."""
    if not output.endswith('.mcap'):
        return recording_folder(output), True
    os.makedirs(os.path.dirname(os.path.abspath(output)), exist_ok=True)
    return output, False


class RecorderNode(Node):
    """Discovers topics, subscribes raw, writes an :class:`McapBag`."""

    def __init__(self) -> None:
        super().__init__(names.RECORDER_NODE)
        self.cfg = declare_config(self, RecorderConfig)
        namespace = self.get_namespace()
        self.prefix = namespace.rstrip('/') + '/'
        self.exclude = {topics.resolve(t.strip(), namespace)
                        for t in self.cfg.exclude.split(',') if t.strip()}
        image_topics = {topics.resolve(t, namespace) for t in image_profile.IMAGE_TOPICS}
        if self.cfg.images == 'none':
            self.exclude |= image_topics
        self.thinned = image_topics if self.cfg.images == 'thin' else set()
        self.thinning = image_profile.Thinning(self.cfg.images_rate_hz)
        self.subscriptions_by_topic: dict[str, tuple[Any, Any]] = {}  # topic -> (sub, QoS)
        self.skipped: set[str] = set()
        self.sim_time = bool(self.get_parameter('use_sim_time').value)
        self.pending: list[tuple[str, bytes]] = []  # received before the first /clock
        # The contract's topics are subscribed right after the file is made (launch.sh
        # waits for the file), so before the plant's first tick.
        try:
            # a folder of its own is a rosbag2 bag (metadata.yaml at the end)
            path, own_folder = output_path(self.cfg.output)
            self.bag = McapBag(path, own_folder=own_folder)
        except OSError as err:
            raise not_recordable(f"parameter 'output' = {self.cfg.output!r}", err) from None
        for relative, type_name in names.TOPIC_TYPES.items():
            topic = topics.resolve(relative, namespace)
            if self.wanted(topic):
                self.subscribe(topic, type_name, topics.contract_qos(relative, QUEUE_DEPTH))
        # Wall clock: discovery and flushing go on when sim time stalls.
        wall = Clock(clock_type=ClockType.STEADY_TIME)
        self.create_timer(self.cfg.discovery_period_s, self.discover, clock=wall)
        self.create_timer(self.cfg.flush_period_s, self.bag.flush, clock=wall)
        self.get_logger().info(f'recording {self.prefix}* and {names.CLOCK} '
                               f'to {self.bag.path}, log time: '
                               f'{"sim time" if self.sim_time else "wall clock"}, images: '
                               f'{self.cfg.images}')
        self.discover()

    def wanted(self, topic: str) -> bool:
        """Topics of this namespace and /clock, less the excluded ones."""
        return ((topic.startswith(self.prefix) or topic == names.CLOCK)
                and topic not in self.exclude)

    def discover(self) -> None:
        """Subscribe to every new wanted, published topic whose type is installed, and
        again to one whose publishers now offer a QoS the subscription does not match; one
        log line names the topics it adds (each topic's own line is at debug level)."""
        known = set(self.subscriptions_by_topic)
        for topic, type_name in topics.topic_types(self).items():
            # Wait for a publisher: its QoS decides ours (a latched topic needs
            # transient local before its one message goes by).
            if topic in self.skipped or not self.wanted(topic) \
                    or not self.count_publishers(topic):
                continue
            qos = topics.subscription_qos(self, topic, QUEUE_DEPTH)
            current = self.subscriptions_by_topic.get(topic)
            if current is None or (current[1].reliability, current[1].durability) != (
                    qos.reliability, qos.durability):
                self.subscribe(topic, type_name, qos)
        added = sorted(set(self.subscriptions_by_topic) - known)
        if added:
            self.get_logger().info(f'recording {len(added)} more topics as they appeared: '
                                   f'{", ".join(added)}')

    def subscribe(self, topic: str, type_name: str, qos: Any) -> None:
        """(Re)subscribe ``topic`` with ``qos``; a type that is not installed is skipped."""
        old = self.subscriptions_by_topic.pop(topic, None)
        try:
            msg_type = topics.message_class(type_name)
            if old is None:
                self.bag.add_topic(topic, type_name, topics.offered_qos(self, topic))
        except (ImportError, AttributeError, LookupError) as err:
            self.skipped.add(topic)
            self.get_logger().warn(f'not recording {topic} [{type_name}]: {err}')
            return
        if old is not None:
            self.destroy_subscription(old[0])
        subscription = self.create_subscription(
            msg_type, topic, self._writer(topic), qos, raw=True,
            event_callbacks=SubscriptionEventCallbacks(use_default_callbacks=False))
        self.subscriptions_by_topic[topic] = (subscription, qos)
        self.get_logger().debug(
            f'recording {topic} [{type_name}] {qos.reliability.name.lower()} '
            f'{qos.durability.name.lower()}')

    def _writer(self, topic: str) -> Callable[[bytes], None]:
        def callback(data: bytes) -> None:
            self.write(topic, data)

        def thinned(data: bytes) -> None:
            try:
                keep = self.thinning.keep(image_profile.stamp_ns(data))
            except ValueError:
                keep = True         # no stamp to thin by: recorded as it came
            if keep:
                self.write(topic, data)
        return thinned if topic in self.thinned else callback

    def write(self, topic: str, data: bytes) -> None:
        """Append one message at the node clock's time (held until sim time is known)."""
        if not self.sim_time:
            self.bag.write(topic, data, time.time_ns())
            return
        now_ns = self.get_clock().now().nanoseconds
        if now_ns == 0:         # no /clock yet
            self.pending.append((topic, data))
            return
        self._write_pending(now_ns)
        self.bag.write(topic, data, now_ns)

    def _write_pending(self, log_time_ns: int) -> None:
        for topic, data in self.pending:
            self.bag.write(topic, data, log_time_ns)
        self.pending.clear()

    def destroy_node(self) -> Any:
        """Complete the file with the node and say what it holds."""
        self._write_pending(0)
        self.bag.close()
        # After shutdown /rosout is gone: say it on stderr.
        counts = ', '.join(f'{t}: {n}' for t, n in sorted(self.bag.counts.items()))
        size_mb = os.path.getsize(self.bag.path) / 1e6
        print(f'[recorder] wrote {self.bag.path} ({size_mb:.1f} MB; {counts})',
              file=sys.stderr, flush=True)
        return super().destroy_node()


def main(args: list[str] | None = None) -> int:
    """Entry point of the recorder_node executable."""
    # (run_node's spin ends between callbacks, never inside a half-written MCAP record)
    return run_node(RecorderNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
