"""Plant core + controller core in one process at 300 Hz, no ROS (tests, campaigns, benches).

The same cores as plant_node and controller_node, wired the way the nodes are: each tick the
plant's sensors go to the controller (odometry, F/T, then the IMU tick) and its command goes
back. Vision comes in through an optional callable.
"""
import collections
import time

import numpy as np
from scipy.spatial.transform import Rotation

from uav_tilt_common.geometry import quat_to_matrix
from uav_tilt_common.vehicle import VehicleParams
from uav_tilt_control.controller_core import ControllerConfig, ControllerCore
from uav_tilt_common.modes import Mode
from uav_tilt_sim.plant import Plant, PlantCoreConfig
from uav_tilt_tools.mission_metrics import mission_summary, mode_samples, push_along_normal
from uav_tilt_tools.task_metrics import task_results, with_tasks


class Flight:
    """A plant and a controller stepped together; keeps a per-tick log.

    ``vision(plant, t_s)`` (optional) returns ``(stamp_s, candidates, planes)`` of a frame,
    as ``target/candidates`` and ``vision/planes`` carry them (planes None when the frame
    was not looked at for them), or None when there is no frame this tick.
    ``recorder(flight, sensors, command)`` (optional) sees every tick after the controller
    (:class:`uav_tilt_tools.flight_bag.FlightBag` writes it as the node graph's topics).
    """

    def __init__(self, scenario, controller_config=None, vehicle=None, plant_config=None,
                 vision=None, recorder=None):
        self.vehicle = vehicle or VehicleParams()
        plant_config = plant_config or PlantCoreConfig(vehicle=self.vehicle)
        self.plant = Plant(plant_config, scenario)
        self.core = ControllerCore(self.vehicle, controller_config or ControllerConfig())
        self.vision = vision
        self.recorder = recorder
        self.sensors = None         # the plant's readings of the last tick
        self.odometry_enabled = True
        self.status = {}
        self.log = []               # one dict per tick, see :meth:`step`
        self.tick_s = []            # wall-clock compute time of each ControllerCore.tick
        world = self.plant.world
        if world.target_poi_map is not None:
            # as plant_node's latched ground_truth/target and ground_truth/targets/<id>
            truths = {'': (world.target_poi_map, world.R_map_target), **world.targets}
            for target_id, (poi_map, R_map_target) in truths.items():
                self.core.on_ground_truth_target(
                    poi_map, Rotation.from_matrix(R_map_target).as_quat(), target_id)

    @property
    def t_s(self):
        """Simulated time."""
        return self.plant.t_s

    def step(self):
        """One 300 Hz tick: sensors -> controller -> plant."""
        plant, core = self.plant, self.core
        sensors = self.sensors = plant.read_sensors()
        if self.odometry_enabled:
            core.on_odometry(sensors.odom)
        core.on_wrench(sensors.ee_force_n, sensors.ee_torque_nm)
        frame = self.vision(plant, sensors.t_s) if self.vision is not None else None
        if frame is not None:
            stamp_s, candidates, planes = frame
            core.on_target_candidates(stamp_s, candidates)
            if planes is not None:
                core.on_planes(stamp_s, planes)
        start = time.perf_counter()
        command, self.status = core.tick(sensors.t_s, sensors.gyro_rad_s, plant.dt_tick,
                                         sensors.accel_m_s2)
        self.tick_s.append(time.perf_counter() - start)
        truth = plant.state()
        self.log.append(dict(t_s=sensors.t_s, mode=self.status['mode'],
                             time_in_mode_s=self.status['time_in_mode_s'], p_map=truth.p_map,
                             q_map_base=truth.q_map_base, tip_map=plant.tool_tip_map(),
                             push_n=self._true_push_n(sensors.in_contact),
                             ft_force_ee_n=sensors.ee_force_n,
                             task_index=self.status.get('task_index', -1), command=command))
        if self.recorder is not None:
            self.recorder(self, sensors, command)
        plant.step(command)

    def run(self, duration_s, until=None):
        """Step for ``duration_s`` or until ``until(self)`` is true; returns whether it was."""
        for _ in range(int(round(duration_s / self.plant.dt_tick))):
            if until is not None and until(self):
                return True
            self.step()
        return until is not None and until(self)

    def close(self):
        """Release the physics server."""
        self.plant.close()

    def _true_push_n(self, in_contact):
        """Contact force on the wall along -normal [N] from the plant's truth.

        ``in_contact`` (from read_sensors, which saw the true contact force) spares the
        contact query on free-flight ticks, where the push is below 1e-6 N.
        """
        if not in_contact:
            return 0.0
        force_ee, _ = self.plant.contact_wrench_ee()
        R_map_base = quat_to_matrix(self.plant.state().q_map_base)
        return float((R_map_base @ force_ee) @ self.plant.world.R_map_wall[:, 2])


