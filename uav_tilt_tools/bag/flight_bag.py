"""An in-process flight written as the recorder would write the node graph's run (MCAP).

:class:`FlightBag` is the ``recorder`` of :class:`uav_tilt_tools.runner.inprocess.Flight`: each
tick it serializes, with the rclpy message classes and the nodes' own conversions
(:mod:`uav_tilt_common.ros_msgs`), what the plant, controller and vision nodes would have
published on the same topics (namespace ``/uav``, ``/clock``) with the same types and
stamps, into an :class:`uav_tilt_tools.bag.writer.McapBag`; ``uav-tilt report`` reads it like
a recording of the graph. Log times are the wall clock of the in-process run. The camera
images (about 0.3 MB a frame, which no report reads) as its ``images`` profile says
(:mod:`uav_tilt_tools.bag.images`: none by default); without vision in the loop a profile
that keeps them renders the camera at its rate for the recording alone. Not written: the
services.
"""
import json
import time
from typing import TYPE_CHECKING, Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.serialization import serialize_message
from rosgraph_msgs.msg import Clock
from scipy.spatial.transform import Rotation
from std_msgs.msg import String

from uav_tilt_common import names, ros_msgs
from uav_tilt_common.modes import WAITING_FOR_SENSORS
from uav_tilt_common.state import ActuatorCommand
from uav_tilt_control.controller_core import ControllerConfig
from uav_tilt_sim.plant import TickSensors
from uav_tilt_sim.world_json import world_json
from uav_tilt_tools.bag import images as image_profile
from uav_tilt_tools.bag.writer import McapBag
from uav_tilt_tools.graph.topics import contract_offer
from uav_tilt_tools.runner.inprocess import Flight

if TYPE_CHECKING:     # the vision stack (torch) is imported only for a flight with vision
    from uav_tilt_tools.runner.camera_vision import CameraVision

CONTROLLER_STATUS_HZ = 10.0     # controller_node's default status_rate_hz
STATUS_HZ = 2.0                 # plant_node's and vision_node's

# The topics written, with the contract's types (names.TOPIC_TYPES).
TYPES = {topic: names.TOPIC_TYPES[topic] for topic in (
    names.CLOCK, names.IMU, names.ODOM, names.EE_WRENCH, names.ACTUATORS_CMD,
    names.ACTUATORS_STATE, names.GROUND_TRUTH_ODOM, names.GROUND_TRUTH_TARGET,
    names.PLANT_STATUS, names.PLANT_SCENARIO, names.CONTROLLER_STATUS, names.CONTROLLER_PLAN)}
VISION_TYPES = {topic: names.TOPIC_TYPES[topic] for topic in (
    names.CAMERA_INFO, names.TARGET_CANDIDATES, names.TARGET_POSE, names.VISION_PLANES,
    names.VISION_STATUS)}
CAMERA_TYPES = {topic: names.TOPIC_TYPES[topic] for topic in (
    names.CAMERA_COLOR, names.CAMERA_DEPTH, names.CAMERA_INFO)}


def absolute(topic: str, namespace: str = names.NAMESPACE) -> str:
    """The recorded name of a topic of :mod:`uav_tilt_common.names`."""
    return topic if topic.startswith('/') else namespace.rstrip('/') + '/' + topic


