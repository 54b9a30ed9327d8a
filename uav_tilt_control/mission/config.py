"""The mission's parameters (controller_node's ``mission.*``, DESIGN section 7), one group per
family of modes and one per detector."""
import dataclasses
from typing import ClassVar

from uav_tilt_common.config import nested, param


@dataclasses.dataclass
class FlightConfig:
    """Free flight: take-off, hover, the flights between tasks, and arrival."""

    takeoff_altitude_m: float = param(1.5, lo=0.3, hi=20.0)
    climb_speed_m_s: float = param(0.5, lo=0.05, hi=3.0)
    # a take-off that has not reached its altitude this long after its climb's own time
    # (a wall leaning over the start that its back-offs do not clear) lands
    takeoff_timeout_s: float = param(20.0, lo=0.0, hi=600.0)
    hover_speed_m_s: float = param(0.5, lo=0.05, hi=3.0)
    hover_settle_s: float = param(1.0, lo=0.0, hi=30.0)     # HOVER before SEARCH on inspect
    yaw_rate_rad_s: float = param(0.5, lo=0.05, hi=3.0)
    # the body pitch that points the tool (contact.pitch_to_normal) turns no faster than
    # this: a step would swing the tool tip 0.45 m ahead by up to 0.2 m at the attitude
    # loop's speed
    pitch_rate_rad_s: float = param(0.5, lo=0.05, hi=3.0)
    # A free-flight segment the vehicle has not arrived at this long after the segment's
    # own time has met something that holds it (the ground, a wall it rests on): APPROACH,
    # RETREAT and HOVER's transit land (failsafe 'unreachable'); a back-off ('clear') goes
    # on from where it got to.
    arrive_timeout_s: float = param(15.0, lo=1.0, hi=600.0)
    arrive_tol_m: float = param(0.05, lo=0.001, hi=1.0)
    arrive_speed_m_s: float = param(0.1, lo=0.001, hi=1.0)
    arrive_yaw_tol_rad: float = param(0.05, lo=0.001, hi=1.0)
    # Arrival and landing ask whether the vehicle is still, which is its mean speed over a
    # while, not one odometry sample: they read the velocity low-passed over this (noise of
    # 0.05 m/s per axis puts a third of the samples over 0.1 m/s).
    speed_tau_s: float = param(0.1, lo=0.0, hi=2.0)
    # Between tasks: a touch's target is looked for from this far in front of where the plan
    # says it is (base_link to the wall, on its normal), so that the camera sees it at once.
    look_distance_m: float = param(1.5, lo=0.3, hi=20.0)
    # APPROACH keeps the vehicle's reach (its tool tip ahead, its rotors round it) this much
    # more off every obstacle the site lists (site.obstacle_boxes), going round them
    obstacle_clearance_m: float = param(0.25, lo=0.0, hi=5.0)


@dataclasses.dataclass
class SearchConfig:
    """SEARCH and its confirmation of a candidate target.

    A full turn at the take-off altitude, one more ``climb_m`` higher (a wider view of a
    tall wall) and one more ``descend_m`` lower (the camera looks level and sees 23 degrees
    down: a low target on a near wall lies below the image), until a candidate target is
    seen; it is confirmed once ``confirm_n`` of its measurements agree within
    ``confirm_radius_m``. One not confirmed within ``confirm_timeout_s`` is looked at again
    from ``confirm_range_m`` (a small far target is seen in few frames), then dropped, and
    the sweep goes on. After the three turns, the search faces the wall vision saw most
    (vision/planes): from ``face_m`` in front of each end of what it saw of it, at the
    take-off altitude, it sweeps ``face_turn_rad`` across the wall (a target seen far off
    its normal from the start is seen nearly head-on there). ``timeout_s`` in all, then the
    task fails. It climbs and descends only as far as keeps the tool's reach
    ``wall_clearance_m`` off every wall it has seen, horizontally: a wall leaning over the
    start nears as the vehicle climbs, and a turn there would swing the tool into it.
    """

    yaw_rate_rad_s: float = param(0.35, lo=0.0, hi=1.0)  # 0: hover and wait
    climb_m: float = param(0.8, lo=0.0, hi=10.0)
    descend_m: float = param(0.6, lo=0.0, hi=10.0)   # not below the lowest hover
    face_m: float = param(2.5, lo=0.0, hi=20.0)      # 0: no facing
    face_turn_rad: float = param(2.1, lo=0.1, hi=6.3)
    timeout_s: float = param(150.0, lo=0.5, hi=600.0)
    wall_clearance_m: float = param(0.3, lo=0.0, hi=5.0)
    confirm_n: int = param(5, lo=1, hi=100, unit='',
                           doc='detections within confirm_radius_m that confirm a target')
    confirm_radius_m: float = param(0.15, lo=0.01, hi=2.0)
    confirm_timeout_s: float = param(4.0, lo=0.1, hi=60.0)
    # a candidate seen but not confirmed farther than this is looked at again from here
    confirm_range_m: float = param(2.5, lo=0.5, hi=20.0)


