"""Inspection mission and failsafes: a plan executor that outputs ImpedanceSetpoints.

A plan is a list of tasks (uav_tilt_control.plan); today's inspection is the one-touch plan.
IDLE -> TAKEOFF -> HOVER, then per task: a touch SEARCHes for its target (after flying, in
HOVER, to look at where the plan says it is), APPROACHes it, makes CONTACT and HOLDs the
push; a slide APPROACHes the start of its line on the site's wall, makes CONTACT and
SLIDEs along the line; both RETREAT to the standoff. After the last task it LANDs -> IDLE.
TARGET_LOST holds while the target is not seen, FAILSAFE_LAND descends blind on stale
odometry (PX4's failsafes). A task that fails (its target never found or lost, no contact,
contact lost, the tool off the line or short of its end) is recorded with its reason and
the plan goes on; the force limit and stale odometry end the plan. Free flight uses the map
frame; near the wall the target frame t (z_t = surface normal). References are
uav_tilt_control.trajectory segments, so that lambda_d, dlambda_d and ddlambda_d stay
consistent. Each mode's entry and tick are in the table :data:`MODES` at the end of this
module.
"""
import collections
import dataclasses
import math
import typing

import numpy as np

from uav_tilt_common.config import ConfigError, param
from uav_tilt_common.geometry import matrix_to_euler_zyx
from uav_tilt_common.modes import Mode
from uav_tilt_common.vehicle import GRAVITY
from uav_tilt_control import frames
from uav_tilt_control.impedance import ImpedanceConfig, contact_depth_for_force
from uav_tilt_control.lowpass import lowpass_weight
from uav_tilt_control.plan import LineProgress, Slide, Touch, check_force
from uav_tilt_control.target_estimator import TargetEstimate
from uav_tilt_control.trajectory import MIN_JERK_PEAK, MinJerk, PolylineCruise, Ramp
from uav_tilt_control.types import ImpedanceSetpoint
from uav_tilt_control.walls import WallMemory

DEFAULT_CONTACT_FORCE_N = 5.0
__all__ = ['DEFAULT_CONTACT_FORCE_N', 'MODES', 'MinJerk', 'Mission', 'MissionConfig', 'Mode',
           'NEAR_WALL', 'Ramp', 'TaskRecord']


NEAR_WALL = (Mode.APPROACH, Mode.CONTACT, Mode.HOLD, Mode.SLIDE, Mode.TARGET_LOST)
# Modes in which the reference is in the target frame t (the working frame is not map).
IN_TARGET_FRAME = NEAR_WALL + (Mode.RETREAT,)
# Modes in which the ground may carry the vehicle (ImpedanceSetpoint.airborne is False).
_NEAR_GROUND = (Mode.IDLE, Mode.TAKEOFF, Mode.LAND, Mode.FAILSAFE_LAND)
# A task that did not end: the plan stopped before it, or while it ran.
NOT_RUN = 'not_run'
# TAKEOFF and LAND back off horizontally; a push whose horizontal part is below this share
# of it is vertical, with no way around it: from above (a ceiling, a wall leaning over by
# more than 70 degrees) the take-off lands, from below (the ground) the landing goes on.
HORIZONTAL_SHARE = math.sin(math.radians(20.0))
# The touch's alignment check low-passes the tool tip's offset with this time constant:
# odometry noise (a few mm at the tool's lever arm) averages out, a gust's drift does not.
ALIGN_TAU_S = 0.1


