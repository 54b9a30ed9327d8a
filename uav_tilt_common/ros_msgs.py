"""Conversions between ROS messages and the cores' numpy data (DESIGN section 3)."""
import math
from typing import Any

import numpy as np
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped, WrenchStamped
from nav_msgs.msg import Odometry
from sensor_msgs.msg import CameraInfo, Image, Imu, JointState, PointCloud2, PointField

from uav_tilt_common import cdr, names
from uav_tilt_common.geometry import quat_to_matrix
from uav_tilt_common.planes import PLANE_FIELDS, planes_from_array, planes_to_array
from uav_tilt_common.state import VehicleState
from uav_tilt_common.targets import CANDIDATE_FIELDS, candidates_from_array, candidates_to_array


def to_stamp(t_s):
    """builtin_interfaces/Time of a time in seconds (exact for the plant's tick times)."""
    return stamp_of_ns(int(round(t_s * 1e9)))


def stamp_of_ns(ns):
    """builtin_interfaces/Time of integer nanoseconds."""
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def from_stamp(stamp):
    """Seconds of a builtin_interfaces/Time."""
    return stamp.sec + stamp.nanosec * 1e-9


def stamp_ns(stamp):
    """Integer nanoseconds of a stamp (exact comparison of tick stamps)."""
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def _set_xyz(target, values):
    target.x, target.y, target.z = float(values[0]), float(values[1]), float(values[2])


def _set_quat(target, q):
    target.x, target.y, target.z, target.w = (float(q[0]), float(q[1]), float(q[2]),
                                              float(q[3]))


def odometry_msg(state, stamp, frame_id=names.FRAME_MAP, child=names.FRAME_BASE):
    """nav_msgs/Odometry; twist in the child frame (base_link) as the message defines."""
    msg = Odometry()
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    msg.child_frame_id = child
    _set_xyz(msg.pose.pose.position, state.p_map)
    _set_quat(msg.pose.pose.orientation, state.q_map_base)
    _set_xyz(msg.twist.twist.linear, _v_child(state))
    _set_xyz(msg.twist.twist.angular, state.w_base)
    return msg


def state_from_odometry(msg):
    """VehicleState of an Odometry message (map -> base_link, twist in base_link)."""
    pose, twist = msg.pose.pose, msg.twist.twist
    return _state(from_stamp(msg.header.stamp),
                  (pose.position.x, pose.position.y, pose.position.z),
                  (pose.orientation.x, pose.orientation.y, pose.orientation.z,
                   pose.orientation.w),
                  (twist.linear.x, twist.linear.y, twist.linear.z),
                  (twist.angular.x, twist.angular.y, twist.angular.z))


def _v_child(state):
    return quat_to_matrix(state.q_map_base).T @ state.v_map


def _state(t_s, p, q, v_child, w_child):
    q = np.array(q)
    return VehicleState(t_s, np.array(p), q, quat_to_matrix(q) @ np.array(v_child),
                        np.array(w_child))


# --- serialized (CDR) forms of the 300 Hz messages, see uav_tilt_common.cdr --------------
def odometry_cdr(state, stamp_ns, frame_id=names.FRAME_MAP, child=names.FRAME_BASE):
    """Serialized :func:`odometry_msg`."""
    return cdr.encode_odometry(stamp_ns, frame_id, child, state.p_map.tolist(),
                               np.asarray(state.q_map_base).tolist(),
                               _v_child(state).tolist(), np.asarray(state.w_base).tolist())


def state_from_odometry_cdr(data):
    """(frame_id, child_frame_id, VehicleState) of a serialized Odometry."""
    stamp_ns, frame_id, child, p, q, v, w = cdr.decode_odometry(data)
    return frame_id, child, _state(stamp_ns * 1e-9, p, q, v, w)


def imu_cdr(gyro, accel, q, stamp_ns):
    """Serialized :func:`imu_msg`."""
    return cdr.encode_imu(stamp_ns, names.FRAME_BASE, np.asarray(q).tolist(),
                          np.asarray(gyro).tolist(), np.asarray(accel).tolist())


def wrench_cdr(force, torque, stamp_ns, frame_id=names.FRAME_EE):
    """Serialized :func:`wrench_msg`."""
    return cdr.encode_wrench(stamp_ns, frame_id, np.asarray(force).tolist(),
                             np.asarray(torque).tolist())