@dataclasses.dataclass
class ContactConfig:
    """APPROACH, CONTACT, HOLD and TARGET_LOST: the standoff, the touch and the push.

    CONTACT closes in to ``touch_margin_m`` before the estimated surface at up to
    ``close_speed_m_s``, creeps on at ``touch_speed_m_s`` until the F/T feels the wall, then
    presses: the push ramps up to the task's over ``press_time_s``. A vehicle of mass M
    arriving at v on a wall of stiffness k meets a peak of about v sqrt(k M), so a slow creep
    keeps the first touch well under the push asked for (docs/control.md).
    """

    MOVED: ClassVar[dict[str, str]] = {'touch_overrun_m': 'touch_overrun_n',
                                       'force_tau_s': '/flight.impedance.force_tau_s'}

    standoff_m: float = param(0.6, lo=0.1, hi=5.0)          # tool tip to surface
    approach_speed_m_s: float = param(0.3, lo=0.05, hi=2.0)
    pitch_to_normal: bool = param(True)                     # align the tool with the normal
    # 31 deg: square on every surface a scenario inclines (a wall's +-30 deg), a degree spare
    max_pitch_rad: float = param(0.54, lo=0.0, hi=1.0)
    # A target whose estimated normal leans further than max_pitch_rad plus this from
    # horizontal is not touched (the tool cannot sit square on it). 4 deg: twice the
    # largest angle between the tool and the true normal in vision campaigns on structures
    # (1.7 deg), so a surface at the limit is not refused for vision's error. More touches
    # off square: the body stands off the normal for the tool tip to meet the POI.
    reach_margin_rad: float = param(0.07, lo=0.0, hi=0.5)
    close_speed_m_s: float = param(0.2, lo=0.01, hi=0.5)
    touch_margin_m: float = param(0.05, lo=0.0, hi=0.5)
    touch_speed_m_s: float = param(0.01, lo=0.001, hi=0.2)
    # Past the estimated surface the creep goes on as a push that rises at
    # touch_push_rate_n_s (the impedance law's contact K_z times touch_speed_m_s on the
    # default gains), to touch_overrun_n at most, or to twice the touch's threshold if more.
    touch_push_rate_n_s: float = param(0.1, lo=0.001, hi=10.0)
    touch_overrun_n: float = param(1.0, lo=0.0, hi=20.0)
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
    # the push ramps up over this, and is let go over it when the tool leaves the wall
    press_time_s: float = param(2.0, lo=0.1, hi=30.0)
    threshold_n: float = param(1.0, lo=0.05, hi=20.0)   # in contact while pressing
    detect_ticks: int = param(2, lo=1, hi=100)
    lost_s: float = param(0.1, lo=0.0, hi=5.0)
    hold_time_s: float = param(5.0, lo=0.0, hi=600.0)
    # Tool tip nearer the surface than this: the tool hides the POI from the eye-in-hand
    # camera, so CONTACT keeps the last target frame (the target is static) instead of
    # calling the target lost.
    tool_occlusion_range_m: float = param(0.15, lo=0.0, hi=2.0)
    target_lost_hold_s: float = param(0.5, lo=0.05, hi=60.0)
    target_lost_retreat_s: float = param(3.0, lo=0.1, hi=600.0)