@dataclasses.dataclass
class MissionConfig:
    """Mission geometry, speeds, detection thresholds and failsafe timeouts."""

    takeoff_altitude_m: float = param(1.5, lo=0.3, hi=20.0)
    climb_speed_m_s: float = param(0.5, lo=0.05, hi=3.0)
    # a take-off that has not reached its altitude this long after its climb's own time
    # (a wall leaning over the start that its back-offs do not clear) lands
    takeoff_timeout_s: float = param(20.0, lo=0.0, hi=600.0)
    hover_speed_m_s: float = param(0.5, lo=0.05, hi=3.0)
    hover_settle_s: float = param(1.0, lo=0.0, hi=30.0)     # HOVER before SEARCH on inspect
    yaw_rate_rad_s: float = param(0.5, lo=0.05, hi=3.0)
    # the body pitch that points the tool (pitch_to_normal) turns no faster than this: a
    # step would swing the tool tip 0.45 m ahead by up to 0.2 m at the attitude loop's speed
    pitch_rate_rad_s: float = param(0.5, lo=0.05, hi=3.0)
    # SEARCH: a full turn at the takeoff altitude, one more search_climb_m higher (a wider
    # view of a tall wall) and one more search_descend_m lower (the camera looks level and
    # sees 23 degrees down: a low target on a near wall lies below the image), until a
    # candidate target is seen; it is confirmed once confirm_n of its measurements agree
    # within confirm_radius_m. One not confirmed within confirm_timeout_s is looked at
    # again from confirm_range_m (a small far target is seen in few frames), then dropped,
    # and the sweep goes on. After the three turns, the search faces the wall vision saw
    # most (vision/planes): from search_face_m in front of each end of what it saw of it,
    # at the takeoff altitude, it sweeps search_face_turn_rad across the wall (a target
    # seen far off its normal from the start is seen nearly head-on there).
    # search_timeout_s in all, then it lands. It climbs and descends only as far as keeps
    # the tool's reach (tool_tip_x_m) search_wall_clearance_m off every wall it has seen,
    # horizontally: a wall leaning over the start nears as the vehicle climbs, and a turn
    # there would swing the tool into it.
    search_yaw_rate_rad_s: float = param(0.35, lo=0.0, hi=1.0)  # 0: hover and wait
    search_climb_m: float = param(0.8, lo=0.0, hi=10.0)
    search_descend_m: float = param(0.6, lo=0.0, hi=10.0)   # not below 2 land_detect_height_m
    search_face_m: float = param(2.5, lo=0.0, hi=20.0)      # 0: no facing
    search_face_turn_rad: float = param(2.1, lo=0.1, hi=6.3)
    search_timeout_s: float = param(150.0, lo=0.5, hi=600.0)
    search_wall_clearance_m: float = param(0.3, lo=0.0, hi=5.0)
    # The tool touched something in free flight (TAKEOFF, HOVER, SEARCH, LAND: a wall
    # leaning over the start as the vehicle climbs or turns, a wall on the way to the next
    # task, one leaning away as it descends): a force on it above free_flight_contact_n
    # stops what the vehicle was doing, and it backs off free_flight_clearance_m along that
    # force (phase 'clear'; in TAKEOFF and LAND along its horizontal part, the ground being
    # below, and a push from above lands the take-off), then goes on from there: the climb,
    # the turn, the descent; a transit to the next task searches from there.
    free_flight_contact_n: float = param(1.0, lo=0.1, hi=50.0)
    # ... told by the F/T force low-passed over this: a touch lasts longer than the sensor's
    # noise, which at 0.3 N (per axis, every tick) passes 1 N several times a second.
    free_flight_contact_tau_s: float = param(0.03, lo=0.0, hi=1.0)
    free_flight_clearance_m: float = param(0.6, lo=0.05, hi=5.0)
    # A free-flight segment the vehicle has not arrived at this long after the segment's
    # own time has met something that holds it (the ground, a wall it rests on): APPROACH,
    # RETREAT and HOVER's transit land (failsafe 'unreachable'); a back-off ('clear') goes
    # on from where it got to.
    arrive_timeout_s: float = param(15.0, lo=1.0, hi=600.0)
    confirm_n: int = param(5, lo=1, hi=100, unit='',
                           doc='detections within confirm_radius_m that confirm a target')
    confirm_radius_m: float = param(0.15, lo=0.01, hi=2.0)
    confirm_timeout_s: float = param(4.0, lo=0.1, hi=60.0)
    # a candidate seen but not confirmed farther than this is looked at again from here
    confirm_range_m: float = param(2.5, lo=0.5, hi=20.0)
    standoff_m: float = param(0.6, lo=0.1, hi=5.0)          # tool tip to surface
    approach_speed_m_s: float = param(0.3, lo=0.05, hi=2.0)
    pitch_to_normal: bool = param(True)                     # align the tool with the normal
    max_pitch_rad: float = param(0.5, lo=0.0, hi=1.0)
    # CONTACT: close in to touch_margin_m before the estimated surface at up to
    # contact_speed_m_s, creep on at touch_speed_m_s until the F/T feels the wall, then
    # press: the push ramps up to the setpoint over press_time_s. A vehicle of mass M
    # arriving at v on a wall of stiffness k meets a peak of about v sqrt(k M): 2.8 N at
    # 1 cm/s on 50,000 N/m for 1.6 kg, so the touch stays under 1.5x a 5 N setpoint.
    contact_speed_m_s: float = param(0.2, lo=0.01, hi=0.5)
    touch_margin_m: float = param(0.05, lo=0.0, hi=0.5)
    touch_speed_m_s: float = param(0.01, lo=0.001, hi=0.2)
    # creep past the estimate, at most (or to the depth that pushes with twice the touch's
    # threshold, if deeper)
    touch_overrun_m: float = param(0.1, lo=0.0, hi=1.0)
    touch_threshold_n: float = param(0.4, lo=0.05, hi=20.0)  # the first touch
    # ... or this many times the F/T's noise if more: the RMS of its normal reading over the
    # approach, in free flight. On two ticks in a row, 4 sigma is passed by noise once in
    # 10^9 ticks; 0.4 N is 4 sigma of 0.1 N, and a noisier sensor needs a firmer touch.
    touch_noise_sigmas: float = param(4.0, lo=0.0, hi=20.0)
    # Friction holds the tool where it first touches (mu F_c is far above what the contact
    # stiffness along the wall pulls with): the creep pauses while the tool tip (odometry)
    # is more than touch_align_m off the target in the wall's plane (a gust), for at most
    # touch_align_wait_s in all, and backs the tool tip out to touch_align_clearance_m from
    # the surface meanwhile (a gust towards the wall would make the touch there, off the
    # target). 0 turns the pause off.
    touch_align_m: float = param(0.004, lo=0.0, hi=0.1)
    touch_align_wait_s: float = param(5.0, lo=0.0, hi=60.0)
    touch_align_clearance_m: float = param(0.01, lo=0.0, hi=0.5)
    press_time_s: float = param(2.0, lo=0.1, hi=30.0)
    # HOLD: the measured push corrects the depth with this time constant, so that a soft
    # wall (which gives way) still gets the setpoint; 0 disables the correction.
    force_tau_s: float = param(0.5, lo=0.0, hi=60.0)
    contact_threshold_n: float = param(1.0, lo=0.05, hi=20.0)  # in contact while pressing
    contact_detect_ticks: int = param(2, lo=1, hi=100)
    contact_lost_s: float = param(0.1, lo=0.0, hi=5.0)
    hold_time_s: float = param(5.0, lo=0.0, hi=600.0)
    force_limit_n: float = param(15.0, lo=1.0, hi=100.0)
    # Tool tip nearer the surface than this: the tool hides the POI from the eye-in-hand
    # camera, so CONTACT keeps the last target frame (the target is static) instead of
    # calling the target lost.
    tool_occlusion_range_m: float = param(0.15, lo=0.0, hi=2.0)
    target_lost_hold_s: float = param(0.5, lo=0.05, hi=60.0)
    target_lost_retreat_s: float = param(3.0, lo=0.1, hi=600.0)
    odom_stale_s: float = param(0.1, lo=0.005, hi=5.0)
    descent_rate_m_s: float = param(0.3, lo=0.05, hi=2.0)
    failsafe_descent_rate_m_s: float = param(0.2, lo=0.05, hi=2.0)
    failsafe_land_margin_s: float = param(2.0, lo=0.0, hi=60.0)  # blind: after the descent
    ground_z_m: float = param(0.0, lo=-100.0, hi=100.0)
    land_detect_height_m: float = param(0.3, lo=0.0, hi=2.0)  # above ground_z_m
    # Geofence (as PX4's GF_MAX_HOR_DIST and GF_MAX_VER_DIST): a hover setpoint farther than
    # this from where the vehicle took off, or higher above ground_z_m, is refused.
    fence_radius_m: float = param(100.0, lo=1.0, hi=1e4)
    fence_height_m: float = param(30.0, lo=1.0, hi=1e3)
    land_detect_speed_m_s: float = param(0.1, lo=0.01, hi=1.0)
    land_detect_s: float = param(0.5, lo=0.0, hi=10.0)
    # Landed above ground_z_m (a roof) only while the vertical thrust asked for is below this
    # fraction of the nominal weight (as PX4's LNDMC_LOW_T_THR): a vehicle that keeps still
    # in the air makes its own weight, at least half the nominal one (the scenarios' range).
    land_detect_thrust_ratio: float = param(0.3, lo=0.0, hi=1.0)
    # Arrival and landing ask whether the vehicle is still, which is its mean speed over a
    # while, not one odometry sample: they read the velocity low-passed over this (noise of
    # 0.05 m/s per axis puts a third of the samples over 0.1 m/s).
    speed_tau_s: float = param(0.1, lo=0.0, hi=2.0)
    # Upset (as PX4's failure detector): tilted past upset_tilt_rad for upset_s, the rotors
    # stop (failsafe `upset`); upside down they would only drive the vehicle into what is
    # near. Missions tilt to 26 degrees at most (60 campaign draws; roll limit 34); a vehicle
    # that lost a rotor tumbles, each half turn past 60 degrees for about 0.3 s.
    upset_tilt_rad: float = param(1.05, lo=0.3, hi=3.2)
    upset_s: float = param(0.1, lo=0.0, hi=10.0)
    arrive_tol_m: float = param(0.05, lo=0.001, hi=1.0)
    arrive_speed_m_s: float = param(0.1, lo=0.001, hi=1.0)
    arrive_yaw_tol_rad: float = param(0.05, lo=0.001, hi=1.0)
    # Between tasks: a touch's target is looked for from this far in front of where the plan
    # says it is (base_link to the wall, on its normal), so that the camera sees it at once.
    look_distance_m: float = param(1.5, lo=0.3, hi=20.0)
    # SLIDE: the tool tip's speed rises to the task's and comes down at the end of each leg
    # with at most this acceleration; the task fails once the tool tip (odometry) is this far
    # off the line, in the wall's plane, or ends this far short of the line's end, along it.
    slide_accel_m_s2: float = param(0.1, lo=0.005, hi=2.0)
    slide_path_tolerance_m: float = param(0.05, lo=0.001, hi=1.0)

    def lowest_hover_m(self):
        """The lowest altitude the mission hovers, searches or works at: twice the landing
        detector's height above the ground, clear of it."""
        return self.ground_z_m + 2.0 * self.land_detect_height_m


@dataclasses.dataclass
class TaskRecord:
    """How a task went: ``success`` (None while it runs or before), the reason it failed,
    contact losses, and when it ran and pushed (HOLD or SLIDE), sim time."""

    kind: str
    target: str
    success: bool | None = None
    reason: str = ''
    contact_lost: int = 0
    t_start_s: float | None = None
    t_end_s: float | None = None
    t_contact_s: list | None = None      # [start, end] of HOLD or SLIDE

    def outcome(self):
        """'ok', the failure reason, or '' while not ended."""
        if self.success is None:
            return ''
        return 'ok' if self.success else self.reason


class TargetFrame(typing.NamedTuple):
    """The target frame t built from one target estimate (the estimate is its key)."""

    key: tuple
    R_map_t: np.ndarray
    origin_map: np.ndarray
    pitch_rad: float        # the body pitch that points the tool along -z_t, within limits
    # What the body's reference shifts in the wall's plane (frame t) so that the tool tip
    # still meets the target when the pitch limit keeps the tool off the normal (x_t, y_t, 0)
    tool_shift_t: np.ndarray


class Persistence:
    """Whether a condition has held for a while (PX4's systemlib::Hysteresis, one way):
    :meth:`update` each tick says so once it has held ``hold_s`` since it began."""

    def __init__(self):
        self.since_s = None

    def reset(self):
        self.since_s = None

    def update(self, holds, now_s, hold_s):
        if not holds:
            self.since_s = None
            return False
        if self.since_s is None:
            self.since_s = now_s
            return False
        return now_s - self.since_s >= hold_s


class SearchState:
    """Where SEARCH is: its phase, the turn swept so far, the candidate being confirmed."""

    def __init__(self):
        self.phase = 'sweep'
        self.level = 0
        self.swept_rad = 0.0
        self.turn_rad = 2.0 * math.pi   # what this sweep turns
        self.walls = WallMemory()
        self.face_points = None         # the points to face the wall from, once planned
        self.face_yaw = 0.0
        self.resume_phase = 'sweep'
        self.since_s = 0.0
        self.ignore_until_s = -math.inf
        self.agreeing = 0
        self.moved_closer = False
        self.position = None
        self._last_stamp_s = None

    def candidate(self, now_s, target):
        """Start confirming the target estimate ``target``."""
        self.resume_phase = self.phase
        self.phase = 'confirm'
        self.since_s = now_s
        self.agreeing = 0
        self.moved_closer = False
        self.position = np.asarray(target[0], dtype=float).copy()
        self._last_stamp_s = None

    def observe(self, now_s, target, radius_m):
        """Count a new measurement of the candidate (a newer stamp) that agrees with the one
        before; one elsewhere starts the count again from there."""
        stamp = now_s - target[2]
        if self._last_stamp_s is not None and stamp <= self._last_stamp_s + 1e-9:
            return
        self._last_stamp_s = stamp
        if np.linalg.norm(np.asarray(target[0]) - self.position) > radius_m:
            self.agreeing = 0
        self.position = np.asarray(target[0], dtype=float).copy()
        self.agreeing += 1


