"""The plan executor: commands, the plan and its task records, transitions, status and
events. Each mode is a :class:`~uav_tilt_control.mission.base.ModeBehaviour` of its own
(flight, search, contact, push); a mode's tick returns the transition it asks for and this
module carries it out.

A plan is a list of tasks (uav_tilt_control.plan); today's inspection is the one-touch plan.
IDLE -> TAKEOFF -> HOVER, then per task: a touch SEARCHes for its target (after flying, in
HOVER, to look at where the plan says it is), APPROACHes it, makes CONTACT and HOLDs the
push; a slide APPROACHes the start of its line on the site's wall, makes CONTACT and
SLIDEs along the line; both RETREAT to the standoff. After the last task it LANDs -> IDLE.
TARGET_LOST holds while the target is not seen, FAILSAFE_LAND descends blind on stale
odometry (PX4's failsafes). A task that fails (its target never found or lost, no contact,
contact lost, the tool off the line or short of its end) is recorded with its reason and
the plan goes on; the force limit, stale odometry, an upset and an unreachable goal end
the plan.
"""
import collections
import math
import typing

import numpy as np

from uav_tilt_common.config import ConfigError
from uav_tilt_common.modes import Mode
from uav_tilt_common.state import VehicleState
from uav_tilt_common.vehicle import VehicleParams
from uav_tilt_control.lowpass import lowpass_weight
from uav_tilt_control.mission.base import (IN_TARGET_FRAME, NEAR_GROUND, NEAR_WALL, Context,
                                           Enter, Failsafe, FailTask, Landed, ModeBehaviour,
                                           NextTask, Task, TaskDone, Transition, usable)
from uav_tilt_control.mission.config import MissionConfig
from uav_tilt_control.mission.contact import Approach, Contact, TargetLost
from uav_tilt_control.mission.detectors import UpsetDetector
from uav_tilt_control.mission.flight import FailsafeLand, Hover, Idle, Land, Takeoff
from uav_tilt_control.mission.push import Hold, Retreat, Slide
from uav_tilt_control.mission.records import TaskRecord
from uav_tilt_control.mission.reference import Reference
from uav_tilt_control.mission.search import Search
from uav_tilt_control.obstacles import ObstacleBox
from uav_tilt_control.plan import Slide as SlideTask, Touch
from uav_tilt_control.target_estimator import TargetEstimate
from uav_tilt_control.types import ImpedanceSetpoint

DEFAULT_CONTACT_FORCE_N = 5.0
Reply = tuple[bool, str]


