"""What every mode of the mission shares (as PX4's MissionBlock): the tick's context, the
transitions a mode's tick returns, the mode interface, and helpers used by several modes."""
import collections
import dataclasses
import math
import typing

import numpy as np

from uav_tilt_common.modes import Mode
from uav_tilt_common.state import VehicleState
from uav_tilt_common.vehicle import VehicleParams
from uav_tilt_control.mission.clock import Clock
from uav_tilt_control.mission.config import MissionConfig
from uav_tilt_control.mission.detectors import BumpDetector, Geofence
from uav_tilt_control.mission.records import TaskRecords
from uav_tilt_control.mission.reference import Reference, SetpointSample
from uav_tilt_control.obstacles import ObstacleBox, route
from uav_tilt_control.plan import Task
from uav_tilt_control.target_estimator import TargetEstimate


# Modes near the wall (the target is locked; abort and land retreat first).
NEAR_WALL = (Mode.APPROACH, Mode.CONTACT, Mode.HOLD, Mode.SLIDE, Mode.TARGET_LOST)
# Modes in which the reference is in the target frame t (the working frame is not map).
IN_TARGET_FRAME = NEAR_WALL + (Mode.RETREAT,)
# Modes in which the ground may carry the vehicle (ImpedanceSetpoint.airborne is False).
NEAR_GROUND = (Mode.IDLE, Mode.TAKEOFF, Mode.LAND, Mode.FAILSAFE_LAND)


# ---- transitions: what a mode's tick asks of the executor ----

@dataclasses.dataclass(frozen=True)
class Enter:
    """Go to ``mode`` (with the target estimate it is about, if any)."""

    mode: Mode
    reason: str = ''
    target: TargetEstimate | None = None


@dataclasses.dataclass(frozen=True)
class FailTask:
    """The task under way failed: back off the wall when near it, then the next task."""

    reason: str


@dataclasses.dataclass(frozen=True)
class Failsafe:
    """A vehicle failsafe: the plan ends here, and the vehicle goes to ``mode``."""

    reason: str
    mode: Mode


@dataclasses.dataclass(frozen=True)
class NextTask:
    """Fly to the plan's next task (its first after take-off), or land after the last."""


@dataclasses.dataclass(frozen=True)
class TaskDone:
    """The push ended as planned: the task succeeded, back off to the standoff."""

    reason: str


@dataclasses.dataclass(frozen=True)
class Landed:
    """On the ground: the rotors stop. ``judged``: the plan's outcome is final now (not
    after a blind descent)."""

    reason: str
    judged: bool = True


Transition = Enter | FailTask | Failsafe | NextTask | TaskDone | Landed


