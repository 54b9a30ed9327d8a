"""Modes that bring the tool to the wall: APPROACH (to the standoff), CONTACT (close in,
touch, press) and TARGET_LOST (hold while the target is not seen)."""
import enum
import math

import numpy as np

from uav_tilt_common.modes import Mode
from uav_tilt_control.lowpass import lowpass_weight
from uav_tilt_control.mission.base import (Context, Enter, Failsafe, FailTask, ModeBehaviour,
                                           Transition, usable)
from uav_tilt_control.mission.reference import SetpointSample
from uav_tilt_control.plan import Slide
from uav_tilt_control.reach import normal_elevation_rad
from uav_tilt_control.target_estimator import TargetEstimate
from uav_tilt_control.trajectory import MIN_SEGMENT_S, MinJerk, Ramp

DETOUR = 'detour'
# The touch's alignment check low-passes the tool tip's offset with this time constant:
# odometry noise (a few mm at the tool's lever arm) averages out, a gust's drift does not.
ALIGN_TAU_S = 0.1


class Phase(str, enum.Enum):
    """CONTACT's phases (the value is what status reports)."""

    CLOSE = 'close'     # to touch_margin_m before the estimated surface
    TOUCH = 'touch'     # creeping on until the F/T feels the wall, a push past the estimate
    ALIGN = 'align'     # the creep paused while the tool tip is off the target
    PRESS = 'press'     # the push ramping up to the task's


class Approach(ModeBehaviour):
    """Fly to the standoff in front of the target, facing its normal, round the site's
    obstacles (phase 'detour', through the corners of their boxes, in map: the target frame
    is taken up again at the last one); meanwhile measure the F/T's noise (free flight),
    which sets how firm a touch must be. Boxed in, the task fails ('no_clear_path')."""

    mode = Mode.APPROACH

    def __init__(self, ctx: Context) -> None:
        super().__init__(ctx)
        self._sum_sq_n2 = 0.0
        self._samples = 0
        self._corners: list[np.ndarray] | None = []    # still to fly to; None: boxed in
        self._detouring = False
        self._target: TargetEstimate | None = None

    @property
    def phase(self) -> str:
        return DETOUR if self._detouring else ''

    def noise_rms_n(self) -> float:
        """The RMS of the F/T's normal reading over the approach (0 before a sample)."""
        return math.sqrt(self._sum_sq_n2 / self._samples) if self._samples else 0.0

    def enter(self, previous: Mode, target: TargetEstimate | None) -> None:
        assert target is not None
        ctx, ref = self.ctx, self.ctx.ref
        self._sum_sq_n2, self._samples = 0.0, 0
        self._target = target
        ref_map = ref.in_map()
        ref.set_target_frame(target)
        path = ctx.route(ref_map[0], ref.standoff_map())
        self._corners = None if path is None else path[:-1]
        self._detouring = bool(self._corners)
        if self._corners:
            ref.plan_map(self._corners.pop(0), ctx.config.contact.approach_speed_m_s, ref_map)
            ctx.event('going round an obstacle')
        elif path is not None:
            ref.plan_t(ref.standoff_t(), ctx.config.contact.approach_speed_m_s, ref_map)

    def tick(self, target: TargetEstimate | None, f_n: float,
             stale: bool) -> Transition | None:
        # On the way to the standoff the target may leave the view (a wall seen at an angle,
        # the turn to face it, a grazing look the detector misses): it is static and its
        # estimate locked, so the segment goes on. It is lost only if the vehicle, at the
        # standoff and facing it, still does not see it.
        ctx = self.ctx
        if self._corners is None:
            return FailTask('no_clear_path')
        self._sum_sq_n2 += f_n * f_n
        self._samples += 1
        if self._detouring:
            return self._go_round(target)
        ctx.track_target(target)
        if ctx.arrived() and ctx.turned():
            return self._unreachable() or ctx.target_lost() or Enter(Mode.CONTACT)
        if ctx.ref.overdue():
            return Failsafe('unreachable', Mode.LAND)
        return None

    def _unreachable(self) -> Transition | None:
        """FailTask('unreachable_normal') when the estimate at the standoff says the tool,
        pitched within contact.max_pitch_rad, cannot sit square on the target (the top or
        the underside of a pipe): the plan check cannot know where vision finds it."""
        cfg, frame = self.ctx.config.contact, self.ctx.ref.target_frame
        assert frame is not None        # the approach works in it
        elevation = normal_elevation_rad(frame.frame.R[:, 2])
        if abs(elevation) > cfg.max_pitch_rad + cfg.reach_margin_rad:
            self.ctx.event(f'the target\'s surface faces {math.degrees(elevation):+.0f} deg: '
                           f'out of the tool\'s reach')
            return FailTask('unreachable_normal')
        return None

    def _go_round(self, target: TargetEstimate | None) -> Transition | None:
        """The detour's next corner once the reference is at the one before; from the last,
        the standoff in the frame of the newest estimate."""
        ctx, ref = self.ctx, self.ctx.ref
        if usable(target):
            self._target = target
        if ref.overdue():
            return Failsafe('unreachable', Mode.LAND)
        if not ref.segment.done(ctx.now_s):
            return None
        if self._corners:
            ref.plan(self._corners.pop(0), ctx.config.contact.approach_speed_m_s)
        else:
            self._detouring = False
            ref_map = ref.in_map()
            assert self._target is not None     # the one APPROACH was entered with, or newer
            ref.set_target_frame(self._target)
            ref.plan_t(ref.standoff_t(), ctx.config.contact.approach_speed_m_s, ref_map)
        return None