@dataclasses.dataclass
class SlideConfig:
    """SLIDE: the tool tip's speed rises to the task's and comes down at the end of each leg
    with at most ``accel_m_s2``; the task fails once the tool tip (odometry) is
    ``path_tolerance_m`` off the line, in the wall's plane, or that far behind its reference
    or short of the line's end, along it."""

    accel_m_s2: float = param(0.1, lo=0.005, hi=2.0)
    path_tolerance_m: float = param(0.05, lo=0.001, hi=1.0)


@dataclasses.dataclass
class BumpConfig:
    """The tool touched something in free flight (TAKEOFF, HOVER, SEARCH, LAND: a wall
    leaning over the start as the vehicle climbs or turns, a wall on the way to the next
    task, one leaning away as it descends): a force on it above ``threshold_n`` stops what
    the vehicle was doing, and it backs off ``clearance_m`` along that force (phase 'clear';
    in TAKEOFF and LAND along its horizontal part, the ground being below, and a push from
    above lands the take-off), then goes on from there."""

    threshold_n: float = param(1.0, lo=0.1, hi=50.0)
    # ... told by the F/T force low-passed over this: a touch lasts longer than the sensor's
    # noise, which at 0.3 N (per axis, every tick) passes 1 N several times a second.
    tau_s: float = param(0.03, lo=0.0, hi=1.0)
    clearance_m: float = param(0.6, lo=0.05, hi=5.0)


@dataclasses.dataclass
class LandConfig:
    """LAND and the land detector (as PX4's): below ``detect_height_m`` above ``ground_z_m``,
    or stopped above its descending setpoint while asking for less than
    ``detect_thrust_ratio`` of the nominal weight (a roof), slower than
    ``detect_speed_m_s`` for ``detect_s``."""

    descent_rate_m_s: float = param(0.3, lo=0.05, hi=2.0)
    ground_z_m: float = param(0.0, lo=-100.0, hi=100.0)
    detect_height_m: float = param(0.3, lo=0.0, hi=2.0)     # above ground_z_m
    detect_speed_m_s: float = param(0.1, lo=0.01, hi=1.0)
    detect_s: float = param(0.5, lo=0.0, hi=10.0)
    # Landed above ground_z_m (a roof) only while the vertical thrust asked for is below this
    # fraction of the nominal weight (as PX4's LNDMC_LOW_T_THR): a vehicle that keeps still
    # in the air makes its own weight, at least half the nominal one (the scenarios' range).
    detect_thrust_ratio: float = param(0.3, lo=0.0, hi=1.0)


@dataclasses.dataclass
class FailsafeConfig:
    """What ends the plan: the force limit, stale odometry (a blind descent), an upset (as
    PX4's failure detector) and the geofence (as PX4's GF_MAX_HOR_DIST, GF_MAX_VER_DIST)."""

    force_limit_n: float = param(15.0, lo=1.0, hi=100.0)
    odom_stale_s: float = param(0.1, lo=0.005, hi=5.0)
    descent_rate_m_s: float = param(0.2, lo=0.05, hi=2.0)
    land_margin_s: float = param(2.0, lo=0.0, hi=60.0)   # blind: after the descent
    # Tilted past upset_tilt_rad for upset_s, the rotors stop: upside down they would only
    # drive the vehicle into what is near. Missions tilt far less (docs/control.md); a
    # vehicle that lost a rotor tumbles, each half turn past 60 degrees for about 0.3 s.
    upset_tilt_rad: float = param(1.05, lo=0.3, hi=3.2)
    upset_s: float = param(0.1, lo=0.0, hi=10.0)
    # a hover setpoint farther than this from where the vehicle took off, or higher above
    # land.ground_z_m, is refused
    fence_radius_m: float = param(100.0, lo=1.0, hi=1e4)
    fence_height_m: float = param(30.0, lo=1.0, hi=1e3)


