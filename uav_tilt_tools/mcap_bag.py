"""One MCAP file in the ros2 profile, written from serialized CDR messages (no rclpy).

A schema (``ros2msg``) per type, a channel (``cdr``) per topic. log_time is when the
recorder received a message; publish_time is its header stamp (sim time) for types that
start with one, else log_time. Messages are kept in zstd chunks; :meth:`McapBag.flush`
closes the current chunk and hands it to the OS, so a killed recorder leaves a file whose
flushed chunks a streaming reader can read; :meth:`McapBag.close` writes the index.
"""
import collections

from mcap.writer import CompressionType, Writer

from uav_tilt_tools import msg_defs

LIBRARY = 'uav_tilt recorder'
CHUNK_BYTES = 1 << 20


class McapBag:
    """Writer of one new MCAP file (a file already there is an error: a recording is never
    overwritten); call :meth:`close` to complete it."""

    def __init__(self, path, chunk_bytes=CHUNK_BYTES):
        self.path = str(path)
        self._stream = open(self.path, 'xb')
        self._writer = Writer(self._stream, chunk_size=chunk_bytes,
                              compression=CompressionType.ZSTD)
        self._writer.start(profile='ros2', library=LIBRARY)
        self._schemas = {}      # type -> schema id
        self._channels = {}     # topic -> (channel id, header-stamped?)
        self.counts = collections.Counter()
        self.closed = False

    def add_topic(self, topic, type_name):
        """Register ``topic`` of ``type_name`` (LookupError when its .msg is not installed)."""
        if type_name not in self._schemas:
            text = msg_defs.full_definition(type_name)
            self._schemas[type_name] = self._writer.register_schema(
                type_name, 'ros2msg', text.encode())
        channel = self._writer.register_channel(topic, 'cdr', self._schemas[type_name])
        self._channels[topic] = (channel, msg_defs.starts_with_time(type_name))

    def write(self, topic, data, log_time_ns):
        """Append one serialized message of a registered topic."""
        channel, stamped = self._channels[topic]
        publish_ns = msg_defs.cdr_stamp_ns(data) if stamped else log_time_ns
        self._writer.add_message(channel, log_time=log_time_ns, data=data,
                                 publish_time=max(publish_ns, 0),
                                 sequence=self.counts[topic])
        self.counts[topic] += 1

    def flush(self):
        """Close the chunk in progress and push everything to the OS."""
        self._writer.flush()

    def close(self):
        """Write the summary (index, statistics) and close the file; idempotent."""
        if not self.closed:
            self.closed = True
            self._writer.finish()
            self._stream.close()