def actuator_cdr(thrusts_n, tilts_rad, stamp_ns):
    """Serialized :func:`actuator_msg`."""
    return cdr.encode_joint_state(stamp_ns, '', names.ACTUATOR_NAMES,
                                  [0.0] * 4 + [float(x) for x in tilts_rad], (),
                                  [float(x) for x in thrusts_n] + [0.0, 0.0])


def clock_cdr(t_s):
    """Serialized rosgraph_msgs/Clock at ``t_s`` (rounded as :func:`to_stamp`)."""
    return cdr.encode_clock(int(round(t_s * 1e9)))


def pose_stamped_msg(p, q, stamp, frame_id=names.FRAME_MAP):
    """geometry_msgs/PoseStamped of a position and an (x, y, z, w) quaternion."""
    msg = PoseStamped()
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    _set_xyz(msg.pose.position, p)
    _set_quat(msg.pose.orientation, q)
    return msg


def imu_msg(gyro, accel, q, stamp):
    """sensor_msgs/Imu in base_link."""
    msg = Imu()
    msg.header.stamp = stamp
    msg.header.frame_id = names.FRAME_BASE
    _set_quat(msg.orientation, q)
    _set_xyz(msg.angular_velocity, gyro)
    _set_xyz(msg.linear_acceleration, accel)
    return msg


def wrench_msg(force, torque, stamp, frame_id=names.FRAME_EE):
    """geometry_msgs/WrenchStamped."""
    msg = WrenchStamped()
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    _set_xyz(msg.wrench.force, force)
    _set_xyz(msg.wrench.torque, torque)
    return msg


def vector_of(v):
    """numpy array of a geometry_msgs Vector3/Point."""
    return np.array([v.x, v.y, v.z])


def actuator_msg(thrusts_n, tilts_rad, stamp):
    """sensor_msgs/JointState: effort = rotor thrust [N], position = tilt [rad]."""
    msg = JointState()
    msg.header.stamp = stamp
    msg.name = list(names.ACTUATOR_NAMES)
    msg.effort = [float(x) for x in thrusts_n] + [0.0, 0.0]
    msg.position = [0.0] * 4 + [float(x) for x in tilts_rad]
    return msg


def _image_layout(array):
    """(encoding, step, contiguous little-endian data) of an rgb8 or 32FC1 image array."""
    if array.ndim == 3:
        return 'rgb8', int(array.shape[1]) * 3, np.ascontiguousarray(array, dtype=np.uint8)
    return '32FC1', int(array.shape[1]) * 4, np.ascontiguousarray(array, dtype='<f4')


def image_msg(array, stamp, frame_id=names.FRAME_CAMERA):
    """sensor_msgs/Image: rgb8 for HxWx3 uint8, 32FC1 for HxW float32."""
    msg = Image()
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    msg.height, msg.width = int(array.shape[0]), int(array.shape[1])
    msg.encoding, msg.step, data = _image_layout(array)
    msg.is_bigendian = 0
    msg.data = data.tobytes()
    return msg


def image_cdr(array, stamp_ns, frame_id=names.FRAME_CAMERA):
    """The serialized form of :func:`image_msg` (see :mod:`cdr`)."""
    encoding, step, data = _image_layout(array)
    return cdr.encode_image(stamp_ns, frame_id, int(array.shape[0]), int(array.shape[1]),
                            encoding, step, data.data)


def array_of_image(msg):
    """numpy copy of an rgb8 or 32FC1 Image (a message or a :class:`cdr.CdrImage`); raises
    ValueError on anything else."""
    dtype: np.dtype[Any]
    if msg.encoding == 'rgb8':
        channels, dtype = 3, np.dtype(np.uint8)
    elif msg.encoding == '32FC1':
        channels, dtype = 1, np.dtype('>f4' if msg.is_bigendian else '<f4')
    else:
        raise ValueError(f'unsupported encoding {msg.encoding!r}')
    itemsize = np.dtype(dtype).itemsize
    if msg.height == 0 or msg.width == 0 or msg.step != msg.width * channels * itemsize \
            or len(msg.data) != msg.step * msg.height:
        raise ValueError(f'inconsistent image {msg.width}x{msg.height} step {msg.step} '
                         f'with {len(msg.data)} bytes')
    data = np.frombuffer(bytes(msg.data), dtype=dtype)
    shape = (msg.height, msg.width, 3) if channels == 3 else (msg.height, msg.width)
    return data.reshape(shape)


