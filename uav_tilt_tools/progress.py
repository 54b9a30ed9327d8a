"""Progress of long in-process work (`uav-tilt fly`, `campaign`, `report`): a tqdm bar on
stderr when stderr is a terminal, nothing in a pipe or a file (stdout is the JSON result)."""
import sys
from typing import Any

from tqdm import tqdm


def on_terminal() -> bool:
    """Whether stderr is a terminal: a user watching, not a pipe, a file or a test."""
    return sys.stderr.isatty()


class SimProgress:
    """A flight's progress (:func:`uav_tilt_tools.runner.inprocess.run_mission`'s
    ``progress``): simulated seconds flown, their rate, and the mission's mode."""

    def __init__(self, desc: str = 'fly') -> None:
        self.desc = desc
        self.bar: Any = None
        self.t_s = 0.0

    def __call__(self, t_s: float, duration_s: float, mode: str) -> None:
        if self.bar is None:
            self.bar = tqdm(desc=self.desc, unit=' sim s', file=sys.stderr, leave=False,
                            bar_format='{desc}: {n:.1f} of at most ' f'{duration_s:.0f}'
                                       ' sim s [{elapsed}, {rate_fmt}{postfix}]')
        self.bar.set_postfix_str(mode, refresh=False)
        self.bar.update(t_s - self.t_s)
        self.t_s = t_s

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


class FileProgress:
    """Reading a file (:func:`uav_tilt_tools.bag.reader.load_recording`'s ``progress``):
    bytes read of its size."""

    def __init__(self, desc: str) -> None:
        self.desc = desc
        self.bar: Any = None
        self.done = 0

    def __call__(self, done: int, size: int) -> None:
        if self.bar is None:
            self.bar = tqdm(desc=self.desc, total=size, unit='B', unit_scale=True,
                            file=sys.stderr, leave=False)
        self.bar.update(done - self.done)
        self.done = done

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
