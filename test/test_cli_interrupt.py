"""Ctrl-C (to the process group, as a terminal sends it) and SIGTERM (to the command alone,
as `kill` or `timeout` send it) end a `uav-tilt` command with one line and exit code 130,
leaving no worker process and no temporary folder behind."""
import os
import pathlib
import shutil
import signal
import subprocess
import sys
import tempfile
import time

import pytest

from ros_graph import REPO, alive, children

# A hold of minutes: the flight outlasts the wait below however fast the machine flies it
# (a ground-truth mission of a 5 s hold ends in about 7 s of wall time).
FLY = ['fly', '--scenario', 'config/scenarios/default.yaml', '--target-source', 'ground_truth',
       '--set', 'mission.contact.hold_time_s=300']
CAMPAIGN = ['campaign', '--n', '2', '--workers', '1', '--duration', '60']
RAY_CAMPAIGN = [*CAMPAIGN, '--backend', 'ray']


@pytest.fixture
def tmp():
    """A TMPDIR of a short path (Ray's sockets go under it: at most 107 bytes)."""
    path = pathlib.Path(tempfile.mkdtemp(prefix='uavt', dir='/tmp'))
    yield path
    shutil.rmtree(path, ignore_errors=True)


def started(tmp, args):
    """`uav-tilt ARGS` with TMPDIR ``tmp``, SIGINT at its default (a terminal's foreground
    job has it so even when the tests run as a background job, which starts with it
    ignored)."""
    proc = subprocess.Popen([sys.executable, '-m', 'uav_tilt_tools.cli', *args], cwd=REPO,
                            env=dict(os.environ, TMPDIR=str(tmp)), process_group=0,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    return proc


def wait_for(predicate, timeout_s):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and not predicate():
        time.sleep(0.1)
    return predicate()


@pytest.mark.parametrize('args, how', [(FLY, 'ctrl-c'), (CAMPAIGN, 'ctrl-c'),
                                       (CAMPAIGN, 'sigterm'), (RAY_CAMPAIGN, 'sigterm')],
                         ids=['fly-ctrl-c', 'campaign-ctrl-c', 'campaign-sigterm',
                              'ray-campaign-sigterm'])
def test_an_interrupted_command_is_one_line_and_leaves_nothing(tmp_path, tmp, args, how):
    campaign = args[0] == 'campaign'
    proc = started(tmp, [*args, *(['--out', str(tmp_path / 'out')] if campaign else [])])
    if campaign:            # a worker is flying its run in its temporary folder
        assert wait_for(lambda: any(p.name.startswith('uav_tilt_run_') for p in tmp.iterdir())
                        or proc.poll() is not None, 120.0)
    else:                   # flying, well past the imports
        assert not wait_for(lambda: proc.poll() is not None, 8.0), proc.communicate()
    workers = children(proc.pid)
    if how == 'ctrl-c':
        os.killpg(proc.pid, signal.SIGINT)
    else:
        proc.send_signal(signal.SIGTERM)
    stdout, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 130, stderr
    lines = [line for line in stderr.splitlines() if line.strip()]   # after the progress bar
    assert 'Traceback' not in stderr and stdout == ''
    assert lines[-1].startswith(f'uav-tilt {args[0]}: interrupted'), stderr
    assert wait_for(lambda: not any(alive(pid) for pid in workers), 10.0), workers
    assert not list(tmp.glob('uav_tilt_run_*'))


def test_a_vision_campaign_that_finishes_ends_without_a_word_on_stderr(tmp):
    """Its workers end on their own: terminated, the ones already in their interpreter's exit
    printed a SystemExit traceback from torch's exit hook, one per worker."""
    proc = started(tmp, ['campaign', '--n', '2', '--workers', '2', '--duration', '1',
                         '--target-source', 'vision'])
    out, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err
    assert 'Traceback' not in err and 'Exception ignored' not in err, err
    assert not [p for p in tmp.iterdir() if p.name.startswith('uav_tilt_run_')]
