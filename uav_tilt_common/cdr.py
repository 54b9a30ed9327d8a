"""Serialized (CDR) form of the 300 Hz control-path messages of DESIGN section 3.

Taking or publishing a message object costs rclpy 100-200 us on this machine (most of it
building the Python message), more than a controller tick. The plant and the controller
exchange /clock, imu, odom, ee_wrench and actuators/cmd serialized instead: they publish
bytes and subscribe raw. The bytes are what rclpy would put on the wire (the ROS 2 default,
XCDR1 plain CDR with a 4-byte encapsulation header), so every other node, the recorder and
`ros2 bag` see ordinary messages. Layouts are fixed by the message definitions; the
alignment of each field is taken from the start of the body, after the header.

Encoders take plain numbers (little endian out); decoders take both byte orders and raise
ValueError on a malformed buffer. Only the fields the cores use are read or written: the
covariances stay zero, as the message objects of :mod:`ros_msgs` leave them.
"""
import struct

_ENCAPSULATION_LE = b'\x00\x01\x00\x00'
_ZEROS = bytes(36 * 8)


def _pad(n, align):
    return -n % align


def _header(stamp_ns, frame_id):
    """Encapsulation + std_msgs/Header; returns (bytearray, body length)."""
    frame = frame_id.encode()
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    out = bytearray(_ENCAPSULATION_LE)
    out += struct.pack('<iII', sec, nanosec, len(frame) + 1)
    out += frame
    out.append(0)
    return out, 12 + len(frame) + 1


def _string(out, body_len, text):
    """Append a CDR string (4-aligned uint32 length with the NUL, bytes, NUL)."""
    data = text.encode()
    pad = _pad(body_len, 4)
    out += bytes(pad) + struct.pack('<I', len(data) + 1) + data + b'\x00'
    return body_len + pad + 4 + len(data) + 1


def _doubles(out, body_len, values):
    """Append float64s aligned to 8."""
    pad = _pad(body_len, 8)
    out += bytes(pad) + struct.pack(f'<{len(values)}d', *values)
    return body_len + pad + 8 * len(values)


def encode_clock(stamp_ns):
    """rosgraph_msgs/Clock."""
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    return _ENCAPSULATION_LE + struct.pack('<iI', sec, nanosec)


def encode_imu(stamp_ns, frame_id, q_xyzw, gyro, accel):
    """sensor_msgs/Imu: orientation, angular velocity and linear acceleration."""
    out, n = _header(stamp_ns, frame_id)
    zeros9 = _ZEROS[:72]
    out += bytes(_pad(n, 8))
    out += struct.pack('<4d', *q_xyzw) + zeros9 + struct.pack('<3d', *gyro) + zeros9 \
        + struct.pack('<3d', *accel) + zeros9
    return bytes(out)


def encode_odometry(stamp_ns, frame_id, child_frame_id, p, q_xyzw, v_child, w_child):
    """nav_msgs/Odometry: pose in ``frame_id``, twist in ``child_frame_id``."""
    out, n = _header(stamp_ns, frame_id)
    n = _string(out, n, child_frame_id)
    out += bytes(_pad(n, 8))
    out += struct.pack('<7d', *p, *q_xyzw) + _ZEROS + struct.pack('<6d', *v_child, *w_child) \
        + _ZEROS
    return bytes(out)


def encode_wrench(stamp_ns, frame_id, force, torque):
    """geometry_msgs/WrenchStamped."""
    out, n = _header(stamp_ns, frame_id)
    _doubles(out, n, (*force, *torque))
    return bytes(out)


def encode_joint_state(stamp_ns, frame_id, names, position, velocity, effort):
    """sensor_msgs/JointState."""
    out, n = _header(stamp_ns, frame_id)
    pad = _pad(n, 4)
    out += bytes(pad) + struct.pack('<I', len(names))
    n += pad + 4
    for name in names:
        n = _string(out, n, name)
    for values in (position, velocity, effort):
        pad = _pad(n, 4)
        out += bytes(pad) + struct.pack('<I', len(values))
        n += pad + 4
        if values:
            n = _doubles(out, n, values)
    return bytes(out)


class _Reader:
    """Reads CDR fields from a serialized message; ValueError on anything malformed."""

    __slots__ = ('data', 'pos', 'order')

    def __init__(self, data):
        if len(data) < 4 or data[0] != 0 or data[1] not in (0, 1):
            raise ValueError('not a plain CDR encapsulation')
        self.data = data
        self.order = '<' if data[1] == 1 else '>'
        self.pos = 4

    def _take(self, fmt, size, align):
        start = self.pos + _pad(self.pos - 4, align)
        try:
            values = struct.unpack_from(self.order + fmt, self.data, start)
        except struct.error as exc:
            raise ValueError(f'truncated message ({exc})') from None
        self.pos = start + size
        return values

    def uint32(self):
        return self._take('I', 4, 4)[0]

    def doubles(self, count):
        # an empty sequence has no elements to align
        return self._take(f'{count}d', 8 * count, 8) if count else ()

    def string(self):
        length = self.uint32()
        end = self.pos + length
        if length == 0 or end > len(self.data) or self.data[end - 1] != 0:
            raise ValueError('malformed string')
        try:
            text = bytes(self.data[self.pos:end - 1]).decode()
        except UnicodeDecodeError as exc:
            raise ValueError(f'string not UTF-8 ({exc})') from None
        self.pos = end
        return text

    def header(self):
        """(stamp_ns, frame_id) of a std_msgs/Header."""
        sec, nanosec = self._take('iI', 8, 4)
        return sec * 1_000_000_000 + nanosec, self.string()

    def sequence(self, count_limit):
        count = self.uint32()
        if count > count_limit:
            raise ValueError(f'sequence of {count} elements')
        return count


def decode_clock(data):
    """stamp_ns of a rosgraph_msgs/Clock."""
    sec, nanosec = _Reader(data)._take('iI', 8, 4)
    return sec * 1_000_000_000 + nanosec


def decode_imu(data):
    """(stamp_ns, frame_id, q_xyzw, gyro, accel) of a sensor_msgs/Imu."""
    r = _Reader(data)
    stamp_ns, frame_id = r.header()
    values = r.doubles(37)
    return stamp_ns, frame_id, values[0:4], values[13:16], values[25:28]


def decode_odometry(data):
    """(stamp_ns, frame_id, child_frame_id, p, q_xyzw, v_child, w_child) of a
    nav_msgs/Odometry."""
    r = _Reader(data)
    stamp_ns, frame_id = r.header()
    child = r.string()
    values = r.doubles(85)
    return stamp_ns, frame_id, child, values[0:3], values[3:7], values[43:46], values[46:49]


def decode_wrench(data):
    """(stamp_ns, frame_id, force, torque) of a geometry_msgs/WrenchStamped."""
    r = _Reader(data)
    stamp_ns, frame_id = r.header()
    values = r.doubles(6)
    return stamp_ns, frame_id, values[0:3], values[3:6]


def decode_joint_state(data, max_joints=64):
    """(stamp_ns, frame_id, names, position, velocity, effort) of a sensor_msgs/JointState;
    more than ``max_joints`` entries in a sequence is malformed."""
    r = _Reader(data)
    stamp_ns, frame_id = r.header()
    names = [r.string() for _ in range(r.sequence(max_joints))]
    position, velocity, effort = (r.doubles(r.sequence(max_joints)) for _ in range(3))
    return stamp_ns, frame_id, names, position, velocity, effort
