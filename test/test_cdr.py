"""The serialized control-path messages are what rclpy puts on the wire, both ways."""
import numpy as np
import pytest
from builtin_interfaces.msg import Time
from geometry_msgs.msg import WrenchStamped
from nav_msgs.msg import Odometry
from rclpy.serialization import deserialize_message, serialize_message
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import Imu, JointState

from uav_tilt_common import cdr, names, ros_msgs
from uav_tilt_common.state import VehicleState

FRAMES = ('', 'a', 'map', 'base_link', 'camera_color_optical_frame', 'éé')


def _random_state(rng, t_s):
    q = rng.normal(size=4)
    return VehicleState(t_s, rng.normal(size=3) * 10, q / np.linalg.norm(q),
                        rng.normal(size=3), rng.normal(size=3))


def _stamp(rng):
    sec, nanosec = int(rng.integers(0, 2 ** 31 - 1)), int(rng.integers(0, 1_000_000_000))
    return sec * 1_000_000_000 + nanosec, Time(sec=sec, nanosec=nanosec)


@pytest.mark.parametrize('frame', FRAMES)
def test_encoded_messages_decode_with_rclpy_to_the_message_objects(frame):
    rng = np.random.default_rng(abs(hash(frame)) % 1000)
    for _ in range(20):
        ns, stamp = _stamp(rng)
        state = _random_state(rng, ns * 1e-9)
        expected = ros_msgs.odometry_msg(state, stamp, frame, frame[::-1])
        got = deserialize_message(ros_msgs.odometry_cdr(state, ns, frame, frame[::-1]),
                                  Odometry)
        assert got == expected
        gyro, accel, force, torque = rng.normal(size=(4, 3))
        expected = ros_msgs.imu_msg(gyro, accel, state.q_map_base, stamp)
        assert deserialize_message(ros_msgs.imu_cdr(gyro, accel, state.q_map_base, ns),
                                   Imu) == expected
        expected = ros_msgs.wrench_msg(force, torque, stamp, frame)
        assert deserialize_message(ros_msgs.wrench_cdr(force, torque, ns, frame),
                                   WrenchStamped) == expected
        thrusts, tilts = rng.uniform(0, 9, 4), rng.uniform(-1, 1, 2)
        expected = ros_msgs.actuator_msg(thrusts, tilts, stamp)
        assert deserialize_message(ros_msgs.actuator_cdr(thrusts, tilts, ns),
                                   JointState) == expected
        assert deserialize_message(cdr.encode_clock(ns), Clock) == Clock(clock=stamp)


@pytest.mark.parametrize('frame', FRAMES)
def test_messages_serialized_by_rclpy_decode_to_their_fields(frame):
    rng = np.random.default_rng(7)
    for n_joints in (0, 1, 6, 9):
        ns, stamp = _stamp(rng)
        msg = JointState()
        msg.header.stamp, msg.header.frame_id = stamp, frame
        msg.name = [frame * i + str(i) for i in range(n_joints)]
        msg.position = rng.normal(size=n_joints).tolist()
        msg.velocity = rng.normal(size=n_joints // 2).tolist()
        msg.effort = rng.normal(size=n_joints).tolist()
        stamp_ns, frame_id, joint_names, position, velocity, effort = \
            cdr.decode_joint_state(serialize_message(msg))
        assert (stamp_ns, frame_id) == (ros_msgs.stamp_ns(stamp), frame)
        assert joint_names == msg.name
        assert (list(position), list(velocity), list(effort)) == (
            list(msg.position), list(msg.velocity), list(msg.effort))
    ns, stamp = _stamp(rng)
    state = _random_state(rng, 0.0)
    odom = ros_msgs.odometry_msg(state, stamp, frame, names.FRAME_BASE)
    odom.pose.covariance = rng.normal(size=36)      # fields the decoder skips
    frame_id, child, got = ros_msgs.state_from_odometry_cdr(serialize_message(odom))
    assert (frame_id, child) == (frame, names.FRAME_BASE)
    want = ros_msgs.state_from_odometry(odom)
    assert got.t_s == pytest.approx(want.t_s, abs=1e-9)
    for field in ('p_map', 'q_map_base', 'v_map', 'w_base'):
        np.testing.assert_array_equal(getattr(got, field), getattr(want, field))
    imu = ros_msgs.imu_msg(*rng.normal(size=(2, 3)), state.q_map_base, stamp)
    imu.header.frame_id = frame
    imu.angular_velocity_covariance = rng.normal(size=9)
    stamp_ns, frame_id, q, gyro, accel = cdr.decode_imu(serialize_message(imu))
    assert (stamp_ns, frame_id) == (ros_msgs.stamp_ns(stamp), frame)
    assert q == tuple(state.q_map_base)
    assert gyro == (imu.angular_velocity.x, imu.angular_velocity.y, imu.angular_velocity.z)
    assert accel == (imu.linear_acceleration.x, imu.linear_acceleration.y,
                     imu.linear_acceleration.z)
    wrench = ros_msgs.wrench_msg(*rng.normal(size=(2, 3)), stamp, frame)
    assert cdr.decode_wrench(serialize_message(wrench)) == (
        ros_msgs.stamp_ns(stamp), frame, tuple(ros_msgs.vector_of(wrench.wrench.force)),
        tuple(ros_msgs.vector_of(wrench.wrench.torque)))
    assert cdr.decode_clock(serialize_message(Clock(clock=stamp))) == ros_msgs.stamp_ns(stamp)


def test_big_endian_messages_decode_too():
    data = bytearray(b'\x00\x00\x00\x00')
    data += (3).to_bytes(4, 'big', signed=True) + (5).to_bytes(4, 'big')
    data += (3).to_bytes(4, 'big') + b'ee\x00' + b'\x00'
    data += np.array([1, 2, 3, 4, 5, 6], dtype='>f8').tobytes()
    assert cdr.decode_wrench(bytes(data)) == (3_000_000_005, 'ee', (1.0, 2.0, 3.0),
                                              (4.0, 5.0, 6.0))


def test_malformed_buffers_raise_value_error():
    good = ros_msgs.actuator_cdr([1.0] * 4, (0.0, 0.0), 5)
    rng = np.random.default_rng(3)
    broken = [b'', b'\x01\x00\x00\x00' + good[4:], good[:len(good) // 2], good[:-1]]
    # a name sequence claiming 10^9 entries
    broken.append(good[:20] + (10 ** 9).to_bytes(4, 'little') + good[24:])
    for _ in range(200):
        junk = bytearray(good)
        junk[rng.integers(4, len(junk))] = rng.integers(0, 256)
        broken.append(bytes(junk))
    decoded = 0
    for data in broken:
        try:
            cdr.decode_joint_state(data)
            decoded += 1
        except ValueError:
            pass
    assert decoded < len(broken)
    for data in broken[:5]:
        with pytest.raises(ValueError):
            cdr.decode_joint_state(data)
