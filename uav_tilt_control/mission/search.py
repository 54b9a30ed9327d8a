"""SEARCH: turn where the vehicle is, at three altitudes, then face the wall vision saw most,
then the faces of the site's structures turned away from where the search began, until a
candidate target is seen; confirm it (phases 'confirm', 'closer') before APPROACH.

Phases: 'sweep' (turning), 'climb' and 'descend' (to the next altitude), 'face' (to a point
in front of the wall or a structure's face, round the site's obstacles), 'confirm', 'closer'
(to look at a far candidate again), 'clear' (backing off what the tool touched). See
SearchConfig.
"""
import math

import numpy as np

from uav_tilt_common.modes import Mode
from uav_tilt_control import frames
from uav_tilt_control.mission.base import (Context, Enter, FailTask, ModeBehaviour,
                                           Transition, usable)
from uav_tilt_control.obstacles import face_views
from uav_tilt_control.target_estimator import TargetEstimate
from uav_tilt_control.walls import WallMemory

SWEEP, CLIMB, DESCEND, FACE = 'sweep', 'climb', 'descend', 'face'
CONFIRM, CLOSER, CLEAR = 'confirm', 'closer', 'clear'
# after a candidate is dropped, the sweep turns on this long before looking at candidates
IGNORE_AFTER_DROP_S = 1.5


