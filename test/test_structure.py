"""The house's rooms: imports point inwards, and the companion computer's vision runtime
installs and runs without the simulator.

- uav_tilt_common imports none of the other packages;
- uav_tilt_control (the flight controller) imports neither the simulator nor vision;
- uav_tilt_vision imports the simulator only in its data set generator (``dataset``);
- no core module (common, sim, control, vision) imports rclpy except the ROS shells.
"""
import ast
import pathlib
import subprocess
import sys

import pytest

REPO = pathlib.Path(__file__).resolve().parent.parent
PACKAGES = ('uav_tilt_common', 'uav_tilt_sim', 'uav_tilt_control', 'uav_tilt_vision',
            'uav_tilt_tools')
# what each package may not import (top-level package names)
FORBIDDEN = {
    'uav_tilt_common': {'uav_tilt_sim', 'uav_tilt_control', 'uav_tilt_vision',
                        'uav_tilt_tools'},
    'uav_tilt_control': {'uav_tilt_sim', 'uav_tilt_vision', 'uav_tilt_tools'},
    'uav_tilt_vision': {'uav_tilt_sim', 'uav_tilt_control', 'uav_tilt_tools'},
    'uav_tilt_sim': {'uav_tilt_control', 'uav_tilt_vision', 'uav_tilt_tools'},
}
ALLOWED = {('uav_tilt_vision', 'dataset'): {'uav_tilt_sim'}}


def _imports(path):
    """Top-level package names imported anywhere in a module (function bodies included)."""
    tree = ast.parse(path.read_text(), str(path))
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name.split('.')[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module.split('.')[0])
    return names


def _modules(package):
    return sorted((REPO / package).glob('*.py'))


@pytest.mark.parametrize('package', sorted(FORBIDDEN))
def test_imports_point_inwards(package):
    offenders = []
    for path in _modules(package):
        allowed = ALLOWED.get((package, path.stem), set())
        bad = (_imports(path) & FORBIDDEN[package]) - allowed
        if bad:
            offenders.append(f'{package}.{path.stem} imports {sorted(bad)}')
    assert not offenders


def test_rclpy_only_in_the_ros_shells():
    offenders = []
    for package in ('uav_tilt_common', 'uav_tilt_sim', 'uav_tilt_control', 'uav_tilt_vision'):
        for path in _modules(package):
            ros = path.stem.endswith('_node') or path.stem.startswith('ros_')
            if not ros and 'rclpy' in _imports(path):
                offenders.append(f'{package}.{path.stem}')
    assert not offenders


def test_the_vision_runtime_imports_without_the_simulator():
    """The Jetson side installs without PyBullet: block the simulator package and import
    everything the vision node runs."""
    code = ('import sys; sys.modules["uav_tilt_sim"] = None; sys.modules["pybullet"] = None\n'
            'import uav_tilt_vision.vision_node, uav_tilt_vision.pipeline, '
            'uav_tilt_vision.backends, uav_tilt_vision.detector\n'
            'print("ok")')
    out = subprocess.run([sys.executable, '-c', code], cwd=REPO, capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 0 and out.stdout.strip() == 'ok', out.stderr
    # and the check can fail: the data set generator does need the simulator
    code = code.replace('uav_tilt_vision.detector', 'uav_tilt_vision.dataset')
    out = subprocess.run([sys.executable, '-c', code], cwd=REPO, capture_output=True,
                         text=True, timeout=120)
    assert out.returncode != 0 and 'halted; None in sys.modules' in out.stderr


def _string_literals(tree):
    return {node.value for node in ast.walk(tree)
            if isinstance(node, ast.Constant) and isinstance(node.value, str)}


def _tests_covariance0(tree):
    """Whether the module compares ``<...>cov...[0]`` with something (the no-target test)."""
    for node in ast.walk(tree):
        if isinstance(node, ast.Compare):
            for side in (node.left, *node.comparators):
                if isinstance(side, ast.Subscript) and isinstance(side.slice, ast.Constant) \
                        and side.slice.value == 0 and 'cov' in ast.unparse(side.value):
                    return True
    return False


def test_the_shared_vocabulary_is_spelled_once():
    """Mode names, the "no target" covariance and the object classes are defined in
    uav_tilt_common and only used elsewhere (tests may spell them: they check the wire)."""
    from uav_tilt_common.modes import NOT_FLYING, Mode

    mode_names = {m.value for m in Mode} | set(NOT_FLYING)
    offenders = []
    for package in PACKAGES:
        for path in _modules(package):
            tree = ast.parse(path.read_text(), str(path))
            home = package == 'uav_tilt_common'
            spelled = _string_literals(tree) & mode_names
            if spelled and (package, path.stem) != ('uav_tilt_common', 'modes'):
                offenders.append(f'{package}.{path.stem} spells modes {sorted(spelled)}')
            if _tests_covariance0(tree) and not home:
                offenders.append(f'{package}.{path.stem} decodes the no-target covariance')
            defined = {t.id for node in ast.walk(tree) if isinstance(node, ast.Assign)
                       for t in node.targets if isinstance(t, ast.Name)}
            if 'OBJECT_CLASSES' in defined and \
                    (package, path.stem) != ('uav_tilt_common', 'targets'):
                offenders.append(f'{package}.{path.stem} defines OBJECT_CLASSES')
    assert not offenders
