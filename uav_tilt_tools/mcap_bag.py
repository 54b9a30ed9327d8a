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

import yaml
from mcap.writer import CompressionType, Writer

from uav_tilt_tools import msg_defs

LIBRARY = 'uav_tilt recorder'
CHUNK_BYTES = 1 << 20
METADATA_FILE = 'metadata.yaml'
ROSBAG2_VERSION = 9             # the metadata.yaml version of Jazzy's rosbag2
ROS_DISTRO = 'jazzy'


def qos_dicts(profiles):
    """rosbag2's (version 9) description of QoS profiles (rclpy QoSProfile-like: enum
    policies, rclpy Duration times)."""
    def time(duration):
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

    def __init__(self, path, chunk_bytes=CHUNK_BYTES, own_folder=False):
        """``own_folder``: the file's folder is this bag's (it gets metadata.yaml)."""
        self.path = str(path)
        self._metadata_path = (os.path.join(os.path.dirname(self.path), METADATA_FILE)
                               if own_folder else None)
        self._stream = open(self.path, 'xb')
        self._writer = Writer(self._stream, chunk_size=chunk_bytes,
                              compression=CompressionType.ZSTD)
        self._writer.start(profile='ros2', library=LIBRARY)
        self._schemas = {}      # type -> schema id
        self._channels = {}     # topic -> (channel id, header-stamped?)
        self._topics = {}       # topic -> (type, offered QoS dicts), for metadata.yaml
        self._log_ns = None     # (first, last) log time written
        self.counts = collections.Counter()
        self.closed = False

    def add_topic(self, topic, type_name, offered_qos=()):
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
        self._topics[topic] = (type_name, qos)

    def write(self, topic, data, log_time_ns):
        """Append one serialized message of a registered topic."""
        channel, stamped = self._channels[topic]
        publish_ns = msg_defs.cdr_stamp_ns(data) if stamped else log_time_ns
        self._writer.add_message(channel, log_time=log_time_ns, data=data,
                                 publish_time=max(publish_ns, 0),
                                 sequence=self.counts[topic])
        self.counts[topic] += 1
        first = log_time_ns if self._log_ns is None else min(self._log_ns[0], log_time_ns)
        last = log_time_ns if self._log_ns is None else max(self._log_ns[1], log_time_ns)
        self._log_ns = (first, last)

    def flush(self):
        """Close the chunk in progress and push everything to the OS."""
        self._writer.flush()

    def close(self):
        """Write the summary (index, statistics) and close the file, then the folder's
        metadata.yaml when it has one; idempotent."""
        if not self.closed:
            self.closed = True
            self._writer.finish()
            self._stream.close()
            if self._metadata_path is not None:
                with open(self._metadata_path, 'w', encoding='utf-8') as stream:
                    yaml.safe_dump(self.rosbag2_metadata(), stream, sort_keys=False)

    def rosbag2_metadata(self):
        """rosbag2's metadata.yaml (version 9) of what was written."""
        start_ns, end_ns = self._log_ns or (0, 0)
        span = {'starting_time': {'nanoseconds_since_epoch': start_ns},
                'duration': {'nanoseconds': end_ns - start_ns}}
        total = sum(self.counts.values())
        name = os.path.basename(self.path)
        return {'rosbag2_bagfile_information': {
            'version': ROSBAG2_VERSION, 'storage_identifier': 'mcap', **span,
            'message_count': total,
            'topics_with_message_count': [
                {'topic_metadata': {'name': topic, 'type': type_name,
                                    'serialization_format': 'cdr',
                                    'offered_qos_profiles': qos, 'type_description_hash': ''},
                 'message_count': self.counts[topic]}
                for topic, (type_name, qos) in self._topics.items()],
            'compression_format': '', 'compression_mode': '',
            'relative_file_paths': [name],
            'files': [{'path': name, **span, 'message_count': total}],
            'custom_data': {}, 'ros_distro': ROS_DISTRO}}
