"""The house's rooms: imports point inwards, and the companion computer's vision runtime
installs and runs without the simulator.

- uav_tilt_common imports none of the other packages;
- uav_tilt_control (the flight controller) imports neither the simulator nor vision;
- uav_tilt_vision imports the simulator only in its offline training sub-package
  (``training``: the data set generator renders with it);
- no core module (common, sim, control, vision) imports rclpy except the ROS shells;
- no import cycle in any package, and nothing imports a command module of `uav-tilt`;
- the flight controller stays in rooms one can find one's way in: no module over 500
  lines, each family of mission modes in a module of its own.
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
# what a module, or every module of a sub-package, may import all the same
ALLOWED = {'uav_tilt_vision.training': {'uav_tilt_sim'}}


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
    """Every module of a package, its sub-packages' included."""
    return sorted((REPO / package).rglob('*.py'))


def _dotted(package, path):
    """The dotted name of a module of ``package`` (``pkg.sub.__init__`` for a package's)."""
    return '.'.join((package, *path.relative_to(REPO / package).with_suffix('').parts))


def _allowed(name):
    """What ALLOWED grants the module ``name``: its own entry and its packages'."""
    parts = name.split('.')
    return set().union(*(ALLOWED.get('.'.join(parts[:i]), set())
                         for i in range(1, len(parts) + 1)))


@pytest.mark.parametrize('package', sorted(FORBIDDEN))
def test_imports_point_inwards(package):
    offenders = []
    for path in _modules(package):
        name = _dotted(package, path)
        bad = (_imports(path) & FORBIDDEN[package]) - _allowed(name)
        if bad:
            offenders.append(f'{name} imports {sorted(bad)}')
    assert not offenders


def test_rclpy_only_in_the_ros_shells():
    offenders = []
    for package in ('uav_tilt_common', 'uav_tilt_sim', 'uav_tilt_control', 'uav_tilt_vision'):
        for path in _modules(package):
            ros = path.stem.endswith('_node') or path.stem.startswith('ros_')
            if not ros and 'rclpy' in _imports(path):
                offenders.append(_dotted(package, path))
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
    # and the check can fail: the training's data set generator does need the simulator
    code = code.replace('uav_tilt_vision.detector', 'uav_tilt_vision.training.dataset')
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
            home, name = package == 'uav_tilt_common', _dotted(package, path)
            spelled = _string_literals(tree) & mode_names
            if spelled and name != 'uav_tilt_common.modes':
                offenders.append(f'{name} spells modes {sorted(spelled)}')
            if _tests_covariance0(tree) and not home:
                offenders.append(f'{name} decodes the no-target covariance')
            defined = {t.id for node in ast.walk(tree) if isinstance(node, ast.Assign)
                       for t in node.targets if isinstance(t, ast.Name)}
            if 'OBJECT_CLASSES' in defined and name != 'uav_tilt_common.targets':
                offenders.append(f'{name} defines OBJECT_CLASSES')
    assert not offenders


def _project_modules():
    """Dotted name -> path of every module of the project's packages."""
    return {_dotted(package, path): path for package in PACKAGES
            for path in _modules(package)}


def _module_imports(path, modules):
    """The project modules that a module imports by name, anywhere in it: ``import a.b``
    and ``from a import b`` name module a.b when it is one, else package a."""
    tree = ast.parse(path.read_text(), str(path))
    found = set()

    def module(name):
        for candidate in (name, name + '.__init__'):
            if candidate in modules:
                return candidate
        return None

    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names = [f'{node.module}.{alias.name}' for alias in node.names]
            names = [name if module(name) else node.module for name in names]
        else:
            continue
        found.update(m for m in map(module, names) if m is not None)
    return found


def _cycles(graph):
    """The strongly connected components of more than one module, or a module that
    imports itself (Tarjan's algorithm)."""
    index, low, stack, on_stack, cycles = {}, {}, [], set(), []

    def visit(node):
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for other in graph.get(node, ()):
            if other not in index:
                visit(other)
                low[node] = min(low[node], low[other])
            elif other in on_stack:
                low[node] = min(low[node], index[other])
        if low[node] == index[node]:
            component = set()
            while True:
                other = stack.pop()
                on_stack.discard(other)
                component.add(other)
                if other == node:
                    break
            if len(component) > 1 or node in graph.get(node, ()):
                cycles.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return cycles


def _import_graph():
    modules = _project_modules()
    return {name: _module_imports(path, modules) for name, path in modules.items()}


def test_no_import_cycle_in_any_package():
    graph = _import_graph()
    # the graph holds the imports of every kind: a sub-module by name, one from a package
    assert {'uav_tilt_control.mission.base', 'uav_tilt_control.plan'} <= \
        graph['uav_tilt_control.mission.executor']
    assert 'uav_tilt_control.mission.__init__' in graph['uav_tilt_control.controller_core']
    assert _cycles(graph) == []


def test_the_cycle_check_finds_a_cycle():
    graph = {'a': {'b'}, 'b': {'c'}, 'c': {'a'}, 'd': {'a'}, 'e': {'e'}}
    assert sorted(_cycles(graph)) == [['a', 'b', 'c'], ['e']]


def test_nothing_imports_a_command_module():
    """A command module only registers its arguments (``uav-tilt``'s list names it): what
    it does lives in library modules that others may use."""
    from uav_tilt_tools.cli import COMMAND_MODULES

    graph = _import_graph()
    for name in COMMAND_MODULES:
        assert name in graph, name
    offenders = sorted(f'{name} imports {sorted(imported & set(COMMAND_MODULES))}'
                       for name, imported in graph.items() if imported & set(COMMAND_MODULES))
    assert not offenders


def test_only_vision_training_imports_the_simulator():
    graph = _import_graph()
    importers = {name.rsplit('.', 1)[0] if name.endswith('__init__') else name
                 for name, imported in graph.items()
                 if name.startswith('uav_tilt_vision')
                 and any(m.startswith('uav_tilt_sim') for m in imported)}
    assert importers and all(name.startswith('uav_tilt_vision.training')
                             for name in importers), importers


def test_no_module_of_the_flight_controller_is_over_500_lines():
    long = {name: n for name, path in _project_modules().items()
            if name.startswith('uav_tilt_control')
            and (n := len(path.read_text().splitlines())) > 500}
    assert not long


# the mission's families of modes (DESIGN section 5): a module each
MODE_FAMILIES = {
    'flight': ('IDLE', 'TAKEOFF', 'HOVER', 'LAND', 'FAILSAFE_LAND'),
    'search': ('SEARCH',),
    'contact': ('APPROACH', 'CONTACT', 'TARGET_LOST'),
    'push': ('HOLD', 'SLIDE', 'RETREAT'),
}


def test_each_family_of_mission_modes_is_a_module_of_its_own():
    from uav_tilt_common.modes import Mode
    from uav_tilt_common.vehicle import VehicleParams
    from uav_tilt_control.mission import Mission

    behaviours = Mission(VehicleParams()).behaviours
    assert sorted(m for family in MODE_FAMILIES.values() for m in family) == \
        sorted(m.value for m in Mode)
    for family, modes in MODE_FAMILIES.items():
        for mode in modes:
            assert type(behaviours[Mode(mode)]).__module__ == \
                f'uav_tilt_control.mission.{family}', mode