def mission_result(flight):
    """Summary of a plan's run: :func:`mission_metrics.mission_summary` of the log (the
    F/T reading and the truth of each tick) with the plan's ``tasks``
    (:func:`task_metrics.with_tasks`), the failsafe reason and where it fired, the history
    of modes, the first touch's true peak push, the target confirmed for the approach and
    the mean tool tip over HOLD."""
    log = flight.log
    modes = [(entry['t_s'], entry['mode']) for entry in log]
    history = [modes[0]] + [modes[i] for i in range(1, len(modes))
                            if modes[i][1] != modes[i - 1][1]]
    t_log = [e['t_s'] for e in log]
    world = flight.plant.world
    # the push on the target's surface; a world without a target has only its wall
    R_surface = world.R_map_target if world.R_map_target is not None else world.R_map_wall
    push = [push_along_normal(quat_to_matrix(e['q_map_base']), e['ft_force_ee_n'], R_surface)
            for e in log]
    normal = world.R_map_target[:, 2] if world.R_map_target is not None else None
    result = mission_summary(mode_samples([(e['t_s'], e) for e in log]), flight.status,
                             t_log, push, t_log, [e['tip_map'] for e in log],
                             world.target_poi_map, normal)
    reason = flight.status.get('failsafe_reason', '')
    events = flight.core.mission.events
    fired = [e for e in events if reason and e['reason'] == reason]
    approached = [e['target_map'] for e in events if e['mode'] == Mode.APPROACH.value
                  and e['previous'] == Mode.SEARCH.value]
    hold = [e['tip_map'] for e in log if e['mode'] == Mode.HOLD.value]
    truths = {'': (world.target_poi_map, world.R_map_target), **world.targets} \
        if world.target_poi_map is not None else {}
    force_map = [quat_to_matrix(e['q_map_base']) @ e['ft_force_ee_n'] for e in log]
    tasks = task_results(flight.core.plan_report()['tasks'], t_log,
                         [e['tip_map'] for e in log], force_map, truths, world.R_map_wall[:, 2])
    result.update(failsafe_reason=reason,
                  # a transition's event names the mode it left, one within a mode the mode
                  failsafe_where=({'mode': fired[-1]['previous'] or fired[-1]['mode'],
                                   'phase': fired[-1]['phase']} if fired else None),
                  first_touch_peak_n=_first_touch_peak(log, np.array([e['push_n']
                                                                      for e in log])),
                  mode_history=[(float(t), m) for t, m in history],
                  hold_tip_map=np.mean(hold, axis=0).tolist() if hold else None,
                  confirmed_target_map=approached[0] if approached else None,
                  sim_time_s=float(flight.t_s), ticks=len(log))
    return with_tasks(result, tasks)


