"""Counting and rate-limited reporting of rejected inputs (nodes never stop for bad data)."""
import time
from typing import Callable, Hashable


class RejectCounter:
    """Counts rejections per reason and says when a log line is due (at most once a period)."""

    def __init__(self, period_s: float = 1.0,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.period_s = period_s
        self.clock = clock
        self.counts: dict[Hashable, int] = {}
        self._last_log = -float('inf')

    @property
    def total(self) -> int:
        """All rejections so far."""
        return sum(self.counts.values())

    def reject(self, reason: Hashable) -> bool:
        """Count one rejection; returns True when the caller should log it now."""
        self.counts[reason] = self.counts.get(reason, 0) + 1
        now = self.clock()
        if now - self._last_log >= self.period_s:
            self._last_log = now
            return True
        return False
