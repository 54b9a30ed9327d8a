"""The split of docs/two-computers.md, run for real: the flight-controller side (plant,
controller, recorder) in one network namespace, the companion side (vision) in another,
joined by a veth pair; discovery beyond localhost; the lockstep mission with vision in the
loop across the link meets the demo's bar, and the link's target/pose latency is reported."""
import json
import os
import shutil
import signal
import subprocess
import sys

import numpy as np
import pytest

from ros_graph import REPO
from uav_tilt_common import names
from uav_tilt_tools.bag import reader as recording

pytestmark = pytest.mark.slow     # minutes of missions or graphs: handed out first

LAUNCH = os.path.join(REPO, 'scripts', 'launch.sh')
# Names and a /24 of this run's own (ip names: at most 15 characters).
TAG = os.getpid() % 100000
SUBNET = f'10.{200 + TAG % 50}.{TAG // 50 % 250}'
SIDES = {'fc': (f'uavfc{TAG}', f'vfc{TAG}', f'{SUBNET}.1'),
         'cc': (f'uavcc{TAG}', f'vcc{TAG}', f'{SUBNET}.2')}
# A frame's colour and depth images, bytes on the wire at least.
FRAME_BYTES = 320 * 240 * (3 + 4)


def ip(*args):
    subprocess.run(['ip', *args], check=True, capture_output=True, text=True, timeout=30)


@pytest.fixture
def link():
    """The two namespaces with lo up and the veth pair addressed; always torn down."""
    if os.geteuid() != 0 or shutil.which('ip') is None:
        pytest.skip('network namespaces need root and iproute2 (ip netns)')
    try:
        for ns, _, _ in SIDES.values():
            ip('netns', 'add', ns)
        ip('link', 'add', SIDES['fc'][1], 'type', 'veth', 'peer', 'name', SIDES['cc'][1])
        for ns, dev, address in SIDES.values():
            ip('link', 'set', dev, 'netns', ns)
            ip('-n', ns, 'addr', 'add', f'{address}/24', 'dev', dev)
            ip('-n', ns, 'link', 'set', 'lo', 'up')
            ip('-n', ns, 'link', 'set', dev, 'up')
    except subprocess.CalledProcessError as err:
        _teardown()
        pytest.skip(f'cannot make network namespaces: {err.stderr.strip()}')
    try:
        yield SIDES
    finally:
        _teardown()


def _teardown():
    for ns, _, _ in SIDES.values():
        subprocess.run(['ip', 'netns', 'del', ns], capture_output=True, timeout=30)


def side(ns, peer_ip, *args, log_path):
    """scripts/launch.sh in namespace ``ns``, discovering on the subnet and at the peer."""
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE='SUBNET', ROS_STATIC_PEERS=peer_ip)
    with open(log_path, 'w') as log:
        return subprocess.Popen(['ip', 'netns', 'exec', ns, LAUNCH, *args], cwd=REPO, env=env,
                                stdout=log, stderr=subprocess.STDOUT)


def rx_bytes(ns, dev):
    out = subprocess.run(['ip', 'netns', 'exec', ns, 'cat',
                          f'/sys/class/net/{dev}/statistics/rx_bytes'],
                         capture_output=True, text=True, timeout=30, check=True).stdout
    return int(out)


def test_the_mission_with_vision_across_the_link(link, tmp_path, record_property):
    (fc_ns, _, fc_ip), (cc_ns, cc_dev, cc_ip) = link['fc'], link['cc']
    run_dir = tmp_path / 'run'
    companion = side(cc_ns, fc_ip, '--vision-only', log_path=tmp_path / 'companion.log')
    controller = None
    try:
        controller = side(
            fc_ns, cc_ip, '--no-vision', '--mission', 'inspect', '--record', str(run_dir),
            '--param', 'controller.mission.contact.hold_time_s:=3.0',
            # Wall-clock log times: image out -> pose back, both on this side's clock.
            '--param', 'recorder.use_sim_time:=false',
            '--param', 'recorder.exclude:=camera/color/image_raw,camera/depth/image_raw,'
                       'vision/debug_image',
            log_path=tmp_path / 'flight.log')
        code = controller.wait(timeout=540)
    finally:
        for proc in (controller, companion):
            if proc is not None and proc.poll() is None:
                proc.send_signal(signal.SIGINT)
        for proc in (controller, companion):
            if proc is not None:
                try:
                    proc.wait(timeout=15)
                except subprocess.TimeoutExpired:
                    proc.kill()
        received = rx_bytes(cc_ns, cc_dev)
    logs = '\n'.join(f'--- {p}\n' + (tmp_path / p).read_text()[-6000:]
                     for p in ('flight.log', 'companion.log'))
    assert code == 0, logs
    assert 'log time: wall clock' in (tmp_path / 'flight.log').read_text()
    report = subprocess.run([sys.executable, '-m', 'uav_tilt_tools.cli', 'report',
                             str(run_dir)], cwd=REPO, capture_output=True, text=True,
                            timeout=300)
    assert report.returncode == 0, report.stdout + report.stderr
    summary = json.loads((run_dir / 'summary.json').read_text())
    # The demo's bar.
    assert summary['success'] is True, summary
    assert summary['poi_error_max_m'] <= 0.01
    assert summary['force_mean_n'] == pytest.approx(5.0, abs=0.1)
    assert summary['force_rms_error_n'] <= 0.2
    assert summary['contact_lost'] == 0
    rec = recording.load_recording(str(run_dir), topics=recording.REPORT_TOPICS)
    ctrl = recording.statuses(rec, names.CONTROLLER_STATUS)
    vision = recording.statuses(rec, names.VISION_STATUS)
    assert ctrl[-1][1]['target_source'] == 'vision'
    processed = vision[-1][1]['frames_processed']
    # The frames went over the veth (not shared memory): the companion side received them.
    assert processed > 100 and received >= processed * FRAME_BYTES
    _, latency_ms = recording.frame_latencies_ms(rec)
    assert len(latency_ms) >= 0.9 * processed
    numbers = dict(poses=int(len(latency_ms)), frames_processed=int(processed),
                   link_rx_mb=round(received / 1e6, 1),
                   target_pose_latency_ms_p50=round(float(np.percentile(latency_ms, 50)), 2),
                   target_pose_latency_ms_p95=round(float(np.percentile(latency_ms, 95)), 2),
                   target_pose_latency_ms_max=round(float(latency_ms.max()), 2),
                   vision_latency_ms_p95=summary['vision_latency_ms_p95'],
                   rtf=summary['rtf'])
    for key, value in numbers.items():
        record_property(key, value)
    print(f'two computers: {json.dumps(numbers)}')
