"""flake8 at 99 columns over the package and the tests (setup.cfg holds the settings)."""
import subprocess
import sys

from ros_graph import REPO

PATHS = ['uav_tilt_common', 'uav_tilt_sim', 'uav_tilt_control', 'uav_tilt_vision',
         'uav_tilt_tools', 'test', 'setup.py']


def test_flake8_is_clean():
    result = subprocess.run([sys.executable, '-m', 'flake8', *PATHS], cwd=REPO,
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stdout + result.stderr