class Mission:
    """Plan executor; call :meth:`update` every control tick."""

    def __init__(self, vehicle, config=None, contact_force_n=DEFAULT_CONTACT_FORCE_N,
                 k_contact_z_n_per_m=None, drop_target=None, plan=None, on_task=None):
        """``k_contact_z_n_per_m``: the impedance law's contact K_z, which turns the wanted
        push into a depth (default: that of the default ImpedanceConfig for the vehicle);
        ``drop_target()``: makes the target estimate forget a candidate SEARCH did not
        confirm (the estimator's reset); ``plan``: the tasks (uav_tilt_control.plan) that
        :meth:`inspect` runs, by default one touch of the target with ``contact_force_n``
        for ``hold_time_s``; ``on_task(task)``: called as each task starts (the estimator
        then aims at the task's target)."""
        self.vehicle = vehicle
        self.config = config or MissionConfig()
        if k_contact_z_n_per_m is None:
            k_contact_z_n_per_m = ImpedanceConfig().contact.k_c(vehicle.mass_kg)[0][2]
        self.contact_force_n = float(contact_force_n)
        self.k_contact_z_n_per_m = float(k_contact_z_n_per_m)
        check_force("parameter 'contact_force'", self.contact_force_n,
                    (self.config.contact_threshold_n, self.config.force_limit_n,
                     'mission.contact_threshold_n, mission.force_limit_n'))
        if self.config.target_lost_retreat_s <= self.config.target_lost_hold_s:
            raise ConfigError(
                f"parameter 'target_lost_retreat_s' = {self.config.target_lost_retreat_s!r} "
                f"must exceed target_lost_hold_s = {self.config.target_lost_hold_s!r}")
        self.plan = list(plan) if plan is not None else [
            Touch('', None, None, self.contact_force_n, self.config.hold_time_s)]
        self._on_task = on_task
        self._mode = Mode.IDLE
        self._now_s = None
        self._t_mode_s = 0.0
        self._state = None
        self._odom_age_s = np.inf
        self._thrust_up_n = None
        self._R_map_t = np.eye(3)
        self._origin_map = np.zeros(3)
        self._target_frame = None       # TargetFrame of the last estimate used
        self._traj = None
        self._yaw_ref = 0.0
        self._yaw_goal = 0.0
        self._pitch_goal = self._pitch_ref = 0.0
        self._tool_shift_t = np.zeros(3)   # TargetFrame.tool_shift_t while frame t is worked in
        self._contact_gains = False
        self._inspect_pending = False
        self._after_retreat = Mode.LAND     # None: the plan's next task
        self._resume_mode = Mode.APPROACH
        self._target_seen_s = -np.inf
        self._last_tick_s = None
        self._landing = Persistence()
        self._upset = Persistence()
        self._contact_ticks = 0
        self._contact_phase = ''       # CONTACT: 'close', 'touch', 'press'
        self._approach_f_n = (0.0, 0)   # sum of squares and count of the F/T's normal reading
        self._aligning = False         # CONTACT touch: the creep paused (touch_align_m)
        self._align_waited_s = 0.0
        self._align_off_t = None        # the tool tip off the target (x_t, y_t), filtered
        self._flight_phase = ''        # TAKEOFF, HOVER, LAND: 'clear'; HOVER 'transit'
        self._takeoff_deadline_s = math.inf
        self._drop_target = drop_target
        self._search = SearchState()
        self._depth_correction_m = 0.0  # HOLD, SLIDE: from the push error (along -z_t)
        self.first_touch_peak_n = 0.0
        self._no_force_since_s = None
        self._in_contact = False
        self._f_contact_map = np.zeros(3)   # F/T force on the vehicle, map, low-passed
        self._v_map = None                  # odometry velocity, low-passed (speed_tau_s)
        self._task_index = -1
        self._records = []
        self.plan_version = 0           # changes whenever a task record does
        self._completed = False
        self._success = False
        self._failsafe_reason = ''
        self.contact_lost = 0
        self.rejected_setpoints = 0
        self.refused_setpoints = 0      # good ones, sent while the mode takes none
        self._home_map = None           # where it last took off (the geofence's centre)
        self.events = collections.deque(maxlen=200)

    @property
    def mode(self):
        """Current :class:`Mode`."""
        return self._mode

    @property
    def phase(self):
        """What the mode is doing: SEARCH 'sweep', 'climb', 'descend', 'face', 'confirm',
        'closer', 'clear' (backing off what the tool touched); CONTACT 'close', 'touch'
        ('align' while the creep waits for the tool tip to come back over the target),
        'press'; HOVER 'transit' (to the next task), 'clear'; TAKEOFF and LAND 'clear'; ''
        otherwise."""
        if self._mode == Mode.SEARCH:
            return self._search.phase
        if self._mode in (Mode.TAKEOFF, Mode.HOVER, Mode.LAND):
            return self._flight_phase
        if self._mode != Mode.CONTACT:
            return ''
        return 'align' if self._contact_phase == 'touch' and self._aligning else \
            self._contact_phase

    @property
    def task(self):
        """The task under way (or the last one run), None before the plan starts."""
        return self.plan[self._task_index] if self._task_index >= 0 else None

    @property
    def records(self):
        """One :class:`TaskRecord` per task of the plan under way (empty before)."""
        return list(self._records)

    @property
    def normal_map(self):
        """The surface normal the mission works against (z_t) near the wall, else None."""
        return self._R_map_t[:, 2].copy() if self._mode in IN_TARGET_FRAME else None

    @property
    def status(self):
        """Mode, time in mode, failsafe reason, outcome, and the task under way."""
        task = self.task
        return dict(
            mode=self._mode.value,
            phase=self.phase,
            time_in_mode_s=0.0 if self._now_s is None else self._now_s - self._t_mode_s,
            failsafe_reason=self._failsafe_reason,
            inspection_completed=self._completed,
            success=self._success,
            contact_lost=self.contact_lost,
            in_contact=self._in_contact,
            rejected_setpoints=self.rejected_setpoints,
            refused_setpoints=self.refused_setpoints,
            task_index=self._task_index,
            task_count=len(self.plan),
            task_kind='' if task is None else task.kind,
            task_target='' if task is None else task.target,
            task_progress=self._task_progress(),
            task_outcomes=','.join(r.outcome() for r in self._records if r.outcome()),
        )

    # ---- commands (std_srvs/Trigger later): each returns (accepted, message) ----

    def takeoff(self):
        """IDLE -> TAKEOFF, then HOVER."""
        ok, why = self._can_arm()
        if not ok:
            return False, why
        self._inspect_pending = False
        self._enter(Mode.TAKEOFF)
        return True, 'taking off'

    def inspect(self):
        """Run the plan: from IDLE take off first, from HOVER start its first task."""
        if self._mode == Mode.HOVER:
            self._start_plan()
            self._start_task(0)
            return True, f'starting the plan ({len(self.plan)} tasks)'
        if self._inspect_pending or self._plan_running():
            where = (f'task {self._task_index + 1} of {len(self.plan)}'
                     if self._task_index >= 0 else 'taking off first')
            return False, (f'the plan is already under way ({where}, {self._mode.value}); '
                           f'abort stops it')
        ok, why = self._can_arm()
        if not ok:
            return False, why
        self._start_plan()
        self._inspect_pending = True
        self._enter(Mode.TAKEOFF)
        return True, 'taking off for inspection'

    def abort(self):
        """Stop the plan: leave the wall (RETREAT) when near it, else stop and HOVER (land
        when still too low to hover)."""
        self._inspect_pending = False
        if self._at_wall():
            self._stop_plan('aborted')
            self._after_retreat = Mode.HOVER
            if self._mode != Mode.RETREAT:
                self._enter(Mode.RETREAT, 'abort')
            return True, 'retreating from the wall'
        if self._mode in (Mode.TAKEOFF, Mode.SEARCH, Mode.LAND, Mode.HOVER, Mode.APPROACH):
            self._stop_plan('aborted')
            if self._mode == Mode.TAKEOFF and \
                    self._ref_map()[0][2] < self.config.lowest_hover_m():
                # HOVER here would leave the rotors running on the ground
                self._enter(Mode.LAND, 'abort below the lowest hover')
                return True, 'landing: too low to hover'
            if self._mode != Mode.HOVER:
                self._enter(Mode.HOVER, 'abort')
            elif self._flight_phase:
                self._flight_phase = ''     # stop the transit (or back-off) where it is
                self._plan(self._ref_map()[0], self.config.hover_speed_m_s)
            return True, 'hovering'
        return False, f'nothing to abort in {self._mode.value}'

    def land(self):
        """Stop the plan and land here; near the wall retreat first."""
        self._inspect_pending = False
        if self._at_wall():
            self._stop_plan('land_requested')
            self._after_retreat = Mode.LAND
            if self._mode != Mode.RETREAT:
                self._enter(Mode.RETREAT, 'land requested')
            return True, 'retreating, then landing'
        if self._mode in (Mode.TAKEOFF, Mode.HOVER, Mode.SEARCH, Mode.LAND, Mode.APPROACH):
            self._stop_plan('land_requested')
            if self._mode != Mode.LAND:
                self._enter(Mode.LAND)
            return True, 'landing'
        return False, f'cannot land from {self._mode.value}'

    def set_hover_setpoint(self, p_map, yaw_rad):
        """Move the hover point (map, ENU) and heading; only in HOVER."""
        p = np.asarray(p_map, dtype=float)
        if p.shape != (3,) or not (np.all(np.isfinite(p)) and np.isfinite(yaw_rad)):
            self.rejected_setpoints += 1
            return False, 'setpoint must be 3 finite coordinates and a finite yaw'
        lowest_m = self.config.lowest_hover_m()
        if p[2] < lowest_m:
            self.rejected_setpoints += 1
            return False, (f'setpoint z {p[2]:g} m is below the lowest hover, {lowest_m:g} m '
                           f'(ground_z_m + 2 land_detect_height_m; land to go lower)')
        outside = self._outside_fence(p)
        if outside:
            self.rejected_setpoints += 1
            return False, f'setpoint {p.tolist()} is outside the geofence: {outside}'
        if self._mode != Mode.HOVER or self._flight_phase:
            self.refused_setpoints += 1
            return False, f'setpoints are accepted in HOVER only, not {self._mode.value}' + (
                f' ({self._flight_phase})' if self._flight_phase else '')
        self._plan(p, self.config.hover_speed_m_s)
        self._yaw_goal = float(yaw_rad)
        return True, 'setpoint accepted'

    def _at_wall(self):
        """Working at the wall, where abort and land retreat first: a mode near it, but an
        approach only once within the standoff (RETREAT's goal); farther out, retreating
        would fly on towards the wall."""
        if self._mode == Mode.APPROACH:
            return self._ref_t()[0][2] <= self._standoff_t()[2] + self.config.arrive_tol_m
        return self._mode in NEAR_WALL or self._mode == Mode.RETREAT

    def _outside_fence(self, p_map):
        """Why ``p_map`` is outside the geofence (mission.fence_*), or ''."""
        cfg = self.config
        if p_map[2] - cfg.ground_z_m > cfg.fence_height_m:
            return f'{p_map[2] - cfg.ground_z_m:g} m above the ground (fence_height_m ' \
                   f'{cfg.fence_height_m:g})'
        if self._home_map is not None:
            radius_m = float(np.hypot(*(p_map[:2] - self._home_map[:2])))
            if radius_m > cfg.fence_radius_m:
                return f'{radius_m:g} m from the take-off (fence_radius_m {cfg.fence_radius_m:g})'
        return ''

    # ---- the tick ----

    def observe_plane(self, point_map, normal_map, share):
        """A plane vision saw (map; share of its frame): SEARCH remembers the walls."""
        if self._mode == Mode.SEARCH:
            self._search.walls.observe(point_map, normal_map, share)

    def update(self, now_s, state, target, f_contact_n, odom_age_s, f_contact_map=None,
               thrust_up_n=None):
        """One control tick: returns the ImpedanceSetpoint for the impedance law.

        ``target``: TargetEstimate(p_poi_map, normal_map, age_s, valid) or None;
        ``f_contact_n``: force along the normal from the F/T sensor, positive pushing;
        ``odom_age_s``: age of the odometry in ``state``; ``f_contact_map``: the F/T's
        whole force on the vehicle in map (N), which SEARCH backs away along;
        ``thrust_up_n``: the vertical thrust (map z, N) the flight core asked for on the
        tick before, which tells a landing on something higher from a hover (None: unknown,
        so no such landing is declared).
        """
        cfg = self.config
        self._now_s = float(now_s)
        self._thrust_up_n = thrust_up_n
        self._odom_age_s = float(odom_age_s)
        stale = not (odom_age_s <= cfg.odom_stale_s and _finite_state(state))
        dt_s = self._tick_dt_s()
        if not stale:
            self._state = state
            v_map = np.asarray(state.v_map, dtype=float)
            self._v_map = v_map if self._v_map is None else self._v_map + lowpass_weight(
                dt_s, cfg.speed_tau_s) * (v_map - self._v_map)
        if self._state is None:
            return ImpedanceSetpoint()
        if stale and self._mode not in (Mode.IDLE, Mode.FAILSAFE_LAND):
            self._failsafe('odometry_stale', Mode.FAILSAFE_LAND)
        elif not stale:
            self._check_upset()
        if isinstance(self.task, Slide) and self._mode in IN_TARGET_FRAME:
            # a slide's line is on the site's wall: no detection, the touch finds the surface
            target = TargetEstimate(self.task.points_map[0], self.task.normal_map, 0.0, True)
        if self._target_usable(target):
            self._target_seen_s = max(self._target_seen_s, now_s - target[2])
        # a broken F/T reading cannot prove contact, nor trip the force limit
        f_n = float(f_contact_n) if math.isfinite(f_contact_n) else 0.0
        if self._mode in NEAR_WALL and f_n > cfg.force_limit_n:
            self._failsafe('force_limit', Mode.RETREAT)
        f_map = np.zeros(3) if f_contact_map is None or not np.all(
            np.isfinite(f_contact_map)) else np.asarray(f_contact_map, dtype=float)
        self._f_contact_map = self._f_contact_map + lowpass_weight(
            dt_s, cfg.free_flight_contact_tau_s) * (f_map - self._f_contact_map)
        MODES[self._mode].tick(self, target, f_n, stale)
        return self._setpoint()

    # ---- the plan ----

    def _start_plan(self):
        self._completed = False
        self._success = False
        self._failsafe_reason = ''
        self.contact_lost = 0
        self._target_seen_s = -np.inf
        self._task_index = -1
        self._records = [TaskRecord(task.kind, task.target) for task in self.plan]
        self.plan_version += 1

    def _plan_running(self):
        return 0 <= self._task_index < len(self._records) and \
            self._records[self._task_index].success is None

    def _start_task(self, index):
        """Fly to task ``index`` (free flight), or land after the last one."""
        cfg = self.config
        self._task_index = min(index, len(self.plan) - 1)
        if index >= len(self.plan):
            self._completed = all(r.success for r in self._records)
            self._after_retreat = Mode.LAND
            self._enter(Mode.LAND, 'plan complete')
            return
        task = self.plan[index]
        record = self._records[index]
        record.t_start_s = self._now_s
        self.plan_version += 1
        self.contact_force_n = float(task.force_n)
        self._target_seen_s = -np.inf
        self._event(f'task {index} ({task.kind}) started')
        if self._on_task is not None:
            self._on_task(task)
        if isinstance(task, Slide):
            self._enter(Mode.APPROACH, f'task {index}: to the line',
                        target=TargetEstimate(task.points_map[0], task.normal_map, 0.0, True))
        elif task.hint_map is not None and task.normal_map is not None:
            # look at where the plan says the target is, facing the wall, then search
            look = task.hint_map + task.normal_map * cfg.look_distance_m
            look[2] = max(look[2], self.config.lowest_hover_m())
            if self._mode != Mode.HOVER:
                self._enter(Mode.HOVER, f'task {index}: to its target')
            self._flight_phase = 'transit'
            self._plan(look, cfg.hover_speed_m_s)
            # The camera looks at the hint: along the normal (down at a wall leaning away),
            # or, where the ground raised the look point (a low target on a wall leaning
            # over), down from there rather than up along the normal and over the target.
            view = look - task.hint_map
            self._yaw_goal = frames.yaw_facing(view, default_rad=self._yaw_ref)
            pitch = frames.pitch_facing(view) if cfg.pitch_to_normal else 0.0
            self._pitch_goal = min(max(pitch, -cfg.max_pitch_rad), cfg.max_pitch_rad)
        else:
            self._enter(Mode.SEARCH)

    def _end_task(self, success, reason=''):
        """Record how the task under way ended."""
        if not self._plan_running():
            return
        record = self._records[self._task_index]
        if record.t_contact_s and record.t_contact_s[1] is None:
            record.t_contact_s[1] = self._now_s
        record.success = bool(success) and record.contact_lost == 0
        record.reason = reason or ('contact_lost' if record.contact_lost else '')
        record.t_end_s = self._now_s
        self.plan_version += 1

    def _fail_task(self, reason):
        """The task under way failed: back off the wall when near it, then the next task."""
        self._failsafe_reason = reason
        self._end_task(False, reason)
        self._event(reason)
        if self._mode in NEAR_WALL:
            self._after_retreat = None
            self._enter(Mode.RETREAT, reason)
        else:
            self._start_task(self._task_index + 1)

    def _stop_plan(self, reason):
        """End the plan here: the task under way and those after it did not run."""
        if self._plan_running():
            self._end_task(False, reason)
        for record in self._records[self._task_index + 1:]:
            if record.success is None:
                record.success, record.reason = False, NOT_RUN
        self.plan_version += 1

    def _task_progress(self):
        """0..1 of the task under way: the hold's time, the line's length."""
        if self._mode == Mode.HOLD and self.task is not None and self.task.hold_s > 0.0:
            return min(self._time_in_mode() / self.task.hold_s, 1.0)
        if self._mode == Mode.SLIDE:
            return self._traj.progress(self._now_s)
        record = self._records[self._task_index] if 0 <= self._task_index < len(
            self._records) else None
        return 1.0 if record is not None and record.t_contact_s and record.t_contact_s[1] \
            is not None else 0.0

    # ---- per-mode logic (see MODES) ----

    def _tick_idle(self, target, f_n, stale):
        # keep the reference on the vehicle so that a takeoff starts from where it is
        self._traj = MinJerk(self._now_s, self._state.p_map, self._state.p_map, 1.0)
        self._yaw_ref = self._yaw_goal = _yaw_of(self._state)

    def _enter_takeoff(self, previous, target):
        cfg = self.config
        p_meas = self._state.p_map
        self._home_map = p_meas.copy()
        goal = np.array([p_meas[0], p_meas[1], cfg.takeoff_altitude_m])
        self._to_map()
        self._traj = MinJerk(self._now_s, p_meas, goal, cfg.climb_speed_m_s)
        self._takeoff_deadline_s = self._now_s + self._traj.T + cfg.takeoff_timeout_s

    def _tick_takeoff(self, target, f_n, stale):
        cfg = self.config
        vertical = self._clear_vertically(cfg.takeoff_altitude_m, cfg.climb_speed_m_s)
        if self._now_s > self._takeoff_deadline_s:
            self._failsafe('takeoff_timeout', Mode.LAND)
        elif vertical is not None and vertical[2] < 0.0:
            self._failsafe('takeoff_blocked', Mode.LAND)
        elif not self._flight_phase and self._arrived():
            self._enter(Mode.HOVER)

    def _clear_vertically(self, z_goal_m, speed_m_s):
        """TAKEOFF and LAND, every tick: back off horizontally what the tool touched (the
        ground is below), then climb or descend on to ``z_goal_m`` from there. Returns a push
        too vertical to back off along (see HORIZONTAL_SHARE), else None."""
        push = self._bump()
        if push is not None and self._flight_phase != 'clear':
            away = push * [1.0, 1.0, 0.0]
            if np.linalg.norm(away) < HORIZONTAL_SHARE * np.linalg.norm(push):
                return push
            self._flight_phase = 'clear'
            self._back_off(away)
        elif self._flight_phase == 'clear' and (self._arrived() or self._overdue()):
            self._flight_phase = ''
            p = self._ref_map()[0]
            self._plan(np.array([p[0], p[1], z_goal_m]), speed_m_s)
        return None

    def _enter_hover(self, previous, target):
        self._flight_phase = ''
        self._to_map()
        self._plan(self._ref_map()[0], self.config.hover_speed_m_s)
        self._yaw_goal = self._yaw_ref

    def _tick_hover(self, target, f_n, stale):
        cfg = self.config
        push = self._bump()
        if push is not None and self._flight_phase != 'clear':
            self._flight_phase = 'clear'
            self._back_off(push)
        elif self._flight_phase == 'clear':
            if self._arrived() or self._overdue():
                self._flight_phase = ''
                if self._plan_running():
                    # in HOVER a task runs only in transit to its target: look from here
                    self._enter(Mode.SEARCH, 'searching from where it backed off')
        elif self._flight_phase == 'transit':
            if self._arrived() and self._turned():
                self._flight_phase = ''
                self._enter(Mode.SEARCH)
            elif self._overdue():
                self._failsafe('unreachable', Mode.LAND)
        elif self._inspect_pending and self._time_in_mode() >= cfg.hover_settle_s:
            self._inspect_pending = False
            self._start_task(0)

    def _enter_search(self, previous, target):
        self._enter_hover(previous, target)
        self._search = SearchState()

    def _tick_search(self, target, f_n, stale):
        cfg, search = self.config, self._search
        push = self._bump()
        if self._time_in_mode() > cfg.search_timeout_s:
            self._fail_task('target_not_found')
        elif push is not None and search.phase != 'clear':
            # turn on from where it backed off (a climb, or a flight to face the wall, that
            # met the wall ends there)
            if search.phase in ('climb', 'descend', 'face'):
                search.swept_rad = 0.0      # its turn is still to come
            search.phase = 'clear'
            self._back_off(push)
        elif search.phase == 'clear':
            if self._arrived() or self._overdue():
                search.phase = 'sweep'
        elif search.phase in ('confirm', 'closer'):
            self._tick_confirm(target)
        elif self._target_usable(target) and self._now_s >= search.ignore_until_s:
            search.candidate(self._now_s, target)
            self._event('candidate target')
            # face it: the detector sees it best in the middle of the image
            d = target[0] - self._state.p_map
            self._yaw_goal = math.atan2(d[1], d[0])
        elif search.phase == 'sweep' and search.swept_rad >= search.turn_rad:
            if not (search.face_points is None and self._next_level()) \
                    and not self._face_next():
                self._fail_task('target_not_found')
        elif search.phase in ('climb', 'descend') and self._arrived():
            search.phase, search.swept_rad = 'sweep', 0.0
        elif search.phase == 'face' and self._arrived():
            # turn to one side of the wall first, then sweep across it
            self._yaw_goal = search.face_yaw - 0.5 * search.turn_rad
            if abs(frames.wrap_angle(self._yaw_goal - self._yaw_ref)) < cfg.arrive_yaw_tol_rad:
                search.phase, search.swept_rad = 'sweep', 0.0

    def _next_level(self):
        """Climb or descend to the next altitude to turn at, or as near it as the walls
        seen let the tool's reach keep search_wall_clearance_m off them (a level that
        leaves no room to move is passed over); False when no level is left."""
        cfg, search = self.config, self._search
        levels = self._search_altitudes_m()
        p = self._ref_map()[0]
        lo, hi = search.walls.altitudes_clear_of(
            p, self.vehicle.tool_tip_x_m + cfg.search_wall_clearance_m)
        while search.level + 1 < len(levels):
            search.level += 1
            # not further into a wall's reach than it already is
            z = min(max(levels[search.level], min(lo, p[2])), max(hi, p[2]))
            if abs(z - p[2]) <= cfg.arrive_tol_m:
                continue
            search.phase = 'climb' if z > p[2] else 'descend'
            self._plan(np.array([p[0], p[1], z]), cfg.climb_speed_m_s)
            self._event(('climbing' if search.phase == 'climb' else 'descending')
                        + f' to search at {z:.2f} m'
                        + ('' if z == levels[search.level] else ', clear of a wall'))
            return True
        return False

    def _face_next(self):
        """Fly to the next point to face the wall from (planned from the wall seen most
        on the first call); False when there is none."""
        cfg, search = self.config, self._search
        if search.face_points is None:
            wall = search.walls.best() if cfg.search_face_m > 0.0 else None
            if wall is None:
                return False
            points, search.face_yaw = wall.face_points(
                cfg.search_face_m, cfg.takeoff_altitude_m, cfg.search_face_m)
            p = self._ref_map()[0]
            search.face_points = sorted(points, key=lambda q: float(np.linalg.norm(q - p)))
        if not search.face_points:
            return False
        goal = search.face_points.pop(0)
        search.phase, search.turn_rad = 'face', cfg.search_face_turn_rad
        self._plan(goal, cfg.hover_speed_m_s)
        self._yaw_goal = search.face_yaw - 0.5 * search.turn_rad
        self._event('facing the wall from ({:.2f}, {:.2f}, {:.2f})'.format(*goal))
        return True

    def _search_altitudes_m(self):
        """The altitudes SEARCH turns at, in turn: takeoff, higher, lower."""
        cfg = self.config
        low = max(cfg.takeoff_altitude_m - cfg.search_descend_m, self.config.lowest_hover_m())
        return (cfg.takeoff_altitude_m, cfg.takeoff_altitude_m + cfg.search_climb_m, low)

    def _tick_confirm(self, target):
        """Hold and watch a candidate: confirmed after confirm_n agreeing measurements."""
        cfg, search = self.config, self._search
        if search.phase == 'closer':
            if self._arrived():
                search.phase, search.since_s = 'confirm', self._now_s
            return
        if self._target_usable(target):
            search.observe(self._now_s, target, cfg.confirm_radius_m)
            if search.agreeing >= cfg.confirm_n:
                self._enter(Mode.APPROACH, 'target confirmed', target=target)
                return
        if self._now_s - search.since_s <= cfg.confirm_timeout_s:
            return
        away = search.position - self._state.p_map
        away[2] = 0.0
        distance = float(np.linalg.norm(away))
        if search.agreeing and not search.moved_closer and \
                distance > cfg.confirm_range_m + cfg.arrive_tol_m:
            search.phase, search.moved_closer = 'closer', True
            p = self._ref_map()[0]
            self._plan(p + away * (1.0 - cfg.confirm_range_m / distance), cfg.hover_speed_m_s)
            self._event('closer to the candidate')
            return
        if self._drop_target is not None:
            self._drop_target()
        # turn on for a while before looking at candidates again
        search.phase, search.ignore_until_s = search.resume_phase, self._now_s + 1.5
        self._event('candidate dropped')

    def _enter_approach(self, previous, target):
        self._approach_f_n = (0.0, 0)
        ref_map = self._ref_map()
        self._set_target_frame(target)
        self._plan_t(self._standoff_t(), self.config.approach_speed_m_s, ref_map)

    def _tick_approach(self, target, f_n, stale):
        # On the way to the standoff the target may leave the view (a wall seen at an angle,
        # the turn to face it, a grazing look the detector misses): it is static and its
        # estimate locked, so the segment goes on. It is lost only if the vehicle, at the
        # standoff and facing it, still does not see it.
        self._track_target(target)
        total, n = self._approach_f_n
        self._approach_f_n = (total + f_n * f_n, n + 1)
        if self._arrived() and self._turned():
            if not self._check_target_lost():
                self._enter(Mode.CONTACT)
        elif self._overdue():
            self._failsafe('unreachable', Mode.LAND)

    def _enter_contact(self, previous, target):
        cfg = self.config
        self._contact_ticks = 0
        self._contact_phase = 'close'
        self._depth_correction_m = 0.0
        self.first_touch_peak_n = 0.0
        self._plan_t(np.array([0.0, 0.0, self.vehicle.tool_tip_x_m + cfg.touch_margin_m]),
                     cfg.contact_speed_m_s)

    def _tick_contact(self, target, f_n, stale):
        cfg = self.config
        if not self._tool_hides_poi() and self._check_target_lost():
            return
        if self._contact_phase != 'press':
            # once pressing, the touch point is where the wall is: the frame stays put
            self._track_target(target)
        phase = self._contact_phase
        if phase == 'close':
            # as in the touch, several readings in a row: F/T noise is not the wall
            self._contact_ticks = self._contact_ticks + 1 if f_n > self._touch_threshold_n() else 0
        if phase == 'close' and self._contact_ticks >= cfg.contact_detect_ticks:
            self._start_press()      # the wall is nearer than estimated
        elif phase == 'close' and self._traj.done(self._now_s):
            self._start_touch()
        elif phase == 'touch':
            self._align_touch()
            self.first_touch_peak_n = max(self.first_touch_peak_n, f_n)
            self._contact_ticks = self._contact_ticks + 1 if f_n > self._touch_threshold_n() else 0
            # a wall felt while the tip is off the target is not pressed on (friction would
            # hold the tip there): the creep backs out until the tip is over it again
            if self._contact_ticks >= cfg.contact_detect_ticks and not self._aligning:
                self._start_press()
            elif self._traj.done(self._now_s):
                self._fail_task('no_contact')
        elif phase == 'press':
            self.first_touch_peak_n = max(self.first_touch_peak_n, f_n)
            self._contact_ticks = self._contact_ticks + 1 if f_n > cfg.contact_threshold_n else 0
            # the push holds (or slides) once it has reached its depth, so at the wanted force
            if self._contact_ticks >= cfg.contact_detect_ticks and self._traj.done(self._now_s):
                self._enter(Mode.SLIDE if isinstance(self.task, Slide) else Mode.HOLD)
            elif self._now_s > self._traj.t0_s + self._traj.T + cfg.press_time_s:
                self._fail_task('no_contact')

    def _touch_threshold_n(self):
        """The F/T reading that is a touch: touch_threshold_n, or touch_noise_sigmas times
        the RMS of the reading over the approach if more."""
        total, n = self._approach_f_n
        rms_n = math.sqrt(total / n) if n else 0.0
        return max(self.config.touch_threshold_n, self.config.touch_noise_sigmas * rms_n)

    def _start_touch(self):
        """Creep along -z_t from where the close-in ended until the F/T feels the wall."""
        cfg = self.config
        self._contact_phase = 'touch'
        self._contact_ticks = 0
        self._aligning, self._align_waited_s, self._align_off_t = False, 0.0, None
        p, _ = self._ref_t()
        # far enough past the estimate that the spring pushes with twice the touch threshold:
        # a noisy F/T's firmer touch is reached, and its reading there falls under the
        # threshold only as rarely as noise passes it
        overrun_m = max(cfg.touch_overrun_m, contact_depth_for_force(
            2.0 * self._touch_threshold_n(), self.k_contact_z_n_per_m))
        self._traj = Ramp(self._now_s, p, [0.0, 0.0, -cfg.touch_speed_m_s],
                          (cfg.touch_margin_m + overrun_m) / cfg.touch_speed_m_s)
        self._event('touching')

    def _align_touch(self):
        """Pause the creep (its clock stands still) while the tool tip is off the target
        in the wall's plane, within the wait allowed."""
        cfg = self.config
        dt = self._tick_dt_s()
        off_t = self._tool_tip_t()[:2]
        if self._align_off_t is None:
            self._align_off_t = off_t
        else:
            self._align_off_t = self._align_off_t + lowpass_weight(dt, ALIGN_TAU_S) * (
                off_t - self._align_off_t)
        off_m = float(np.linalg.norm(self._align_off_t))
        self._aligning = (cfg.touch_align_m > 0.0 and off_m > cfg.touch_align_m
                          and self._align_waited_s + dt <= cfg.touch_align_wait_s)
        if self._aligning:
            self._align_waited_s += dt
            self._traj.t0_s += dt
            # the creep runs backwards, at its own speed, until the tip is clear of the wall
            clearance_m = self._ref_t()[0][2] - self.vehicle.tool_tip_x_m
            if clearance_m < cfg.touch_align_clearance_m:
                self._traj.t0_s += dt

    def _start_press(self):
        """Ramp the depth that pushes with the setpoint, from one that holds the tool on the
        wall with ``contact_threshold_n`` at once (so that a stiff wall's rebound does not
        carry it off)."""
        cfg = self.config
        self._contact_phase = 'press'
        self._contact_ticks = 0
        k_z = self.k_contact_z_n_per_m
        final = contact_depth_for_force(self.contact_force_n, k_z)
        start = min(contact_depth_for_force(cfg.contact_threshold_n, k_z), final)
        # the wall is where it stopped the vehicle (the reference runs ahead while it creeps)
        touch_z = frames.to_frame(self._R_map_t, self._origin_map, self._state.p_map)[2]
        p0, goal = np.array([0.0, 0.0, touch_z - start]), np.array([0.0, 0.0, touch_z - final])
        distance = float(np.linalg.norm(goal - p0))
        self._traj = MinJerk(self._now_s, p0, goal,
                             max(MIN_JERK_PEAK * distance / cfg.press_time_s, 1e-3))
        self._event('pressing')

    def _enter_pushing(self, previous, target):
        """HOLD and SLIDE: in contact from here; the record notes when the push started."""
        self._in_contact = True
        self._no_force_since_s = None
        if self._plan_running():
            self._records[self._task_index].t_contact_s = [self._now_s, None]
            self.plan_version += 1

    def _regulate_push(self, f_n):
        """HOLD and SLIDE: the measured push trims the depth (force_tau_s), and contact
        lost is counted."""
        cfg = self.config
        if f_n > cfg.contact_threshold_n:
            self._no_force_since_s = None
            self._in_contact = True
            if cfg.force_tau_s > 0.0 and self._last_tick_s is not None:
                # d(push)/d(depth) is K_z on a rigid wall and less on one that gives way
                dt = self._now_s - self._last_tick_s
                self._depth_correction_m += ((self.contact_force_n - f_n) * dt
                                             / (self.k_contact_z_n_per_m * cfg.force_tau_s))
        elif self._no_force_since_s is None:
            self._no_force_since_s = self._now_s
        elif self._in_contact and self._now_s - self._no_force_since_s > cfg.contact_lost_s:
            self._in_contact = False
            self.contact_lost += 1
            if self._plan_running():
                self._records[self._task_index].contact_lost += 1
                self.plan_version += 1
            self._event('contact lost')

    def _end_push(self, reason):
        """HOLD or SLIDE done: record the task and back off to the standoff."""
        self._end_task(True)
        self._after_retreat = None
        self._enter(Mode.RETREAT, reason)

    def _tick_hold(self, target, f_n, stale):
        self._regulate_push(f_n)
        hold_s = self.task.hold_s if self.task is not None else self.config.hold_time_s
        if self._time_in_mode() >= hold_s:
            self._end_push('hold complete')

    def _enter_slide(self, previous, target):
        """The tool tip follows the task's line from where it touched, at the press depth."""
        self._enter_pushing(previous, target)
        cfg, task = self.config, self.task
        depth_z = self._traj.p1[2]
        points_t = np.array([frames.to_frame(self._R_map_t, self._origin_map, p)
                             for p in task.points_map])
        points_t[:, 2] = depth_z
        self._traj = PolylineCruise(self._now_s, points_t, task.speed_m_s, cfg.slide_accel_m_s2)
        self._slide_line_t = points_t[:, :2].copy()
        self._slide_progress = LineProgress(self._slide_line_t)
        self._event('sliding')

    def _tool_tip_t(self):
        """The tool tip in frame t, as odometry (position and attitude) sees it."""
        x_tool_map = frames.quat_matrix(self._state.q_map_base)[:, 0]
        p_t = frames.to_frame(self._R_map_t, self._origin_map, self._state.p_map)
        return p_t + self._R_map_t.T @ x_tool_map * self.vehicle.tool_tip_x_m

    def _tick_slide(self, target, f_n, stale):
        self._regulate_push(f_n)
        # the tool tip as odometry sees it, against the line in the wall's plane
        tip_t = self._tool_tip_t()[:2]
        tolerance_m = self.config.slide_path_tolerance_m
        progress = self._slide_progress
        progress.update(tip_t)
        # how far the tool tip is behind its reference along the line (at the line's end
        # time, short of the end): friction, or something on the line, holds it, and the
        # vehicle pitches against it while the reference slides on
        behind_m = self._traj.progress(self._now_s) * self._traj.length - progress.along_m
        if _distance_to_polyline(tip_t, self._slide_line_t) > tolerance_m:
            self._fail_task('off_line')
        elif behind_m > tolerance_m:
            self._fail_task('short_of_line')
        elif self._traj.done(self._now_s):
            self._end_push('line complete')

    def _enter_target_lost(self, previous, target):
        self._resume_mode = previous
        self._plan_t(self._ref_t()[0], self.config.approach_speed_m_s)

    def _tick_target_lost(self, target, f_n, stale):
        cfg = self.config
        # lost since the last sight, or (lost on the way, see _tick_approach) since the
        # standoff: the vehicle gets the same wait there to find it again
        lost_since = max(self._target_seen_s, self._t_mode_s - cfg.target_lost_hold_s)
        if self._target_usable(target):
            self._enter(self._resume_mode, 'target reacquired', target=target)
        elif self._now_s - lost_since > cfg.target_lost_retreat_s:
            self._fail_task('target_lost')

    def _enter_retreat(self, previous, target):
        self._plan_t(self._standoff_t(), self.config.approach_speed_m_s)

    def _tick_retreat(self, target, f_n, stale):
        if self._arrived():
            if self._after_retreat is None:
                self._start_task(self._task_index + 1)
            else:
                self._enter(self._after_retreat)
        elif self._overdue():
            self._failsafe('unreachable', Mode.LAND)

    def _enter_land(self, previous, target):
        cfg = self.config
        self._landing.reset()
        rate = cfg.descent_rate_m_s if self._mode == Mode.LAND else cfg.failsafe_descent_rate_m_s
        self._plan(self._landing_point(self._ref_map()[0]), rate)
        self._yaw_goal = self._yaw_ref
        self._pitch_goal = 0.0

    def _landing_point(self, p_map):
        """Where the descent from ``p_map`` ends: on the ground below it or, below the last
        surface worked on when that leans away from the vehicle (its foot comes nearer as
        the vehicle descends), out from it as far as keeps the tool tip ``standoff_m`` from
        its plane down to the ground. The straight line there keeps at least that much all
        the way: it starts at the standoff."""
        cfg = self.config
        goal = np.array([p_map[0], p_map[1], cfg.ground_z_m])
        if self._target_frame is None:
            return goal
        n_map = self._target_frame.R_map_t[:, 2]       # the surface's outward normal
        n_h2 = float(n_map[:2] @ n_map[:2])
        if n_h2 < 1e-6:
            return goal                                 # a floor or a ceiling
        tool_map = self.vehicle.tool_tip_x_m * np.array(
            [math.cos(self._yaw_ref), math.sin(self._yaw_ref), 0.0])
        origin = self._target_frame.origin_map
        if float((p_map + tool_map - origin) @ n_map) <= 0.0:
            return goal                                 # not in front of that surface
        short_m = cfg.standoff_m - float((goal + tool_map - origin) @ n_map)
        if short_m > 0.0:
            goal[:2] += short_m * n_map[:2] / n_h2      # out along the normal's level part
        return goal

    def _tick_land(self, target, f_n, stale):
        cfg = self.config
        if self._mode == Mode.LAND:
            # a wall leaning away from the vehicle comes nearer as it descends
            self._clear_vertically(cfg.ground_z_m, cfg.descent_rate_m_s)
            if self._flight_phase:
                return
        z_m = self._state.p_map[2]
        low = z_m < cfg.ground_z_m + cfg.land_detect_height_m
        # Or stopped on something higher (a roof, a box; ground_z_m set too low, odometry
        # drifting up): that far above its descending setpoint, asking for less thrust than
        # any vehicle it may be weighs, and still. Being above the setpoint alone says
        # nothing: a vehicle lighter than the controller's model hovers there until the
        # hover-thrust estimate has learnt its weight. Resting on its gear, not hanging by
        # its tool, which would fall once the rotors stop.
        thrust_low = self._thrust_up_n is not None and self._thrust_up_n < (
            cfg.land_detect_thrust_ratio * self.vehicle.mass_kg * GRAVITY)
        held = (z_m > self._ref_map()[0][2] + cfg.land_detect_height_m and thrust_low
                and self._bump() is None)
        slow = np.linalg.norm(self._v_map) < cfg.land_detect_speed_m_s
        if self._landing.update((low or held) and slow, self._now_s, cfg.land_detect_s):
            self._success = self._completed
            self._enter(Mode.IDLE, 'landed' if low else
                        f'landed {z_m - cfg.ground_z_m:.2f} m above ground_z_m')

    def _tick_failsafe_land(self, target, f_n, stale):
        # blind: position cannot be trusted, so landing is declared after the time the
        # descent needs plus a margin, unless fresh odometry shows it earlier
        if not stale:
            self._tick_land(target, f_n, stale)
        elif self._now_s > self._traj.t0_s + self._traj.T + self.config.failsafe_land_margin_s:
            self._enter(Mode.IDLE, 'landed (blind)')

    # ---- helpers ----

    def _enter(self, mode, reason='', target=None):
        old, old_phase = self._mode, self.phase
        self._mode = mode
        self._t_mode_s = self._now_s
        self._event(reason, old, old_phase, target)
        self._contact_gains = mode in (Mode.CONTACT, Mode.HOLD, Mode.SLIDE) or (
            mode == Mode.TARGET_LOST and self._contact_gains)
        if mode != Mode.CONTACT:
            self._contact_phase = ''
        self._flight_phase = ''
        enter = MODES[mode].enter
        if enter is not None:
            enter(self, old, target)

    def _event(self, reason, old=None, old_phase='', target=None):
        """Log a transition from ``old`` (in ``old_phase``), or an event within a mode; with
        the target's POI (map) when it is about one."""
        self.events.append(dict(t_s=self._now_s, mode=self._mode.value,
                                previous=None if old is None else old.value,
                                phase=old_phase if old is not None else self.phase,
                                reason=reason, task_index=self._task_index,
                                target_map=None if target is None else
                                [float(v) for v in target[0]]))

    def _failsafe(self, reason, mode):
        """A vehicle failsafe: the plan ends here."""
        self._failsafe_reason = reason
        self._completed = False
        self._inspect_pending = False
        self._stop_plan(reason)
        if mode == Mode.RETREAT:
            self._after_retreat = Mode.LAND
        self._enter(mode, reason)

    def _check_upset(self):
        cfg = self.config
        tilted = _cos_tilt_of(self._state) < math.cos(cfg.upset_tilt_rad)
        if self._upset.update(self._mode != Mode.IDLE and tilted, self._now_s, cfg.upset_s):
            self._failsafe('upset', Mode.IDLE)

    def _can_arm(self):
        if self._mode != Mode.IDLE:
            return False, f'already flying ({self._mode.value})'
        if self._state is None or not self._odom_age_s <= self.config.odom_stale_s:
            return False, 'no fresh odometry'
        return True, ''

    def _bump(self):
        """The F/T force on the vehicle (map, low-passed) when it says the tool touched
        something (above free_flight_contact_n), else None."""
        touched = float(np.linalg.norm(self._f_contact_map))
        return self._f_contact_map if touched > self.config.free_flight_contact_n else None

    def _back_off(self, away_map):
        """Fly free_flight_clearance_m along ``away_map`` from where the body is, not
        turning meanwhile."""
        away = np.linalg.norm(away_map)
        self._plan(self._state.p_map + away_map / away * self.config.free_flight_clearance_m,
                   self.config.hover_speed_m_s)
        self._yaw_goal = self._yaw_ref
        self._event(f'touched something ({np.linalg.norm(self._f_contact_map):.1f} N): '
                    'backing off')

    def _overdue(self):
        """Whether the segment under way ended arrive_timeout_s ago (for a mode still
        waiting to arrive: something holds the vehicle)."""
        return self._now_s > self._traj.t0_s + self._traj.T + self.config.arrive_timeout_s

    def _time_in_mode(self):
        return self._now_s - self._t_mode_s

    def _tick_dt_s(self):
        """Seconds since the previous tick's setpoint (0 before the first)."""
        return 0.0 if self._last_tick_s is None else max(self._now_s - self._last_tick_s, 0.0)

    def _tool_hides_poi(self):
        p_t = frames.to_frame(self._R_map_t, self._origin_map, self._state.p_map)
        return p_t[2] - self.vehicle.tool_tip_x_m < self.config.tool_occlusion_range_m

    def _target_usable(self, target):
        return target is not None and bool(target[3])

    def _check_target_lost(self):
        if self._now_s - self._target_seen_s > self.config.target_lost_hold_s:
            self._enter(Mode.TARGET_LOST, 'target lost')
            return True
        return False

    def _set_target_frame(self, target):
        cfg = self.config
        p_poi, n_map = target[0], target[1]
        # tracked every tick, so the frame is rebuilt only when the estimate moves
        key = tuple(np.concatenate((p_poi, n_map)).tolist())
        self._yaw_goal = frames.yaw_facing(n_map, default_rad=self._yaw_ref)
        if self._target_frame is None or key != self._target_frame.key:
            pitch = frames.pitch_facing(n_map) if cfg.pitch_to_normal else 0.0
            pitch = min(max(pitch, -cfg.max_pitch_rad), cfg.max_pitch_rad)
            R_map_t, origin_map = frames.target_frame_from_normal(p_poi, n_map)
            # the tip is L x_FLU ahead of the body: where x_FLU is not -z_t, the body
            # stands off the normal by L times x_FLU's part in the wall's plane
            x_tool_t = R_map_t.T @ frames.tool_direction(self._yaw_goal, pitch)
            shift_t = -self.vehicle.tool_tip_x_m * np.array([x_tool_t[0], x_tool_t[1], 0.0])
            self._target_frame = TargetFrame(key, R_map_t, origin_map, pitch, shift_t)
        frame = self._target_frame
        self._R_map_t, self._origin_map = frame.R_map_t, frame.origin_map
        self._pitch_goal, self._tool_shift_t = frame.pitch_rad, frame.tool_shift_t

    def _track_target(self, target):
        # the segment lives in frame t, so a refined estimate moves the whole reference
        if self._target_usable(target):
            self._set_target_frame(target)

    def _standoff_t(self):
        return np.array([0.0, 0.0, self.config.standoff_m + self.vehicle.tool_tip_x_m])

    def _to_map(self):
        """Re-express the current reference in map and make map the working frame."""
        p, v, a = self._ref_map()
        self._R_map_t, self._origin_map = np.eye(3), np.zeros(3)
        self._tool_shift_t = np.zeros(3)
        self._traj = MinJerk(self._now_s, p, p, 1.0, v, a)
        self._depth_correction_m = 0.0      # now part of the new segment

    def _ref_t(self):
        p, v, _ = self._sample()
        return p, v

    def _sample(self):
        """(p, v, a) of the reference in frame t now, the push's depth correction included."""
        p, v, a = self._traj.sample(self._now_s)
        p[2] -= self._depth_correction_m
        return p, v, a

    def _ref_map(self):
        """(p, v, a) of the body's reference in map (frame t's reference plus the tool
        shift)."""
        p, v, a = self._sample()
        R = self._R_map_t
        return self._origin_map + R @ (p + self._tool_shift_t), R @ v, R @ a

    def _plan(self, goal_map, v_max):
        """New segment in map from the current reference (continuous position, speed and
        acceleration)."""
        self._to_map()
        p, v, a = self._sample()
        self._traj = MinJerk(self._now_s, p, goal_map, v_max, v, a)

    def _plan_t(self, goal_t, v_max, ref_map=None):
        """New segment in the current target frame from the current reference
        (``ref_map`` = (p_map, v_map, a_map) when the frame has just changed)."""
        p_map, v_map, a_map = ref_map or self._ref_map()
        R, o = self._R_map_t, self._origin_map
        self._traj = MinJerk(self._now_s, frames.to_frame(R, o, p_map) - self._tool_shift_t,
                             goal_t, v_max, R.T @ v_map, R.T @ a_map)
        self._depth_correction_m = 0.0      # now part of the new segment

    def _arrived(self):
        cfg = self.config
        if not self._traj.done(self._now_s):
            return False
        p_t = frames.to_frame(self._R_map_t, self._origin_map, self._state.p_map)
        return (np.linalg.norm(p_t - self._tool_shift_t - self._traj.p1) < cfg.arrive_tol_m
                and np.linalg.norm(self._v_map) < cfg.arrive_speed_m_s)

    def _turned(self):
        """Whether the body faces its yaw goal and the pitch reference has reached its goal."""
        yaw_err = frames.wrap_angle(self._yaw_goal - _yaw_of(self._state))
        return max(abs(yaw_err), abs(self._pitch_goal - self._pitch_ref)) < (
            self.config.arrive_yaw_tol_rad)

    def _setpoint(self):
        cfg = self.config
        dt = self._tick_dt_s()
        self._last_tick_s = self._now_s
        if self._mode == Mode.SEARCH and self._search.phase == 'sweep':
            # no faster than the yaw reference may turn, or the turn counted is not made
            sweep = min(cfg.search_yaw_rate_rad_s, cfg.yaw_rate_rad_s) * dt
            self._yaw_goal = self._yaw_ref + sweep
            self._search.swept_rad += sweep
        err = frames.wrap_angle(self._yaw_goal - self._yaw_ref)
        step = cfg.yaw_rate_rad_s * dt
        self._yaw_ref = frames.wrap_angle(self._yaw_ref + min(max(err, -step), step))
        step = cfg.pitch_rate_rad_s * dt
        self._pitch_ref += min(max(self._pitch_goal - self._pitch_ref, -step), step)
        p, v, a = self._sample()
        if self._mode == Mode.CONTACT and self._contact_phase == 'press':
            # a quasi-static press: with the reference's own speed in C e' + M e'' the push
            # would overshoot by C times that speed halfway through the ramp
            v[2] = a[2] = 0.0
        if self.phase == 'align':
            v[:] = 0.0      # paused: the reference stands still, and so does its speed
        # leaving the wall, the reference starts behind the surface: keep the compliant
        # gains until it is out, so the push fades instead of stiffening
        releasing = self._mode == Mode.RETREAT and p[2] < self.vehicle.tool_tip_x_m
        return ImpedanceSetpoint(
            R_map_t=self._R_map_t.copy(), origin_map=self._origin_map.copy(),
            lambda_d_t=p + self._tool_shift_t, dlambda_d_t=v, ddlambda_d_t=a,
            yaw_rad=self._yaw_ref, pitch_rad=self._pitch_ref,
            contact_gains=self._contact_gains or releasing,
            tangential_feedforward=self._mode == Mode.SLIDE,
            airborne=self._mode not in _NEAR_GROUND)


