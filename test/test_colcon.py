"""`colcon build` lays the package out the way `ros2 run uav_tilt <exe>` finds it."""
import configparser
import os
import shutil
import subprocess
import sys

import pytest

from ros_graph import REPO

pytest.importorskip('colcon_core')

# What an ament_python package install needs from the source tree.
SOURCES = ['setup.py', 'setup.cfg', 'package.xml', 'resource', 'config', 'uav_tilt_common',
           'uav_tilt_sim', 'uav_tilt_control', 'uav_tilt_vision', 'uav_tilt_tools']
# DESIGN section 1's executables that exist today; the rest come from setup.py itself.
REQUIRED = {'plant_node', 'controller_node', 'uav-tilt'}
SITE = f'lib/python{sys.version_info.major}.{sys.version_info.minor}/site-packages'


@pytest.fixture(scope='module')
def workspace(tmp_path_factory):
    """A colcon workspace with a copy of the package in src/uav_tilt, built."""
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
    return ws


def installed_env(ws):
    """The environment `source install/setup.bash` gives (the parts these checks need)."""
    prefix = ws / 'install' / 'uav_tilt'
    return dict(os.environ, AMENT_PREFIX_PATH=str(prefix),
                PYTHONPATH=os.pathsep.join([str(prefix / SITE), os.environ.get('PYTHONPATH',
                                                                               '')]))


def test_every_console_script_is_in_lib_uav_tilt(workspace):
    egg = next((workspace / 'install' / 'uav_tilt' / SITE).glob('uav_tilt-*.egg-info'))
    entry_points = configparser.ConfigParser()
    entry_points.read(egg / 'entry_points.txt')
    scripts = set(entry_points['console_scripts'])
    assert REQUIRED <= scripts
    lib = workspace / 'install' / 'uav_tilt' / 'lib' / 'uav_tilt'
    assert {p.name for p in lib.iterdir()} >= scripts
    assert all(os.access(lib / name, os.X_OK) for name in scripts)


def test_the_ament_index_resolves_executables_like_ros2_run(workspace):
    # ros2 run: package prefix from the ament index, then <prefix>/lib/<package>/<exe>.
    lookup = ('from ament_index_python.packages import get_package_prefix; '
              'import uav_tilt_sim; '
              'print(get_package_prefix("uav_tilt")); print(uav_tilt_sim.__file__)')
    found = subprocess.run([sys.executable, '-c', lookup], cwd=workspace,
                           env=installed_env(workspace), capture_output=True, text=True,
                           timeout=60, check=True)
    prefix, module = found.stdout.split()
    assert prefix == str(workspace / 'install' / 'uav_tilt')
    assert module.startswith(prefix)        # the installed copy, not the source tree
    assert (workspace / 'install' / 'uav_tilt' / 'share' / 'ament_index' / 'resource_index'
            / 'packages' / 'uav_tilt').is_file()
    exe = os.path.join(prefix, 'lib', 'uav_tilt')
    cli = subprocess.run([os.path.join(exe, 'uav-tilt'), '--help'], cwd=workspace,
                         env=installed_env(workspace), capture_output=True, text=True,
                         timeout=60)
    assert cli.returncode == 0 and 'usage: uav-tilt' in cli.stdout
    plant = subprocess.run([os.path.join(exe, 'plant_node'), '--ros-args', '-p', 'rtf:=-2.0'],
                           cwd=workspace, env=installed_env(workspace), capture_output=True,
                           text=True, timeout=120)
    assert plant.returncode == 2
    assert [line for line in plant.stderr.splitlines() if 'FATAL' in line and "'rtf'" in line]
