"""`colcon build` (no --symlink-install) installs a package that runs on its own: the layout
`ros2 run uav_tilt <exe>` finds, the config, scenarios and models in share/uav_tilt, and
nodes that start with their defaults and fly the mission from a Python that cannot see
the source tree (no editable install on its path)."""
import configparser
import os
import shutil
import subprocess
import sys
import sysconfig

import pytest
from diagnostic_msgs.msg import DiagnosticArray

from ros_graph import REPO, status_values, stop
from uav_tilt_common import names, ros_qos

pytestmark = pytest.mark.slow     # minutes of missions or graphs: handed out first

pytest.importorskip('colcon_core')

# What an ament_python package install needs from the source tree.
SOURCES = ['setup.py', 'setup.cfg', 'package.xml', 'resource', 'config', 'models',
           'uav_tilt_common', 'uav_tilt_sim', 'uav_tilt_control', 'uav_tilt_vision',
           'uav_tilt_tools']
# DESIGN section 1's executables that exist today; the rest come from setup.py itself.
REQUIRED = {'plant_node', 'controller_node', 'vision_node', 'recorder_node', 'uav-tilt'}
SITE = f'lib/python{sys.version_info.major}.{sys.version_info.minor}/site-packages'
# The third-party packages (rclpy, numpy, ...), without the .pth files that would put the
# editable install of the source tree back on the path.
THIRD_PARTY = sysconfig.get_paths()['purelib']


