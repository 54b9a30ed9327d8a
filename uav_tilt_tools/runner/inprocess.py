"""Plant core + controller core in one process at 300 Hz, no ROS (tests, campaigns, benches).

The same cores as plant_node and controller_node, wired the way the nodes are: each tick the
plant's sensors go to the controller (odometry, F/T, then the IMU tick) and its command goes
back. Vision comes in through an optional callable.
"""
import time
from typing import Any, Callable, Optional

import numpy as np
from scipy.spatial.transform import Rotation

from uav_tilt_common.geometry import quat_to_matrix
from uav_tilt_common.state import ActuatorCommand
from uav_tilt_common.vehicle import VehicleParams
from uav_tilt_control.controller_core import ControllerConfig, ControllerCore
from uav_tilt_common.modes import Mode
from uav_tilt_sim.plant import Plant, PlantCoreConfig, TickSensors
from uav_tilt_sim.scenario import Scenario
from uav_tilt_tools.metrics.mission import mission_summary, mode_samples, push_along_normal
from uav_tilt_tools.metrics.tasks import task_results, with_tasks

# vision(plant, t_s) -> (stamp_s, candidates, planes) of this tick's frame, or None
Vision = Callable[[Plant, float], Optional[tuple[float, Any, Any]]]
# recorder(flight, sensors, command), after the controller's tick
Recorder = Callable[['Flight', TickSensors, ActuatorCommand], None]
# progress(t_s, duration_s, mode): how far a flight is, every PROGRESS_TICKS ticks
Progress = Callable[[float, float, str], None]
PROGRESS_TICKS = 30


class Flight:
    """A plant and a controller stepped together; keeps a per-tick log.

    ``vision(plant, t_s)`` (optional) returns ``(stamp_s, candidates, planes)`` of a frame,
    as ``target/candidates`` and ``vision/planes`` carry them (planes None when the frame
    was not looked at for them), or None when there is no frame this tick.
    ``recorder(flight, sensors, command)`` (optional) sees every tick after the controller
    (:class:`uav_tilt_tools.bag.flight_bag.FlightBag` writes it as the node graph's topics).
    """

    def __init__(self, scenario: Scenario, controller_config: ControllerConfig | None = None,
                 vehicle: VehicleParams | None = None,
                 plant_config: PlantCoreConfig | None = None, vision: Vision | None = None,
                 recorder: Recorder | None = None) -> None:
        self.vehicle = vehicle or VehicleParams()
        plant_config = plant_config or PlantCoreConfig(vehicle=self.vehicle)
        self.plant = Plant(plant_config, scenario)
        self.core = ControllerCore(self.vehicle, controller_config or ControllerConfig())
        self.vision = vision
        self.recorder = recorder
        self.sensors: TickSensors | None = None     # the plant's readings of the last tick
        self.odometry_enabled = True
        self.status: dict[str, Any] = {}
        self.log: list[dict[str, Any]] = []     # one dict per tick, see :meth:`step`
        self.tick_s: list[float] = []   # wall-clock compute time of each ControllerCore.tick
        world = self.plant.world
        # as plant_node's latched ground_truth/target and ground_truth/targets/<id>
        for target_id, (poi_map, R_map_target) in world.truth_targets().items():
            self.core.on_ground_truth_target(
                poi_map, Rotation.from_matrix(R_map_target).as_quat(), target_id)

    @property
    def t_s(self) -> float:
        """Simulated time."""
        return self.plant.t_s

    def step(self) -> None:
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

    def run(self, duration_s: float, until: Callable[['Flight'], bool] | None = None) -> bool:
        """Step for ``duration_s`` or until ``until(self)`` is true; returns whether it was."""
        for _ in range(int(round(duration_s / self.plant.dt_tick))):
            if until is not None and until(self):
                return True
            self.step()
        return until is not None and until(self)

    def close(self) -> None:
        """Release the physics server."""
        self.plant.close()

    def _true_push_n(self, in_contact: bool) -> float:
        """Contact force on the wall along -normal [N] from the plant's truth.

        ``in_contact`` (from read_sensors, which saw the true contact force) spares the
        contact query on free-flight ticks, where the push is below 1e-6 N.
        """
        if not in_contact:
            return 0.0
        force_ee, _ = self.plant.contact_wrench_ee()
        R_map_base = quat_to_matrix(self.plant.state().q_map_base)
        return float((R_map_base @ force_ee) @ self.plant.world.R_map_wall[:, 2])


def mission_result(flight: Flight) -> dict[str, Any]:
    """Summary of a plan's run: :func:`metrics.mission.mission_summary` of the log (the
    F/T reading and the truth of each tick) with the plan's ``tasks``
    (:func:`metrics.tasks.with_tasks`), the failsafe reason and where it fired, the history
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
    axes = [quat_to_matrix(e['q_map_base'])[:, 0] for e in log]
    result = mission_summary(mode_samples([(e['t_s'], e) for e in log]), flight.status,
                             t_log, push, t_log, [e['tip_map'] for e in log],
                             world.target_poi_map, normal, tool_axes_map=axes)
    reason = flight.status.get('failsafe_reason', '')
    events = flight.core.mission.events
    fired = [e for e in events if reason and e['reason'] == reason]
    approached = [e['target_map'] for e in events if e['mode'] == Mode.APPROACH.value
                  and e['previous'] == Mode.SEARCH.value]
    hold = [e['tip_map'] for e in log if e['mode'] == Mode.HOLD.value]
    truths = world.truth_targets()
    force_map = [quat_to_matrix(e['q_map_base']) @ e['ft_force_ee_n'] for e in log]
    tasks = task_results(flight.core.plan_report()['tasks'], t_log,
                         [e['tip_map'] for e in log], force_map, truths, world.R_map_wall[:, 2],
                         tool_axis_map=axes)
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


def _first_touch_peak(log: list[dict[str, Any]], push: np.ndarray, window_s: float = 0.25
                      ) -> float | None:
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


def run_mission(scenario: Scenario, controller_config: ControllerConfig | None = None,
                duration_s: float = 120.0, vehicle: VehicleParams | None = None,
                plant_config: PlantCoreConfig | None = None, vision: Vision | None = None,
                recorder: Recorder | None = None, progress: Progress | None = None
                ) -> dict[str, Any]:
    """Fly the configured plan (``inspect`` at t = 0: the one-touch inspection unless
    ``controller_config.plan_file`` names a plan) until landed or ``duration_s``;
    ``progress`` (it only reads) is told how far it got every :data:`PROGRESS_TICKS` ticks.

    Returns :func:`mission_result`'s dict.
    """
    config = controller_config or ControllerConfig()
    flight = Flight(scenario, config, vehicle, plant_config, vision, recorder)
    try:
        flight.step()
        ok, message = flight.core.inspect()
        if not ok:
            raise RuntimeError(f'inspect refused: {message}')
        ticks = [0]

        def landed(f: Flight) -> bool:
            mode = f.core.mission.mode
            if progress is not None and ticks[0] % PROGRESS_TICKS == 0:
                progress(f.t_s, duration_s, mode.value)
            ticks[0] += 1
            return mode == Mode.IDLE
        flight.run(duration_s, until=landed)
        return mission_result(flight)
    finally:
        flight.close()
