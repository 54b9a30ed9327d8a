"""Inspection mission and failsafes: a state machine that outputs ImpedanceSetpoints.

IDLE -> TAKEOFF -> HOVER -> SEARCH -> APPROACH -> CONTACT -> HOLD -> RETREAT -> LAND -> IDLE,
with TARGET_LOST (hold while the target is not seen) and FAILSAFE_LAND (blind descent on
stale odometry), modelled on PX4's failsafes. Free flight uses the map frame; from APPROACH
on, the target frame t of the estimate (z_t = surface normal). References are quintic
(minimum-jerk) segments so that lambda_d, dlambda_d and ddlambda_d stay consistent.
"""
import collections
import dataclasses
import math

import numpy as np

from uav_tilt_common.config import ConfigError, param
from uav_tilt_common.geometry import matrix_to_euler_zyx
from uav_tilt_common.modes import Mode
from uav_tilt_control import frames
from uav_tilt_control.impedance import ImpedanceConfig, contact_depth_for_force
from uav_tilt_control.types import ImpedanceSetpoint

# Shortest reference segment: bounds the accelerations of a segment that only has to
# bring the reference velocity to rest.
_MIN_SEGMENT_S = 1.0
# Peak speed of a minimum-jerk segment is 1.875 * distance / duration.
_MIN_JERK_PEAK = 1.875
DEFAULT_CONTACT_FORCE_N = 5.0


NEAR_WALL = (Mode.APPROACH, Mode.CONTACT, Mode.HOLD, Mode.TARGET_LOST)


@dataclasses.dataclass
class MissionConfig:
    """Mission geometry, speeds, detection thresholds and failsafe timeouts."""

    takeoff_altitude_m: float = param(1.5, lo=0.3, hi=20.0)
    climb_speed_m_s: float = param(0.5, lo=0.05, hi=3.0)
    hover_speed_m_s: float = param(0.5, lo=0.05, hi=3.0)
    hover_settle_s: float = param(1.0, lo=0.0, hi=30.0)     # HOVER before SEARCH on inspect
    yaw_rate_rad_s: float = param(0.5, lo=0.05, hi=3.0)
    # SEARCH: a full turn at the takeoff altitude, then one more turn search_climb_m higher
    # (a wider view of a tall wall), until a candidate target is seen; it is confirmed once
    # confirm_n of its measurements agree within confirm_radius_m. One not confirmed within
    # confirm_timeout_s is looked at again from confirm_range_m (a small far target is
    # seen in few frames), then dropped, and the sweep goes on. search_timeout_s in all,
    # then it lands.
    search_yaw_rate_rad_s: float = param(0.35, lo=0.0, hi=1.0)  # 0: hover and wait
    search_climb_m: float = param(0.8, lo=0.0, hi=10.0)
    search_timeout_s: float = param(75.0, lo=0.5, hi=600.0)
    confirm_n: int = param(5, lo=1, hi=100)
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
    touch_overrun_m: float = param(0.1, lo=0.0, hi=1.0)     # creep past the estimate, at most
    touch_threshold_n: float = param(0.4, lo=0.05, hi=20.0)  # the first touch
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
    land_detect_speed_m_s: float = param(0.1, lo=0.01, hi=1.0)
    land_detect_s: float = param(0.5, lo=0.0, hi=10.0)
    arrive_tol_m: float = param(0.05, lo=0.001, hi=1.0)
    arrive_speed_m_s: float = param(0.1, lo=0.001, hi=1.0)
    arrive_yaw_tol_rad: float = param(0.05, lo=0.001, hi=1.0)


