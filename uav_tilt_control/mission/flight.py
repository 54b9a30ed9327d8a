"""Free-flight modes: IDLE, TAKEOFF, HOVER (and its transit to the next task's target),
LAND and FAILSAFE_LAND.

A bump (the tool touched something, see BumpConfig) stops what the vehicle was doing: it
backs off (phase 'clear'), in TAKEOFF and LAND along the push's horizontal part, the ground
being below, then goes on from where it got to.
"""
import math

import numpy as np

from uav_tilt_common.modes import Mode
from uav_tilt_control import frames
from uav_tilt_control.mission.base import (Context, Enter, Failsafe, FailTask, Landed,
                                           ModeBehaviour, NextTask, Transition)
from uav_tilt_control.mission.detectors import LandDetector
from uav_tilt_control.mission.reference import yaw_of
from uav_tilt_control.target_estimator import TargetEstimate
from uav_tilt_control.trajectory import MinJerk

# TAKEOFF and LAND back off horizontally; a push whose horizontal part is below this share
# of it is vertical, with no way around it: from above (a ceiling, a wall leaning over by
# more than 70 degrees) the take-off lands, from below (the ground) the landing goes on.
HORIZONTAL_SHARE = math.sin(math.radians(20.0))
CLEAR = 'clear'
TRANSIT = 'transit'


class Idle(ModeBehaviour):
    """On the ground, rotors stopped: the reference stays on the vehicle, so that a take-off
    starts from where it is."""

    mode = Mode.IDLE

    def tick(self, target: TargetEstimate | None, f_n: float,
             stale: bool) -> Transition | None:
        state = self.ctx.vehicle_state
        self.ctx.ref.follow(MinJerk(self.ctx.now_s, state.p_map, state.p_map, 1.0))
        self.ctx.ref.yaw_ref = self.ctx.ref.yaw_goal = yaw_of(state)
        return None


class _FreeFlight(ModeBehaviour):
    """A free-flight mode with the phase 'clear' while it backs off a bump."""

    def __init__(self, ctx: Context) -> None:
        super().__init__(ctx)
        self._phase = ''

    @property
    def phase(self) -> str:
        return self._phase

    def clear_vertically(self, z_goal_m: float, speed_m_s: float) -> np.ndarray | None:
        """TAKEOFF and LAND, every tick: back off horizontally what the tool touched (the
        ground is below), then climb or descend on to ``z_goal_m`` from there. Returns a push
        too vertical to back off along (see HORIZONTAL_SHARE), else None."""
        ctx = self.ctx
        push = ctx.bump()
        if push is not None and self._phase != CLEAR:
            away = push * [1.0, 1.0, 0.0]
            if np.linalg.norm(away) < HORIZONTAL_SHARE * np.linalg.norm(push):
                return push
            self._phase = CLEAR
            ctx.back_off(away)
        elif self._phase == CLEAR and (ctx.arrived() or ctx.ref.overdue()):
            self._phase = ''
            p = ctx.ref.in_map()[0]
            ctx.ref.plan(np.array([p[0], p[1], z_goal_m]), speed_m_s)
        return None


class Takeoff(_FreeFlight):
    """Climb to flight.takeoff_altitude_m above where the vehicle stands, then HOVER."""

    mode = Mode.TAKEOFF

    def __init__(self, ctx: Context) -> None:
        super().__init__(ctx)
        self._deadline_s = math.inf

    def enter(self, previous: Mode, target: TargetEstimate | None) -> None:
        ctx, cfg = self.ctx, self.ctx.config.flight
        self._phase = ''
        p_meas = ctx.vehicle_state.p_map
        ctx.geofence.home_map = p_meas.copy()
        goal = np.array([p_meas[0], p_meas[1], cfg.takeoff_altitude_m])
        ctx.ref.to_map()
        segment = MinJerk(ctx.now_s, p_meas, goal, cfg.climb_speed_m_s)
        ctx.ref.follow(segment)
        self._deadline_s = ctx.now_s + segment.T + cfg.takeoff_timeout_s

    def tick(self, target: TargetEstimate | None, f_n: float,
             stale: bool) -> Transition | None:
        cfg = self.ctx.config.flight
        vertical = self.clear_vertically(cfg.takeoff_altitude_m, cfg.climb_speed_m_s)
        if self.ctx.now_s > self._deadline_s:
            return Failsafe('takeoff_timeout', Mode.LAND)
        if vertical is not None and vertical[2] < 0.0:
            return Failsafe('takeoff_blocked', Mode.LAND)
        if not self._phase and self.ctx.arrived():
            return Enter(Mode.HOVER)
        return None


