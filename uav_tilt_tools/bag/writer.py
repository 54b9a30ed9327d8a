"""One MCAP file in the ros2 profile, written from serialized CDR messages (no rclpy).

A schema (``ros2msg``) per type, a channel (``cdr``) per topic. log_time is when the
recorder received a message; publish_time is its header stamp (sim time) for types that
start with one, else log_time. Messages are kept in zstd chunks; :meth:`McapBag.flush`
closes the current chunk and hands it to the OS, so a killed recorder leaves a file whose
flushed chunks a streaming reader can read; :meth:`McapBag.close` writes the index.

As rosbag2 does, each channel keeps the QoS its publishers offered (``offered_qos_profiles``,
so that a replay latches what was latched), and a bag that has its folder to itself gets
rosbag2's ``metadata.yaml`` at close, so that the folder opens as a bag
(``ros2 bag info|play DIR``, rosbags) as well as the file.
"""
import collections
import os
from typing import Any, Iterable

import yaml
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from uav_tilt_tools.bag import msg_defs
from uav_tilt_tools.bag.folder import METADATA_FILE

LIBRARY = 'uav_tilt recorder'
CHUNK_BYTES = 1 << 20
ROSBAG2_VERSION = 9             # the metadata.yaml version of Jazzy's rosbag2
ROS_DISTRO = 'jazzy'


def qos_dicts(profiles: Iterable[Any]) -> list[dict[str, Any]]:
    """rosbag2's (version 9) description of QoS profiles (rclpy QoSProfile-like: enum
    policies, rclpy Duration times)."""
    def time(duration: Any) -> dict[str, int]:
        sec, nsec = divmod(duration.nanoseconds, 10**9)
        return {'sec': sec, 'nsec': nsec}

    return [{'history': q.history.name.lower(), 'depth': q.depth,
             'reliability': q.reliability.name.lower(),
             'durability': q.durability.name.lower(), 'deadline': time(q.deadline),
             'lifespan': time(q.lifespan), 'liveliness': q.liveliness.name.lower(),
             'liveliness_lease_duration': time(q.liveliness_lease_duration),
             'avoid_ros_namespace_conventions': bool(q.avoid_ros_namespace_conventions)}
            for q in profiles]


class McapBag:
    """Writer of one new MCAP file (a file already there is an error: a recording is never
    overwritten); call :meth:`close` to complete it."""

    def __init__(self, path: str | os.PathLike[str], chunk_bytes: int = CHUNK_BYTES,
                 own_folder: bool = False) -> None:
        """``own_folder``: the file's folder is this bag's (it gets metadata.yaml)."""
        self.path = str(path)
        self._own_folder = own_folder
        self._stream = open(self.path, 'xb')
        self._writer = Writer(self._stream, chunk_size=chunk_bytes,
                              compression=CompressionType.ZSTD)
        self._writer.start(profile='ros2', library=LIBRARY)
        self._schemas: dict[str, int] = {}      # type -> schema id
        # topic -> (channel id, header-stamped?)
        self._channels: dict[str, tuple[int, bool]] = {}
        self.counts: collections.Counter[str] = collections.Counter()
        self.closed = False

    def add_topic(self, topic: str, type_name: str, offered_qos: Iterable[Any] = ()) -> None:
        """Register ``topic`` of ``type_name`` (LookupError when its .msg is not installed),
        published with the QoS profiles ``offered_qos``."""
        if type_name not in self._schemas:
            text = msg_defs.full_definition(type_name)
            self._schemas[type_name] = self._writer.register_schema(
                type_name, 'ros2msg', text.encode())
        qos = qos_dicts(offered_qos)
        channel = self._writer.register_channel(
            topic, 'cdr', self._schemas[type_name],
            {'offered_qos_profiles': yaml.safe_dump(qos)} if qos else {})
        self._channels[topic] = (channel, msg_defs.starts_with_time(type_name))

    def write(self, topic: str, data: bytes, log_time_ns: int) -> None:
        """Append one serialized message of a registered topic."""
        channel, stamped = self._channels[topic]
        publish_ns = msg_defs.cdr_stamp_ns(data) if stamped else log_time_ns
        self._writer.add_message(channel, log_time=log_time_ns, data=data,
                                 publish_time=max(publish_ns, 0),
                                 sequence=self.counts[topic])
        self.counts[topic] += 1

    def flush(self) -> None:
        """Close the chunk in progress and push everything to the OS."""
        self._writer.flush()

    def close(self) -> None:
        """Write the summary (index, statistics) and close the file, then the folder's
        metadata.yaml when it has one; idempotent."""
        if not self.closed:
            self.closed = True
            self._writer.finish()
            self._stream.close()
            if self._own_folder:
                write_rosbag2_metadata(self.path)


def write_rosbag2_metadata(path: str) -> None:
    """Write rosbag2's metadata.yaml (version 9) of the complete MCAP file ``path`` beside
    it, from the file's own summary: its folder then opens as a bag."""
    with open(path, 'rb') as stream:
        summary = make_reader(stream).get_summary()
    # a complete file, as this module writes it, has its summary and statistics
    assert summary is not None and summary.statistics is not None, path
    stats = summary.statistics
    span = {'starting_time': {'nanoseconds_since_epoch': stats.message_start_time},
            'duration': {'nanoseconds': stats.message_end_time - stats.message_start_time}}
    name = os.path.basename(path)
    metadata = {'rosbag2_bagfile_information': {
        'version': ROSBAG2_VERSION, 'storage_identifier': 'mcap', **span,
        'message_count': stats.message_count,
        'topics_with_message_count': [
            {'topic_metadata': {
                'name': channel.topic, 'type': summary.schemas[channel.schema_id].name,
                'serialization_format': channel.message_encoding,
                'offered_qos_profiles': yaml.safe_load(
                    channel.metadata.get('offered_qos_profiles', '[]')),
                'type_description_hash': ''},
             'message_count': stats.channel_message_counts.get(channel.id, 0)}
            for channel in summary.channels.values()],
        'compression_format': '', 'compression_mode': '',
        'relative_file_paths': [name],
        'files': [{'path': name, **span, 'message_count': stats.message_count}],
        'custom_data': {}, 'ros_distro': ROS_DISTRO}}
    with open(os.path.join(os.path.dirname(path), METADATA_FILE), 'w',
              encoding='utf-8') as stream:
        yaml.safe_dump(metadata, stream, sort_keys=False)
