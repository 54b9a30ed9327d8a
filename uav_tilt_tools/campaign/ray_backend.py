"""The Ray backend of `uav-tilt campaign`: one Ray task per run, results as they finish.

Each run is :func:`uav_tilt_tools.campaign.jobs.run_one` as a task of one CPU (its detector and
OpenCV get one thread). Without an address a local Ray starts with this machine's cores
(or ``workers`` CPUs), no dashboard and a small object store, and stops at the end; with
one (``auto``, ``HOST:6379``) the tasks go to that cluster, whose every node needs the
same uav_tilt installed. A task whose worker dies (killed, out of memory, node lost) is
run again by Ray up to :data:`MAX_RETRIES` times; a run that fails in Python fails the
campaign as it would locally.
"""
import logging
import os
import signal
import socket
from typing import Any, Callable, Generator

from uav_tilt_common.config import ConfigError
from uav_tilt_tools.campaign.jobs import Job

MAX_RETRIES = 3
OBJECT_STORE_BYTES = 256 * 2**20    # results are kB, recordings ~10 MB, fetched at once
# ray.init keeps trying an address that does not answer; a campaign says so instead
CONNECT_TIMEOUT_S = 10.0
CANCEL_WAIT_S = 5.0


class CampaignError(RuntimeError):
    """A campaign could not finish: a run lost its worker too often, or Ray is missing."""


def ray_runs(run_one: Callable[[Job], Any], jobs: list[Job], workers: int | None = None,
             address: str | None = None) -> Generator[Any, None, None]:
    """``run_one(job)`` of each job as its task finishes."""
    if not jobs:
        return
    try:
        import ray      # the optional extra uav_tilt[ray], for this backend alone
    except ImportError:
        raise CampaignError("--backend ray needs Ray: pip install 'uav_tilt[ray]'") from None
    started = not ray.is_initialized()
    if started:
        # campaigns run on clusters without internet access: no usage reports
        os.environ.setdefault('RAY_USAGE_STATS_ENABLED', '0')
        # ray.init takes SIGTERM (it exits with a stack dump): the command's own handler
        # ends the campaign as Ctrl-C does, through the clean-up below
        on_term = signal.getsignal(signal.SIGTERM)
        if address is not None:
            _connect(ray, address)
        else:
            _init_local(ray, workers or os.cpu_count() or 1)
        signal.signal(signal.SIGTERM, on_term)
    task = ray.remote(num_cpus=1, max_retries=MAX_RETRIES, retry_exceptions=False)(run_one)
    pending = {task.options(name=f'campaign run {job["index"]}').remote(job): job['index']
               for job in jobs}
    try:
        while pending:
            ready, _ = ray.wait(list(pending), num_returns=1)
            index = pending.pop(ready[0])
            try:
                result = ray.get(ready[0])
            except ray.exceptions.RayTaskError as err:
                raise err.as_instanceof_cause() from None
            except ray.exceptions.RayError as err:
                raise CampaignError(f'run {index} was lost after {MAX_RETRIES} retries: '
                                    f'{type(err).__name__}') from None
            yield result
    finally:
        # a cancelled task leaves by KeyboardInterrupt, removing its run's temporary folder;
        # what has not left after CANCEL_WAIT_S goes with the shutdown
        for ref in pending:
            ray.cancel(ref)
        if pending:
            ray.wait(list(pending), num_returns=len(pending), timeout=CANCEL_WAIT_S)
        if started:
            ray.shutdown()


def _connect(ray: Any, address: str) -> None:
    """Join the cluster at ``address`` ('auto', HOST:PORT or ray://HOST:PORT): a malformed
    address is a ConfigError, one that does not answer within CONNECT_TIMEOUT_S or that
    Ray refuses a CampaignError, each one line."""
    if address != 'auto':
        host, sep, port = address.removeprefix('ray://').rpartition(':')
        if not (sep and host and port.isdigit()):
            raise ConfigError(f"--address {address!r}: expected 'auto' or HOST:PORT")
        try:
            socket.create_connection((host, int(port)), timeout=CONNECT_TIMEOUT_S).close()
        except OSError as err:
            raise CampaignError(f'--address {address}: no Ray there ({err})') from None
    try:
        ray.init(address=address, logging_level=logging.WARNING)
    except (ConnectionError, ValueError, RuntimeError) as err:
        reason = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
        raise CampaignError(f'--address {address}: {reason}') from None


def _init_local(ray: Any, cpus: int) -> None:
    """A local Ray of ``cpus`` CPUs whose workers import the uav_tilt this process runs,
    installed or not (they inherit the environment of the raylet started here; a
    runtime_env would cost seconds per worker)."""
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    before = os.environ.get('PYTHONPATH')
    os.environ['PYTHONPATH'] = os.pathsep.join(p for p in (root, before) if p)
    try:
        ray.init(num_cpus=cpus, include_dashboard=False, object_store_memory=OBJECT_STORE_BYTES,
                 logging_level=logging.WARNING)
    except OSError as err:      # e.g. its sockets' paths under a long TMPDIR
        raise CampaignError(f'cannot start a local Ray: {err}') from None
    finally:
        if before is None:
            del os.environ['PYTHONPATH']
        else:
            os.environ['PYTHONPATH'] = before
