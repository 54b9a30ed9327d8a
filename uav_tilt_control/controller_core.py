"""The flight controller without ROS: odometry, F/T, target -> mission -> flight core.

:class:`ControllerCore` is what controller_node and the in-process runner share. It runs one
control tick per IMU sample (PX4 style): the rate loop uses the IMU gyro, everything else the
newest odometry, whose age drives the stale-odometry failsafe. While the odometry is stale
the vehicle flies blind: position and velocity are taken to be the reference (so only the
reference's feed-forward acts) and the attitude is the last odometry attitude integrated
with the gyro.
"""
import dataclasses
import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from uav_tilt_common import resources
from uav_tilt_common.config import ConfigError, nested, param
from uav_tilt_common.geometry import quat_multiply, rotvec_to_quat
from uav_tilt_common.planes import Plane
from uav_tilt_common.state import ActuatorCommand, VehicleState
from uav_tilt_common.targets import TargetCandidate
from uav_tilt_common.vehicle import VehicleParams
from uav_tilt_control import frames
from uav_tilt_control.flight_core import FlightCore, FlightCoreConfig
from uav_tilt_control.mission import (DEFAULT_CONTACT_FORCE_N, NEAR_WALL, Mission,
                                      MissionConfig, Mode)
from uav_tilt_control.plan import (ForceRange, Task, Touch, check_force, load_plan,
                                   one_touch_plan)
from uav_tilt_control.site import SiteConfig
from uav_tilt_control.target_estimator import (TargetEstimate, TargetEstimator,
                                               TargetEstimatorConfig)
from uav_tilt_control.types import ImpedanceSetpoint

TARGET_SOURCES = ('vision', 'ground_truth')
__all__ = ['ControllerConfig', 'ControllerCore', 'SiteConfig', 'TARGET_SOURCES', 'plan_of']


@dataclasses.dataclass
class ControllerConfig:
    """Controller parameters; the top-level names are DESIGN section 7's. ``autostart``
    'inspect' runs the one-touch plan (``contact_force`` for mission.contact.hold_time_s), 'plan'
    the plan in ``plan_file`` (uav_tilt_control.plan), validated against ``site``."""

    target_source: str = param('vision', choices=TARGET_SOURCES,
                               doc='where the target comes from (ground_truth: evaluation)')
    contact_force: float = param(DEFAULT_CONTACT_FORCE_N, unit='N',
                                 doc='push along the surface normal during HOLD; one the '
                                     'vehicle cannot make is refused with the range')
    autostart: str = param('', choices=('', 'inspect', 'plan'),
                           doc="mission started by itself (with odometry, and with the "
                               "target from vision once vision sends): 'inspect' the "
                               "one-touch plan, 'plan' the plan in plan_file")
    plan_file: str = param('', doc='inspection plan (YAML) for autostart plan')
    flight: FlightCoreConfig = nested(FlightCoreConfig)
    mission: MissionConfig = nested(MissionConfig)
    estimator: TargetEstimatorConfig = nested(TargetEstimatorConfig)
    site: SiteConfig = nested(SiteConfig)


def force_range_n(cfg: ControllerConfig, vehicle: VehicleParams) -> ForceRange:
    """(low, high, what sets them): the open range of a push asked for (``contact_force``,
    a plan's ``force_n``) with ControllerConfig ``cfg`` on ``vehicle``. It must be felt as
    contact and stay under the force limit; and without contact feedforward the impedance
    law pushes with the vehicle's mass times its commanded acceleration, whose norm is
    limited: a push beyond that is never reached."""
    m, impedance = cfg.mission, cfg.flight.impedance
    reach_n = vehicle.mass_kg * impedance.accel_limit_mps2
    if not impedance.contact_feedforward and reach_n < m.failsafe.force_limit_n:
        return (m.contact.threshold_n, reach_n, 'mission.contact.threshold_n, the most the '
                'vehicle pushes: vehicle.mass_kg x flight.impedance.accel_limit_mps2')
    return m.contact.threshold_n, m.failsafe.force_limit_n, 'mission.contact.threshold_n, ' \
        'mission.failsafe.force_limit_n'