class FlightBag:
    """Per-tick recorder of a Flight into one MCAP file; call :meth:`close` at the end."""

    def __init__(self, path: str, controller_config: ControllerConfig, camera_config: Any,
                 vision: 'CameraVision | None' = None, own_folder: bool = False,
                 images: str = 'none') -> None:
        """``vision``: the flight's CameraVision (its frames give target/* and the camera
        info), or None when the target comes from ground truth; ``own_folder``: the file's
        folder is the recording's (:class:`McapBag`); ``images``: the camera images kept,
        ``all``, ``thin`` or ``none`` (:mod:`uav_tilt_tools.bag.images`)."""
        if images not in image_profile.PROFILES:
            raise ValueError(f'images {images!r}: one of {image_profile.PROFILES}')
        self.bag = McapBag(path, own_folder=own_folder)
        self.config = controller_config
        self.camera = camera_config
        self.vision = vision
        self.images = images
        self.thinning = image_profile.Thinning()
        types = {**TYPES, **(VISION_TYPES if vision is not None else {}),
                 **(CAMERA_TYPES if images != 'none' else {})}
        for topic, type_name in types.items():
            self.bag.add_topic(absolute(topic), type_name, [contract_offer(topic)])
        self._flight: Flight | None = None
        self._saturated_ticks = 0
        self._wall_t0_ns = time.time_ns()
        self._window = (self._wall_t0_ns, 0)     # (wall ns, tick) at the last status
        self._plan_version: Any = None
        self._frame_stamp: float | None = None
        self._vision_window = (time.time_ns(), 0)

    def _write(self, topic: str, msg: Any, log_ns: int) -> None:
        self.bag.write(absolute(topic), serialize_message(msg), log_ns)

    def __call__(self, flight: Flight, sensors: TickSensors, command: ActuatorCommand) -> None:
        """One tick: the plant's sensors, the controller's command and statuses."""
        now = time.time_ns()
        plant = flight.plant
        if self._flight is None:
            self._flight = flight
            self._write_targets(flight, now)
        stamp = ros_msgs.to_stamp(sensors.t_s)
        self._write(names.CLOCK, Clock(clock=stamp), now)
        self._write(names.ODOM, ros_msgs.odometry_msg(sensors.odom, stamp), now)
        self._write(names.EE_WRENCH, ros_msgs.wrench_msg(sensors.ee_force_n,
                                                         sensors.ee_torque_nm, stamp), now)
        self._write(names.ACTUATORS_STATE,
                    ros_msgs.actuator_msg(sensors.thrusts_n, sensors.tilts_rad, stamp), now)
        self._write(names.GROUND_TRUTH_ODOM, ros_msgs.odometry_msg(plant.state(), stamp), now)
        self._write(names.IMU, ros_msgs.imu_msg(sensors.gyro_rad_s, sensors.accel_m_s2,
                                                sensors.q_imu, stamp), now)
        self._write(names.ACTUATORS_CMD, ros_msgs.actuator_msg(
            command.thrusts_n, (command.alpha_rad, command.beta_rad), stamp), now)
        self._saturated_ticks += int(flight.status.get('saturated', False))
        ticks_per_s = 1.0 / plant.dt_tick
        if self.vision is not None:
            self._write_frame(self.vision)
        elif self.images != 'none' \
                and plant.tick % max(1, round(ticks_per_s / self.camera.rate_hz)) == 0:
            # the camera drawn for the recording alone, as the plant draws it for one
            rgb, depth, _ = plant.render()
            self._write_images(sensors.t_s, rgb, depth, now)
        if plant.tick % max(1, round(ticks_per_s / CONTROLLER_STATUS_HZ)) == 0:
            self._write_controller_status(flight, now)
        if plant.tick % max(1, round(ticks_per_s / STATUS_HZ)) == 0:
            self._write_plant_status(flight, sensors, now)
            if self.vision is not None:
                self._write_vision_status(self.vision, now)

    def close(self) -> None:
        """The last statuses (the outcome of the mission), then complete the file."""
        if self.bag.closed:
            return
        if self._flight is not None:
            self._write_controller_status(self._flight, time.time_ns(), final=True)
        self.bag.close()

    # --- what each node would publish ------------------------------------------------
    def _write_targets(self, flight: Flight, now: int) -> None:
        """The world and each target's ground truth, as the plant latches them once."""
        self._write(names.PLANT_SCENARIO, String(data=world_json(flight.plant.scenario,
                                                                 flight.plant.world)), now)
        for target_id, (poi_map, R_map_target) in flight.plant.world.truth_targets().items():
            topic = names.ground_truth_target(target_id)
            if target_id:
                self.bag.add_topic(absolute(topic), names.TOPIC_TYPES[names.GROUND_TRUTH_TARGET],
                                   [contract_offer(topic)])
            self._write(topic, ros_msgs.pose_stamped_msg(
                poi_map, Rotation.from_matrix(R_map_target).as_quat(), ros_msgs.to_stamp(0.0)),
                now)

    def _write_frame(self, vision: 'CameraVision') -> None:
        """camera_info when the image was ready, target/* when vision was done with it."""
        frame = vision.last_frame
        if frame is None or frame.stamp_s == self._frame_stamp:
            return
        from uav_tilt_vision.vision_node import pose_msg    # torch: only with vision
        t_s, result, processed_ns = frame.stamp_s, frame.result, frame.processed_ns
        self._frame_stamp = t_s
        stamp = ros_msgs.to_stamp(t_s)
        if self.images != 'none' and frame.rgb is not None:
            self._write_images(t_s, frame.rgb, frame.depth, frame.rendered_ns)
        else:
            self._write(names.CAMERA_INFO, ros_msgs.camera_info_msg(self.camera, stamp),
                        frame.rendered_ns)
        self._write(names.TARGET_CANDIDATES, ros_msgs.candidates_msg(result.candidates, stamp),
                    processed_ns)
        self._write(names.TARGET_POSE, pose_msg(result, stamp), processed_ns)
        if result.planes is not None:
            self._write(names.VISION_PLANES, ros_msgs.planes_msg(result.planes, stamp),
                        processed_ns)

    def _write_images(self, t_s: float, rgb: Any, depth: Any, log_ns: int) -> None:
        """A camera frame as the plant publishes it (the images, then camera_info), the
        images as the profile keeps them."""
        stamp = ros_msgs.to_stamp(t_s)
        stamp_ns = ros_msgs.stamp_ns(stamp)
        if self.images == 'all' or self.thinning.keep(stamp_ns):
            self.bag.write(absolute(names.CAMERA_COLOR), ros_msgs.image_cdr(rgb, stamp_ns),
                           log_ns)
            self.bag.write(absolute(names.CAMERA_DEPTH), ros_msgs.image_cdr(depth, stamp_ns),
                           log_ns)
        self._write(names.CAMERA_INFO, ros_msgs.camera_info_msg(self.camera, stamp), log_ns)

    def _write_controller_status(self, flight: Flight, now: int, final: bool = False) -> None:
        """controller/status as controller_node's, its loop rate over the wall clock since
        the status before (the last status, written after the flight: over the whole
        flight, the rate `fly` reports); and controller/plan when a task record changed, as
        controller_node sends them."""
        mission = flight.core.mission
        if mission.plan_version != self._plan_version:
            self._plan_version = mission.plan_version
            self._write(names.CONTROLLER_PLAN,
                        String(data=json.dumps(flight.core.plan_report())), now)
        status = flight.status
        wall_ns, tick = self._window
        self._window = (now, flight.plant.tick)
        values = dict(status) or dict(mode=WAITING_FOR_SENSORS)
        values.update(ticks=flight.plant.tick, saturated_ticks=self._saturated_ticks,
                      target_source=self.config.target_source, rejected_inputs=0,
                      contact_force=self.config.contact_force,
                      wall_time_s=(now - self._wall_t0_ns) * 1e-9)
        if final:
            wall_ns, tick = self._wall_t0_ns, 0
        if now > wall_ns and flight.plant.tick > tick:
            values['loop_rate_hz'] = (flight.plant.tick - tick) / ((now - wall_ns) * 1e-9)
        level = DiagnosticStatus.WARN if values.get('failsafe_reason') else DiagnosticStatus.OK
        self._write(names.CONTROLLER_STATUS, ros_msgs.diagnostics_msg(
            'controller', values, ros_msgs.to_stamp(values.get('t_s', 0.0)), level,
            values.get('failsafe_reason') or 'ok'), now)

    def _write_plant_status(self, flight: Flight, sensors: TickSensors, now: int) -> None:
        plant = flight.plant
        values = dict(mode='inprocess', sim_time_s=plant.t_s, tick=plant.tick,
                      wall_time_s=(now - self._wall_t0_ns) * 1e-9,
                      in_contact=sensors.in_contact, rejected_commands=0)
        self._write(names.PLANT_STATUS, ros_msgs.diagnostics_msg(
            'plant', values, ros_msgs.to_stamp(plant.t_s)), now)

    def _write_vision_status(self, vision: 'CameraVision', now: int) -> None:
        wall_ns, frames = self._vision_window
        self._vision_window = (now, vision.frames)
        # a loaded detector (backends.load_detector), which says its backend and model
        detector: Any = vision.pipeline.detector
        values = dict(backend=detector.backend, model=detector.model_path,
                      fps=(vision.frames - frames) / max((now - wall_ns) * 1e-9, 1e-9),
                      frames_processed=vision.frames, targets_found=vision.found)
        if vision.latency_ms:
            latency = np.asarray(vision.latency_ms)
            values.update(latency_ms_p50=float(np.percentile(latency, 50)),
                          latency_ms_p95=float(np.percentile(latency, 95)))
        stamp = ros_msgs.to_stamp(self._frame_stamp or 0.0)
        self._write(names.VISION_STATUS, ros_msgs.diagnostics_msg('vision', values, stamp), now)
