"""The Ray backend of `uav-tilt campaign`: one Ray task per run, results as they finish.

Each run is :func:`uav_tilt_tools.campaign.run_one` as a task of one CPU (its detector and
OpenCV get one thread). Without an address a local Ray starts with this machine's cores
(or ``workers`` CPUs), no dashboard and a small object store, and stops at the end; with
one (``auto``, ``HOST:6379``) the tasks go to that cluster, whose every node needs the
same uav_tilt installed. A task whose worker dies (killed, out of memory, node lost) is
run again by Ray up to :data:`MAX_RETRIES` times; a run that fails in Python fails the
campaign as it would locally.
"""
import logging
import os
import socket

from uav_tilt_common.config import ConfigError

MAX_RETRIES = 3
OBJECT_STORE_BYTES = 256 * 2**20    # results are kB, recordings ~10 MB, fetched at once
# ray.init keeps trying an address that does not answer; a campaign says so instead
CONNECT_TIMEOUT_S = 10.0


class CampaignError(RuntimeError):
    """A campaign could not finish: a run lost its worker too often, or Ray is missing."""


def ray_runs(run_one, jobs, workers=None, address=None):
    """``run_one(job)`` of each job as its task finishes."""
    if not jobs:
        return
    try:
        import ray
    except ImportError:
        raise CampaignError("--backend ray needs Ray: pip install 'uav_tilt[ray]'") from None
    started = not ray.is_initialized()
    if started:
        # campaigns run on clusters without internet access: no usage reports
        os.environ.setdefault('RAY_USAGE_STATS_ENABLED', '0')
        if address is not None:
            _connect(ray, address)
        else:
            _init_local(ray, workers or os.cpu_count() or 1)
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
        for ref in pending:
            ray.cancel(ref, force=True)
        if started:
            ray.shutdown()


def _connect(ray, address):
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


def _init_local(ray, cpus):
    """A local Ray of ``cpus`` CPUs whose workers import the uav_tilt this process runs,
    installed or not (they inherit the environment of the raylet started here; a
    runtime_env would cost seconds per worker)."""
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    before = os.environ.get('PYTHONPATH')
    os.environ['PYTHONPATH'] = os.pathsep.join(p for p in (root, before) if p)
    try:
        ray.init(num_cpus=cpus, include_dashboard=False, object_store_memory=OBJECT_STORE_BYTES,
                 logging_level=logging.WARNING)
    finally:
        if before is None:
            del os.environ['PYTHONPATH']
        else:
            os.environ['PYTHONPATH'] = before