@dataclasses.dataclass
class MissionConfig:
    """Mission geometry, speeds, detection thresholds and failsafe timeouts, by group."""

    # Parameters of the single flat group before it was split: their new place.
    MOVED: ClassVar[dict[str, str]] = {
        **{name: 'flight.' + name for name in (
            'takeoff_altitude_m', 'climb_speed_m_s', 'takeoff_timeout_s', 'hover_speed_m_s',
            'hover_settle_s', 'yaw_rate_rad_s', 'pitch_rate_rad_s', 'arrive_timeout_s',
            'arrive_tol_m', 'arrive_speed_m_s', 'arrive_yaw_tol_rad', 'speed_tau_s',
            'look_distance_m')},
        **{'search_' + name: 'search.' + name for name in (
            'yaw_rate_rad_s', 'climb_m', 'descend_m', 'face_m', 'face_turn_rad', 'timeout_s',
            'wall_clearance_m')},
        **{name: 'search.' + name for name in (
            'confirm_n', 'confirm_radius_m', 'confirm_timeout_s', 'confirm_range_m')},
        **{name: 'contact.' + name for name in (
            'standoff_m', 'approach_speed_m_s', 'pitch_to_normal', 'max_pitch_rad',
            'touch_margin_m', 'touch_speed_m_s', 'touch_threshold_n', 'touch_noise_sigmas',
            'touch_align_m', 'touch_align_wait_s', 'touch_align_clearance_m',
            'press_time_s', 'hold_time_s', 'tool_occlusion_range_m', 'target_lost_hold_s',
            'target_lost_retreat_s')},
        # a distance past the surface is now the push there (touch_push_rate_n_s)
        'touch_overrun_m': 'contact.touch_overrun_n',
        # the push's trim is the impedance law's
        'force_tau_s': '/flight.impedance.force_tau_s',
        'contact_speed_m_s': 'contact.close_speed_m_s',
        'contact_threshold_n': 'contact.threshold_n',
        'contact_detect_ticks': 'contact.detect_ticks',
        'contact_lost_s': 'contact.lost_s',
        'slide_accel_m_s2': 'slide.accel_m_s2',
        'slide_path_tolerance_m': 'slide.path_tolerance_m',
        'free_flight_contact_n': 'bump.threshold_n',
        'free_flight_contact_tau_s': 'bump.tau_s',
        'free_flight_clearance_m': 'bump.clearance_m',
        'descent_rate_m_s': 'land.descent_rate_m_s',
        'ground_z_m': 'land.ground_z_m',
        **{'land_' + name: 'land.' + name for name in (
            'detect_height_m', 'detect_speed_m_s', 'detect_s', 'detect_thrust_ratio')},
        **{name: 'failsafe.' + name for name in (
            'force_limit_n', 'odom_stale_s', 'upset_tilt_rad', 'upset_s', 'fence_radius_m',
            'fence_height_m')},
        'failsafe_descent_rate_m_s': 'failsafe.descent_rate_m_s',
        'failsafe_land_margin_s': 'failsafe.land_margin_s',
    }

    flight: FlightConfig = nested(FlightConfig)
    search: SearchConfig = nested(SearchConfig)
    contact: ContactConfig = nested(ContactConfig)
    slide: SlideConfig = nested(SlideConfig)
    bump: BumpConfig = nested(BumpConfig)
    land: LandConfig = nested(LandConfig)
    failsafe: FailsafeConfig = nested(FailsafeConfig)

    def lowest_hover_m(self) -> float:
        """The lowest altitude the mission hovers, searches or works at: twice the landing
        detector's height above the ground, clear of it."""
        return self.land.ground_z_m + 2.0 * self.land.detect_height_m

    def search_altitudes_m(self) -> tuple[float, float, float]:
        """The altitudes SEARCH turns at, in turn: take-off, higher, lower."""
        takeoff_m, search = self.flight.takeoff_altitude_m, self.search
        low = max(takeoff_m - search.descend_m, self.lowest_hover_m())
        return takeoff_m, takeoff_m + search.climb_m, low
