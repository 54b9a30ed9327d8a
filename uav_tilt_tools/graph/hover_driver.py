"""A trivial lockstep client: answers every IMU tick with hover thrust, checks sensor sets.

The thrust holds the first odom height with a PD term on the vertical axis only (the
rotors spin up from rest, so pure hover thrust would leave the vehicle sinking).

Used by the plant's ROS tests and by ``uav-tilt bench sim`` as the controller in another
process. Writes a JSON report after ``--ticks`` answered ticks.
"""
import argparse
import json
import os
import time
from typing import Any, Callable

import numpy as np
import rclpy
from rclpy.executors import ExternalShutdownException
from geometry_msgs.msg import WrenchStamped
from nav_msgs.msg import Odometry
from rclpy.node import Node
from sensor_msgs.msg import Imu, JointState

from uav_tilt_common import names, ros_msgs, ros_qos
from uav_tilt_common.vehicle import GRAVITY, VehicleParams

KP_Z, KD_Z = 4.0, 4.0    # 1/s^2, 1/s: a critically damped 2 rad/s height loop


class HoverDriver(Node):
    """Answers each IMU message with a hover command stamped like it."""

    def __init__(self, ticks: int) -> None:
        super().__init__('hover_driver')
        self.ticks = ticks
        self.thrust_n = VehicleParams().hover_thrust_n
        q = ros_qos.CONTROL
        self.latest: dict[str, Any] = {}
        self.latest_topics = (names.ODOM, names.EE_WRENCH)
        # What a flight controller reads besides the imu.
        for topic, msg_type in ((names.ODOM, Odometry), (names.EE_WRENCH, WrenchStamped)):
            ros_qos.quiet_subscription(self, msg_type, topic, self._remember(topic), q)
        ros_qos.quiet_subscription(self, Imu, names.IMU, self.on_imu, q)
        self.pub = ros_qos.quiet_publisher(self, JointState, names.ACTUATORS_CMD, q)
        self.answered: list[int] = []   # stamps (ns) of the ticks answered
        self.complete_sets = 0      # ticks whose odom and wrench had arrived before the imu
        self.wall_first = 0.0       # monotonic clock at the first and last tick answered
        self.wall_last = 0.0
        self.z_ref_m: float | None = None   # the height held: the first odom's
        self.last_cmd: Any = None   # the answer to the last tick, re-sent if it is re-sent

    def _remember(self, topic: str) -> Callable[[Any], None]:
        def callback(msg: Any) -> None:
            self.latest[topic] = msg
        return callback

    def thrust_per_rotor_n(self) -> float:
        """Hover thrust scaled by a vertical PD on the odom height (none before odom)."""
        odom = self.latest.get(names.ODOM)
        if odom is None:
            return self.thrust_n
        z_m = odom.pose.pose.position.z
        self.z_ref_m = z_m if self.z_ref_m is None else self.z_ref_m
        accel = KP_Z * (self.z_ref_m - z_m) - KD_Z * odom.twist.twist.linear.z
        return self.thrust_n * (1.0 + float(np.clip(accel / GRAVITY, -0.5, 0.5)))

    def on_imu(self, msg: Any) -> None:
        """One control tick: answer with hover thrust until ``ticks`` are done."""
        if len(self.answered) >= self.ticks:
            return
        stamp = ros_msgs.stamp_ns(msg.header.stamp)
        if self.answered and stamp == self.answered[-1]:
            # the plant re-sent a tick it is still waiting on (our answer went out before
            # its subscription matched ours): answer it again
            self.pub.publish(self.last_cmd)
            return
        if all(t in self.latest and ros_msgs.stamp_ns(self.latest[t].header.stamp) == stamp
               for t in self.latest_topics):
            self.complete_sets += 1
        self.answered.append(stamp)
        now = time.monotonic()
        self.wall_first = self.wall_first or now
        self.wall_last = now
        self.last_cmd = ros_msgs.actuator_msg(np.full(4, self.thrust_per_rotor_n()), (0.0, 0.0),
                                              msg.header.stamp)
        self.pub.publish(self.last_cmd)

    def report(self) -> dict[str, Any]:
        """Counts, stamp ordering and the achieved real-time factor."""
        stamps = np.array(self.answered, dtype=np.int64)
        sim_span = (stamps[-1] - stamps[0]) * 1e-9 if len(stamps) > 1 else 0.0
        wall_span = (self.wall_last - self.wall_first) if len(stamps) > 1 else 0.0
        return {
            'ticks': len(stamps),
            'complete_sets': self.complete_sets,
            'strictly_increasing': bool(np.all(np.diff(stamps) > 0)),
            'first_stamp_ns': int(stamps[0]) if len(stamps) else None,
            'last_stamp_ns': int(stamps[-1]) if len(stamps) else None,
            'rtf': sim_span / wall_span if wall_span > 0 else None,
        }


def main(argv: list[str] | None = None) -> None:
    """Run until ``--ticks`` are answered, write the report, then exit or stay (--stay)."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument('--ticks', type=int, default=300)
    parser.add_argument('--out', required=True, help='JSON report path')
    parser.add_argument('--stay', action='store_true', help='keep running after the report')
    args, ros_args = parser.parse_known_args(argv)
    rclpy.init(args=['hover_driver'] + ros_args)
    node = HoverDriver(args.ticks)
    try:
        while rclpy.ok() and len(node.answered) < args.ticks:
            rclpy.spin_once(node, timeout_sec=0.5)
        with open(args.out + '.tmp', 'w', encoding='utf-8') as stream:
            json.dump(node.report(), stream)
        # Renamed into place so a reader never sees half a report.
        os.replace(args.out + '.tmp', args.out)
        while args.stay and rclpy.ok():
            rclpy.spin_once(node, timeout_sec=0.5)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == '__main__':
    main()
