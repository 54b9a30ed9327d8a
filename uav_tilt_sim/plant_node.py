"""plant_node: the PyBullet plant on ROS 2 (DESIGN sections 3-4).

Owns time: each 300 Hz tick it publishes /clock and the control-path sensors stamped t_k.
In lockstep it steps past t_k only once `actuators/cmd` stamped t_k has arrived, or after
`lockstep_timeout_s` of wall time, when it applies the failsafe and free-runs until
commands come back. In realtime, sim time follows the wall clock and late commands are
counted, never waited for.
"""
import dataclasses
import functools
import time

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, WrenchStamped
from nav_msgs.msg import Odometry
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import CameraInfo, Image, Imu, JointState

from uav_tilt_common import names, ros_msgs, ros_qos
from uav_tilt_common.config import param
from uav_tilt_common.rate_limit import RejectCounter
from uav_tilt_common.ros_params import declare_config, run_node
from uav_tilt_common.state import ActuatorCommand
from uav_tilt_sim.command_check import check_command
from uav_tilt_sim.plant import Plant, PlantCoreConfig
from uav_tilt_sim.scenario import load_scenario

# Before the first command the current tick is re-sent this often (late-joining controllers).
RESEND_PERIOD_S = 0.25
# Free-running ticks one timer callback may step to catch up with the wall clock.
MAX_CATCH_UP = 10


@dataclasses.dataclass
class PlantNodeConfig(PlantCoreConfig):
    """Parameters of plant_node (DESIGN section 7 names are stable)."""

    scenario_file: str = param('')
    mode: str = param('lockstep', choices=('lockstep', 'realtime'))
    rtf: float = param(0.0, lo=0.0, hi=1000.0)
    lockstep_timeout_s: float = param(0.5, lo=0.005, hi=60.0)
    timeout_failsafe: str = param('cut_thrust', choices=('cut_thrust', 'hold_last'))
    camera_enabled: bool = param(True)
    status_rate_hz: float = param(2.0, lo=0.1, hi=50.0)