def plan_of(cfg: ControllerConfig, vehicle: VehicleParams | None = None) -> list[Task]:
    """The tasks that ``inspect`` runs with ControllerConfig ``cfg`` on ``vehicle``
    (default VehicleParams()): the plan file's, validated against the site, or the one-touch
    inspection (ConfigError when bad)."""
    if cfg.autostart == 'plan' and not cfg.plan_file:
        raise ConfigError("parameter 'autostart' = 'plan' needs 'plan_file'")
    if cfg.autostart == 'inspect' and cfg.plan_file:
        raise ConfigError(f"parameter 'plan_file' = {cfg.plan_file!r}: autostart 'inspect' is "
                          f"the one-touch inspection; a plan file runs with 'plan'")
    m = cfg.mission
    forces = force_range_n(cfg, vehicle or VehicleParams())
    # the push of the one-touch inspection, and the one status reports before a plan's
    check_force("parameter 'contact_force'", cfg.contact_force, forces)
    if not cfg.plan_file:
        return one_touch_plan(cfg.site.check(), cfg.contact_force, m.contact.hold_time_s)
    return load_plan(resources.resolve(cfg.plan_file, 'plan_file'), cfg.site, forces,
                     m.lowest_hover_m(), m.slide.path_tolerance_m, m.contact.max_pitch_rad)


