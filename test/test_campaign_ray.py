"""The Ray backend of the campaign: the same runs as the local backend, each counted once
even when a worker dies under a run (Ray runs the task again)."""
import os
import signal
import subprocess
import sys
import threading
import time

import pytest

from uav_tilt_tools.campaign import run as cp

# Alone: beside a vision mission on the other core the Ray campaign took 115 s against
# 11.5 s by itself (the local backend's 2.2x), and the killed-worker test has a deadline.
pytestmark = pytest.mark.alone

N, SEED = 6, 20261201
DURATION_S = 8.0             # takeoff and the climb to the search: short runs
WALL_CLOCK_KEYS = ('rtf', 'controller_rate_hz', 'vision_fps')


def comparable(run):
    """A run's dict without what depends on the wall clock."""
    return {k: v for k, v in run.items() if k not in WALL_CLOCK_KEYS}


@pytest.fixture(scope='module')
def local():
    return cp.campaign(N, SEED, workers=2, duration_s=DURATION_S, progress=False)


def test_ray_campaign_gives_the_local_runs(local):
    ray = cp.campaign(N, SEED, workers=2, duration_s=DURATION_S, progress=False,
                      backend='ray')
    assert [r['index'] for r in ray['runs']] == list(range(N))
    assert [comparable(r) for r in ray['runs']] == [comparable(r) for r in local['runs']]
    assert {k: v for k, v in ray.items() if k != 'runs'} == \
        {k: v for k, v in local.items() if k != 'runs'}


def _ray_task_pids(name_prefix):
    """Pids of the processes whose title starts with ``name_prefix`` (Ray titles a worker
    ``ray::<task name>`` while it runs that task)."""
    pids = []
    for entry in os.listdir('/proc'):
        if not entry.isdigit():
            continue
        try:
            with open(f'/proc/{entry}/cmdline', 'rb') as stream:
                title = stream.read().replace(b'\0', b' ').decode(errors='replace')
        except OSError:
            continue
        if title.startswith(name_prefix):
            pids.append(int(entry))
    return pids


def test_a_worker_killed_mid_run_still_counts_every_run_once(local):
    killed = []

    def kill_one_worker():
        deadline = time.monotonic() + 120.0
        while time.monotonic() < deadline and not killed:
            pids = _ray_task_pids('ray::campaign run')
            if pids:
                time.sleep(0.3)         # into the run: its physics is flying
                if pids[0] in _ray_task_pids('ray::campaign run'):
                    os.kill(pids[0], signal.SIGKILL)
                    killed.append(pids[0])
            time.sleep(0.05)

    killer = threading.Thread(target=kill_one_worker, daemon=True)
    killer.start()
    result = cp.campaign(N, SEED, workers=2, duration_s=DURATION_S, progress=False,
                         backend='ray')
    killer.join()
    assert killed, 'no campaign task was seen running'
    assert result['n'] == N and [r['index'] for r in result['runs']] == list(range(N))
    # the run that lost its worker was flown again from its seed: the same result
    assert [comparable(r) for r in result['runs']] == [comparable(r) for r in local['runs']]


@pytest.mark.parametrize('address, code, words', [
    ('garbage::x', 2, "expected 'auto' or HOST:PORT"),
    ('127.0.0.1:1', 1, 'no Ray there'),       # nothing listens: refused at once
])
def test_an_address_without_a_cluster_is_one_line(tmp_path, address, code, words):
    out = subprocess.run([sys.executable, '-m', 'uav_tilt_tools.cli', 'campaign', '--n', '1',
                          '--backend', 'ray', '--address', address], cwd=tmp_path,
                         capture_output=True, text=True, timeout=120)
    said = [line for line in out.stderr.splitlines() if line.startswith('uav-tilt campaign:')]
    assert out.returncode == code and 'Traceback' not in out.stderr, out.stderr
    assert len(said) == 1 and words in said[0], out.stderr


def test_a_local_ray_that_cannot_start_is_one_line(tmp_path):
    # Ray's sockets go under TMPDIR, and a socket's path is at most 107 bytes
    deep = tmp_path / ('d' * 100)
    deep.mkdir()
    out = subprocess.run([sys.executable, '-m', 'uav_tilt_tools.cli', 'campaign', '--n', '1',
                          '--backend', 'ray'], cwd=tmp_path, capture_output=True, text=True,
                         env=dict(os.environ, TMPDIR=str(deep)), timeout=120)
    said = [line for line in out.stderr.splitlines() if line.startswith('uav-tilt campaign:')]
    assert out.returncode == 1 and 'Traceback' not in out.stderr, out.stderr
    assert len(said) == 1 and 'cannot start a local Ray' in said[0], out.stderr