class Context:
    """What the modes of one mission share: its configuration and vehicle, the clock, the
    reference, the plan's task and records, the latest odometry and the detectors every
    mode reads."""

    def __init__(self, vehicle: VehicleParams, config: MissionConfig, plan: list[Task],
                 event: typing.Callable[[str], None]) -> None:
        """``event(reason)``: logs an event within the mode under way (the executor's)."""
        self.vehicle = vehicle
        self.config = config
        self.plan = plan
        self.clock = Clock()
        self.ref = Reference(vehicle, config, self.clock)
        self.tasks = TaskRecords()
        self.bump_detector = BumpDetector(config.bump)
        self.geofence = Geofence(config)
        self.state: VehicleState | None = None
        self.v_map: np.ndarray | None = None    # odometry velocity, low-passed (speed_tau_s)
        self.thrust_up_n: float | None = None
        self.t_mode_s = 0.0
        self.target_seen_s = -np.inf
        # what RETREAT does at the standoff: go to this mode, or (None) the next task
        self.after_retreat: Mode | None = Mode.LAND
        self.inspect_pending = False        # take-off for the plan: start it in HOVER
        # makes the target estimate forget a candidate SEARCH did not confirm
        self.drop_target: typing.Callable[[], None] | None = None
        self.in_contact = False
        self.push_n = 0.0                   # the push of the task under way
        self.contact_lost = 0
        self.events: collections.deque[dict[str, typing.Any]] = collections.deque(maxlen=200)
        self.event = event
        self.obstacles: list[ObstacleBox] = []     # the site's (set by the executor)

    @property
    def now_s(self) -> float:
        return self.clock.now_s

    @property
    def task(self) -> Task | None:
        """The task under way (or the last one run), None before the plan starts."""
        return self.plan[self.tasks.index] if self.tasks.index >= 0 else None

    @property
    def vehicle_state(self) -> VehicleState:
        """The latest fresh odometry (a mode ticks only once there is one)."""
        assert self.state is not None
        return self.state

    @property
    def velocity(self) -> np.ndarray:
        """The odometry velocity (map), low-passed; there once the state is."""
        assert self.v_map is not None
        return self.v_map

    def time_in_mode(self) -> float:
        return self.clock.now_s - self.t_mode_s

    def bump(self) -> np.ndarray | None:
        """The F/T force on the vehicle (map, low-passed) when the tool touched something."""
        return self.bump_detector.bump()

    def arrived(self) -> bool:
        return self.ref.arrived(self.vehicle_state, self.velocity)

    def turned(self) -> bool:
        return self.ref.turned(self.vehicle_state)

    def back_off(self, away_map: np.ndarray) -> None:
        """Fly bump.clearance_m along ``away_map`` from where the body is, not turning
        meanwhile."""
        away = np.linalg.norm(away_map)
        self.ref.plan(self.vehicle_state.p_map + away_map / away
                      * self.config.bump.clearance_m, self.config.flight.hover_speed_m_s)
        self.ref.yaw_goal = self.ref.yaw_ref
        self.event(f'touched something ({np.linalg.norm(self.bump_detector.f_contact_map):.1f}'
                   f' N): backing off')

    @property
    def keep_off_m(self) -> float:
        """How far the body keeps off an obstacle: the vehicle's reach (its tool tip ahead,
        its rotors round it) and flight.obstacle_clearance_m."""
        v = self.vehicle
        return (max(v.tool_tip_x_m, math.hypot(v.l1_m, v.l2_m))
                + self.config.flight.obstacle_clearance_m)

    def route(self, start_map: np.ndarray, goal_map: np.ndarray) -> list[np.ndarray] | None:
        """Waypoints from ``start_map`` to ``goal_map`` (the goal last) keeping
        :attr:`keep_off_m` off the site's obstacles; None when boxed in."""
        return route(start_map, goal_map, self.obstacles, self.keep_off_m)

    def target_lost(self) -> Transition | None:
        """TARGET_LOST once the target has not been seen for contact.target_lost_hold_s."""
        if self.clock.now_s - self.target_seen_s > self.config.contact.target_lost_hold_s:
            return Enter(Mode.TARGET_LOST, 'target lost')
        return None

    def track_target(self, target: TargetEstimate | None) -> None:
        """The segment lives in frame t, so a refined estimate moves the whole reference."""
        if usable(target):
            assert target is not None
            self.ref.set_target_frame(target)


class ModeBehaviour:
    """One mode of the mission (as PX4's NavigatorMode, nav2's behaviours): it owns its
    state; :meth:`enter` once on entry, :meth:`tick` every control tick, which returns the
    next transition or None."""

    mode: Mode
    # the selective (contact) gains while in this mode; None: as the mode before
    contact_gains: bool | None = False
    # sliding: the law cancels the measured friction (ImpedanceSetpoint)
    tangential_feedforward = False

    def __init__(self, ctx: Context) -> None:
        self.ctx = ctx

    @property
    def phase(self) -> str:
        """What the mode is doing within it ('' when it has no phases)."""
        return ''

    def enter(self, previous: Mode, target: TargetEstimate | None) -> None:
        """Entered from ``previous``."""

    def tick(self, target: TargetEstimate | None, f_n: float,
             stale: bool) -> Transition | None:
        """One control tick: ``target`` the estimate, ``f_n`` the push along the normal,
        ``stale`` whether the odometry is."""
        raise NotImplementedError

    def steer(self, dt_s: float) -> None:
        """Before the setpoint of this tick: move the reference's goals (a sweep)."""

    def shape(self, sample: SetpointSample) -> None:
        """Adjust the reference's sample in place for the setpoint."""

    def trim_push(self) -> bool:
        """Whether the impedance law trims the push by the measured one now."""
        return False

    def releasing(self, sample: SetpointSample) -> bool:
        """Whether the contact gains stay on for this sample although the mode's are off."""
        return False

    def progress(self) -> float | None:
        """0..1 of the task's push in this mode, None when the mode does not measure it."""
        return None


def usable(target: TargetEstimate | None) -> bool:
    """A target estimate to act on."""
    return target is not None and bool(target.valid)