class Hover(_FreeFlight):
    """Hold the hover point (moved by setpoints), start the plan's first task once settled,
    or fly to the next task's target (phase 'transit', round the site's obstacles as the
    approach goes: at rest at each corner) and SEARCH there; boxed in, the task fails
    ('no_clear_path')."""

    mode = Mode.HOVER

    def __init__(self, ctx: Context) -> None:
        super().__init__(ctx)
        self._corners: list[np.ndarray] | None = []     # still to fly to; None: boxed in

    def enter(self, previous: Mode, target: TargetEstimate | None) -> None:
        self._phase = ''
        self._corners = []
        ref = self.ctx.ref
        ref.to_map()
        ref.plan(ref.in_map()[0], self.ctx.config.flight.hover_speed_m_s)
        ref.yaw_goal = ref.yaw_ref

    def transit(self, look_map: np.ndarray, view_map: np.ndarray) -> None:
        """Fly to ``look_map``, the camera looking along ``view_map``."""
        ctx, cfg = self.ctx, self.ctx.config
        self._phase = TRANSIT
        path = ctx.route(ctx.ref.in_map()[0], look_map)
        self._corners = None if path is None else path[1:]
        if path is not None:
            ctx.ref.plan(path[0], cfg.flight.hover_speed_m_s)
        ctx.ref.yaw_goal = frames.yaw_facing(view_map, default_rad=ctx.ref.yaw_ref)
        pitch = frames.pitch_facing(view_map) if cfg.contact.pitch_to_normal else 0.0
        ctx.ref.pitch_goal = min(max(pitch, -cfg.contact.max_pitch_rad),
                                 cfg.contact.max_pitch_rad)

    def stop(self) -> None:
        """Stop the transit (or back-off) where the reference is."""
        if self._phase:
            self._phase = ''
            self.ctx.ref.plan(self.ctx.ref.in_map()[0], self.ctx.config.flight.hover_speed_m_s)

    def tick(self, target: TargetEstimate | None, f_n: float,
             stale: bool) -> Transition | None:
        ctx = self.ctx
        push = ctx.bump()
        if push is not None and self._phase != CLEAR:
            self._phase = CLEAR
            ctx.back_off(push)
        elif self._phase == CLEAR:
            if ctx.arrived() or ctx.ref.overdue():
                self._phase = ''
                if ctx.tasks.running():
                    # in HOVER a task runs only in transit to its target: look from here
                    return Enter(Mode.SEARCH, 'searching from where it backed off')
        elif self._phase == TRANSIT:
            if self._corners is None:
                self._phase = ''
                return FailTask('no_clear_path')
            if self._corners:
                if ctx.ref.segment.done(ctx.now_s):
                    ctx.ref.plan(self._corners.pop(0), ctx.config.flight.hover_speed_m_s)
            elif ctx.arrived() and ctx.turned():
                self._phase = ''
                return Enter(Mode.SEARCH)
            if ctx.ref.overdue():
                return Failsafe('unreachable', Mode.LAND)
        elif ctx.inspect_pending and ctx.time_in_mode() >= ctx.config.flight.hover_settle_s:
            ctx.inspect_pending = False
            return NextTask()
        return None


class Land(_FreeFlight):
    """Descend to the ground (out from the last surface worked on when it leans away) until
    the land detector says landed."""

    mode = Mode.LAND

    def __init__(self, ctx: Context) -> None:
        super().__init__(ctx)
        self.detector = LandDetector(ctx.config.land, ctx.vehicle)

    def descent_rate_m_s(self) -> float:
        return self.ctx.config.land.descent_rate_m_s

    def enter(self, previous: Mode, target: TargetEstimate | None) -> None:
        ref = self.ctx.ref
        self._phase = ''
        self.detector.reset()
        ref.plan(landing_point(self.ctx, ref.in_map()[0]), self.descent_rate_m_s())
        ref.yaw_goal = ref.yaw_ref
        ref.pitch_goal = 0.0

    def tick(self, target: TargetEstimate | None, f_n: float,
             stale: bool) -> Transition | None:
        cfg = self.ctx.config.land
        # a wall leaning away from the vehicle comes nearer as it descends
        self.clear_vertically(cfg.ground_z_m, cfg.descent_rate_m_s)
        if self._phase:
            return None
        return self.detect()

    def detect(self) -> Transition | None:
        ctx = self.ctx
        reason = self.detector.update(
            ctx.now_s, float(ctx.vehicle_state.p_map[2]), float(ctx.ref.in_map()[0][2]),
            float(np.linalg.norm(ctx.velocity)), ctx.thrust_up_n, ctx.bump() is not None)
        return Landed(reason) if reason else None


class FailsafeLand(Land):
    """Descend blind on stale odometry (PX4's failsafe): landed after the time the descent
    needs plus failsafe.land_margin_s, unless fresh odometry shows it earlier."""

    mode = Mode.FAILSAFE_LAND

    def descent_rate_m_s(self) -> float:
        return self.ctx.config.failsafe.descent_rate_m_s

    @property
    def phase(self) -> str:
        return ''

    def tick(self, target: TargetEstimate | None, f_n: float,
             stale: bool) -> Transition | None:
        if not stale:
            return self.detect()
        segment = self.ctx.ref.segment
        if self.ctx.now_s > segment.t0_s + segment.T + self.ctx.config.failsafe.land_margin_s:
            return Landed('landed (blind)', judged=False)
        return None


def landing_point(ctx: Context, p_map: np.ndarray) -> np.ndarray:
    """Where the descent from ``p_map`` ends: on the ground below it or, below the last
    surface worked on when that leans away from the vehicle (its foot comes nearer as the
    vehicle descends), out from it as far as keeps the tool tip contact.standoff_m from its
    plane down to the ground. The straight line there keeps at least that much all the
    way: it starts at the standoff."""
    cfg = ctx.config
    goal = np.array([p_map[0], p_map[1], cfg.land.ground_z_m])
    surface = ctx.ref.target_frame
    if surface is None:
        return goal
    n_map = surface.frame.R[:, 2]       # the surface's outward normal
    n_h2 = float(n_map[:2] @ n_map[:2])
    if n_h2 < 1e-6:
        return goal                                 # a floor or a ceiling
    yaw_rad = ctx.ref.yaw_ref
    tool_map = ctx.vehicle.tool_tip_x_m * np.array([math.cos(yaw_rad), math.sin(yaw_rad), 0.0])
    origin = surface.frame.p
    if float((p_map + tool_map - origin) @ n_map) <= 0.0:
        return goal                                 # not in front of that surface
    short_m = cfg.contact.standoff_m - float((goal + tool_map - origin) @ n_map)
    if short_m > 0.0:
        goal[:2] += short_m * n_map[:2] / n_h2      # out along the normal's level part
    return goal