class Handlers(typing.NamedTuple):
    """What a mode does: ``enter(mission, previous mode, target)`` once on entry (None:
    nothing), ``tick(mission, target, f_n, stale)`` every control tick."""

    enter: typing.Callable | None
    tick: typing.Callable


# Each mode's entry and tick.
MODES = {
    Mode.IDLE: Handlers(None, Mission._tick_idle),
    Mode.TAKEOFF: Handlers(Mission._enter_takeoff, Mission._tick_takeoff),
    Mode.HOVER: Handlers(Mission._enter_hover, Mission._tick_hover),
    Mode.SEARCH: Handlers(Mission._enter_search, Mission._tick_search),
    Mode.APPROACH: Handlers(Mission._enter_approach, Mission._tick_approach),
    Mode.CONTACT: Handlers(Mission._enter_contact, Mission._tick_contact),
    Mode.HOLD: Handlers(Mission._enter_pushing, Mission._tick_hold),
    Mode.SLIDE: Handlers(Mission._enter_slide, Mission._tick_slide),
    Mode.TARGET_LOST: Handlers(Mission._enter_target_lost, Mission._tick_target_lost),
    Mode.RETREAT: Handlers(Mission._enter_retreat, Mission._tick_retreat),
    Mode.LAND: Handlers(Mission._enter_land, Mission._tick_land),
    Mode.FAILSAFE_LAND: Handlers(Mission._enter_land, Mission._tick_failsafe_land),
}