class Search(ModeBehaviour):
    """SEARCH, owning its sweep, the walls it has seen and the candidate it confirms."""

    mode = Mode.SEARCH

    def __init__(self, ctx: Context) -> None:
        super().__init__(ctx)
        self._reset()

    def _reset(self) -> None:
        self._phase = SWEEP
        self.level = 0
        self.swept_rad = 0.0
        self.turn_rad = 2.0 * math.pi   # what this sweep turns
        self.walls = WallMemory()
        # (point, yaw) to face a wall or a structure from, once planned
        self.face_points: list[tuple[np.ndarray, float]] | None = None
        self.legs: list[np.ndarray] = []    # the way to the point under way, corner by corner
        self.closer_legs: list[np.ndarray] = []     # the same, closer to a candidate
        self.face_yaw = 0.0
        self.origin = np.zeros(3)           # where the search began
        self.resume_phase = SWEEP
        self.since_s = 0.0
        self.ignore_until_s = -math.inf
        self.agreeing = 0
        self.moved_closer = False
        self.position = np.zeros(3)
        self._last_stamp_s: float | None = None

    @property
    def phase(self) -> str:
        return self._phase

    def enter(self, previous: Mode, target: TargetEstimate | None) -> None:
        ref = self.ctx.ref
        ref.to_map()
        ref.plan(ref.in_map()[0], self.ctx.config.flight.hover_speed_m_s)
        ref.yaw_goal = ref.yaw_ref
        self._reset()
        self.origin = ref.in_map()[0]

    def observe_plane(self, point_map: np.ndarray, normal_map: np.ndarray,
                      share: float) -> None:
        """A plane vision saw (map; share of its frame): a wall to face later."""
        self.walls.observe(point_map, normal_map, share)

    def tick(self, target: TargetEstimate | None, f_n: float,
             stale: bool) -> Transition | None:
        ctx = self.ctx
        push = ctx.bump()
        if ctx.time_in_mode() > ctx.config.search.timeout_s:
            return FailTask('target_not_found')
        if push is not None and self._phase != CLEAR:
            # turn on from where it backed off (a climb, or a flight to face the wall, that
            # met the wall ends there)
            if self._phase in (CLIMB, DESCEND, FACE):
                self.swept_rad = 0.0      # its turn is still to come
            self._phase, self.legs = CLEAR, []
            ctx.back_off(push)
        elif self._phase == CLEAR:
            if ctx.arrived() or ctx.ref.overdue():
                self._phase = SWEEP
        elif self._phase in (CONFIRM, CLOSER):
            return self._confirm(target)
        elif usable(target) and ctx.now_s >= self.ignore_until_s:
            assert target is not None
            self._candidate(target)
            ctx.event('candidate target')
            # face it: the detector sees it best in the middle of the image
            d = target.p_poi_map - ctx.vehicle_state.p_map
            ctx.ref.yaw_goal = math.atan2(d[1], d[0])
        elif self._phase == SWEEP and self.swept_rad >= self.turn_rad:
            if not (self.face_points is None and self._next_level()) \
                    and not self._face_next():
                return FailTask('target_not_found')
        elif self._phase in (CLIMB, DESCEND) and ctx.arrived():
            self._phase, self.swept_rad = SWEEP, 0.0
        elif self._phase == FACE and ctx.arrived() and self.legs:
            ctx.ref.plan(self.legs.pop(0), ctx.config.flight.hover_speed_m_s)
        elif self._phase == FACE and ctx.arrived():
            # turn to one side of the wall first, then sweep across it
            ref = ctx.ref
            ref.yaw_goal = self.face_yaw - 0.5 * self.turn_rad
            if abs(frames.wrap_angle(ref.yaw_goal - ref.yaw_ref)) < (
                    ctx.config.flight.arrive_yaw_tol_rad):
                self._phase, self.swept_rad = SWEEP, 0.0
        return None

    def steer(self, dt_s: float) -> None:
        """The sweep's yaw step: no faster than the yaw reference may turn, or the turn
        counted is not made."""
        if self._phase != SWEEP:
            return
        cfg = self.ctx.config
        sweep = min(cfg.search.yaw_rate_rad_s, cfg.flight.yaw_rate_rad_s) * dt_s
        self.ctx.ref.yaw_goal = self.ctx.ref.yaw_ref + sweep
        self.swept_rad += sweep

    # ---- the sweep ----

    def _next_level(self) -> bool:
        """Climb or descend to the next altitude to turn at, or as near it as the walls
        seen let the tool's reach keep search.wall_clearance_m off them (a level that
        leaves no room to move is passed over); False when no level is left."""
        ctx, cfg = self.ctx, self.ctx.config
        levels = cfg.search_altitudes_m()
        p = ctx.ref.in_map()[0]
        lo, hi = self.walls.altitudes_clear_of(
            p, ctx.vehicle.tool_tip_x_m + cfg.search.wall_clearance_m)
        while self.level + 1 < len(levels):
            self.level += 1
            # not further into a wall's reach than it already is
            z = min(max(levels[self.level], min(lo, p[2])), max(hi, p[2]))
            if abs(z - p[2]) <= cfg.flight.arrive_tol_m:
                continue
            self._phase = CLIMB if z > p[2] else DESCEND
            ctx.ref.plan(np.array([p[0], p[1], z]), cfg.flight.climb_speed_m_s)
            ctx.event(('climbing' if self._phase == CLIMB else 'descending')
                      + f' to search at {z:.2f} m'
                      + ('' if z == levels[self.level] else ', clear of a wall'))
            return True
        return False

    def _face_next(self) -> bool:
        """Fly to the next point to face the wall or a structure from (planned on the first
        call: in front of the wall seen most, then the site's structures' faces turned away
        from where the search began, one after the nearest), round the site's obstacles;
        False when there is none left."""
        ctx, cfg = self.ctx, self.ctx.config
        if self.face_points is None:
            self.face_points = self._plan_faces() if cfg.search.face_m > 0.0 else []
        while self.face_points:
            goal, yaw = self.face_points.pop(0)
            path = ctx.route(ctx.ref.in_map()[0], goal)
            if path is None:
                continue
            self.legs, self.face_yaw = path, yaw
            self._phase, self.turn_rad = FACE, cfg.search.face_turn_rad
            ctx.ref.plan(self.legs.pop(0), cfg.flight.hover_speed_m_s)
            ctx.ref.yaw_goal = self.face_yaw - 0.5 * self.turn_rad
            ctx.event('facing the wall from ({:.2f}, {:.2f}, {:.2f})'.format(*goal))
            return True
        return False

    def _plan_faces(self) -> list[tuple[np.ndarray, float]]:
        """The points to face from and their headings (see :meth:`_face_next`)."""
        ctx, cfg = self.ctx, self.ctx.config
        p = ctx.ref.in_map()[0]
        wall = self.walls.best()
        points: list[tuple[np.ndarray, float]] = []
        if wall is not None:
            ends, yaw = wall.face_points(
                cfg.search.face_m, cfg.flight.takeoff_altitude_m, cfg.search.face_m)
            points = [(q, yaw) for q in sorted(ends, key=lambda q: float(np.linalg.norm(q - p)))]
        views = face_views(ctx.obstacles, cfg.search.face_m, cfg.flight.takeoff_altitude_m,
                           self.origin, ctx.keep_off_m)
        here = points[-1][0] if points else p
        while views:    # the nearest next
            k = min(range(len(views)), key=lambda i: float(np.linalg.norm(views[i][0] - here)))
            points.append(views.pop(k))
            here = points[-1][0]
        return points

    # ---- the candidate ----

    def _candidate(self, target: TargetEstimate) -> None:
        """Start confirming the target estimate ``target``."""
        self.resume_phase = self._phase
        self._phase = CONFIRM
        self.since_s = self.ctx.now_s
        self.agreeing = 0
        self.moved_closer = False
        self.position = np.asarray(target.p_poi_map, dtype=float).copy()
        self._last_stamp_s = None

    def _observe(self, target: TargetEstimate) -> None:
        """Count a new measurement of the candidate (a newer stamp) that agrees with the one
        before; one elsewhere starts the count again from there."""
        stamp = self.ctx.now_s - target.age_s
        if self._last_stamp_s is not None and stamp <= self._last_stamp_s + 1e-9:
            return
        self._last_stamp_s = stamp
        if np.linalg.norm(np.asarray(target.p_poi_map) - self.position) > (
                self.ctx.config.search.confirm_radius_m):
            self.agreeing = 0
        self.position = np.asarray(target.p_poi_map, dtype=float).copy()
        self.agreeing += 1

    def _confirm(self, target: TargetEstimate | None) -> Transition | None:
        """Hold and watch a candidate: confirmed after search.confirm_n agreeing
        measurements."""
        ctx, cfg = self.ctx, self.ctx.config
        if self._phase == CLOSER:
            if ctx.arrived() and self.closer_legs:
                ctx.ref.plan(self.closer_legs.pop(0), cfg.flight.hover_speed_m_s)
            elif ctx.arrived():
                self._phase, self.since_s = CONFIRM, ctx.now_s
            return None
        if usable(target):
            assert target is not None
            self._observe(target)
            if self.agreeing >= cfg.search.confirm_n:
                return Enter(Mode.APPROACH, 'target confirmed', target=target)
        if ctx.now_s - self.since_s <= cfg.search.confirm_timeout_s:
            return None
        away = self.position - ctx.vehicle_state.p_map
        away[2] = 0.0
        distance = float(np.linalg.norm(away))
        if self.agreeing and not self.moved_closer and \
                distance > cfg.search.confirm_range_m + cfg.flight.arrive_tol_m:
            p = ctx.ref.in_map()[0]
            # round the site's obstacles (boxed in: the candidate is dropped)
            path = ctx.route(p, p + away * (1.0 - cfg.search.confirm_range_m / distance))
            if path is not None:
                self._phase, self.moved_closer, self.closer_legs = CLOSER, True, path
                ctx.ref.plan(self.closer_legs.pop(0), cfg.flight.hover_speed_m_s)
                ctx.event('closer to the candidate')
                return None
        if ctx.drop_target is not None:
            ctx.drop_target()
        self._phase, self.ignore_until_s = self.resume_phase, ctx.now_s + IGNORE_AFTER_DROP_S
        ctx.event('candidate dropped')
        return None