class Contact(ModeBehaviour):
    """Close in to touch_margin_m before the estimated surface, creep on until the F/T feels
    the wall (pausing while the tool tip is off the target), then press: the push ramps up
    to the task's; then HOLD, or SLIDE for a slide."""

    mode = Mode.CONTACT
    contact_gains = True

    def __init__(self, ctx: Context, approach: Approach) -> None:
        super().__init__(ctx)
        self._approach = approach
        self._phase = Phase.CLOSE
        self._ticks = 0
        self._aligning = False
        self._align_waited_s = 0.0
        self._align_off_t: np.ndarray | None = None   # the tool tip off the target, filtered

    @property
    def phase(self) -> str:
        if self._phase == Phase.TOUCH and self._aligning:
            return Phase.ALIGN.value
        return self._phase.value

    def enter(self, previous: Mode, target: TargetEstimate | None) -> None:
        ctx, cfg = self.ctx, self.ctx.config.contact
        self._ticks = 0
        self._phase = Phase.CLOSE
        ctx.ref.plan_t(np.array([0.0, 0.0, ctx.vehicle.tool_tip_x_m + cfg.touch_margin_m]),
                       cfg.close_speed_m_s)

    def tick(self, target: TargetEstimate | None, f_n: float,
             stale: bool) -> Transition | None:
        ctx, cfg = self.ctx, self.ctx.config.contact
        if not self.tool_hides_poi():
            lost = ctx.target_lost()
            if lost:
                return lost
        if self._phase != Phase.PRESS:
            # once pressing, the touch point is where the wall is: the frame stays put
            ctx.track_target(target)
        phase, segment, push = self._phase, ctx.ref.segment, ctx.ref.push
        if phase == Phase.CLOSE:
            # as in the touch, several readings in a row: F/T noise is not the wall
            self._ticks = self._ticks + 1 if f_n > self.touch_threshold_n() else 0
            if self._ticks >= cfg.detect_ticks:
                self._start_press()      # the wall is nearer than estimated
            elif segment.done(ctx.now_s):
                self._start_touch()
        elif phase == Phase.TOUCH:
            self._align()
            self._ticks = self._ticks + 1 if f_n > self.touch_threshold_n() else 0
            # a wall felt while the tip is off the target is not pressed on (friction would
            # hold the tip there): the creep backs out until the tip is over it again
            if self._ticks >= cfg.detect_ticks and not self._aligning:
                self._start_press()
            elif push.done(ctx.now_s):
                return FailTask('no_contact')
        else:
            self._ticks = self._ticks + 1 if f_n > cfg.threshold_n else 0
            # the push holds (or slides) once it has reached the wanted force
            if self._ticks >= cfg.detect_ticks and push.done(ctx.now_s):
                return Enter(Mode.SLIDE if isinstance(ctx.task, Slide) else Mode.HOLD)
            if ctx.now_s > push.t0_s + push.T + cfg.press_time_s:
                return FailTask('no_contact')
        return None

    def shape(self, sample: SetpointSample) -> None:
        if self.phase == Phase.ALIGN:
            # paused: the reference stands still, and so does its speed
            sample.v[:] = 0.0
            sample.dpush_n_s = 0.0

    def touch_threshold_n(self) -> float:
        """The F/T reading that is a touch: contact.touch_threshold_n, or
        contact.touch_noise_sigmas times the RMS of the reading over the approach if more."""
        cfg = self.ctx.config.contact
        return max(cfg.touch_threshold_n, cfg.touch_noise_sigmas * self._approach.noise_rms_n())

    def tool_hides_poi(self) -> bool:
        """Whether the tool tip is so near the surface that it hides the POI from the
        camera (contact.tool_occlusion_range_m)."""
        ctx = self.ctx
        p_t = ctx.ref.to_frame(ctx.vehicle_state.p_map)
        return bool(p_t[2] - ctx.vehicle.tool_tip_x_m < ctx.config.contact.tool_occlusion_range_m)

    def _start_touch(self) -> None:
        """Creep along -z_t from where the close-in ended to the estimated surface, then on
        past it as a push that rises at contact.touch_push_rate_n_s, until the F/T feels
        the wall."""
        ctx, cfg = self.ctx, self.ctx.config.contact
        self._phase = Phase.TOUCH
        self._ticks = 0
        self._aligning, self._align_waited_s, self._align_off_t = False, 0.0, None
        p, _ = ctx.ref.in_frame()
        to_surface_s = cfg.touch_margin_m / cfg.touch_speed_m_s
        ctx.ref.follow(Ramp(ctx.now_s, p, [0.0, 0.0, -cfg.touch_speed_m_s], to_surface_s))
        # as far past the estimate as pushes with twice the touch threshold, at least: a
        # noisy F/T's firmer touch is reached, and its reading there falls under the
        # threshold only as rarely as noise passes it
        ctx.ref.push.creep(ctx.now_s + to_surface_s,
                           max(cfg.touch_overrun_n, 2.0 * self.touch_threshold_n()),
                           cfg.touch_push_rate_n_s)
        ctx.event('touching')

    def _align(self) -> None:
        """Pause the creep (its clock stands still) while the tool tip is off the target
        in the wall's plane, within the wait allowed."""
        ctx, cfg = self.ctx, self.ctx.config.contact
        dt = ctx.clock.dt_s()
        off_t = ctx.ref.tool_tip_t(ctx.vehicle_state)[:2]
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
            segment, push = ctx.ref.segment, ctx.ref.push
            segment.t0_s += dt
            push.t0_s += dt
            # the creep runs backwards, at its own speed, until the tip is clear of the wall
            clearance_m = ctx.ref.in_frame()[0][2] - ctx.vehicle.tool_tip_x_m
            if clearance_m < cfg.touch_align_clearance_m:
                segment.t0_s += dt
                push.t0_s += dt

    def _start_press(self) -> None:
        """Ramp the push up to the task's over contact.press_time_s, from one that holds the
        tool on the wall with contact.threshold_n at once (so that a stiff wall's rebound
        does not carry it off); quasi-static, so that the impedance law's damping does not
        make it overshoot."""
        ctx, cfg = self.ctx, self.ctx.config.contact
        self._phase = Phase.PRESS
        self._ticks = 0
        # the wall is where it stopped the vehicle (the reference runs ahead while it creeps)
        touch = np.array([0.0, 0.0, ctx.ref.to_frame(ctx.vehicle_state.p_map)[2]])
        ctx.ref.follow(MinJerk(ctx.now_s, touch, touch, 1.0))
        ctx.ref.push.ramp(ctx.now_s, min(cfg.threshold_n, ctx.push_n), ctx.push_n,
                          max(cfg.press_time_s, MIN_SEGMENT_S))
        ctx.event('pressing')