class PlantNode(Node):
    """Thin shell around :class:`Plant`: parameters, topics, lockstep."""

    def __init__(self):
        super().__init__('plant')
        self.cfg = declare_config(self, PlantNodeConfig)
        scenario = load_scenario(self.cfg.scenario_file or None)
        self.plant = Plant(self.cfg, scenario, warn=self.get_logger().warn)
        self.camera_every = max(1, int(round(self.cfg.control_hz / self.cfg.camera.rate_hz)))
        q = ros_qos.CONTROL
        quiet = functools.partial(ros_qos.quiet_publisher, self)
        self.pub_clock = quiet(Clock, names.CLOCK, ros_qos.CLOCK)
        self.pub_imu = quiet(Imu, names.IMU, q)
        self.pub_odom = quiet(Odometry, names.ODOM, q)
        self.pub_wrench = quiet(WrenchStamped, names.EE_WRENCH, q)
        self.pub_act = quiet(JointState, names.ACTUATORS_STATE, q)
        self.pub_gt_odom = quiet(Odometry, names.GROUND_TRUTH_ODOM, q)
        # latched: the first target (compatibility) and each target with an id
        self.pub_gt_targets = {
            target_id: self.create_publisher(PoseStamped, names.ground_truth_target(target_id),
                                             ros_qos.LATCHED)
            for target_id in ['', *self.plant.world.targets]}
        self.pub_rgb = self.create_publisher(Image, names.CAMERA_COLOR, ros_qos.CAMERA_PUB)
        self.pub_depth = self.create_publisher(Image, names.CAMERA_DEPTH, ros_qos.CAMERA_PUB)
        self.pub_info = self.create_publisher(CameraInfo, names.CAMERA_INFO,
                                              ros_qos.CAMERA_PUB)
        self.pub_status = self.create_publisher(DiagnosticArray, names.PLANT_STATUS,
                                                ros_qos.STATUS)
        ros_qos.quiet_subscription(self, JointState, names.ACTUATORS_CMD, self.on_command, q)

        self.rejects = RejectCounter()
        self.stats = dict(lockstep_waits=0, lockstep_timeouts=0, late_commands=0,
                          clamped_commands=0, commands=0)
        self.waiting = False            # lockstep: waiting for the command of this tick
        self.synced = False             # lockstep: a command has arrived since the last timeout
        self.ever_commanded = False
        self.wait_started = time.monotonic()
        self.wall_start = time.monotonic()
        self.sim_start = 0.0
        self.last_status = (time.monotonic(), 0.0)
        self.in_contact = False

        self._publish_target()
        self._publish_tick()
        period = self.plant.dt_tick / (self.cfg.rtf if self.cfg.rtf > 0 else 1.0)
        self.tick_timer = self.create_timer(period, self.on_free_tick)
        if self.cfg.mode == 'lockstep':
            self.tick_timer.cancel()
            self.create_timer(0.05, self.on_watchdog)
        self.create_timer(1.0 / self.cfg.status_rate_hz, self.on_status)
        self.get_logger().info(
            f'plant up: mode={self.cfg.mode} rtf={self.cfg.rtf} '
            f'scenario={self.cfg.scenario_file or "default"} camera={self.cfg.camera_enabled}')

    # --- inputs -------------------------------------------------------------------------
    def on_command(self, msg):
        """Validate a command; in lockstep, the command of the current tick steps the plant."""
        result = check_command(msg.name, msg.effort, msg.position, self.plant.vehicle)
        if result.command is None:
            if self.rejects.reject(result.kind):
                self.get_logger().warn(f'rejected actuator command ({result.detail}); '
                                       f'{self.rejects.total} rejected so far')
            return
        self.stats['commands'] += 1
        self.stats['clamped_commands'] += int(result.clamped)
        self.plant.command = result.command
        self.ever_commanded = True
        stamp_tick = round(ros_msgs.from_stamp(msg.header.stamp) / self.plant.dt_tick)
        if self.cfg.mode == 'realtime':
            # The answer to tick k normally lands during tick k+1; older is late.
            if stamp_tick < self.plant.tick - 1:
                self.stats['late_commands'] += 1
            return
        if stamp_tick != self.plant.tick:
            self.stats['late_commands'] += 1
            return
        if not self.synced:
            self.synced = True
            self.tick_timer.cancel()
            self.wall_start, self.sim_start = time.monotonic(), self.plant.t_s
            self.get_logger().info(f'lockstep synchronised at t={self.plant.t_s:.3f} s')
        self.waiting = False
        self._advance()

    def on_watchdog(self):
        """Lockstep wall-clock guard: re-send before the first command, time out after."""
        if not self.waiting:
            return
        waited = time.monotonic() - self.wait_started
        if not self.ever_commanded:
            if waited > RESEND_PERIOD_S:
                self.wait_started = time.monotonic()
                self._publish_sensors()
            return
        if waited > self.cfg.lockstep_timeout_s:
            self.stats['lockstep_timeouts'] += 1
            self.get_logger().warn(
                f'no actuator command for t={self.plant.t_s:.4f} s within '
                f'{self.cfg.lockstep_timeout_s} s: failsafe {self.cfg.timeout_failsafe}, '
                f'free-running until commands return')
            self.waiting = False
            self.synced = False
            self._apply_failsafe()
            self.wall_start, self.sim_start = time.monotonic(), self.plant.t_s
            self.tick_timer.reset()

    def on_free_tick(self):
        """Realtime mode, or lockstep after a timeout: sim time follows the wall clock.

        Steps as many ticks as are due (at most MAX_CATCH_UP per call), so late timer
        callbacks on a busy machine do not slow simulated time down.
        """
        if self.cfg.mode == 'lockstep':
            self._apply_failsafe()
        rate = self.cfg.rtf if self.cfg.rtf > 0 else 1.0
        due = self.sim_start + (time.monotonic() - self.wall_start) * rate
        for _ in range(MAX_CATCH_UP):
            if self.plant.t_s + self.plant.dt_tick > due + 1e-9:
                break
            self.plant.step()
            self._publish_tick()

    # --- stepping -----------------------------------------------------------------------
    def _apply_failsafe(self):
        if self.cfg.timeout_failsafe == 'cut_thrust':
            self.plant.command = ActuatorCommand(np.zeros(4), self.plant.command.alpha_rad,
                                                 self.plant.command.beta_rad)

    def _advance(self):
        """Step one tick and publish it, paced to the target real-time factor."""
        self.plant.step()
        if self.cfg.rtf > 0:
            due = self.wall_start + (self.plant.t_s - self.sim_start) / self.cfg.rtf
            delay = due - time.monotonic()
            if delay > 0:
                time.sleep(delay)
        self._publish_tick()

    def _publish_tick(self):
        self.pub_clock.publish(Clock(clock=ros_msgs.to_stamp(self.plant.t_s)))
        self._publish_sensors()
        if self.cfg.camera_enabled and self.plant.tick % self.camera_every == 0:
            self._publish_camera()
        if self.cfg.mode == 'lockstep' and self.synced:
            self.stats['lockstep_waits'] += 1
        self.waiting = self.cfg.mode == 'lockstep' and (self.synced or not self.ever_commanded)
        self.wait_started = time.monotonic()

    def _publish_sensors(self):
        s = self.plant.read_sensors()
        stamp = ros_msgs.to_stamp(s.t_s)
        # The controller runs on imu, so everything it reads goes out before it.
        self.pub_odom.publish(ros_msgs.odometry_msg(s.odom, stamp))
        self.pub_wrench.publish(ros_msgs.wrench_msg(s.ee_force_n, s.ee_torque_nm, stamp))
        # Monitoring-only topics cost the 300 Hz loop nothing when nobody listens.
        if self.pub_act.get_subscription_count():
            self.pub_act.publish(ros_msgs.actuator_msg(s.thrusts_n, s.tilts_rad, stamp))
        if self.pub_gt_odom.get_subscription_count():
            self.pub_gt_odom.publish(ros_msgs.odometry_msg(self.plant.state(), stamp))
        self.pub_imu.publish(ros_msgs.imu_msg(s.gyro_rad_s, s.accel_m_s2, s.q_imu, stamp))
        self.in_contact = s.in_contact

    def _publish_camera(self):
        rgb, depth, _ = self.plant.render()
        stamp = ros_msgs.to_stamp(self.plant.t_s)
        self.pub_info.publish(ros_msgs.camera_info_msg(self.cfg.camera, stamp))
        self.pub_rgb.publish(ros_msgs.image_msg(rgb, stamp))
        self.pub_depth.publish(ros_msgs.image_msg(depth, stamp))

    def _publish_target(self):
        world = self.plant.world
        if world.target_poi_map is None:
            return
        poses = {'': (world.target_poi_map, world.R_map_target), **world.targets}
        for target_id, (poi_map, R_map_target) in poses.items():
            msg = PoseStamped()
            msg.header.stamp = ros_msgs.to_stamp(0.0)
            msg.header.frame_id = names.FRAME_MAP
            p, q = msg.pose.position, msg.pose.orientation
            p.x, p.y, p.z = (float(v) for v in poi_map)
            q.x, q.y, q.z, q.w = (float(v) for v in Rotation.from_matrix(R_map_target).as_quat())
            self.pub_gt_targets[target_id].publish(msg)

    def on_status(self):
        """plant/status: real-time factor, lockstep counters, rejected commands, contact."""
        now = time.monotonic()
        last_wall, last_sim = self.last_status
        rtf = (self.plant.t_s - last_sim) / max(now - last_wall, 1e-9)
        self.last_status = (now, self.plant.t_s)
        values = dict(mode=self.cfg.mode, sim_time_s=self.plant.t_s, tick=self.plant.tick,
                      rtf=rtf, synced=self.synced, rejected_commands=self.rejects.total,
                      in_contact=getattr(self, 'in_contact', False), **self.stats)
        values.update({f'rejected_{k}': v for k, v in self.rejects.counts.items()})
        self.pub_status.publish(ros_msgs.diagnostics_msg(
            'plant', values, ros_msgs.to_stamp(self.plant.t_s)))

    def destroy_node(self):
        """Release the physics server with the node."""
        self.plant.close()
        return super().destroy_node()


def main(args=None):
    """Entry point of the plant_node executable."""
    return run_node(PlantNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