def _distance_to_polyline(p, vertices):
    """Distance from the 2-D point ``p`` to the polyline through ``vertices`` (N, 2)."""
    best = math.inf
    for a, b in zip(vertices[:-1], vertices[1:]):
        d = b - a
        u = min(max(float((p - a) @ d / (d @ d)), 0.0), 1.0)
        best = min(best, float(np.linalg.norm(p - a - u * d)))
    return best


def _finite_state(state):
    return state is not None and all(map(math.isfinite, np.concatenate(
        (state.p_map, state.q_map_base, state.v_map)).tolist()))


def _cos_tilt_of(state):
    """Cosine of the angle between the body's z axis and the vertical."""
    x, y, z, w = np.asarray(state.q_map_base, dtype=float).tolist()
    return 1.0 - 2.0 * (x * x + y * y) / (x * x + y * y + z * z + w * w)


def _yaw_of(state):
    # the yaw of matrix_to_euler_zyx from the two matrix entries it needs (every tick)
    x, y, z, w = np.asarray(state.q_map_base, dtype=float).tolist()
    n2 = x * x + y * y + z * z + w * w
    m00, m10 = 1.0 - 2.0 * (y * y + z * z) / n2, 2.0 * (x * y + z * w) / n2
    if math.hypot(m00, m10) < 1e-12:
        return matrix_to_euler_zyx(frames.quat_matrix(state.q_map_base))[0]
    return math.atan2(m10, m00)
