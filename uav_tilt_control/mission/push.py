"""Modes that push on the wall and leave it: HOLD (a touch's push), SLIDE (the push carried
along a line) and RETREAT (back to the standoff)."""

import numpy as np

from uav_tilt_common.modes import Mode
from uav_tilt_control.mission.base import (Context, Enter, Failsafe, FailTask, ModeBehaviour,
                                           NextTask, TaskDone, Transition)
from uav_tilt_control.mission.reference import SetpointSample
from uav_tilt_control.plan import LineProgress, Slide as SlideTask, Touch, nearest_on_path
from uav_tilt_control.target_estimator import TargetEstimate
from uav_tilt_control.trajectory import MinJerk, SurfaceCruise


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
    """The tool tip follows the slide's path from where it touched, at the press depth: the
    working frame rides along the path on the surface, turned to its normal there, so that
    the push follows the normal round a curved surface; the task fails once the tip is off
    the path or held back behind its reference."""

    mode = Mode.SLIDE
    tangential_feedforward = True

    def __init__(self, ctx: Context) -> None:
        super().__init__(ctx)
        self._cruise: SurfaceCruise | None = None
        self._progress: LineProgress | None = None
        self._depth_m = 0.0
        self._v_map = self._a_map = np.zeros(3)

    def enter(self, previous: Mode, target: TargetEstimate | None) -> None:
        super().enter(previous, target)
        ctx, task = self.ctx, self.ctx.task
        assert isinstance(task, SlideTask)
        self._cruise = SurfaceCruise(ctx.now_s, task.path, task.speed_m_s,
                                     ctx.config.slide.accel_m_s2)
        self._progress = LineProgress(task.points_map)
        # in the frame that rides along the path the body's reference stays at the press
        # depth, out along the normal (frame z)
        self._depth_m = float(ctx.ref.segment.p1[2])
        depth = np.array([0.0, 0.0, self._depth_m])
        ctx.ref.follow(MinJerk(ctx.now_s, depth, depth, 1.0))
        self.steer(0.0)
        ctx.event('sliding')

    def steer(self, dt_s: float) -> None:
        assert self._cruise is not None
        point, normal, self._v_map, self._a_map = self._cruise.sample(self.ctx.now_s,
                                                                      self._depth_m)
        self.ctx.ref.set_target_frame(TargetEstimate(point, normal, 0.0, True))

    def shape(self, sample: SetpointSample) -> None:
        # the frame's own motion, fed forward
        R = self.ctx.ref.frame.R
        sample.v, sample.a = R.T @ self._v_map, R.T @ self._a_map

    def progress(self) -> float | None:
        return None if self._cruise is None else self._cruise.progress(self.ctx.now_s)

    def tick(self, target: TargetEstimate | None, f_n: float,
             stale: bool) -> Transition | None:
        ctx, cruise, line, task = self.ctx, self._cruise, self._progress, self.ctx.task
        assert cruise is not None and line is not None and isinstance(task, SlideTask)
        self.regulate(f_n)
        # the tool tip as odometry sees it, against the path on the surface
        tip_map = ctx.ref.tool_tip_map(ctx.vehicle_state)
        tolerance_m = ctx.config.slide.path_tolerance_m
        along_m = line.update(tip_map)
        # how far the tool tip is behind its reference along the line (at the line's end
        # time, short of the end): friction, or something on the line, holds it, and the
        # vehicle pitches against it while the reference slides on
        behind_m = cruise.progress(ctx.now_s) * cruise.length - along_m
        if distance_on_surface(tip_map, task.points_map, task.normals_map) > tolerance_m:
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


def distance_on_surface(p: np.ndarray, points: np.ndarray, normals: np.ndarray) -> float:
    """Distance from ``p`` to the path through ``points`` (N, 3) along the surface whose
    outward normals there are ``normals``: the part along the normal (a tip pressed into a
    surface that gives way, or lifted off it) left out."""
    return float(nearest_on_path(np.asarray(p, dtype=float)[None, :], points, normals)[0][0])