def _first_touch_peak(log, push, window_s=0.25):
    """Largest true push within ``window_s`` of the mission's first touch, its first contact
    in CONTACT: the impact's transient (a rebound lasts tens of ms, the rotors answer in
    25 ms), or None without one. A wall met on the way (a take-off under a wall leaning over
    it) is no touch; ``max_force_n`` has it."""
    touched = np.nonzero((push > 0.0) & np.array([e['mode'] == Mode.CONTACT.value
                                                  for e in log]))[0]
    if not len(touched):
        return None
    t0 = log[touched[0]]['t_s']
    return float(max(p for e, p in zip(log[touched[0]:], push[touched[0]:])
                     if e['t_s'] <= t0 + window_s))


def run_mission(scenario, controller_config=None, duration_s=120.0, vehicle=None,
                plant_config=None, vision=None, recorder=None):
    """Fly the configured plan (``inspect`` at t = 0: the one-touch inspection unless
    ``controller_config.plan_file`` names a plan) until landed or ``duration_s``.

    Returns :func:`mission_result`'s dict.
    """
    config = controller_config or ControllerConfig()
    flight = Flight(scenario, config, vehicle, plant_config, vision, recorder)
    try:
        flight.step()
        ok, message = flight.core.inspect()
        if not ok:
            raise RuntimeError(f'inspect refused: {message}')
        flight.run(duration_s, until=lambda f: f.core.mission.mode == Mode.IDLE)
        return mission_result(flight)
    finally:
        flight.close()


class CameraVision:
    """Vision in the loop without ROS: renders the eye-in-hand camera at its rate and runs
    the VisionPipeline; each frame gives its target candidates and planes stamped with the
    frame time (as vision_node stamps target/candidates and vision/planes), an empty list
    included. ``last_frame`` is
    (stamp_s, FrameResult, rendered_ns, processed_ns) of the newest frame (wall clock ns
    when the image was ready and when the pipeline was done with it), or None;
    ``latency_ms`` the last frames' times from one to the other, the window of
    vision/status's latency."""

    def __init__(self, pipeline, camera_rate_hz, control_rate_hz):
        from uav_tilt_vision.pipeline import STATS_WINDOW
        self.pipeline = pipeline
        self.every = max(1, int(round(control_rate_hz / camera_rate_hz)))
        self.frames = 0
        self.found = 0
        self.last_frame = None
        self.latency_ms = collections.deque(maxlen=STATS_WINDOW)

    def __call__(self, plant, t_s):
        """(stamp_s, candidates, planes) of this tick's frame, or None when none is
        rendered."""
        if plant.tick % self.every:
            return None
        rgb, depth, _ = plant.render()
        rendered_ns = time.time_ns()
        result = self.pipeline.process(rgb, depth, t_s)
        self.last_frame = (t_s, result, rendered_ns, time.time_ns())
        self.latency_ms.append((self.last_frame[3] - rendered_ns) * 1e-6)
        self.frames += 1
        self.found += int(result.found)
        return t_s, result.candidates, result.planes


def camera_vision(plant_config, model_path='', backend='auto', vision_config=None, threads=0):
    """A :class:`CameraVision` with the detector at ``model_path`` (found like the vision
    node's: the working directory, then the package's files; '' the deployed detector) and
    the plant's camera; ``threads`` (0: the libraries' defaults) sizes the detector's thread
    pool and OpenCV's (process-wide), e.g. to the one CPU a campaign run gets."""
    from uav_tilt_common.resources import resolve
    from uav_tilt_vision.backends import DEPLOYED_MODEL, load_detector
    from uav_tilt_vision.pipeline import VisionPipeline
    from uav_tilt_vision.target_pose import CameraIntrinsics
    if threads:
        import cv2
        cv2.setNumThreads(threads)
    cam = plant_config.camera
    intrinsics = CameraIntrinsics(cam.fx, cam.fy, cam.cx, cam.cy, cam.width, cam.height)
    detector = load_detector(resolve(model_path or DEPLOYED_MODEL, 'model_path'), backend,
                             threads)
    pipeline = VisionPipeline(detector, intrinsics, vision_config)
    return CameraVision(pipeline, cam.rate_hz, plant_config.control_hz)
