"""Counting and rate-limited reporting of rejected inputs (nodes never stop for bad data)."""
import time


class RejectCounter:
    """Counts rejections per reason and says when a log line is due (at most once a period)."""

    def __init__(self, period_s=1.0, clock=time.monotonic):
        self.period_s = period_s
        self.clock = clock
        self.counts = {}
        self._last_log = -float('inf')

    @property
    def total(self):
        """All rejections so far."""
        return sum(self.counts.values())

    def reject(self, reason):
        """Count one rejection; returns True when the caller should log it now."""
        self.counts[reason] = self.counts.get(reason, 0) + 1
        now = self.clock()
        if now - self._last_log >= self.period_s:
            self._last_log = now
            return True
        return False
