"""controller_node: the flight controller on ROS 2 (DESIGN sections 3-4), a shell around
:class:`ControllerCore`.

Each `imu` message runs one control tick and is answered on `actuators/cmd` stamped with
the IMU stamp (the plant's lockstep waits for exactly that). The tick's period is the IMU
stamp difference: the controller keeps its rate in sim time whatever the wall clock does
(`control_rate_hz` only serves the first tick, gaps, and the wall-clock jitter statistic).
Bad messages are rejected, counted and logged at most once a second. The 300 Hz messages
(odom, ee_wrench, imu, actuators/cmd) travel serialized (uav_tilt_common.cdr).
"""
import collections
import dataclasses
import functools
import json
import math
import time
from collections.abc import Callable, Collection, Iterable
from typing import Any, TypeVar

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import Pose, PoseStamped, WrenchStamped
from nav_msgs.msg import Odometry
from numpy.typing import NDArray
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.parameter import Parameter
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import Imu, JointState, PointCloud2
from std_msgs.msg import String
from std_srvs.srv import Trigger

from uav_tilt_common import cdr, modes, names, ros_msgs, ros_qos
from uav_tilt_common.config import nested, param
from uav_tilt_common.rate_limit import RejectCounter
from uav_tilt_common.ros_params import declare_config, run_node
from uav_tilt_common.ros_recorder import recorder_listens
from uav_tilt_common.vehicle import VehicleParams
from uav_tilt_control.controller_core import ControllerConfig, ControllerCore

# Loop statistics cover the last few seconds of ticks, recomputed at most this often (the
# percentiles cost a millisecond; status goes out at 10 Hz).
STATS_WINDOW = 3000
STATS_PERIOD_S = 1.0
# An IMU stamp gap outside (0, MAX_DT_S] is a restart or a stall: use the nominal period.
MAX_DT_S = 0.1
# A quaternion shorter than this is no rotation (all zeros, a default-made message); one
# longer is normalised.
MIN_QUATERNION_NORM = 0.5
# Setpoints are logged at most this often (wall clock), accepted and refused apart.
SETPOINT_LOG_PERIOD_S = 1.0

T = TypeVar('T')


@dataclasses.dataclass
class ControllerNodeConfig(ControllerConfig):
    """Parameters of controller_node: the core's, the vehicle model and the status rate."""

    vehicle: VehicleParams = nested(VehicleParams)
    status_rate_hz: float = param(10.0, lo=0.5, hi=50.0,
                                  doc='controller/status rate (wall clock)')
    control_rate_hz: float = param(
        300.0, lo=10.0, hi=5000.0,
        doc="the plant's IMU rate: the period of a tick without a usable previous stamp, "
            'and the wall-clock period the jitter is measured against in realtime')
    hold_until_recorded: bool = param(
        False, doc='answer the first tick and autostart once the recorder subscribes to '
        'controller/status and actuators/cmd, so that the recording has the whole mission; '
        f'at most {names.RECORDER_WAIT_S:.0f} s of wall time')