class MinJerk:
    """Quintic from (p0, v0, a=0) to (p1, v=0, a=0) with peak speed about v_max."""

    def __init__(self, t0_s, p0, p1, v_max, v0=np.zeros(3)):
        self.t0_s = t0_s
        self.p1 = np.asarray(p1, dtype=float).copy()
        d = self.p1 - p0
        self.T = max(_MIN_JERK_PEAK * np.linalg.norm(d) / v_max, _MIN_SEGMENT_S)
        T = self.T
        self._c = np.array([p0, v0, np.zeros(3),
                            (20 * d - 12 * v0 * T) / (2 * T ** 3),
                            (-30 * d + 16 * v0 * T) / (2 * T ** 4),
                            (12 * d - 6 * v0 * T) / (2 * T ** 5)], dtype=float)

    def done(self, t_s):
        """True once the segment has reached p1."""
        return t_s >= self.t0_s + self.T

    def sample(self, t_s):
        """(p, v, a) at ``t_s``; held at p1 after the end."""
        if self.done(t_s):
            return self.p1.copy(), np.zeros(3), np.zeros(3)
        t1 = max(t_s - self.t0_s, 0.0)
        t2 = t1 * t1
        t3 = t2 * t1
        # rows: d^k/dtau^k of (1, tau, ..., tau^5); one product gives p, v and a
        p, v, a = np.array([[1.0, t1, t2, t3, t3 * t1, t3 * t2],
                            [0.0, 1.0, 2.0 * t1, 3.0 * t2, 4.0 * t3, 5.0 * t3 * t1],
                            [0.0, 0.0, 2.0, 6.0 * t1, 12.0 * t2, 20.0 * t3]]) @ self._c
        return p, v, a


SEARCH_LEVELS = 2      # full turns: at the takeoff altitude, then search_climb_m higher


class SearchState:
    """Where SEARCH is: its phase, the turn swept so far, the candidate being confirmed."""

    def __init__(self):
        self.phase = 'sweep'
        self.level = 0
        self.swept_rad = 0.0
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


class Ramp:
    """Constant-velocity segment from p0 along ``velocity`` for at most ``duration`` s (the
    guarded move of a touch); same interface as :class:`MinJerk`."""

    def __init__(self, t0_s, p0, velocity, duration):
        self.t0_s = t0_s
        self.T = float(duration)
        self._p0 = np.asarray(p0, dtype=float).copy()
        self._v = np.asarray(velocity, dtype=float).copy()
        self.p1 = self._p0 + self._v * self.T

    def done(self, t_s):
        """True once the segment has run its full length."""
        return t_s >= self.t0_s + self.T

    def sample(self, t_s):
        """(p, v, a) at ``t_s``; held at the end point after the end."""
        if self.done(t_s):
            return self.p1.copy(), np.zeros(3), np.zeros(3)
        return self._p0 + self._v * max(t_s - self.t0_s, 0.0), self._v.copy(), np.zeros(3)