class TargetLost(ModeBehaviour):
    """Hold where the reference is while the target is not seen: back to the mode it was
    lost in once seen again, the task failed after contact.target_lost_retreat_s."""

    mode = Mode.TARGET_LOST
    contact_gains = None    # as in the mode it was lost in

    def __init__(self, ctx: Context) -> None:
        super().__init__(ctx)
        self._resume_mode = Mode.APPROACH

    def enter(self, previous: Mode, target: TargetEstimate | None) -> None:
        self._resume_mode = previous
        ref = self.ctx.ref
        ref.plan_t(ref.in_frame()[0], self.ctx.config.contact.approach_speed_m_s)
        ref.push.hold(ref.push.sample(self.ctx.now_s)[0])

    def tick(self, target: TargetEstimate | None, f_n: float,
             stale: bool) -> Transition | None:
        ctx, cfg = self.ctx, self.ctx.config.contact
        # lost since the last sight, or (lost on the way, see Approach) since the standoff:
        # the vehicle gets the same wait there to find it again
        lost_since = max(ctx.target_seen_s, ctx.t_mode_s - cfg.target_lost_hold_s)
        if usable(target):
            return Enter(self._resume_mode, 'target reacquired', target=target)
        if ctx.now_s - lost_since > cfg.target_lost_retreat_s:
            return FailTask('target_lost')
        return None
