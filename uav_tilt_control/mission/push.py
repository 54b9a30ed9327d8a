"""Modes that push on the wall and leave it: HOLD (a touch's push), SLIDE (the push carried
along a line) and RETREAT (back to the standoff)."""
import math

import numpy as np

from uav_tilt_common.modes import Mode
from uav_tilt_control.mission.base import (Context, Enter, Failsafe, FailTask, ModeBehaviour,
                                           NextTask, TaskDone, Transition)
from uav_tilt_control.mission.reference import SetpointSample
from uav_tilt_control.plan import LineProgress, Slide as SlideTask, Touch
from uav_tilt_control.target_estimator import TargetEstimate
from uav_tilt_control.trajectory import PolylineCruise


class _Pushing(ModeBehaviour):
    """HOLD and SLIDE: in contact from entry; while the wall is felt, the impedance law
    trims the push by the measured one, and contact lost is counted."""

    contact_gains = True

    def __init__(self, ctx: Context) -> None:
        super().__init__(ctx)
        self._no_force_since_s: float | None = None
        self._felt = False

    def enter(self, previous: Mode, target: TargetEstimate | None) -> None:
        self.ctx.in_contact = True
        self._no_force_since_s = None
        self._felt = False
        self.ctx.tasks.contact_started(self.ctx.now_s)

    def trim_push(self) -> bool:
        return self._felt

    def regulate(self, f_n: float) -> None:
        ctx, cfg = self.ctx, self.ctx.config.contact
        self._felt = f_n > cfg.threshold_n
        if self._felt:
            self._no_force_since_s = None
            ctx.in_contact = True
        elif self._no_force_since_s is None:
            self._no_force_since_s = ctx.now_s
        elif ctx.in_contact and ctx.now_s - self._no_force_since_s > cfg.lost_s:
            ctx.in_contact = False
            ctx.contact_lost += 1
            ctx.tasks.contact_lost()
            ctx.event('contact lost')


class Hold(_Pushing):
    """Push for the touch's hold_s."""

    mode = Mode.HOLD

    def hold_s(self) -> float:
        task = self.ctx.task
        return task.hold_s if isinstance(task, Touch) else self.ctx.config.contact.hold_time_s

    def progress(self) -> float | None:
        hold_s = self.hold_s()
        return min(self.ctx.time_in_mode() / hold_s, 1.0) if hold_s > 0.0 else None

    def tick(self, target: TargetEstimate | None, f_n: float,
             stale: bool) -> Transition | None:
        self.regulate(f_n)
        if self.ctx.time_in_mode() >= self.hold_s():
            return TaskDone('hold complete')
        return None


class Slide(_Pushing):
    """The tool tip follows the slide's line from where it touched, at the press depth; the
    task fails once the tip is off the line or held back behind its reference."""

    mode = Mode.SLIDE
    tangential_feedforward = True

    def __init__(self, ctx: Context) -> None:
        super().__init__(ctx)
        self._cruise: PolylineCruise | None = None
        self._line_t = np.zeros((0, 2))
        self._progress: LineProgress | None = None

    def enter(self, previous: Mode, target: TargetEstimate | None) -> None:
        super().enter(previous, target)
        ctx, task = self.ctx, self.ctx.task
        assert isinstance(task, SlideTask)
        depth_z = ctx.ref.segment.p1[2]
        points_t = np.array([ctx.ref.to_frame(p) for p in task.points_map])
        points_t[:, 2] = depth_z
        self._cruise = PolylineCruise(ctx.now_s, points_t, task.speed_m_s,
                                      ctx.config.slide.accel_m_s2)
        ctx.ref.follow(self._cruise)
        self._line_t = points_t[:, :2].copy()
        self._progress = LineProgress(self._line_t)
        ctx.event('sliding')

    def progress(self) -> float | None:
        return None if self._cruise is None else self._cruise.progress(self.ctx.now_s)

    def tick(self, target: TargetEstimate | None, f_n: float,
             stale: bool) -> Transition | None:
        ctx, cruise, line = self.ctx, self._cruise, self._progress
        assert cruise is not None and line is not None
        self.regulate(f_n)
        # the tool tip as odometry sees it, against the line in the wall's plane
        tip_t = ctx.ref.tool_tip_t(ctx.vehicle_state)[:2]
        tolerance_m = ctx.config.slide.path_tolerance_m
        along_m = line.update(tip_t)
        # how far the tool tip is behind its reference along the line (at the line's end
        # time, short of the end): friction, or something on the line, holds it, and the
        # vehicle pitches against it while the reference slides on
        behind_m = cruise.progress(ctx.now_s) * cruise.length - along_m
        if distance_to_polyline(tip_t, self._line_t) > tolerance_m:
            return FailTask('off_line')
        if behind_m > tolerance_m:
            return FailTask('short_of_line')
        if cruise.done(ctx.now_s):
            return TaskDone('line complete')
        return None


RELEASE = 'release'


class Retreat(ModeBehaviour):
    """Let go of the push as it was pressed (phase 'release'), then back to the standoff,
    then the next task (or what the command or failsafe that ended the plan asked for)."""

    mode = Mode.RETREAT

    def __init__(self, ctx: Context) -> None:
        super().__init__(ctx)
        self._phase = ''

    @property
    def phase(self) -> str:
        return self._phase

    def enter(self, previous: Mode, target: TargetEstimate | None) -> None:
        ctx, ref = self.ctx, self.ctx.ref
        if ref.push.sample(ctx.now_s)[0] > 0.0:
            self._phase = RELEASE
            ref.plan_t(ref.in_frame()[0], ctx.config.contact.approach_speed_m_s)
            ref.push.release(ctx.now_s, ctx.config.contact.press_time_s)
        else:
            self._phase = ''
            ref.plan_t(ref.standoff_t(), ctx.config.contact.approach_speed_m_s)

    def tick(self, target: TargetEstimate | None, f_n: float,
             stale: bool) -> Transition | None:
        ctx = self.ctx
        if self._phase == RELEASE:
            if ctx.ref.push.done(ctx.now_s) and ctx.ref.segment.done(ctx.now_s):
                self._phase = ''
                ctx.ref.plan_t(ctx.ref.standoff_t(), ctx.config.contact.approach_speed_m_s)
        elif ctx.arrived():
            return NextTask() if ctx.after_retreat is None else Enter(ctx.after_retreat)
        if ctx.ref.overdue():
            return Failsafe('unreachable', Mode.LAND)
        return None

    def releasing(self, sample: SetpointSample) -> bool:
        """Leaving the wall, the reference starts at or behind the surface: the compliant
        gains stay on while it pushes and until it is out, so the push fades instead of
        stiffening."""
        return sample.push_n > 0.0 or bool(sample.p[2] < self.ctx.vehicle.tool_tip_x_m)


def distance_to_polyline(p: np.ndarray, vertices: np.ndarray) -> float:
    """Distance from the 2-D point ``p`` to the polyline through ``vertices`` (N, 2)."""
    best = math.inf
    for a, b in zip(vertices[:-1], vertices[1:]):
        d = b - a
        u = min(max(float((p - a) @ d / (d @ d)), 0.0), 1.0)
        best = min(best, float(np.linalg.norm(p - a - u * d)))
    return best
