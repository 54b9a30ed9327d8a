"""plant_node: the PyBullet plant on ROS 2 (DESIGN sections 3-4).

Owns time: each 300 Hz tick it publishes the control-path sensors and /clock stamped t_k,
then the camera frame when one is due (so that rendering overlaps the controller's tick; in
realtime the frame is drawn by a process of its own, :mod:`uav_tilt_sim.camera_process`, and
published once drawn, so that it does not delay the ticks that follow).
In lockstep it steps past t_k only once `actuators/cmd` stamped t_k has arrived, sending
t_k again every RESEND_PERIOD_S while it waits, or after `lockstep_timeout_s` of wall time,
when it applies the failsafe and free-runs until commands come back. In realtime, sim time
follows the wall clock and late commands are counted, never waited for; when the host
cannot keep up, the ticks it is behind by more than MAX_CATCH_UP are dropped (sim time
slips), and plant/status reports the achieved real-time factor, the late commands and the
dropped ticks, with a warning at most every REALTIME_WARN_PERIOD_S. The 300 Hz messages
travel serialized (uav_tilt_common.cdr).
"""
import dataclasses
import functools
import json
import math
import time

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PoseStamped, WrenchStamped
from nav_msgs.msg import Odometry
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import CameraInfo, Image, Imu, JointState
from std_msgs.msg import String

from uav_tilt_common import cdr, names, ros_msgs, ros_qos
from uav_tilt_common.config import ConfigError, param
from uav_tilt_common.rate_limit import RejectCounter
from uav_tilt_common.ros_params import declare_config, run_node
from uav_tilt_common.ros_recorder import recorder_listens, recorder_subscribes
from uav_tilt_common.state import ActuatorCommand
from uav_tilt_sim.camera_process import CameraProcess
from uav_tilt_sim.command_check import check_command
from uav_tilt_sim.plant import Plant, PlantCoreConfig
from uav_tilt_sim.scenario import load_scenario
from uav_tilt_sim.world_json import world_json

# A tick unanswered this long is sent again, and again as often: before the first command for
# a controller that joins late, after it for a message lost to a stalled process.
RESEND_PERIOD_S = 0.25
# Free-running ticks one timer callback may step to catch up with the wall clock; a larger
# backlog is dropped: a burst of them would come too fast for the controller to answer.
MAX_CATCH_UP = 10
# Realtime: a warning when the host does not keep up, at most this often.
REALTIME_WARN_PERIOD_S = 5.0
# Realtime: achieved real-time factor below this share of the target counts as not keeping up.
KEEP_UP_SHARE = 0.98


@dataclasses.dataclass
class PlantNodeConfig(PlantCoreConfig):
    """Parameters of plant_node (DESIGN section 7 names are stable)."""

    scenario_file: str = param('', doc='scenario YAML; empty: config/scenarios/default.yaml')
    mode: str = param('lockstep', choices=('lockstep', 'realtime'),
                      doc='lockstep: wait for each tick\'s command; realtime: follow the clock')
    rtf: float = param(0.0, lo=0.0, hi=1000.0, doc='target real-time factor, 0 = as fast '
                       'as possible')
    # A stalled controller only slows a lockstep run down; the failsafe is for one that is
    # gone, so the wait outlasts what a loaded machine stalls a process for (seconds).
    lockstep_timeout_s: float = param(5.0, lo=0.005, hi=60.0,
                                      doc='wall time to wait for a command before failsafe')
    timeout_failsafe: str = param('cut_thrust', choices=('cut_thrust', 'hold_last'),
                                  doc='what a lockstep timeout applies')
    camera_enabled: bool = param(True, doc='render and publish the RGB-D camera (a frame is '
                                 'drawn only while a camera image topic has a subscriber)')
    camera_process: bool = param(
        True, doc='realtime: draw the camera in a process of its own, so that a frame (2-3 ms '
        'on a CPU) does not delay the tick it belongs to; lockstep draws it on the tick')
    status_rate_hz: float = param(2.0, lo=0.1, hi=50.0, doc='plant/status rate (wall clock)')
    hold_until_recorded: bool = param(
        False, doc='lockstep: keep the first tick until the recorder\'s subscription to every '
        'topic a tick publishes is matched, at most 30 s of wall time')
    summary_file: str = param('', doc="one JSON line with the run's timing, written at exit")


