"""Long in-process work shows its progress on a terminal and stays quiet in a pipe: `uav-tilt
fly` (simulated seconds and the mode), `campaign` (runs), `report` (bytes read)."""
import errno
import fcntl
import json
import os
import struct
import subprocess
import sys
import termios

import pytest

from ros_graph import REPO

CLI = [sys.executable, '-m', 'uav_tilt_tools.cli']
SCENARIO = os.path.join(REPO, 'config', 'scenarios', 'default.yaml')
# seconds of sim time: enough for a few updates of each bar, and quick
FLY = ['fly', '--scenario', SCENARIO, '--target-source', 'ground_truth', '--duration', '3']
CAMPAIGN = ['campaign', '--n', '2', '--workers', '1', '--duration', '2']


def in_a_pipe(args):
    """(exit code, stdout, stderr) with both in pipes."""
    done = subprocess.run([*CLI, *args], cwd=REPO, capture_output=True, text=True,
                          timeout=300)
    return done.returncode, done.stdout, done.stderr


def on_a_terminal(args):
    """(exit code, stdout, what went to stderr) with stderr a terminal (a pty)."""
    master, slave = os.openpty()
    # a terminal 160 columns wide (a new pty has none: tqdm would cut its bar to nothing)
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack('HHHH', 40, 160, 0, 0))
    proc = subprocess.Popen([*CLI, *args], cwd=REPO, stdout=subprocess.PIPE, stderr=slave)
    os.close(slave)
    chunks = []
    while True:
        try:
            chunk = os.read(master, 4096)
        except OSError as err:      # the child closed its end: EIO on Linux
            assert err.errno == errno.EIO
            break
        if not chunk:
            break
        chunks.append(chunk)
    os.close(master)
    stdout, _ = proc.communicate(timeout=300)
    return proc.returncode, stdout.decode(), b''.join(chunks).decode(errors='replace')


def a_bar(text):
    """Whether ``text`` holds a tqdm bar (redrawn with carriage returns)."""
    return '\r' in text and ('sim s' in text or 'run' in text or 'B/s' in text)


@pytest.fixture(scope='module')
def recorded(tmp_path_factory):
    """A short recorded flight, flown in a pipe: (exit code, stdout, stderr, folder)."""
    folder = tmp_path_factory.mktemp('progress') / 'run'
    return (*in_a_pipe([*FLY, '--record', str(folder)]), folder)


def test_fly_is_quiet_in_a_pipe_and_shows_its_flight_on_a_terminal(recorded):
    code, out, err, _ = recorded
    assert code in (0, 1) and json.loads(out)['sim_time_s'] > 0
    assert not a_bar(err) and 'sim s' not in err, err
    code, out, shown = on_a_terminal(FLY)
    assert code in (0, 1) and json.loads(out)['sim_time_s'] > 0
    assert a_bar(shown) and 'fly: ' in shown and 'of at most 3 sim s' in shown, shown
    assert 'TAKEOFF' in shown or 'HOVER' in shown       # the mode under way


def test_report_shows_its_reading_on_a_terminal_only(recorded):
    folder = recorded[-1]
    code, out, err = in_a_pipe(['report', str(folder)])
    assert code in (0, 1) and json.loads(out) and not a_bar(err), err
    code, out, shown = on_a_terminal(['report', str(folder)])
    assert code in (0, 1) and json.loads(out)
    assert a_bar(shown) and 'reading' in shown, shown


def test_campaign_is_quiet_in_a_pipe_and_counts_runs_on_a_terminal():
    code, out, err = in_a_pipe(CAMPAIGN)
    assert json.loads(out)['n'] == 2 and not a_bar(err) and 'campaign' not in err, err
    code, out, shown = on_a_terminal(CAMPAIGN)
    assert json.loads(out)['n'] == 2
    assert a_bar(shown) and 'campaign' in shown and '2/2' in shown, shown
