"""How the tasks of the plan under way went: one record each (controller/plan)."""
import dataclasses

# A task that did not end: the plan stopped before it, or while it ran.
NOT_RUN = 'not_run'


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
    t_contact_s: list[float | None] | None = None      # [start, end] of HOLD or SLIDE

    def outcome(self) -> str:
        """'ok', the failure reason, or '' while not ended."""
        if self.success is None:
            return ''
        return 'ok' if self.success else self.reason


class TaskRecords:
    """The records of the plan under way and the index of its task; :attr:`version` changes
    whenever a record does (the controller re-sends controller/plan)."""

    def __init__(self) -> None:
        self.records: list[TaskRecord] = []
        self.index = -1
        self.version = 0

    def start_plan(self, kinds_targets: list[tuple[str, str]]) -> None:
        self.index = -1
        self.records = [TaskRecord(kind, target) for kind, target in kinds_targets]
        self.version += 1

    def running(self) -> bool:
        """Whether the task at :attr:`index` has started and not ended."""
        return 0 <= self.index < len(self.records) and self.records[self.index].success is None

    def current(self) -> TaskRecord | None:
        return self.records[self.index] if 0 <= self.index < len(self.records) else None

    def start(self, index: int, now_s: float) -> None:
        self.records[index].t_start_s = now_s
        self.version += 1

    def end(self, now_s: float, success: bool, reason: str = '') -> None:
        """Record how the task under way ended (nothing when none runs)."""
        if not self.running():
            return
        record = self.records[self.index]
        if record.t_contact_s and record.t_contact_s[1] is None:
            record.t_contact_s[1] = now_s
        record.success = bool(success) and record.contact_lost == 0
        record.reason = reason or ('contact_lost' if record.contact_lost else '')
        record.t_end_s = now_s
        self.version += 1

    def stop(self, now_s: float, reason: str) -> None:
        """End the plan here: the task under way and those after it did not run."""
        if self.running():
            self.end(now_s, False, reason)
        for record in self.records[self.index + 1:]:
            if record.success is None:
                record.success, record.reason = False, NOT_RUN
        self.version += 1

    def contact_started(self, now_s: float) -> None:
        """The task under way pushes from now (HOLD or SLIDE)."""
        if self.running():
            self.records[self.index].t_contact_s = [now_s, None]
            self.version += 1

    def contact_lost(self) -> None:
        if self.running():
            self.records[self.index].contact_lost += 1
            self.version += 1

    def pushed(self) -> bool:
        """Whether the task under way has pushed and stopped pushing."""
        record = self.current()
        pushed_s = None if record is None else record.t_contact_s
        return bool(pushed_s) and pushed_s is not None and pushed_s[1] is not None

    def outcomes(self) -> str:
        return ','.join(r.outcome() for r in self.records if r.outcome())