# Parameters a `ros2 param set` changes while the plant runs; the others are read-only.
DYNAMIC = ('rtf', 'lockstep_timeout_s', 'timeout_failsafe', 'camera_enabled')


class PlantNode(Node):
    """Thin shell around :class:`Plant`: parameters, topics, lockstep."""

    def __init__(self):
        super().__init__('plant')
        self.cfg = declare_config(self, PlantNodeConfig, DYNAMIC, self._on_parameters)
        if self.cfg.summary_file:
            # made now, so that a path it cannot be written to stops the start, not the exit
            try:
                open(self.cfg.summary_file, 'w', encoding='utf-8').close()
            except OSError as err:
                raise ConfigError(f"parameter 'summary_file' = {self.cfg.summary_file!r}: "
                                  f"{err.strerror}") from None
        scenario = load_scenario(self.cfg.scenario_file or None)
        self.plant = Plant(self.cfg, scenario, warn=self.get_logger().warn)
        self.camera_every = max(1, int(round(self.cfg.control_hz / self.cfg.camera.rate_hz)))
        self.camera = None      # the camera's process, where it draws the frames
        if self.cfg.mode == 'realtime' and self.cfg.camera_enabled and self.cfg.camera_process:
            self._start_camera_process(scenario)
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
        self.pub_scenario = self.create_publisher(String, names.PLANT_SCENARIO,
                                                  ros_qos.LATCHED)
        self.pub_scenario.publish(String(data=world_json(scenario, self.plant.world)))
        ros_qos.quiet_subscription(self, JointState, names.ACTUATORS_CMD, self.on_command, q,
                                   raw=True)

        self.rejects = RejectCounter()
        self.stats = dict(lockstep_waits=0, lockstep_timeouts=0, resent_ticks=0,
                          late_commands=0, repeated_commands=0, clamped_commands=0,
                          commands=0, dropped_ticks=0, skipped_frames=0,
                          unwatched_frames=0)
        self.answered_tick = -1     # lockstep: the last tick a command stepped
        self.waiting = False            # lockstep: waiting for the command of this tick
        self.synced = False             # lockstep: a command has arrived since the last timeout
        self.ever_commanded = False
        self.wait_started = self.resent_at = time.monotonic()
        self.wall_start = time.monotonic()
        self.sim_start = 0.0
        self.last_status = (time.monotonic(), 0.0)
        self.wall_t0 = time.monotonic()
        self.holding = self.cfg.hold_until_recorded and self.cfg.mode == 'lockstep'
        self.held_command = None        # the first command, while holding
        self.in_contact = False
        # run statistics from the first command (lockstep) or the first tick (realtime)
        self.run_start = None           # (wall, sim)
        self.last_warning = (time.monotonic(), 0.0, 0, 0)  # (wall, sim, late, dropped)

        self._publish_target()
        self._publish_tick()
        self.tick_timer = self.create_timer(self._free_tick_period_s(), self.on_free_tick)
        self.status_due = time.monotonic()
        if self.cfg.mode == 'lockstep':
            # realtime sends its status from the tick loop (a timer starves under overload)
            self.tick_timer.cancel()
            self.create_timer(0.05, self.on_watchdog)
            self.create_timer(1.0 / self.cfg.status_rate_hz, self.on_status)
        self.get_logger().info(
            f'plant up: mode={self.cfg.mode} rtf={self.target_rtf} '
            f'scenario={self.cfg.scenario_file or "default"} camera={self.cfg.camera_enabled}')

    def _free_rtf(self):
        """The pace of ticks no command drives (realtime mode, and lockstep's free run after
        a timeout): ``rtf``, or the wall clock for 0, where "as fast as possible" has no
        meaning."""
        return self.cfg.rtf if self.cfg.rtf > 0 else 1.0

    @property
    def target_rtf(self):
        """The real-time factor plant/status reports as the target: the free pace in
        realtime mode, ``rtf`` in lockstep (0: not paced)."""
        return self._free_rtf() if self.cfg.mode == 'realtime' else self.cfg.rtf

    def _free_tick_period_s(self):
        return self.plant.dt_tick / self._free_rtf()

    def _on_parameters(self, changed):
        """A new rtf paces from now on: sim and wall time restart their common origin."""
        if 'rtf' in changed:
            self.wall_start, self.sim_start = time.monotonic(), self.plant.t_s
            self.tick_timer.timer_period_ns = int(self._free_tick_period_s() * 1e9)

    # --- inputs -------------------------------------------------------------------------
    def on_command(self, data):
        """Validate a command (serialized JointState); in lockstep, the command of the
        current tick steps the plant."""
        try:
            stamp_ns, _, joint_names, position, _, effort = cdr.decode_joint_state(data)
        except ValueError as exc:
            self._reject_command('malformed', f'malformed message ({exc})')
            return
        result = check_command(joint_names, effort, position, self.plant.vehicle)
        if result.command is None:
            self._reject_command(result.kind, result.detail)
            return
        if not self.ever_commanded and not self._recorded():
            self.held_command = data    # applied by the watchdog once the recorder listens
            return
        stamp_tick = round(stamp_ns * 1e-9 / self.plant.dt_tick)
        if self.cfg.mode == 'lockstep' and self.synced and stamp_tick != self.plant.tick:
            # not applied: the tick it answers has been stepped. A second answer to a tick
            # sent again (its first answer was slow, not lost) is no late command.
            self.stats['repeated_commands' if stamp_tick == self.answered_tick
                       else 'late_commands'] += 1
            return
        self.stats['commands'] += 1
        self.stats['clamped_commands'] += int(result.clamped)
        self.plant.command = result.command
        if not self.ever_commanded and self.cfg.mode == 'lockstep':
            self.run_start = (time.monotonic(), self.plant.t_s)
        self.ever_commanded = True
        if self.cfg.mode == 'realtime':
            # The answer to tick k normally lands during tick k+1; older is late.
            if stamp_tick < self.plant.tick - 1:
                self.stats['late_commands'] += 1
            return
        if stamp_tick != self.plant.tick:
            self.stats['late_commands'] += 1
            return
        self.answered_tick = stamp_tick
        if not self.synced:
            self.synced = True
            self.tick_timer.cancel()
            self.wall_start, self.sim_start = time.monotonic(), self.plant.t_s
            self.get_logger().info(f'lockstep synchronised at t={self.plant.t_s:.3f} s')
        self.waiting = False
        self._advance()

    def _recorded(self):
        """hold_until_recorded: whether the recorder listens to every topic a tick
        publishes, or the wait is over."""
        if not self.holding:
            return True
        pubs = [self.pub_clock, self.pub_imu, self.pub_odom, self.pub_wrench, self.pub_act,
                self.pub_gt_odom]
        if self.cfg.camera_enabled:
            # the images only where the recorder takes them (its `images` profile: none)
            pubs += [self.pub_info] + [pub for pub in (self.pub_rgb, self.pub_depth)
                                       if recorder_subscribes(self, pub)]
        if all(recorder_listens(self, pub) for pub in pubs):
            return True
        if time.monotonic() - self.wall_t0 < names.RECORDER_WAIT_S:
            return False
        self.get_logger().warn(f'hold_until_recorded: not every topic has a subscriber after '
                               f'{names.RECORDER_WAIT_S:.0f} s; starting anyway')
        self.holding = False
        return True

    def _reject_command(self, kind, detail):
        if self.rejects.reject(kind):
            self.get_logger().warn(f'rejected actuator command ({detail}); '
                                   f'{self.rejects.total} rejected so far')

    def on_watchdog(self):
        """Lockstep wall-clock guard: re-send before the first command, time out after."""
        if self.held_command is not None and self._recorded():
            msg, self.held_command = self.held_command, None
            self.on_command(msg)
        if not self.waiting:
            return
        now = time.monotonic()
        waited = now - self.wait_started
        if not self.ever_commanded:
            if waited > RESEND_PERIOD_S:
                self.wait_started = now
                self._publish_sensors()
            return
        if now - self.resent_at > RESEND_PERIOD_S and waited <= self.cfg.lockstep_timeout_s:
            # a tick or its answer lost on the way (a stalled process's full buffers): DDS
            # would repair it only at the writer's next heartbeat, seconds on
            self.resent_at = now
            self.stats['resent_ticks'] += 1
            self._publish_sensors()
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

        Steps the ticks that are due, as many as MAX_CATCH_UP per call, so late timer
        callbacks on a busy machine do not slow simulated time down; a longer backlog is
        dropped (counted) by moving the wall-clock anchor.
        """
        if self.cfg.mode == 'lockstep':
            self._apply_failsafe()
        elif self.run_start is None:
            # the clock starts with the first tick, not with the node's start-up
            self.run_start = (time.monotonic(), self.plant.t_s)
            self.wall_start, self.sim_start = self.run_start
        self._publish_drawn_frame()
        rate = self._free_rtf()
        dt = self.plant.dt_tick
        now = time.monotonic()
        due = self.sim_start + (now - self.wall_start) * rate
        backlog = math.floor((due - self.plant.t_s) / dt + 1e-9)
        if backlog > MAX_CATCH_UP:
            self.stats['dropped_ticks'] += backlog - MAX_CATCH_UP
            self.sim_start, self.wall_start = self.plant.t_s, now - MAX_CATCH_UP * dt / rate
            backlog = MAX_CATCH_UP
        for _ in range(backlog):
            self.plant.step()
            self._publish_tick()
        if self.cfg.mode == 'realtime' and now >= self.status_due:
            # from here, not from a timer of its own: on a host that cannot keep up, rclpy's
            # timer events for the ticks queue up faster than they are served, and the status
            # timer's came later and later (seconds), just when the status matters
            self.on_status()

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
        self._publish_sensors()
        self.pub_clock.publish(ros_msgs.clock_cdr(self.plant.t_s))
        if self.cfg.mode == 'lockstep' and self.synced:
            self.stats['lockstep_waits'] += 1
        self.waiting = self.cfg.mode == 'lockstep' and (self.synced or not self.ever_commanded)
        self.wait_started = self.resent_at = time.monotonic()
        if self.cfg.camera_enabled and self.plant.tick % self.camera_every == 0:
            if not self._camera_wanted():
                # drawn for no one: the depth noise goes on as if it had been, so that the
                # frames a subscriber gets later are the ones it would have got
                if self.camera is None:
                    self.plant.skip_frame()
                self.stats['unwatched_frames'] += 1
            elif self.camera is None:
                rgb, depth, _ = self.plant.render()
                self._publish_frame(self.plant.t_s, rgb, depth)
            elif not self.camera.request(self.plant.t_s, self.plant.render_state()):
                self.stats['skipped_frames'] += 1   # the last one is still being drawn

    def _camera_wanted(self):
        """Whether a camera image topic has a subscriber (vision, here or on another host, a
        recorder that takes images, a viewer): a frame no one takes is not drawn."""
        return bool(self.pub_rgb.get_subscription_count()
                    or self.pub_depth.get_subscription_count())

    def _start_camera_process(self, scenario):
        try:
            self.camera = CameraProcess(self.cfg, scenario)
        except RuntimeError as err:
            self.get_logger().warn(f'{err}: the camera is drawn on the tick')
            return
        for line in self.camera.warnings:
            self.get_logger().warn(line)

    def _publish_drawn_frame(self):
        """Publish the frame the camera's process has drawn, if it has."""
        if self.camera is None:
            return
        try:
            frame = self.camera.frame()
        except RuntimeError as err:
            self.get_logger().error(f'{err}: the camera is drawn on the tick from now on')
            self.camera.close()
            self.camera = None
            return
        if frame is not None:
            self._publish_frame(*frame)

    def _publish_sensors(self):
        s = self.plant.read_sensors()
        stamp_ns = round(s.t_s * 1e9)
        # The controller runs on imu, so everything it reads goes out before it.
        self.pub_odom.publish(ros_msgs.odometry_cdr(s.odom, stamp_ns))
        self.pub_wrench.publish(ros_msgs.wrench_cdr(s.ee_force_n, s.ee_torque_nm, stamp_ns))
        # Monitoring-only topics cost the 300 Hz loop nothing when nobody listens.
        if self.pub_act.get_subscription_count():
            self.pub_act.publish(ros_msgs.actuator_cdr(s.thrusts_n, s.tilts_rad, stamp_ns))
        if self.pub_gt_odom.get_subscription_count():
            self.pub_gt_odom.publish(ros_msgs.odometry_cdr(self.plant.state(), stamp_ns))
        self.pub_imu.publish(ros_msgs.imu_cdr(s.gyro_rad_s, s.accel_m_s2, s.q_imu, stamp_ns))
        self.in_contact = s.in_contact

    def _publish_frame(self, t_s, rgb, depth):
        stamp = ros_msgs.to_stamp(t_s)
        # serialized: rclpy would take longer over each image than the renderer
        stamp_ns = ros_msgs.stamp_ns(stamp)
        self.pub_rgb.publish(ros_msgs.image_cdr(rgb, stamp_ns))
        self.pub_depth.publish(ros_msgs.image_cdr(depth, stamp_ns))
        # camera_info last: sent ahead of the two large writes, it was the sample a loaded
        # recorder lost (and got again only at the writer's next heartbeat, seconds later)
        self.pub_info.publish(ros_msgs.camera_info_msg(self.cfg.camera, stamp))

    def _publish_target(self):
        for target_id, (poi_map, R_map_target) in self.plant.world.truth_targets().items():
            self.pub_gt_targets[target_id].publish(ros_msgs.pose_stamped_msg(
                poi_map, Rotation.from_matrix(R_map_target).as_quat(), ros_msgs.to_stamp(0.0)))

    def on_status(self):
        """plant/status: sim and wall time, real-time factor, lockstep counters, rejected
        commands, contact."""
        now = time.monotonic()
        self.status_due = now + 1.0 / self.cfg.status_rate_hz
        last_wall, last_sim = self.last_status
        rtf = (self.plant.t_s - last_sim) / max(now - last_wall, 1e-9)
        self.last_status = (now, self.plant.t_s)
        values = dict(mode=self.cfg.mode, sim_time_s=self.plant.t_s, tick=self.plant.tick,
                      wall_time_s=now - self.wall_t0, rtf=rtf, rtf_mean=self._run_rtf(now),
                      target_rtf=self.target_rtf, synced=self.synced,
                      rejected_commands=self.rejects.total, in_contact=self.in_contact,
                      **self.stats)
        values.update({f'rejected_{k}': v for k, v in self.rejects.counts.items()})
        level, message = DiagnosticStatus.OK, 'ok'
        if self.cfg.mode == 'realtime':
            lagging = self._realtime_warning(now)
            if lagging:
                level, message = DiagnosticStatus.WARN, lagging
        self.pub_status.publish(ros_msgs.diagnostics_msg(
            'plant', values, ros_msgs.to_stamp(self.plant.t_s), level, message))

    def _run_rtf(self, now):
        """Simulated over wall seconds since the run started (None before)."""
        if self.run_start is None or now <= self.run_start[0]:
            return None
        return (self.plant.t_s - self.run_start[1]) / (now - self.run_start[0])

    def _realtime_warning(self, now):
        """'' while the host keeps up; else the reason, logged at most every
        REALTIME_WARN_PERIOD_S, over the time since the last warning."""
        wall, sim, late, dropped = self.last_warning
        if now - wall < REALTIME_WARN_PERIOD_S:
            return ''
        self.last_warning = (now, self.plant.t_s, self.stats['late_commands'],
                             self.stats['dropped_ticks'])
        target = self.target_rtf
        rtf = (self.plant.t_s - sim) / (now - wall)
        new_late = self.stats['late_commands'] - late
        new_dropped = self.stats['dropped_ticks'] - dropped
        reason = realtime_reason(rtf, target, new_late, new_dropped, now - wall)
        if reason:
            self.get_logger().warn(reason)
        return reason

    def summary(self):
        """The run's timing and counters (written to ``summary_file`` at exit)."""
        now = time.monotonic()
        return dict(mode=self.cfg.mode, sim_time_s=self.plant.t_s,
                    wall_time_s=None if self.run_start is None else now - self.run_start[0],
                    rtf=self._run_rtf(now), target_rtf=self.target_rtf,
                    rejected_commands=self.rejects.total, **self.stats)

    def destroy_node(self):
        """Write the summary and release the physics server with the node."""
        if self.cfg.summary_file:
            with open(self.cfg.summary_file, 'w', encoding='utf-8') as stream:
                stream.write(json.dumps(self.summary()) + '\n')
        if self.camera is not None:
            self.camera.close()
        self.plant.close()
        return super().destroy_node()


def realtime_reason(rtf, target_rtf, late_commands, dropped_ticks, window_s):
    """What went wrong with real time over a window: '' when nothing did."""
    parts = []
    if rtf < KEEP_UP_SHARE * target_rtf:
        parts.append(f'not keeping up with the wall clock: sim time at {rtf:.2f}x '
                     f'(target {target_rtf:g}x)')
    if dropped_ticks:
        parts.append(f'{dropped_ticks} tick{"s" * (dropped_ticks != 1)} dropped')
    if late_commands:
        parts.append(f'{late_commands} command{"s" * (late_commands != 1)} came after the '
                     f'next tick had started')
    return '; '.join(parts) + f' in the last {window_s:.0f} s' if parts else ''


def main(args=None):
    """Entry point of the plant_node executable."""
    return run_node(PlantNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