def camera_info_msg(cam, stamp, frame_id=names.FRAME_CAMERA):
    """sensor_msgs/CameraInfo of a CameraConfig (plumb_bob, no distortion)."""
    msg = CameraInfo()
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    msg.width, msg.height = cam.width, cam.height
    msg.distortion_model = 'plumb_bob'
    msg.d = [0.0] * 5
    msg.k = [float(x) for x in cam.k_matrix().reshape(-1)]
    msg.r = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
    msg.p = [cam.fx, 0.0, cam.cx, 0.0, 0.0, cam.fy, cam.cy, 0.0, 0.0, 0.0, 1.0, 0.0]
    return msg


def diagnostics_msg(name, values, stamp, level=DiagnosticStatus.OK, message='ok'):
    """diagnostic_msgs/DiagnosticArray with one status holding ``values`` as key/values."""
    status = DiagnosticStatus(level=level, name=name, message=message, hardware_id='uav_tilt')
    status.values = [KeyValue(key=str(k), value=_fmt(v)) for k, v in values.items()]
    msg = DiagnosticArray()
    msg.header.stamp = stamp
    msg.status = [status]
    return msg


def _fmt(value):
    if isinstance(value, float):
        return f'{value:.6g}' if math.isfinite(value) else str(value)
    return str(value)


def candidates_msg(candidates, stamp, frame_id=names.FRAME_CAMERA):
    """target/candidates: a PointCloud2 of float32 CANDIDATE_FIELDS, one point each."""
    return _cloud_msg(candidates_to_array(candidates), CANDIDATE_FIELDS, stamp, frame_id)


def candidates_of_msg(msg):
    """The TargetCandidates of a target/candidates message; ValueError when its layout is
    not :func:`candidates_msg`'s."""
    return candidates_from_array(_cloud_rows(msg, CANDIDATE_FIELDS))


def planes_msg(planes, stamp, frame_id=names.FRAME_CAMERA):
    """vision/planes: a PointCloud2 of float32 PLANE_FIELDS, one point per plane."""
    return _cloud_msg(planes_to_array(planes), PLANE_FIELDS, stamp, frame_id)


def planes_of_msg(msg):
    """The Planes of a vision/planes message; ValueError when its layout is not
    :func:`planes_msg`'s or a plane is not valid."""
    return planes_from_array(_cloud_rows(msg, PLANE_FIELDS))


def _cloud_msg(rows, fields, stamp, frame_id):
    """A PointCloud2 of float32 ``fields``, one point per row."""
    msg = PointCloud2()
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    msg.height, msg.width = 1, len(rows)
    msg.fields = [PointField(name=name, offset=4 * i, datatype=PointField.FLOAT32, count=1)
                  for i, name in enumerate(fields)]
    msg.is_bigendian = False
    msg.point_step = 4 * len(fields)
    msg.row_step = msg.point_step * len(rows)
    msg.is_dense = True
    msg.data = rows.astype('<f4').tobytes()
    return msg


def _cloud_rows(msg, fields):
    """The float32 rows of a :func:`_cloud_msg` PointCloud2; ValueError on another layout."""
    names_ = tuple(f.name for f in msg.fields)
    if names_ != fields or any(f.datatype != PointField.FLOAT32 or f.count != 1
                               or f.offset != 4 * i for i, f in enumerate(msg.fields)) \
            or msg.point_step != 4 * len(fields) \
            or len(msg.data) != msg.point_step * msg.width * msg.height:
        offsets = tuple(f.offset for f in msg.fields)
        raise ValueError(f'unexpected point layout: fields {names_} at offsets {offsets}, '
                         f'point_step {msg.point_step}, {len(msg.data)} bytes')
    dtype = np.dtype('>f4' if msg.is_bigendian else '<f4')
    return np.frombuffer(bytes(msg.data), dtype=dtype)


def status_value(text):
    """A value of :func:`diagnostics_msg` decoded: bool, float, or the string itself."""
    if text in ('True', 'False'):
        return text == 'True'
    try:
        return float(text)
    except ValueError:
        return text


def diagnostics_values(msg):
    """{key: decoded value} of the first status of a DiagnosticArray ({} if it has none)."""
    return {kv.key: status_value(kv.value) for kv in msg.status[0].values} if msg.status \
        else {}