@pytest.fixture(scope='module')
def workspace(tmp_path_factory):
    """A colcon workspace with a copy of the package in src/uav_tilt, built and installed."""
    ws = tmp_path_factory.mktemp('ws')
    (ws / 'src' / 'uav_tilt').mkdir(parents=True)
    for name in SOURCES:
        src, dst = os.path.join(REPO, name), ws / 'src' / 'uav_tilt' / name
        if os.path.isdir(src):
            shutil.copytree(src, dst, ignore=shutil.ignore_patterns('__pycache__'))
        else:
            shutil.copy(src, dst)
    env = dict(os.environ, COLCON_HOME=str(ws / 'colcon_home'))
    result = subprocess.run([sys.executable, '-m', 'colcon', 'build', '--base-paths', 'src'],
                            cwd=ws, env=env, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout + result.stderr
    shutil.rmtree(ws / 'src')       # nothing left to fall back on
    (ws / 'run').mkdir()
    return ws


def prefix_of(ws):
    return ws / 'install' / 'uav_tilt'


def installed_env(ws):
    """What `source install/setup.bash` gives (the parts these checks need), with this
    process's PYTHONPATH (the source tree) replaced by the install and the third parties."""
    prefix = prefix_of(ws)
    return dict(os.environ, AMENT_PREFIX_PATH=str(prefix),
                PYTHONPATH=os.pathsep.join([str(prefix / SITE), THIRD_PARTY]))


def installed(ws, *args):
    """argv running ``args`` (an installed executable or ``-c``) with site processing off
    (``-S``: no .pth, so no editable install), as a ROS install's own Python would."""
    exe = prefix_of(ws) / 'lib' / 'uav_tilt' / args[0]
    return [sys.executable, '-S', *([str(exe)] if exe.is_file() else [args[0]]), *args[1:]]


def start_installed(ws, exe, params=None, log_path=None):
    """Start installed node ``exe`` in /uav with ``params``, from a folder outside it."""
    cmd = installed(ws, exe, '--ros-args', '-r', '__ns:=/uav')
    for name, value in (params or {}).items():
        cmd += ['-p', f'{name}:={value}']
    log = open(log_path, 'w') if log_path else subprocess.DEVNULL
    return subprocess.Popen(cmd, cwd=ws / 'run', stdout=log, stderr=subprocess.STDOUT,
                            env=dict(installed_env(ws), PYTHONUNBUFFERED='1'))


def test_every_console_script_is_in_lib_uav_tilt(workspace):
    egg = next((prefix_of(workspace) / SITE).glob('uav_tilt-*.egg-info'))
    entry_points = configparser.ConfigParser()
    entry_points.read(egg / 'entry_points.txt')
    scripts = set(entry_points['console_scripts'])
    assert REQUIRED <= scripts
    lib = prefix_of(workspace) / 'lib' / 'uav_tilt'
    assert {p.name for p in lib.iterdir()} >= scripts
    assert all(os.access(lib / name, os.X_OK) for name in scripts)


def test_the_installed_copy_runs_and_finds_its_files_in_share(workspace):
    # ros2 run: package prefix from the ament index, then <prefix>/lib/<package>/<exe>.
    lookup = ('from ament_index_python.packages import get_package_prefix; '
              'import uav_tilt_common.resources as r; '
              'print(get_package_prefix("uav_tilt")); print(r.__file__); '
              'print(r.source_root()); print(r.share_dir())')
    found = subprocess.run(installed(workspace, '-c', lookup), cwd=workspace / 'run',
                           env=installed_env(workspace), capture_output=True, text=True,
                           timeout=60, check=True)
    prefix, module, source, share = found.stdout.split()
    assert prefix == str(prefix_of(workspace))
    assert module.startswith(prefix)        # the installed copy, not the source tree
    assert source == 'None' and share == str(prefix_of(workspace) / 'share' / 'uav_tilt')
    for shipped in ('config/plant.yaml', 'config/scenarios/default.yaml',
                    'config/plans/inspection.yaml', 'models/detector_int8.onnx',
                    'models/detector_int8.json'):
        assert (prefix_of(workspace) / 'share' / 'uav_tilt' / shipped).is_file(), shipped
    assert (prefix_of(workspace) / 'share' / 'ament_index' / 'resource_index' / 'packages'
            / 'uav_tilt').is_file()
    cli = subprocess.run(installed(workspace, 'uav-tilt', '--help'), cwd=workspace / 'run',
                         env=installed_env(workspace), capture_output=True, text=True,
                         timeout=60)
    assert cli.returncode == 0 and 'usage: uav-tilt' in cli.stdout
    plant = subprocess.run(installed(workspace, 'plant_node', '--ros-args', '-p', 'rtf:=-2.0'),
                           cwd=workspace / 'run', env=installed_env(workspace),
                           capture_output=True, text=True, timeout=120)
    assert plant.returncode == 2
    assert [line for line in plant.stderr.splitlines() if 'FATAL' in line and "'rtf'" in line]


def test_installed_plant_and_vision_start_with_their_defaults(workspace, probe, tmp_path):
    plant = start_installed(workspace, 'plant_node', log_path=tmp_path / 'plant.log')
    vision = start_installed(workspace, 'vision_node', log_path=tmp_path / 'vision.log')
    try:
        probe.record(names.PLANT_STATUS, DiagnosticArray, ros_qos.STATUS)
        probe.record(names.VISION_STATUS, DiagnosticArray, ros_qos.STATUS)
        logs = [p.read_text() for p in (tmp_path / 'plant.log', tmp_path / 'vision.log')]
        assert probe.spin_until(lambda: probe.messages[names.PLANT_STATUS] and
                                probe.messages[names.VISION_STATUS], 90.0), logs
        vision_status = probe.latest_status(names.VISION_STATUS)
        plant_status = probe.latest_status(names.PLANT_STATUS)
    finally:
        codes = [stop(plant)[0], stop(vision)[0]]
    share = str(prefix_of(workspace) / 'share' / 'uav_tilt')
    # The default detector, from the install's share folder, on its default backend.
    assert vision_status['backend'] == 'onnxruntime'
    assert vision_status['model'] == os.path.join(share, 'models', 'detector_int8.onnx')
    assert plant_status['mode'] == 'lockstep'
    assert 'scenario=default' in (tmp_path / 'plant.log').read_text()
    logs = [p.read_text()[-2000:] for p in (tmp_path / 'plant.log', tmp_path / 'vision.log')]
    assert codes == [0, 0], logs


def test_the_installed_graph_flies_the_ground_truth_mission(workspace, probe, tmp_path):
    controller = start_installed(workspace, 'controller_node',
                                 params={'target_source': 'ground_truth',
                                         'autostart': 'inspect', 'use_sim_time': 'true',
                                         'mission.contact.hold_time_s': 2.0},
                                 log_path=tmp_path / 'controller.log')
    modes, statuses, plant = [], [], None

    def on_status(msg):
        values = status_values(msg)
        if not modes or modes[-1] != values['mode']:
            modes.append(values['mode'])
        statuses.append(values)

    try:
        probe.node.create_subscription(DiagnosticArray, names.CONTROLLER_STATUS, on_status,
                                       ros_qos.STATUS)
        assert probe.spin_until(
            lambda: probe.node.count_publishers(names.CONTROLLER_STATUS) > 0, 60.0)
        plant = start_installed(workspace, 'plant_node', log_path=tmp_path / 'plant.log',
                                params={'camera_enabled': 'false'})
        done = probe.spin_until(lambda: 'TAKEOFF' in modes and modes[-1] == 'IDLE', 240.0)
        logs = [p.read_text()[-2000:] for p in (tmp_path / 'plant.log',
                                                tmp_path / 'controller.log')]
        assert done, (modes, logs)
    finally:
        codes = [stop(controller)[0], stop(plant)[0] if plant else None]
    assert {'TAKEOFF', 'CONTACT', 'HOLD', 'LAND'} <= set(modes)
    assert statuses[-1]['success'] == 'True' and statuses[-1]['contact_lost'] == '0'
    assert codes == [0, 0]