class ControllerNode(Node):
    """Thin shell: messages -> ControllerCore -> actuators/cmd and controller/status."""

    def __init__(self) -> None:
        super().__init__('controller',
                         parameter_overrides=[Parameter('use_sim_time', value=True)])
        self.cfg = declare_config(self, ControllerNodeConfig)
        self.core = ControllerCore(self.cfg.vehicle, self.cfg)
        q = ros_qos.CONTROL
        self.pub_cmd = ros_qos.quiet_publisher(self, JointState, names.ACTUATORS_CMD, q)
        self.pub_status = ros_qos.quiet_publisher(self, DiagnosticArray,
                                                  names.CONTROLLER_STATUS, ros_qos.STATUS)
        sub = ros_qos.quiet_subscription
        sub(self, Odometry, names.ODOM, self.on_odom, q, raw=True)
        sub(self, WrenchStamped, names.EE_WRENCH, self.on_wrench, q, raw=True)
        sub(self, PointCloud2, names.TARGET_CANDIDATES, self.on_candidates, q)
        sub(self, PointCloud2, names.VISION_PLANES, self.on_planes, q)
        sub(self, PoseStamped, names.SETPOINT_POSE, self.on_setpoint, q)
        if self.cfg.target_source == 'ground_truth':
            for target_id in ['', *self.cfg.site.target_ids]:
                sub(self, PoseStamped, names.ground_truth_target(target_id),
                    functools.partial(self.on_ground_truth, target_id=target_id),
                    ros_qos.LATCHED)
        # the plan and how its tasks went, JSON, re-sent when a task record changes
        self.pub_plan = self.create_publisher(String, names.CONTROLLER_PLAN, ros_qos.LATCHED)
        self.plan_version: int | None = None
        sub(self, Imu, names.IMU, self.on_imu, q, raw=True)
        for srv, method in ((names.SRV_TAKEOFF, self.core.takeoff),
                            (names.SRV_INSPECT, self.core.inspect),
                            (names.SRV_ABORT, self.core.abort),
                            (names.SRV_LAND, self.core.land)):
            self.create_service(Trigger, srv, self._trigger(srv, method))

        self.rejects = RejectCounter()
        self.nominal_dt_s = 1.0 / self.cfg.control_rate_hz
        self.status: dict[str, Any] = {}
        self.last_stamp_ns: int | None = None
        self.last_cmd: bytes | None = None
        self.saturated_ticks = 0
        self.ticks = 0
        self.wall_last: float | None = None
        self.periods_s: collections.deque[float] = collections.deque(maxlen=STATS_WINDOW)
        self.compute_s: collections.deque[float] = collections.deque(maxlen=STATS_WINDOW)
        # (wall time computed, values)
        self.loop_stats: tuple[float, dict[str, float]] = (-float('inf'), {})
        self.core.autostart_held = self.cfg.hold_until_recorded
        self.wall_t0 = time.monotonic()
        # Wall clock: status keeps coming when sim time stalls (the plant is gone).
        self.create_timer(1.0 / self.cfg.status_rate_hz, self.on_status,
                          clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.get_logger().info(f'controller up: target_source={self.cfg.target_source} '
                               f'contact_force={self.cfg.contact_force} N '
                               f'autostart={self.cfg.autostart!r} '
                               f'tasks={len(self.core.mission.plan)}')

    # --- inputs -------------------------------------------------------------------------
    def _reject(self, reason: str, detail: str) -> None:
        if self.rejects.reject(reason):
            self.get_logger().warn(f'rejected {detail}; {self.rejects.total} rejected so far')

    def _frame_ok(self, frame: str, frame_id: str, what: str) -> bool:
        if frame != frame_id:
            self._reject('frame', f'{what} in frame {frame!r}, not {frame_id!r}')
            return False
        return True

    def _finite(self, values: Iterable[float], what: str) -> bool:
        if not all(math.isfinite(v) for v in values):
            self._reject('non_finite', f'{what} with non-finite values')
            return False
        return True

    def _unit(self, q: NDArray[np.float64], what: str) -> NDArray[np.float64] | None:
        """Quaternion ``q`` (an array) normalised, itself when it is a unit one already, or
        None (rejected and counted) when it is no rotation."""
        # odometry comes at 300 Hz: plain floats (numpy's per-call cost is most of this)
        norm = math.sqrt(sum(v * v for v in q.tolist()))
        if norm < MIN_QUATERNION_NORM:
            self._reject('quaternion', f'{what} with a quaternion of norm {norm:.3g}')
            return None
        return q if abs(norm - 1.0) < 1e-9 else q / norm

    def _decoded(self, decode: Callable[[bytes], T], data: bytes, what: str) -> T | None:
        """``decode(data)``, or None (rejected) for a malformed message."""
        try:
            return decode(data)
        except ValueError as exc:
            self._reject('malformed', f'{what}: malformed message ({exc})')
            return None

    def on_odom(self, data: bytes) -> None:
        """Odometry map -> base_link (serialized)."""
        decoded = self._decoded(ros_msgs.state_from_odometry_cdr, data, 'odom')
        if decoded is None:
            return
        frame, child, state = decoded
        if not self._frame_ok(frame, names.FRAME_MAP, 'odom'):
            return
        if child != names.FRAME_BASE:
            self._reject('frame', f'odom with child frame {child!r}')
            return
        if not self._finite([*state.p_map.tolist(), *state.q_map_base.tolist(),
                             *state.v_map.tolist()], 'odom'):
            return
        q = self._unit(state.q_map_base, 'odom')
        if q is None:
            return
        if q is not state.q_map_base:
            state = dataclasses.replace(state, q_map_base=q)
        last = self.core.odometry
        if last is not None and state.t_s < last.t_s:
            # the pose history and the estimator's look-ups run forward in time
            self._reject('stamp', f'odom stamped {state.t_s:.4f} s, before the last '
                                  f'{last.t_s:.4f} s')
            return
        self.core.on_odometry(state)

    def on_wrench(self, data: bytes) -> None:
        """F/T sensor at the tool, ee_link (serialized)."""
        decoded = self._decoded(cdr.decode_wrench, data, 'ee_wrench')
        if decoded is None:
            return
        _, frame, force, torque = decoded
        if self._frame_ok(frame, names.FRAME_EE, 'ee_wrench') and self._finite(
                force + torque, 'ee_wrench'):
            self.core.on_wrench(force, torque)

    def on_candidates(self, msg: PointCloud2) -> None:
        """Vision's target candidates of one frame, camera optical frame (none: no target)."""
        candidates = self._camera_cloud(msg, names.TARGET_CANDIDATES, ros_msgs.candidates_of_msg)
        if candidates is not None:
            self.core.on_target_candidates(ros_msgs.from_stamp(msg.header.stamp), candidates)

    def on_planes(self, msg: PointCloud2) -> None:
        """The planes vision saw in one frame, camera optical frame (for the search)."""
        planes = self._camera_cloud(msg, names.VISION_PLANES, ros_msgs.planes_of_msg)
        if planes is not None:
            self.core.on_planes(ros_msgs.from_stamp(msg.header.stamp), planes)

    def _camera_cloud(self, msg: PointCloud2, topic: str, decode: Callable[[PointCloud2], T]
                      ) -> T | None:
        """``decode(msg)`` of a PointCloud2 of vision's, or None (rejected and counted) when
        it is not in the camera optical frame or not laid out as ``decode`` expects."""
        if not self._frame_ok(msg.header.frame_id, names.FRAME_CAMERA, topic):
            return None
        try:
            return decode(msg)
        except ValueError as err:
            self._reject('layout', f'{topic}: {err}')
            return None

    def on_ground_truth(self, msg: PoseStamped, target_id: str = '') -> None:
        """Evaluation mode: the true pose in map of target ``target_id``."""
        p_map, q_raw = _pose_arrays(msg.pose)
        topic = names.ground_truth_target(target_id)
        if not (self._frame_ok(msg.header.frame_id, names.FRAME_MAP, topic) and self._finite(
                np.concatenate([p_map, q_raw]), topic)):
            return
        q_map_t = self._unit(q_raw, topic)
        if q_map_t is not None:
            self.core.on_ground_truth_target(p_map, q_map_t, target_id)

    def on_setpoint(self, msg: PoseStamped) -> None:
        """A hover point and heading in map (accepted in HOVER)."""
        p_map, q_raw = _pose_arrays(msg.pose)
        if not (self._frame_ok(msg.header.frame_id, names.FRAME_MAP, 'setpoint/pose')
                and self._finite(np.concatenate([p_map, q_raw]), 'setpoint/pose')):
            return
        q = self._unit(q_raw, 'setpoint/pose')
        if q is None:
            return
        yaw = Rotation.from_quat(q).as_euler('ZYX')[0]
        ok, message = self.core.set_setpoint(p_map, yaw)
        line = f'setpoint {np.round(p_map, 3).tolist()}: {message}'
        if ok:
            self.get_logger().info(line, throttle_duration_sec=SETPOINT_LOG_PERIOD_S)
        else:
            self.get_logger().warn(line, throttle_duration_sec=SETPOINT_LOG_PERIOD_S)

    def _trigger(self, name: str, method: Callable[[], tuple[bool, str]]
                 ) -> Callable[[Any, Any], Any]:
        def callback(request: Any, response: Any) -> Any:
            response.success, response.message = method()
            self.get_logger().info(f'{name}: {response.message}')
            return response
        return callback

    # --- the 300 Hz loop ----------------------------------------------------------------
    def on_imu(self, data: bytes) -> None:
        """One control tick, answered with actuators/cmd stamped like the IMU message."""
        decoded = self._decoded(cdr.decode_imu, data, 'imu')
        if decoded is None:
            return
        stamp_ns, frame, _, gyro, accel = decoded
        if not (self._frame_ok(frame, names.FRAME_BASE, 'imu')
                and self._finite([*gyro, *accel], 'imu')):
            return
        if self.core.autostart_held:
            # hold_until_recorded: unanswered, the lockstep plant sends the tick again
            return
        if stamp_ns == self.last_stamp_ns:
            # the plant re-sent a tick it is still waiting on: answer it again
            self.pub_cmd.publish(self.last_cmd)
            return
        wall = time.perf_counter()
        if self.wall_last is not None:
            self.periods_s.append(wall - self.wall_last)
        self.wall_last = wall
        dt_s = self.nominal_dt_s
        if self.last_stamp_ns is not None and 0 < stamp_ns - self.last_stamp_ns <= MAX_DT_S * 1e9:
            dt_s = (stamp_ns - self.last_stamp_ns) * 1e-9
        self.last_stamp_ns = stamp_ns
        command, self.status = self.core.tick(stamp_ns * 1e-9, gyro, dt_s, accel)
        self.last_cmd = ros_msgs.actuator_cdr(command.thrusts_n,
                                              (command.alpha_rad, command.beta_rad), stamp_ns)
        self.pub_cmd.publish(self.last_cmd)
        self.compute_s.append(time.perf_counter() - wall)
        self.ticks += 1
        self.saturated_ticks += int(self.status['saturated'])

    # --- status -------------------------------------------------------------------------
    def _release_autostart(self) -> None:
        """hold_until_recorded: answer ticks and let the autostart go once the recorder
        listens to controller/status and actuators/cmd (its subscriptions matched; other
        subscribers, the plant, a probe or a viewer, do not count), or the wait is over."""
        if all(recorder_listens(self, pub) for pub in (self.pub_status, self.pub_cmd)):
            self.core.autostart_held = False
        elif time.monotonic() - self.wall_t0 >= names.RECORDER_WAIT_S:
            self.core.autostart_held = False
            self.get_logger().warn(f'hold_until_recorded: no recorder on controller/status '
                                   f'and actuators/cmd after {names.RECORDER_WAIT_S:.0f} s; '
                                   f'starting anyway')

    def on_status(self) -> None:
        """controller/status: mode, mission, saturation, rejected inputs, loop statistics;
        and controller/plan when a task record changed."""
        if self.core.autostart_held:
            self._release_autostart()
        if self.core.mission.plan_version != self.plan_version:
            self.plan_version = self.core.mission.plan_version
            self.pub_plan.publish(String(data=json.dumps(self.core.plan_report())))
        values = dict(self.status) or dict(mode=modes.WAITING_FOR_SENSORS)
        now = time.monotonic()
        values.update(ticks=self.ticks, saturated_ticks=self.saturated_ticks,
                      target_source=self.cfg.target_source,
                      rejected_inputs=self.rejects.total, wall_time_s=now - self.wall_t0)
        if now - self.loop_stats[0] >= STATS_PERIOD_S:
            self.loop_stats = (now, _loop_stats(self.periods_s, self.compute_s,
                                                self.nominal_dt_s))
        values.update(self.loop_stats[1])
        values.update({f'rejected_{k}': v for k, v in self.rejects.counts.items()})
        level = DiagnosticStatus.WARN if values.get('failsafe_reason') else DiagnosticStatus.OK
        self.pub_status.publish(ros_msgs.diagnostics_msg(
            'controller', values, ros_msgs.to_stamp(values.get('t_s', 0.0)), level,
            values.get('failsafe_reason') or 'ok'))


def _pose_arrays(pose: Pose) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    o = pose.orientation
    return ros_msgs.vector_of(pose.position), np.array([o.x, o.y, o.z, o.w])


def _loop_stats(periods_s: Collection[float], compute_s: Collection[float],
                nominal_dt_s: float) -> dict[str, float]:
    """Loop rate and wall-clock period jitter of the IMU callbacks, and compute time."""
    if len(periods_s) < 2:
        return {}
    periods = np.fromiter(periods_s, float, len(periods_s))
    compute_us = np.fromiter(compute_s, float, len(compute_s)) * 1e6
    jitter_ms = np.abs(periods - nominal_dt_s) * 1e3
    compute_p50, compute_p99 = np.percentile(compute_us, [50, 99])
    return dict(loop_rate_hz=1.0 / periods.mean(),
                loop_period_ms_p50=float(np.median(periods)) * 1e3,
                loop_jitter_ms_p99=float(np.percentile(jitter_ms, 99)),
                compute_us_p50=float(compute_p50),
                compute_us_p99=float(compute_p99))


def main(args: list[str] | None = None) -> int:
    """Entry point of the controller_node executable."""
    return run_node(ControllerNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
