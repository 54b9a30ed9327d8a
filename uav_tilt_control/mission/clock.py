"""The mission's time: the tick's sim time and the one before."""
import math


class Clock:
    """Sim time of the tick under way (:attr:`now_s`) and of the last setpoint made."""

    def __init__(self) -> None:
        self.now_s = math.nan
        self.last_tick_s: float | None = None

    @property
    def started(self) -> bool:
        """Whether a tick has come."""
        return not math.isnan(self.now_s)

    def dt_s(self) -> float:
        """Seconds since the previous tick's setpoint (0 before the first)."""
        return 0.0 if self.last_tick_s is None else max(self.now_s - self.last_tick_s, 0.0)