class Mission:
    """Plan executor; call :meth:`update` every control tick."""

    def __init__(self, vehicle: VehicleParams, config: MissionConfig | None = None,
                 contact_force_n: float = DEFAULT_CONTACT_FORCE_N,
                 drop_target: typing.Callable[[], None] | None = None,
                 plan: list[Task] | None = None,
                 on_task: typing.Callable[[Task], None] | None = None,
                 obstacles: typing.Sequence[ObstacleBox] = ()) -> None:
        """``drop_target()``: makes the target estimate forget a candidate SEARCH did not
        confirm (the estimator's reset); ``plan``: the tasks (uav_tilt_control.plan) that
        :meth:`inspect` runs, by default one touch of the target with ``contact_force_n``
        for contact.hold_time_s, forces checked by whoever made them
        (controller_core.plan_of); ``on_task(task)``: called as each task starts (the
        estimator then aims at the task's target); ``obstacles``: the site's, which the
        approach goes round."""
        self.vehicle = vehicle
        self.config = config or MissionConfig()
        cfg = self.config
        if cfg.contact.target_lost_retreat_s <= cfg.contact.target_lost_hold_s:
            raise ConfigError(
                "parameter 'mission.contact.target_lost_retreat_s' = "
                f"{cfg.contact.target_lost_retreat_s!r} must exceed target_lost_hold_s = "
                f"{cfg.contact.target_lost_hold_s!r}")
        self.plan: list[Task] = list(plan) if plan is not None else [
            Touch('', None, None, float(contact_force_n), cfg.contact.hold_time_s)]
        self._ctx = ctx = Context(vehicle, cfg, self.plan, self._event)
        ctx.obstacles = list(obstacles)
        ctx.push_n = float(contact_force_n)
        ctx.drop_target = drop_target
        self._on_task = on_task
        approach = Approach(ctx)
        behaviours: list[ModeBehaviour] = [
            Idle(ctx), Takeoff(ctx), Hover(ctx), Search(ctx), approach, Contact(ctx, approach),
            Hold(ctx), Slide(ctx), TargetLost(ctx), Retreat(ctx), Land(ctx), FailsafeLand(ctx)]
        self.behaviours: dict[Mode, ModeBehaviour] = {b.mode: b for b in behaviours}
        self._upset = UpsetDetector(cfg.failsafe)
        self._mode = Mode.IDLE
        self._odom_age_s = math.inf
        self._contact_gains = False
        self._completed = False
        self._success = False
        self._failsafe_reason = ''
        self.rejected_setpoints = 0
        self.refused_setpoints = 0      # good ones, sent while the mode takes none

    # ---- what it reports ----

    @property
    def mode(self) -> Mode:
        """Current :class:`Mode`."""
        return self._mode

    @property
    def phase(self) -> str:
        """What the mode is doing: SEARCH 'sweep', 'climb', 'descend', 'face', 'confirm',
        'closer', 'clear' (backing off what the tool touched); CONTACT 'close', 'touch'
        ('align' while the creep waits for the tool tip to come back over the target),
        'press'; HOVER 'transit' (to the next task), 'clear'; TAKEOFF and LAND 'clear'; ''
        otherwise."""
        return self.behaviours[self._mode].phase

    @property
    def reference(self) -> Reference:
        """The mission's reference (its working frame and segment)."""
        return self._ctx.ref

    @property
    def events(self) -> collections.deque[dict[str, typing.Any]]:
        """The latest transitions and events, oldest first."""
        return self._ctx.events

    @property
    def plan_version(self) -> int:
        """Changes whenever a task record does."""
        return self._ctx.tasks.version

    @property
    def contact_force_n(self) -> float:
        """The push of the task under way (or the last one run)."""
        return self._ctx.push_n

    @property
    def contact_lost(self) -> int:
        """Contact losses over the plan."""
        return self._ctx.contact_lost

    @property
    def task(self) -> Task | None:
        """The task under way (or the last one run), None before the plan starts."""
        return self._ctx.task

    @property
    def records(self) -> list[TaskRecord]:
        """One :class:`TaskRecord` per task of the plan under way (empty before)."""
        return list(self._ctx.tasks.records)

    @property
    def normal_map(self) -> np.ndarray | None:
        """The surface normal the mission works against (z_t) near the wall, else None."""
        return self._ctx.ref.frame.R[:, 2].copy() if self._mode in IN_TARGET_FRAME else None

    @property
    def status(self) -> dict[str, typing.Any]:
        """Mode, time in mode, failsafe reason, outcome, and the task under way."""
        ctx, task = self._ctx, self.task
        return dict(
            mode=self._mode.value,
            phase=self.phase,
            time_in_mode_s=ctx.time_in_mode() if ctx.clock.started else 0.0,
            failsafe_reason=self._failsafe_reason,
            inspection_completed=self._completed,
            success=self._success,
            contact_lost=ctx.contact_lost,
            in_contact=ctx.in_contact,
            rejected_setpoints=self.rejected_setpoints,
            refused_setpoints=self.refused_setpoints,
            task_index=ctx.tasks.index,
            task_count=len(self.plan),
            task_kind='' if task is None else task.kind,
            task_target='' if task is None else task.target,
            task_progress=self._task_progress(),
            task_outcomes=ctx.tasks.outcomes(),
        )

    # ---- commands (std_srvs/Trigger): each returns (accepted, message) ----

    def takeoff(self) -> Reply:
        """IDLE -> TAKEOFF, then HOVER."""
        ok, why = self._can_arm()
        if not ok:
            return False, why
        self._ctx.inspect_pending = False
        self._enter(Mode.TAKEOFF)
        return True, 'taking off'

    def inspect(self) -> Reply:
        """Run the plan: from IDLE take off first, from HOVER start its first task."""
        ctx = self._ctx
        if self._mode == Mode.HOVER:
            self._start_plan()
            self._start_task(0)
            return True, f'starting the plan ({len(self.plan)} tasks)'
        if ctx.inspect_pending or ctx.tasks.running():
            where = (f'task {ctx.tasks.index + 1} of {len(self.plan)}'
                     if ctx.tasks.index >= 0 else 'taking off first')
            return False, (f'the plan is already under way ({where}, {self._mode.value}); '
                           f'abort stops it')
        ok, why = self._can_arm()
        if not ok:
            return False, why
        self._start_plan()
        ctx.inspect_pending = True
        self._enter(Mode.TAKEOFF)
        return True, 'taking off for inspection'

    def abort(self) -> Reply:
        """Stop the plan: leave the wall (RETREAT) when near it, else stop and HOVER (land
        when still too low to hover)."""
        ctx = self._ctx
        ctx.inspect_pending = False
        if self._at_wall():
            return self._retreat_first('aborted', Mode.HOVER, 'abort',
                                       'retreating from the wall')
        if self._mode not in (Mode.TAKEOFF, Mode.SEARCH, Mode.LAND, Mode.HOVER, Mode.APPROACH):
            return False, f'nothing to abort in {self._mode.value}'
        ctx.tasks.stop(ctx.now_s, 'aborted')
        if self._mode == Mode.TAKEOFF and \
                ctx.ref.in_map()[0][2] < self.config.lowest_hover_m():
            # HOVER here would leave the rotors running on the ground
            self._enter(Mode.LAND, 'abort below the lowest hover')
            return True, 'landing: too low to hover'
        hover = self.behaviours[Mode.HOVER]
        if self._mode != Mode.HOVER:
            self._enter(Mode.HOVER, 'abort')
        elif isinstance(hover, Hover):
            hover.stop()
        return True, 'hovering'

    def land(self) -> Reply:
        """Stop the plan and land here; near the wall retreat first."""
        ctx = self._ctx
        ctx.inspect_pending = False
        if self._at_wall():
            return self._retreat_first('land_requested', Mode.LAND, 'land requested',
                                       'retreating, then landing')
        if self._mode not in (Mode.TAKEOFF, Mode.HOVER, Mode.SEARCH, Mode.LAND, Mode.APPROACH):
            return False, f'cannot land from {self._mode.value}'
        ctx.tasks.stop(ctx.now_s, 'land_requested')
        if self._mode != Mode.LAND:
            self._enter(Mode.LAND)
        return True, 'landing'

    def set_hover_setpoint(self, p_map: typing.Any, yaw_rad: float) -> Reply:
        """Move the hover point (map, ENU) and heading; only in HOVER."""
        p = np.asarray(p_map, dtype=float)
        if p.shape != (3,) or not (np.all(np.isfinite(p)) and np.isfinite(yaw_rad)):
            self.rejected_setpoints += 1
            return False, 'setpoint must be 3 finite coordinates and a finite yaw'
        lowest_m = self.config.lowest_hover_m()
        if p[2] < lowest_m:
            self.rejected_setpoints += 1
            return False, (f'setpoint z {p[2]:g} m is below the lowest hover, {lowest_m:g} m '
                           f'(land.ground_z_m + 2 land.detect_height_m; land to go lower)')
        outside = self._ctx.geofence.outside(p)
        if outside:
            self.rejected_setpoints += 1
            return False, f'setpoint {p.tolist()} is outside the geofence: {outside}'
        flight_phase = self.phase if self._mode in (Mode.TAKEOFF, Mode.HOVER, Mode.LAND) \
            else ''
        if self._mode != Mode.HOVER or flight_phase:
            self.refused_setpoints += 1
            return False, f'setpoints are accepted in HOVER only, not {self._mode.value}' + (
                f' ({flight_phase})' if flight_phase else '')
        self._ctx.ref.plan(p, self.config.flight.hover_speed_m_s)
        self._ctx.ref.yaw_goal = float(yaw_rad)
        return True, 'setpoint accepted'

    def observe_plane(self, point_map: np.ndarray, normal_map: np.ndarray,
                      share: float) -> None:
        """A plane vision saw (map; share of its frame): SEARCH remembers the walls."""
        search = self.behaviours[Mode.SEARCH]
        if self._mode == Mode.SEARCH and isinstance(search, Search):
            search.observe_plane(point_map, normal_map, share)

    # ---- the tick ----

    def update(self, now_s: float, state: VehicleState | None,
               target: TargetEstimate | None, f_contact_n: float, odom_age_s: float,
               f_contact_map: np.ndarray | None = None,
               thrust_up_n: float | None = None) -> ImpedanceSetpoint:
        """One control tick: returns the ImpedanceSetpoint for the impedance law.

        ``target``: the target estimate, or None; ``f_contact_n``: force along the normal
        from the F/T sensor, positive pushing; ``odom_age_s``: age of the odometry in
        ``state``; ``f_contact_map``: the F/T's whole force on the vehicle in map (N), which
        free flight backs away along; ``thrust_up_n``: the vertical thrust (map z, N) the
        flight core asked for on the tick before, which tells a landing on something higher
        from a hover (None: unknown, so no such landing is declared).
        """
        ctx, cfg = self._ctx, self.config
        ctx.clock.now_s = float(now_s)
        ctx.thrust_up_n = thrust_up_n
        self._odom_age_s = float(odom_age_s)
        stale = not (odom_age_s <= cfg.failsafe.odom_stale_s and _finite_state(state))
        dt_s = ctx.clock.dt_s()
        if not stale:
            assert state is not None
            ctx.state = state
            v_map = np.asarray(state.v_map, dtype=float)
            ctx.v_map = v_map if ctx.v_map is None else ctx.v_map + lowpass_weight(
                dt_s, cfg.flight.speed_tau_s) * (v_map - ctx.v_map)
        if ctx.state is None:
            return ImpedanceSetpoint()
        if stale and self._mode not in (Mode.IDLE, Mode.FAILSAFE_LAND):
            self._failsafe('odometry_stale', Mode.FAILSAFE_LAND)
        elif not stale and self._upset.update(ctx.now_s, ctx.state, self._mode != Mode.IDLE):
            self._failsafe('upset', Mode.IDLE)
        task = ctx.task
        if isinstance(task, SlideTask) and self._mode in IN_TARGET_FRAME:
            # a slide's line is on the site's wall: no detection, the touch finds the surface
            target = TargetEstimate(task.points_map[0], task.normal_map, 0.0, True)
        if usable(target):
            assert target is not None
            ctx.target_seen_s = max(ctx.target_seen_s, now_s - target.age_s)
        # a broken F/T reading cannot prove contact, nor trip the force limit
        f_n = float(f_contact_n) if math.isfinite(f_contact_n) else 0.0
        if self._mode in NEAR_WALL and f_n > cfg.failsafe.force_limit_n:
            self._failsafe('force_limit', Mode.RETREAT)
        ctx.bump_detector.update(f_contact_map, dt_s)
        self._apply(self.behaviours[self._mode].tick(target, f_n, stale))
        return self._setpoint()

    def _setpoint(self) -> ImpedanceSetpoint:
        ctx = self._ctx
        dt_s = ctx.clock.dt_s()
        ctx.clock.last_tick_s = ctx.now_s
        behaviour = self.behaviours[self._mode]
        behaviour.steer(dt_s)
        ctx.ref.turn(dt_s)
        sample = ctx.ref.setpoint_sample()
        behaviour.shape(sample)
        return ctx.ref.setpoint(
            sample, contact_gains=self._contact_gains or behaviour.releasing(sample),
            tangential_feedforward=behaviour.tangential_feedforward,
            trim_push=behaviour.trim_push(), airborne=self._mode not in NEAR_GROUND)

    # ---- transitions ----

    def _apply(self, transition: Transition | None) -> None:
        """Carry out what a mode's tick asked for."""
        ctx = self._ctx
        if transition is None:
            return
        if isinstance(transition, Enter):
            self._enter(transition.mode, transition.reason, transition.target)
        elif isinstance(transition, FailTask):
            self._fail_task(transition.reason)
        elif isinstance(transition, Failsafe):
            self._failsafe(transition.reason, transition.mode)
        elif isinstance(transition, NextTask):
            self._start_task(ctx.tasks.index + 1)
        elif isinstance(transition, TaskDone):
            ctx.tasks.end(ctx.now_s, True)
            ctx.after_retreat = None
            self._enter(Mode.RETREAT, transition.reason)
        elif isinstance(transition, Landed):
            if transition.judged:
                self._success = self._completed
            self._enter(Mode.IDLE, transition.reason)

    def _enter(self, mode: Mode, reason: str = '', target: TargetEstimate | None = None
               ) -> None:
        old, old_phase = self._mode, self.phase
        self._mode = mode
        self._ctx.t_mode_s = self._ctx.now_s
        self._event(reason, old, old_phase, target)
        behaviour = self.behaviours[mode]
        if behaviour.contact_gains is not None:
            self._contact_gains = behaviour.contact_gains
        behaviour.enter(old, target)

    def _event(self, reason: str, old: Mode | None = None, old_phase: str = '',
               target: TargetEstimate | None = None) -> None:
        """Log a transition from ``old`` (in ``old_phase``), or an event within a mode; with
        the target's POI (map) when it is about one."""
        self._ctx.events.append(dict(
            t_s=self._ctx.now_s, mode=self._mode.value,
            previous=None if old is None else old.value,
            phase=old_phase if old is not None else self.phase, reason=reason,
            task_index=self._ctx.tasks.index,
            target_map=None if target is None else [float(v) for v in target.p_poi_map]))

    def _failsafe(self, reason: str, mode: Mode) -> None:
        """A vehicle failsafe: the plan ends here."""
        ctx = self._ctx
        self._failsafe_reason = reason
        self._completed = False
        ctx.inspect_pending = False
        ctx.tasks.stop(ctx.now_s, reason)
        if mode == Mode.RETREAT:
            ctx.after_retreat = Mode.LAND
        self._enter(mode, reason)

    def _retreat_first(self, stop_reason: str, after: Mode, reason: str, reply: str) -> Reply:
        """Stop the plan at the wall: RETREAT, then ``after``."""
        ctx = self._ctx
        ctx.tasks.stop(ctx.now_s, stop_reason)
        ctx.after_retreat = after
        if self._mode != Mode.RETREAT:
            self._enter(Mode.RETREAT, reason)
        return True, reply

    # ---- the plan ----

    def _start_plan(self) -> None:
        ctx = self._ctx
        self._completed = False
        self._success = False
        self._failsafe_reason = ''
        ctx.contact_lost = 0
        ctx.target_seen_s = -np.inf
        ctx.tasks.start_plan([(task.kind, task.target) for task in self.plan])

    def _start_task(self, index: int) -> None:
        """Fly to task ``index`` (free flight), or land after the last one."""
        ctx, cfg = self._ctx, self.config
        ctx.tasks.index = min(index, len(self.plan) - 1)
        if index >= len(self.plan):
            self._completed = all(r.success for r in ctx.tasks.records)
            ctx.after_retreat = Mode.LAND
            self._enter(Mode.LAND, 'plan complete')
            return
        task = self.plan[index]
        ctx.tasks.start(index, ctx.now_s)
        ctx.push_n = float(task.force_n)
        ctx.target_seen_s = -np.inf
        self._event(f'task {index} ({task.kind}) started')
        if self._on_task is not None:
            self._on_task(task)
        if isinstance(task, SlideTask):
            self._enter(Mode.APPROACH, f'task {index}: to the line',
                        target=TargetEstimate(task.points_map[0], task.normal_map, 0.0, True))
        elif task.hint_map is not None and task.normal_map is not None:
            # look at where the plan says the target is, facing the wall, then search
            look = task.hint_map + task.normal_map * cfg.flight.look_distance_m
            look[2] = max(look[2], cfg.lowest_hover_m())
            if self._mode != Mode.HOVER:
                self._enter(Mode.HOVER, f'task {index}: to its target')
            hover = self.behaviours[Mode.HOVER]
            assert isinstance(hover, Hover)
            # The camera looks at the hint: along the normal (down at a wall leaning away),
            # or, where the ground raised the look point (a low target on a wall leaning
            # over), down from there rather than up along the normal and over the target.
            hover.transit(look, look - task.hint_map)
        else:
            self._enter(Mode.SEARCH)

    def _fail_task(self, reason: str) -> None:
        """The task under way failed: back off the wall when near it, then the next task."""
        ctx = self._ctx
        self._failsafe_reason = reason
        ctx.tasks.end(ctx.now_s, False, reason)
        self._event(reason)
        if self._mode in NEAR_WALL:
            ctx.after_retreat = None
            self._enter(Mode.RETREAT, reason)
        else:
            self._start_task(ctx.tasks.index + 1)

    def _task_progress(self) -> float:
        """0..1 of the task under way: the hold's time, the line's length."""
        progress = self.behaviours[self._mode].progress()
        if progress is not None:
            return progress
        return 1.0 if self._ctx.tasks.pushed() else 0.0

    # ---- helpers ----

    def _can_arm(self) -> Reply:
        if self._mode != Mode.IDLE:
            return False, f'already flying ({self._mode.value})'
        if self._ctx.state is None or not self._odom_age_s <= self.config.failsafe.odom_stale_s:
            return False, 'no fresh odometry'
        return True, ''

    def _at_wall(self) -> bool:
        """Working at the wall, where abort and land retreat first: a mode near it, but an
        approach only once within the standoff (RETREAT's goal); farther out, retreating
        would fly on towards the wall."""
        ref = self._ctx.ref
        if self._mode == Mode.APPROACH:
            return bool(ref.in_frame()[0][2] <= ref.standoff_t()[2]
                        + self.config.flight.arrive_tol_m)
        return self._mode in NEAR_WALL or self._mode == Mode.RETREAT


def _finite_state(state: VehicleState | None) -> bool:
    return state is not None and all(map(math.isfinite, np.concatenate(
        (state.p_map, state.q_map_base, state.v_map)).tolist()))
