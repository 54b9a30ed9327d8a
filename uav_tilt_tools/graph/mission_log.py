"""The mission as a log a user can follow (launch.sh prints it through the mission watcher):
one line per mode change, task start, task outcome and failsafe, each stamped with the sim
time controller/status gives, and one line at the end with the numbers the status has.

A mode's line carries the sim time it was entered (the status's ``t_s`` less its
``time_in_mode_s``); statuses come at 10 Hz of wall clock, so a mode shorter than that may
pass unseen. The push of a task is the controller's own F/T reading along the wall's
normal (``f_normal_n``) in the statuses of its HOLD or SLIDE: a sample, not the report's
series (``uav-tilt report`` scores a recording against the truth).
"""
import dataclasses
import math
from typing import Any

from uav_tilt_common.modes import NOT_FLYING, WAITING_FOR_SENSORS, Mode

PUSHING = (Mode.HOLD.value, Mode.SLIDE.value)


def stamp(t_s: float | None) -> str:
    """The sim time column of a line."""
    return 't =    ?    ' if t_s is None else f't = {t_s:7.2f} s'


@dataclasses.dataclass
class Push:
    """Status samples of one task's push: (measured, asked for) [N]."""

    measured: list[float] = dataclasses.field(default_factory=list)
    asked: list[float] = dataclasses.field(default_factory=list)

    def describe(self) -> str:
        """'push 5.01 N mean, 0.031 N RMS error of 5.0 N (40 status samples)', or ''."""
        if not self.measured:
            return ''
        n = len(self.measured)
        mean = sum(self.measured) / n
        rms = math.sqrt(sum((m - a) ** 2 for m, a in zip(self.measured, self.asked)) / n)
        return (f'push {mean:.2f} N mean, {rms:.3f} N RMS error of {self.asked[-1]:.1f} N '
                f'({n} status samples)')


def _int(value: Any) -> int | None:
    """A count or index of a status (numbers come as floats), or None."""
    return int(value) if isinstance(value, (int, float)) and math.isfinite(value) else None


class MissionLog:
    """Feed it controller status dicts (:meth:`update`); it returns the lines to print."""

    def __init__(self) -> None:
        self.mode: str | None = None
        self.t_s: float | None = None
        self.task = -1
        self.task_count = 0
        self.names: dict[int, str] = {}         # task index -> 'touch plate_a'
        self.pushes: dict[int, Push] = {}
        self.outcomes: list[str] = []
        self.failsafe = ''
        self.took_off_s: float | None = None
        self.entered_s: float | None = None     # when the mode under way was entered

    def update(self, values: dict[str, Any]) -> list[str]:
        """The lines that the status ``values`` (key -> decoded value) adds."""
        lines: list[str] = []
        t_s = values.get('t_s')
        self.t_s = float(t_s) if isinstance(t_s, (int, float)) else self.t_s
        mode = values.get('mode', self.mode)
        if mode != self.mode and mode not in (None, WAITING_FOR_SENSORS):
            since = values.get('time_in_mode_s')
            entered = self.t_s - since if self.t_s is not None and isinstance(
                since, (int, float)) else self.t_s
            if self.took_off_s is None and mode not in NOT_FLYING:
                self.took_off_s = entered
            self.entered_s = entered
            phase = values.get('phase') or ''
            lines.append(f"{stamp(entered)}  {mode}{f' ({phase})' if phase else ''}")
            self.mode = mode
        lines += self._tasks(values)
        reason = values.get('failsafe_reason') or ''
        if reason and reason != self.failsafe:
            lines.append(f'{stamp(self.t_s)}  failsafe: {reason}')
        self.failsafe = reason
        return lines

    def _tasks(self, values: dict[str, Any]) -> list[str]:
        lines = []
        index, count = _int(values.get('task_index')), _int(values.get('task_count'))
        self.task_count = self.task_count if count is None else count
        if index is not None and index >= 0 and index != self.task:
            self.task = index
            name = ' '.join(str(values.get(k) or '') for k in ('task_kind', 'task_target'))
            self.names[index] = name.strip()
            lines.append(f'{stamp(self.t_s)}  task {self._of(index)}: {self.names[index]}')
        if self.mode in PUSHING and self.task >= 0:
            push = self.pushes.setdefault(self.task, Push())
            measured, asked = values.get('f_normal_n'), values.get('contact_force_n')
            if isinstance(measured, (int, float)) and isinstance(asked, (int, float)):
                push.measured.append(float(measured))
                push.asked.append(float(asked))
        text = values.get('task_outcomes')
        outcomes = [o for o in text.split(',') if o] if isinstance(text, str) else []
        for i in range(len(self.outcomes), len(outcomes)):
            name = f' ({self.names[i]})' if self.names.get(i) else ''
            pushed = self.pushes[i].describe() if i in self.pushes else ''
            lines.append(f"{stamp(self.t_s)}  task {self._of(i)}{name}: {outcomes[i]}"
                         f"{'; ' + pushed if pushed else ''}")
        if len(outcomes) >= len(self.outcomes):
            self.outcomes = outcomes
        return lines

    def _of(self, index: int) -> str:
        return f'{index + 1} of {self.task_count}' if self.task_count else str(index + 1)

    def end(self, success: bool) -> str:
        """The last line: the verdict, how many tasks went well, the time flown."""
        ok = sum(o == 'ok' for o in self.outcomes)
        # back in IDLE: its entry is the end
        end_s = self.entered_s if self.mode == Mode.IDLE.value else self.t_s
        parts = [f"mission ended at {stamp(end_s)}: {'success' if success else 'failure'}"]
        if self.outcomes:
            parts.append(f'{ok} of {len(self.outcomes)} tasks ok')
        if self.failsafe:
            parts.append(f'failsafe {self.failsafe}')
        if self.took_off_s is not None and end_s is not None:
            parts.append(f'{end_s - self.took_off_s:.1f} s of sim time from the take-off')
        return '; '.join(parts)
