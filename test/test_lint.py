"""`make lint`: flake8 at 99 columns over the packages and the tests, and mypy over the
packages (setup.cfg holds the settings), run by the test suite so that a style or type
error fails it."""
import subprocess
import sys

from ros_graph import REPO


def test_make_lint_is_clean():
    # this interpreter's environment, already set up: no venv stamp to build
    result = subprocess.run(['make', '-s', 'lint', f'PY={sys.executable}', 'STAMP='], cwd=REPO,
                            capture_output=True, text=True, timeout=900)
    assert result.returncode == 0, result.stdout + result.stderr
