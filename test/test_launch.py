"""scripts/launch.sh: the graph runs in /uav, Ctrl-C stops every node cleanly, a dying node
fails the launch; and the mission watcher's verdict."""
import os
import signal
import subprocess

import pytest
from diagnostic_msgs.msg import DiagnosticArray
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from ros_graph import REPO, status_values
from uav_tilt_common import names, ros_qos
from uav_tilt_tools.mission_watch import MissionWatch

LAUNCH = os.path.join(REPO, 'scripts', 'launch.sh')
# The spec's shutdown limit for every node, plus the script's own bookkeeping.
SHUTDOWN_S = 5.0 + 3.0


def children(pid):
    """pid -> command line of the processes whose parent is ``pid``."""
    found = {}
    for entry in os.listdir('/proc'):
        try:
            with open(f'/proc/{entry}/stat') as stream:
                ppid = int(stream.read().rsplit(')', 1)[1].split()[1])
            if ppid == pid:
                with open(f'/proc/{entry}/cmdline', 'rb') as stream:
                    found[int(entry)] = stream.read().replace(b'\0', b' ').decode()
        except (OSError, ValueError, IndexError):
            continue        # not a process, or it is gone already
    return found


def alive(pid):
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


def start_graph(tmp_path, probe, *args):
    """launch.sh with plant and controller (no vision); returns (process, log path, nodes)
    once the controller answers the plant's ticks."""
    log_path = tmp_path / 'launch.log'
    with open(log_path, 'w') as log:
        launch = subprocess.Popen([LAUNCH, '--no-vision', *args], cwd=tmp_path, stdout=log,
                                  stderr=subprocess.STDOUT)
    probe.record(names.CONTROLLER_STATUS, DiagnosticArray, ros_qos.STATUS)

    def ticking():
        msgs = probe.messages[names.CONTROLLER_STATUS]
        return bool(msgs) and int(status_values(msgs[-1])['ticks']) >= 100

    assert probe.spin_until(ticking, 90.0), log_path.read_text()
    nodes = children(launch.pid)
    assert sum('plant_node' in c for c in nodes.values()) == 1, nodes
    assert all('__ns:=/uav' in c for c in nodes.values()), nodes
    return launch, log_path, nodes


def test_ctrl_c_stops_every_node_cleanly(tmp_path, probe):
    launch, log_path, nodes = start_graph(tmp_path, probe)
    try:
        launch.send_signal(signal.SIGINT)
        assert launch.wait(timeout=SHUTDOWN_S) == 0, log_path.read_text()
    finally:
        launch.kill()
    assert not any(alive(pid) for pid in nodes)
    log = log_path.read_text()
    assert '[launch] plant: exit code 0' in log and '[launch] controller: exit code 0' in log


def test_ctrl_c_mid_mission_leaves_a_complete_recording(tmp_path, probe):
    run_dir = tmp_path / 'run'
    launch, log_path, nodes = start_graph(
        tmp_path, probe, '--mission', 'inspect', '--target-source', 'ground_truth',
        '--record', str(run_dir))
    try:
        assert probe.spin_until(lambda: probe.latest_status(names.CONTROLLER_STATUS)
                                .get('mode') == 'APPROACH', 120.0), log_path.read_text()
        launch.send_signal(signal.SIGINT)
        # Interrupted, the mission did not succeed, so the script reports failure ...
        assert launch.wait(timeout=SHUTDOWN_S) != 0
    finally:
        launch.kill()
    assert not any(alive(pid) for pid in nodes)
    log = log_path.read_text()
    # ... while every node itself shut down cleanly.
    for node in ('plant', 'controller', 'recorder'):
        assert f'[launch] {node}: exit code 0' in log, log
    with open(run_dir / 'recording.mcap', 'rb') as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        # Finished properly: the summary section with its statistics was written at exit.
        summary = reader.get_summary()
        assert summary is not None and summary.statistics.message_count > 0
        decoded = list(reader.iter_decoded_messages())
    # Readable to its last message, and every message counted in the summary is there.
    assert len(decoded) == summary.statistics.message_count
    modes = [status_values(d)['mode'] for _, channel, _, d in decoded
             if channel.topic == '/uav/' + names.CONTROLLER_STATUS]
    assert 'TAKEOFF' in modes


def test_a_dying_node_fails_the_launch_and_stops_the_others(tmp_path, probe):
    launch, log_path, nodes = start_graph(tmp_path, probe)
    plant = next(pid for pid, cmd in nodes.items() if 'plant_node' in cmd)
    try:
        os.kill(plant, signal.SIGKILL)
        assert launch.wait(timeout=SHUTDOWN_S) != 0
    finally:
        launch.kill()
    assert not any(alive(pid) for pid in nodes)
    assert f'plant (pid {plant}) exited with code 137' in log_path.read_text()


def test_bad_arguments_start_nothing(tmp_path):
    result = subprocess.run([LAUNCH, '--mission', 'survey'], cwd=tmp_path,
                            capture_output=True, text=True, timeout=30)
    assert result.returncode == 2
    assert "--mission: 'inspect' or 'plan'" in result.stderr


@pytest.mark.parametrize('modes, success, result', [
    (['WAITING_FOR_SENSORS', 'IDLE', 'TAKEOFF', 'HOLD', 'LAND', 'IDLE'], 'True', True),
    (['IDLE', 'TAKEOFF', 'FAILSAFE_LAND', 'IDLE'], 'False', False),
    (['IDLE', 'IDLE', 'TAKEOFF', 'HOVER'], 'False', None),
])
def test_mission_watch_waits_for_the_return_to_idle(modes, success, result):
    watch = MissionWatch()
    for mode in modes:
        watch.update({'mode': mode, 'success': success})
    assert watch.result is result
