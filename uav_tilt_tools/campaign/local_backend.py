"""The local backend of a campaign: the runs spread over this machine's cores by a spawn
process pool, results as they finish."""
import multiprocessing
import signal
import types
from typing import Any, Callable, Generator

from uav_tilt_tools.campaign.jobs import Job


def local_runs(run_one: Callable[[Job], Any], jobs: list[Job], workers: int | None = None,
               address: str | None = None) -> Generator[Any, None, None]:
    """``run_one(job)`` of each job as it finishes, from a spawn process pool of
    ``workers`` (``address``: the Ray backend's, unused here)."""
    if not jobs:
        return
    with multiprocessing.get_context('spawn').Pool(workers, initializer=_ignore_sigint) as pool:
        yield from pool.imap_unordered(run_one, jobs)
        # every run is in: the workers end on their own. The pool's terminate would send
        # SIGTERM to workers already in their interpreter's exit, where the SystemExit it
        # raises is a traceback from an exit hook (torch's, with vision).
        pool.close()
        pool.join()


def _ignore_sigint() -> None:
    # Ctrl-C reaches the whole process group: the parent keeps what finished and
    # terminates the pool, instead of every worker printing a traceback. The pool ends a
    # worker with SIGTERM: leaving by SystemExit, it removes its run's temporary folder.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _leave)


def _leave(signum: int, frame: types.FrameType | None) -> None:
    raise SystemExit(128 + signum)