class ControllerCore:
    """Owns FlightCore, Mission and TargetEstimator; feed it messages, call :meth:`tick`."""

    def __init__(self, vehicle: VehicleParams, config: ControllerConfig | None = None
                 ) -> None:
        self.vehicle = vehicle
        self.config = config or ControllerConfig()
        cfg = self.config
        self.flight = FlightCore(vehicle, cfg.flight)
        self.estimator = TargetEstimator(cfg.estimator, vehicle.camera_in_base())
        self.estimator.hint_map = cfg.site.target_hint_map()
        self.mission = Mission(vehicle, cfg.mission, cfg.contact_force,
                               drop_target=self.estimator.reset, plan=plan_of(cfg, vehicle),
                               on_task=self._on_task, obstacles=cfg.site.obstacles())
        self._odom: VehicleState | None = None
        self._R_map_base: np.ndarray | None = None  # of the odometry, on first use
        self._q_blind: np.ndarray | None = None
        # target id ('' = the target) -> (p_map, R_map_t)
        self._ground_truths: dict[str, tuple[NDArray[np.float64], NDArray[np.float64]]] = {}
        self._truth_id = ''         # the target of the task under way
        self._f_contact_map = np.zeros(3)
        self._thrust_up_n: float | None = None  # the vertical thrust asked for on the tick before
        self._autostarted = False
        self.autostart_held = False     # set by the node until a recorder listens
        # an autostart with the target from vision waits for vision's first frame: the
        # detector loads while the plant already runs, the start's busiest moments
        self._target_source_up = self.config.target_source != 'vision'
        self._was_idle = True
        self.f_normal_n = 0.0
        # setpoint_hook(setpoint) -> setpoint: an outer loop's correction of the mission's
        # setpoint before the impedance law (a learnt policy, uav_tilt_tools.gym.env)
        self.setpoint_hook: Callable[[ImpedanceSetpoint], ImpedanceSetpoint] | None = None

    def _on_task(self, task: Task) -> None:
        """A task starts: look for its target near where the plan says it is."""
        self._truth_id = task.target
        if isinstance(task, Touch):
            self.estimator.aim(task.hint_map)

    def plan_report(self) -> dict[str, Any]:
        """The plan and how each task went, JSON-able (controller/plan): each task's
        description (uav_tilt_control.plan) with its TaskRecord, and the site's wall."""
        records = self.mission.records
        tasks = []
        for i, task in enumerate(self.mission.plan):
            entry = dict(index=i, **task.describe())
            if i < len(records):
                entry.update(dataclasses.asdict(records[i]))
            tasks.append(entry)
        return dict(tasks=tasks, wall=self.config.site.wall_frame())

    # ---- inputs ----

    @property
    def odometry(self) -> VehicleState | None:
        """The last odometry taken, or None."""
        return self._odom

    def on_odometry(self, state: VehicleState) -> None:
        """Mocap-like odometry (map -> base_link); also feeds the estimator's pose history."""
        self._odom = state
        self._R_map_base = None
        self._q_blind = np.asarray(state.q_map_base, dtype=float)
        self.estimator.add_state(state)

    def on_wrench(self, force_ee: ArrayLike, torque_ee: ArrayLike) -> None:
        """F/T reading at the tool (ee_link, FLU axes): the contact force on the vehicle."""
        force_ee = np.asarray(force_ee, dtype=float)
        if self._odom is None or not np.all(np.isfinite(force_ee)):
            return
        self._f_contact_map = self._odom_rotation() @ force_ee

    def on_target_candidates(self, stamp_s: float,
                             candidates: Sequence[TargetCandidate]) -> bool:
        """Vision's ``target/candidates`` of one frame (TargetCandidates in the camera
        optical frame, the tracked one first); returns True when one was accepted."""
        if self.config.target_source != 'vision':
            return False
        self._target_source_up = True
        return self.estimator.add_candidates(
            stamp_s, [(c.p_cam, c.n_cam, c.cov_cam) for c in candidates])

    def on_planes(self, stamp_s: float, planes: Sequence[Plane]) -> int:
        """Vision's ``vision/planes`` of one frame (Planes in the camera optical frame):
        moved to map with the pose at the frame's stamp, for the mission's search; returns
        how many were moved (none without a pose at that stamp)."""
        pose = self.estimator.pose_at(stamp_s) if math.isfinite(stamp_s) else None
        if pose is None:
            return 0
        map_cam = pose @ self.vehicle.camera_in_base()
        for plane in planes:
            self.mission.observe_plane(map_cam.apply(plane.point_cam),
                                       map_cam.rotate(plane.normal_cam), plane.share)
        return len(planes)

    def on_ground_truth_target(self, p_map: ArrayLike, q_map_t: ArrayLike,
                               target_id: str = '') -> bool:
        """Evaluation mode only: the true pose (map) of the target ``target_id`` ('' = the
        target of a one-touch inspection); ignored with vision."""
        if self.config.target_source != 'ground_truth':
            return False
        p_map, q_map_t = np.asarray(p_map, dtype=float), np.asarray(q_map_t, dtype=float)
        if not (np.all(np.isfinite(p_map)) and np.all(np.isfinite(q_map_t))
                and np.linalg.norm(q_map_t) > 0.5):
            return False
        self._ground_truths[target_id] = (p_map, frames.quat_matrix(q_map_t))
        return True

    # ---- services: each returns (ok, message) ----

    def takeoff(self) -> tuple[bool, str]:
        """Take off and hover."""
        return self.mission.takeoff()

    def inspect(self) -> tuple[bool, str]:
        """Run the inspection mission."""
        return self.mission.inspect()

    def abort(self) -> tuple[bool, str]:
        """Leave the wall or stop and hover."""
        return self.mission.abort()

    def land(self) -> tuple[bool, str]:
        """Land (retreating from the wall first)."""
        return self.mission.land()

    def set_setpoint(self, p_map: ArrayLike, yaw_rad: float) -> tuple[bool, str]:
        """Move the hover point (map) and heading; HOVER only, non-finite rejected."""
        return self.mission.set_hover_setpoint(p_map, yaw_rad)

    # ---- the tick ----

    def tick(self, t_s: float, gyro: ArrayLike, dt_s: float, accel: ArrayLike | None = None
             ) -> tuple[ActuatorCommand, dict[str, Any]]:
        """One control tick at IMU time ``t_s``; returns (ActuatorCommand, status dict).

        ``accel``: the IMU's specific force (base_link, m/s^2), for the disturbance observer.
        """
        gyro = np.asarray(gyro, dtype=float)
        if self._odom is None or not all(map(math.isfinite, gyro.tolist())):
            return self._idle_command(), self._status(t_s, np.inf, {'input_fault': True}, None)
        odom_age_s = t_s - self._odom.t_s
        truth = self._ground_truths.get(self._truth_id)
        if truth is not None:
            # the latched pose is re-stamped so the estimate stays valid
            self.estimator.add_ground_truth(t_s, *truth)
        # once the mission flies to a target it never swaps it for a look-alike
        self.estimator.locked = self.mission.mode in NEAR_WALL
        target = self.estimator.estimate(t_s)
        self.f_normal_n = self._normal_force(target)
        if (self.config.autostart and not self._autostarted and self._target_source_up
                and not self.autostart_held):
            self._autostarted = self.mission.inspect()[0]
        setpoint = self.mission.update(t_s, self._odom, target, self.f_normal_n, odom_age_s,
                                       self._f_contact_map, self._thrust_up_n)
        if self.mission.mode == Mode.IDLE:
            self._was_idle = True
            return self._idle_command(), self._status(t_s, odom_age_s, {}, target)
        if self._was_idle:
            self.flight.reset()
            self._was_idle = False
        stale = self.mission.mode == Mode.FAILSAFE_LAND and not (
            odom_age_s <= self.config.mission.failsafe.odom_stale_s)
        if stale:
            state, setpoint = self._blind(t_s, setpoint, gyro, dt_s)
        else:
            if self.setpoint_hook is not None:
                setpoint = self.setpoint_hook(setpoint)
            state = VehicleState(t_s, self._odom.p_map, self._odom.q_map_base,
                                 self._odom.v_map, gyro)
        command, diagnostics = self.flight.step(state, setpoint, self._f_contact_map, dt_s,
                                                None if stale else accel)
        f_p_map = diagnostics.get('f_p_map')
        self._thrust_up_n = None if f_p_map is None else float(f_p_map[2])
        return self._bounded(command), self._status(t_s, odom_age_s, diagnostics, target)

    # ---- helpers ----

    def _odom_rotation(self) -> NDArray[np.float64]:
        """R_map_base of the newest odometry; shared by the F/T intake and the tick."""
        if self._R_map_base is None:
            # called only with odometry: the F/T intake and the tick return early without
            assert self._odom is not None
            self._R_map_base = frames.quat_matrix(self._odom.q_map_base)
        return self._R_map_base

    def _normal_force(self, target: TargetEstimate | None) -> float:
        """Push on the wall along -normal [N] (positive pushing), from the F/T reading: along
        the normal the mission works against near the wall, else the target's."""
        normal = self.mission.normal_map
        if normal is not None:
            return float(self._f_contact_map @ normal)
        if target is not None:
            return float(self._f_contact_map @ target.normal_map)
        # no estimate: the tool axis stands for the normal
        x_tool_map = self._odom_rotation()[:, 0]
        return float(-self._f_contact_map @ x_tool_map)

    def _blind(self, t_s: float, setpoint: ImpedanceSetpoint, gyro: NDArray[np.float64],
               dt_s: float) -> tuple[VehicleState, ImpedanceSetpoint]:
        """(state, setpoint) for flying without odometry: only feed-forward acts, and never
        upwards, so the vehicle keeps descending until the ground stops it."""
        # set with the odometry, and the tick flies blind only after it had odometry
        assert self._q_blind is not None
        # not renormalised here: every consumer of the attitude normalises it
        self._q_blind = quat_multiply(self._q_blind, rotvec_to_quat(gyro * dt_s))
        p_map = setpoint.origin_map + setpoint.R_map_t @ setpoint.lambda_d_t
        v_map = setpoint.R_map_t @ setpoint.dlambda_d_t
        a_map = setpoint.R_map_t @ setpoint.ddlambda_d_t
        a_map[2] = min(a_map[2], 0.0)
        setpoint = dataclasses.replace(setpoint, ddlambda_d_t=setpoint.R_map_t.T @ a_map)
        return VehicleState(t_s, p_map, self._q_blind, v_map, gyro), setpoint

    def _idle_command(self) -> ActuatorCommand:
        """Disarmed: rotors stopped, arms level."""
        return ActuatorCommand(np.zeros(4), 0.0, 0.0)

    def _bounded(self, command: ActuatorCommand) -> ActuatorCommand:
        thrusts = command.thrusts_n.tolist()
        if not all(map(math.isfinite, thrusts + [command.alpha_rad, command.beta_rad])):
            return self.flight.safe_command()
        f_max = self.vehicle.f_max_n
        command.thrusts_n = np.array([min(max(f, 0.0), f_max) for f in thrusts])
        return command

    def _status(self, t_s: float, odom_age_s: float, diagnostics: dict[str, Any],
                target: TargetEstimate | None) -> dict[str, Any]:
        status = self.mission.status
        status.update(
            t_s=float(t_s),
            target_source=self.config.target_source,
            target_valid=bool(target is not None and target.valid),
            odom_age_s=float(odom_age_s),
            f_normal_n=self.f_normal_n,
            contact_force_n=self.mission.contact_force_n,
            saturated=bool(diagnostics.get('saturated', False)),
            input_fault=bool(diagnostics.get('input_fault', False)),
        )
        for key, value in self.estimator.counters.items():
            status['target_' + key] = value
        return status