class Mission:
    """Inspection state machine; call :meth:`update` every control tick."""

    def __init__(self, vehicle, config=None, contact_force_n=DEFAULT_CONTACT_FORCE_N,
                 k_contact_z_n_per_m=None, drop_target=None):
        """``k_contact_z_n_per_m``: the impedance law's contact K_z, which turns the wanted
        push into a depth (default: that of the default ImpedanceConfig for the vehicle);
        ``drop_target()``: makes the target estimate forget a candidate SEARCH did not
        confirm (the estimator's reset)."""
        self.vehicle = vehicle
        self.config = config or MissionConfig()
        if k_contact_z_n_per_m is None:
            k_contact_z_n_per_m = ImpedanceConfig().contact.k_c(vehicle.mass_kg)[0][2]
        self.contact_force_n = float(contact_force_n)
        self.k_contact_z_n_per_m = float(k_contact_z_n_per_m)
        if not 0.0 <= self.contact_force_n < self.config.force_limit_n:
            raise ConfigError(
                f"parameter 'contact_force' = {contact_force_n!r} must be in "
                f"[0, force_limit_n = {self.config.force_limit_n!r})")
        if self.config.target_lost_retreat_s <= self.config.target_lost_hold_s:
            raise ConfigError(
                f"parameter 'target_lost_retreat_s' = {self.config.target_lost_retreat_s!r} "
                f"must exceed target_lost_hold_s = {self.config.target_lost_hold_s!r}")
        self._mode = Mode.IDLE
        self._now_s = None
        self._t_mode_s = 0.0
        self._state = None
        self._odom_age_s = np.inf
        self._R_map_t = np.eye(3)
        self._origin_map = np.zeros(3)
        self._target_frame = (None, None)   # (target key, (R_map_t, origin_map, pitch))
        self._traj = None
        self._yaw_ref = 0.0
        self._yaw_goal = 0.0
        self._pitch = 0.0
        self._contact_gains = False
        self._inspect_pending = False
        self._after_retreat = Mode.LAND
        self._resume_mode = Mode.APPROACH
        self._target_seen_s = -np.inf
        self._last_tick_s = None
        self._landing_since_s = None
        self._contact_ticks = 0
        self._contact_phase = ''       # CONTACT: 'close', 'touch', 'press'
        self._drop_target = drop_target
        self._search = SearchState()
        self._depth_correction_m = 0.0  # HOLD: from the push error (along -z_t)
        self.first_touch_peak_n = 0.0
        self._no_force_since_s = None
        self._in_contact = False
        self._hold_completed = False
        self._success = False
        self._failsafe_reason = ''
        self.contact_lost = 0
        self.rejected_setpoints = 0
        self.events = collections.deque(maxlen=200)

    @property
    def mode(self):
        """Current :class:`Mode`."""
        return self._mode

    @property
    def phase(self):
        """What the mode is doing: SEARCH 'sweep', 'climb', 'confirm', 'closer'; CONTACT
        'close', 'touch', 'press'; '' otherwise."""
        if self._mode == Mode.SEARCH:
            return self._search.phase
        return self._contact_phase if self._mode == Mode.CONTACT else ''

    @property
    def status(self):
        """Mode, time in mode, failsafe reason and outcome of the inspection."""
        return dict(
            mode=self._mode.value,
            phase=self.phase,
            time_in_mode_s=0.0 if self._now_s is None else self._now_s - self._t_mode_s,
            failsafe_reason=self._failsafe_reason,
            inspection_completed=self._hold_completed,
            success=self._success,
            contact_lost=self.contact_lost,
            in_contact=self._in_contact,
            rejected_setpoints=self.rejected_setpoints,
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
        """Run the inspection: from IDLE take off first, from HOVER start SEARCH."""
        if self._mode == Mode.HOVER:
            self._start_inspection()
            self._enter(Mode.SEARCH)
            return True, 'searching for the target'
        ok, why = self._can_arm()
        if not ok:
            return False, why
        self._start_inspection()
        self._inspect_pending = True
        self._enter(Mode.TAKEOFF)
        return True, 'taking off for inspection'

    def abort(self):
        """Leave the wall (RETREAT) when near it, else stop and HOVER."""
        self._inspect_pending = False
        if self._mode in NEAR_WALL or self._mode == Mode.RETREAT:
            self._after_retreat = Mode.HOVER
            if self._mode != Mode.RETREAT:
                self._enter(Mode.RETREAT, 'abort')
            return True, 'retreating from the wall'
        if self._mode in (Mode.TAKEOFF, Mode.SEARCH, Mode.LAND, Mode.HOVER):
            if self._mode != Mode.HOVER:
                self._enter(Mode.HOVER, 'abort')
            return True, 'hovering'
        return False, f'nothing to abort in {self._mode.value}'

    def land(self):
        """Land here; near the wall retreat first."""
        self._inspect_pending = False
        if self._mode in NEAR_WALL or self._mode == Mode.RETREAT:
            self._after_retreat = Mode.LAND
            if self._mode != Mode.RETREAT:
                self._enter(Mode.RETREAT, 'land requested')
            return True, 'retreating, then landing'
        if self._mode in (Mode.TAKEOFF, Mode.HOVER, Mode.SEARCH, Mode.LAND):
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
        if self._mode != Mode.HOVER:
            return False, f'setpoints are accepted in HOVER only, not {self._mode.value}'
        self._plan(p, self.config.hover_speed_m_s)
        self._yaw_goal = float(yaw_rad)
        return True, 'setpoint accepted'

    # ---- the tick ----

    def update(self, now_s, state, target, f_contact_n, odom_age_s):
        """One control tick: returns the ImpedanceSetpoint for the impedance law.

        ``target``: TargetEstimate(p_poi_map, normal_map, age_s, valid) or None;
        ``f_contact_n``: force along the normal from the F/T sensor, positive pushing;
        ``odom_age_s``: age of the odometry in ``state``.
        """
        cfg = self.config
        self._now_s = float(now_s)
        self._odom_age_s = float(odom_age_s)
        stale = not (odom_age_s <= cfg.odom_stale_s and _finite_state(state))
        if not stale:
            self._state = state
        if self._state is None:
            return ImpedanceSetpoint()
        if stale and self._mode not in (Mode.IDLE, Mode.FAILSAFE_LAND):
            self._failsafe('odometry_stale', Mode.FAILSAFE_LAND)
        if self._target_usable(target):
            self._target_seen_s = max(self._target_seen_s, now_s - target[2])
        # a broken F/T reading cannot prove contact, nor trip the force limit
        f_n = float(f_contact_n) if math.isfinite(f_contact_n) else 0.0
        if self._mode in NEAR_WALL and f_n > cfg.force_limit_n:
            self._failsafe('force_limit', Mode.RETREAT)
        getattr(self, '_tick_' + self._mode.value.lower())(target, f_n, stale)
        return self._setpoint()

    # ---- per-mode logic ----

    def _tick_idle(self, target, f_n, stale):
        # keep the reference on the vehicle so that a takeoff starts from where it is
        self._traj = MinJerk(self._now_s, self._state.p_map, self._state.p_map, 1.0)
        self._yaw_ref = self._yaw_goal = _yaw_of(self._state)

    def _tick_takeoff(self, target, f_n, stale):
        if self._arrived():
            self._enter(Mode.HOVER)

    def _tick_hover(self, target, f_n, stale):
        if self._inspect_pending and self._time_in_mode() >= self.config.hover_settle_s:
            self._inspect_pending = False
            self._enter(Mode.SEARCH)

    def _tick_search(self, target, f_n, stale):
        cfg, search = self.config, self._search
        if self._time_in_mode() > cfg.search_timeout_s:
            self._failsafe('target_not_found', Mode.LAND)
        elif search.phase in ('confirm', 'closer'):
            self._tick_confirm(target)
        elif self._target_usable(target) and self._now_s >= search.ignore_until_s:
            search.candidate(self._now_s, target)
            self._event('candidate target')
            # face it: the detector sees it best in the middle of the image
            d = target[0] - self._state.p_map
            self._yaw_goal = math.atan2(d[1], d[0])
        elif search.phase == 'sweep' and search.swept_rad >= 2.0 * math.pi:
            if search.level + 1 < SEARCH_LEVELS:
                search.level += 1
                search.phase = 'climb'
                p = self._ref_map()[0]
                self._plan(np.array([p[0], p[1], cfg.takeoff_altitude_m + cfg.search_climb_m]),
                           cfg.climb_speed_m_s)
                self._event('climbing to search higher')
            else:
                self._failsafe('target_not_found', Mode.LAND)
        elif search.phase == 'climb' and self._arrived():
            search.phase, search.swept_rad = 'sweep', 0.0

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

    def _tick_approach(self, target, f_n, stale):
        if self._check_target_lost():
            return
        self._track_target(target)
        yaw_err = frames.wrap_angle(self._yaw_goal - _yaw_of(self._state))
        if self._arrived() and abs(yaw_err) < self.config.arrive_yaw_tol_rad:
            self._enter(Mode.CONTACT)

    def _tick_contact(self, target, f_n, stale):
        cfg = self.config
        if not self._tool_hides_poi() and self._check_target_lost():
            return
        if self._contact_phase != 'press':
            # once pressing, the touch point is where the wall is: the frame stays put
            self._track_target(target)
        phase = self._contact_phase
        if phase == 'close' and self._traj.done(self._now_s):
            self._start_touch()
        elif phase == 'close' and f_n > cfg.touch_threshold_n:
            self._start_press()      # the wall is nearer than estimated
        elif phase == 'touch':
            self.first_touch_peak_n = max(self.first_touch_peak_n, f_n)
            self._contact_ticks = self._contact_ticks + 1 if f_n > cfg.touch_threshold_n else 0
            if self._contact_ticks >= cfg.contact_detect_ticks:
                self._start_press()
            elif self._traj.done(self._now_s):
                self._failsafe('no_contact', Mode.RETREAT)
        elif phase == 'press':
            self.first_touch_peak_n = max(self.first_touch_peak_n, f_n)
            self._contact_ticks = self._contact_ticks + 1 if f_n > cfg.contact_threshold_n else 0
            # HOLD starts once the push has reached its depth, so it holds the wanted force
            if self._contact_ticks >= cfg.contact_detect_ticks and self._traj.done(self._now_s):
                self._enter(Mode.HOLD)
            elif self._now_s > self._traj.t0_s + self._traj.T + cfg.press_time_s:
                self._failsafe('no_contact', Mode.RETREAT)

    def _start_touch(self):
        """Creep along -z_t from where the close-in ended until the F/T feels the wall."""
        cfg = self.config
        self._contact_phase = 'touch'
        self._contact_ticks = 0
        p, _ = self._ref_t()
        self._traj = Ramp(self._now_s, p, [0.0, 0.0, -cfg.touch_speed_m_s],
                          (cfg.touch_margin_m + cfg.touch_overrun_m) / cfg.touch_speed_m_s)
        self._event('touching')

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
                             max(_MIN_JERK_PEAK * distance / cfg.press_time_s, 1e-3))
        self._event('pressing')

    def _tick_hold(self, target, f_n, stale):
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
            self._event('contact lost')
        if self._time_in_mode() >= cfg.hold_time_s:
            self._hold_completed = self.contact_lost == 0 and not self._failsafe_reason
            self._after_retreat = Mode.LAND
            self._enter(Mode.RETREAT, 'hold complete')

    def _tick_target_lost(self, target, f_n, stale):
        cfg = self.config
        if self._target_usable(target):
            self._enter(self._resume_mode, 'target reacquired', target=target)
        elif self._now_s - self._target_seen_s > cfg.target_lost_retreat_s:
            self._failsafe('target_lost', Mode.RETREAT)

    def _tick_retreat(self, target, f_n, stale):
        if self._arrived():
            self._enter(self._after_retreat)

    def _tick_land(self, target, f_n, stale):
        cfg = self.config
        low = self._state.p_map[2] < cfg.ground_z_m + cfg.land_detect_height_m
        slow = np.linalg.norm(self._state.v_map) < cfg.land_detect_speed_m_s
        if not (low and slow):
            self._landing_since_s = None
        elif self._landing_since_s is None:
            self._landing_since_s = self._now_s
        elif self._now_s - self._landing_since_s >= cfg.land_detect_s:
            self._success = self._hold_completed
            self._enter(Mode.IDLE, 'landed')

    def _tick_failsafe_land(self, target, f_n, stale):
        # blind: position cannot be trusted, so landing is declared after the time the
        # descent needs plus a margin, unless fresh odometry shows it earlier
        if not stale:
            self._tick_land(target, f_n, stale)
        elif self._now_s > self._traj.t0_s + self._traj.T + self.config.failsafe_land_margin_s:
            self._enter(Mode.IDLE, 'landed (blind)')

    # ---- helpers ----

    def _enter(self, mode, reason='', target=None):
        cfg = self.config
        old, old_phase = self._mode, self.phase
        self._mode = mode
        self._t_mode_s = self._now_s
        self._event(reason, old, old_phase, target)
        self._contact_gains = mode in (Mode.CONTACT, Mode.HOLD) or (
            mode == Mode.TARGET_LOST and self._contact_gains)
        if mode == Mode.TAKEOFF:
            p_meas = self._state.p_map
            goal = np.array([p_meas[0], p_meas[1], cfg.takeoff_altitude_m])
            self._to_map()
            self._traj = MinJerk(self._now_s, p_meas, goal, cfg.climb_speed_m_s)
        elif mode in (Mode.HOVER, Mode.SEARCH):
            self._to_map()
            self._plan(self._ref_map()[0], cfg.hover_speed_m_s)
            self._yaw_goal = self._yaw_ref
            if mode == Mode.SEARCH:
                self._search = SearchState()
        elif mode == Mode.APPROACH:
            ref_map = self._ref_map()
            self._set_target_frame(target)
            self._plan_t(self._standoff_t(), cfg.approach_speed_m_s, ref_map)
        elif mode == Mode.CONTACT:
            self._contact_ticks = 0
            self._contact_phase = 'close'
            self._depth_correction_m = 0.0
            self.first_touch_peak_n = 0.0
            self._plan_t(np.array([0.0, 0.0, self.vehicle.tool_tip_x_m + cfg.touch_margin_m]),
                         cfg.contact_speed_m_s)
        elif mode == Mode.HOLD:
            self._in_contact = True
            self._no_force_since_s = None
        elif mode == Mode.TARGET_LOST:
            self._resume_mode = old
            self._plan_t(self._ref_t()[0], cfg.approach_speed_m_s)
        elif mode == Mode.RETREAT:
            self._plan_t(self._standoff_t(), cfg.approach_speed_m_s)
        elif mode in (Mode.LAND, Mode.FAILSAFE_LAND):
            self._landing_since_s = None
            rate = cfg.descent_rate_m_s if mode == Mode.LAND else cfg.failsafe_descent_rate_m_s
            p0 = self._ref_map()[0]
            self._plan(np.array([p0[0], p0[1], cfg.ground_z_m]), rate)
            self._yaw_goal = self._yaw_ref
            self._pitch = 0.0

    def _event(self, reason, old=None, old_phase='', target=None):
        """Log a transition from ``old`` (in ``old_phase``), or an event within a mode; with
        the target's POI (map) when it is about one."""
        self.events.append(dict(t_s=self._now_s, mode=self._mode.value,
                                previous=None if old is None else old.value,
                                phase=old_phase if old is not None else self.phase,
                                reason=reason,
                                target_map=None if target is None else
                                [float(v) for v in target[0]]))

    def _failsafe(self, reason, mode):
        self._failsafe_reason = reason
        self._hold_completed = False
        self._inspect_pending = False
        if mode == Mode.RETREAT:
            self._after_retreat = Mode.LAND
        self._enter(mode, reason)

    def _start_inspection(self):
        self._hold_completed = False
        self._success = False
        self._failsafe_reason = ''
        self.contact_lost = 0
        self._target_seen_s = -np.inf

    def _can_arm(self):
        if self._mode != Mode.IDLE:
            return False, f'already flying ({self._mode.value})'
        if self._state is None or not self._odom_age_s <= self.config.odom_stale_s:
            return False, 'no fresh odometry'
        return True, ''

    def _time_in_mode(self):
        return self._now_s - self._t_mode_s

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
        if key != self._target_frame[0]:
            pitch = frames.pitch_facing(n_map) if cfg.pitch_to_normal else 0.0
            pitch = min(max(pitch, -cfg.max_pitch_rad), cfg.max_pitch_rad)
            self._target_frame = (key, (*frames.target_frame_from_normal(p_poi, n_map), pitch))
        self._R_map_t, self._origin_map, self._pitch = self._target_frame[1]
        self._yaw_goal = frames.yaw_facing(n_map, default_rad=self._yaw_ref)

    def _track_target(self, target):
        # the segment lives in frame t, so a refined estimate moves the whole reference
        if self._target_usable(target):
            self._set_target_frame(target)

    def _standoff_t(self):
        return np.array([0.0, 0.0, self.config.standoff_m + self.vehicle.tool_tip_x_m])

    def _to_map(self):
        """Re-express the current reference in map and make map the working frame."""
        p, v = self._ref_map()
        self._R_map_t, self._origin_map = np.eye(3), np.zeros(3)
        self._traj = MinJerk(self._now_s, p, p, 1.0, v)
        self._depth_correction_m = 0.0      # now part of the new segment

    def _ref_t(self):
        p, v, _ = self._sample()
        return p, v

    def _sample(self):
        """(p, v, a) of the reference in frame t now, HOLD's depth correction included."""
        p, v, a = self._traj.sample(self._now_s)
        p[2] -= self._depth_correction_m
        return p, v, a

    def _ref_map(self):
        p, v = self._ref_t()
        return self._origin_map + self._R_map_t @ p, self._R_map_t @ v

    def _plan(self, goal_map, v_max):
        """New segment in map from the current reference (continuous position and speed)."""
        self._to_map()
        p, v = self._ref_t()
        self._traj = MinJerk(self._now_s, p, goal_map, v_max, v)

    def _plan_t(self, goal_t, v_max, ref_map=None):
        """New segment in the current target frame from the current reference
        (``ref_map`` = (p_map, v_map) when the frame has just changed)."""
        p_map, v_map = ref_map or self._ref_map()
        R, o = self._R_map_t, self._origin_map
        self._traj = MinJerk(self._now_s, frames.to_frame(R, o, p_map), goal_t, v_max,
                             R.T @ v_map)
        self._depth_correction_m = 0.0      # now part of the new segment

    def _arrived(self):
        cfg = self.config
        if not self._traj.done(self._now_s):
            return False
        p_t = frames.to_frame(self._R_map_t, self._origin_map, self._state.p_map)
        return (np.linalg.norm(p_t - self._traj.p1) < cfg.arrive_tol_m
                and np.linalg.norm(self._state.v_map) < cfg.arrive_speed_m_s)

    def _setpoint(self):
        cfg = self.config
        dt = 0.0 if self._last_tick_s is None else max(self._now_s - self._last_tick_s, 0.0)
        self._last_tick_s = self._now_s
        if self._mode == Mode.SEARCH and self._search.phase == 'sweep':
            self._yaw_goal = self._yaw_ref + cfg.search_yaw_rate_rad_s * dt
            self._search.swept_rad += cfg.search_yaw_rate_rad_s * dt
        err = frames.wrap_angle(self._yaw_goal - self._yaw_ref)
        step = cfg.yaw_rate_rad_s * dt
        self._yaw_ref = frames.wrap_angle(self._yaw_ref + min(max(err, -step), step))
        p, v, a = self._sample()
        if self._mode == Mode.CONTACT and self._contact_phase == 'press':
            # a quasi-static press: with the reference's own speed in C e' + M e'' the push
            # would overshoot by C times that speed halfway through the ramp
            v[2] = a[2] = 0.0
        # leaving the wall, the reference starts behind the surface: keep the compliant
        # gains until it is out, so the push fades instead of stiffening
        releasing = self._mode == Mode.RETREAT and p[2] < self.vehicle.tool_tip_x_m
        return ImpedanceSetpoint(
            R_map_t=self._R_map_t.copy(), origin_map=self._origin_map.copy(),
            lambda_d_t=p, dlambda_d_t=v, ddlambda_d_t=a,
            yaw_rad=self._yaw_ref, pitch_rad=self._pitch,
            contact_gains=self._contact_gains or releasing)


def _finite_state(state):
    return state is not None and all(map(math.isfinite, np.concatenate(
        (state.p_map, state.q_map_base, state.v_map)).tolist()))


def _yaw_of(state):
    # the yaw of matrix_to_euler_zyx from the two matrix entries it needs (every tick)
    x, y, z, w = np.asarray(state.q_map_base, dtype=float).tolist()
    n2 = x * x + y * y + z * z + w * w
    m00, m10 = 1.0 - 2.0 * (y * y + z * z) / n2, 2.0 * (x * y + z * w) / n2
    if math.hypot(m00, m10) < 1e-12:
        return matrix_to_euler_zyx(frames.quat_matrix(state.q_map_base))[0]
    return math.atan2(m10, m00)
