"""Config dataclasses as ROS parameters (descriptors, bad start values, changes at run
time), run_node's SIGINT bookkeeping and the parent watch, without a ROS graph."""
import dataclasses
import importlib
import os
import pathlib
import signal
import subprocess
import sys
import time

import pytest
import rclpy
import yaml
from rclpy.parameter import Parameter

from ros_graph import REPO, alive
from uav_tilt_common.config import ConfigError, fields_flat, param, unit_of
from uav_tilt_common.ros_params import STOP_SIGNALS, declare_config, note_stop_signals, \
    params_files, section_applies


@pytest.fixture
def restore_signals():
    saved = {number: signal.getsignal(number) for number in STOP_SIGNALS}
    yield
    for number, handler in saved.items():
        signal.signal(number, handler)


def test_stop_signals_are_noted_and_raise_nothing_in_a_callback(restore_signals):
    # Python's default SIGINT handler would raise KeyboardInterrupt wherever the main thread
    # is: inside a callback, which the executor logs as FATAL with its stack
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    stop = note_stop_signals()
    assert not stop.done()
    for number in STOP_SIGNALS:
        os.kill(os.getpid(), number)
        time.sleep(0.1)     # the handler runs as soon as the signal lands
    assert stop.result() == signal.SIGINT       # the first; the second changes nothing


def test_a_previous_handler_still_runs(restore_signals):
    calls = []
    signal.signal(signal.SIGINT, lambda *_: calls.append(1))
    stop = note_stop_signals()
    os.kill(os.getpid(), signal.SIGINT)
    time.sleep(0.1)
    assert stop.result() == signal.SIGINT and calls == [1]


@dataclasses.dataclass
class Demo:
    rate_hz: float = param(2.0, lo=0.5, hi=50.0, doc='how often')
    count: int = param(3, lo=1, hi=5)
    mode: str = param('a', choices=('a', 'b'))
    gains_n_m: list = param([1.0, 2.0], lo=0.0, hi=9.0, length=2)
    contact_force: float = param(5.0, lo=0.0, hi=20.0, unit='N')


@pytest.fixture
def node_of():
    """node_of(*ros_args) -> an in-process node in a context of its own."""
    made = []

    def make(*ros_args):
        context = rclpy.Context()
        rclpy.init(args=['--ros-args', *ros_args], context=context)
        node = rclpy.create_node('demo', context=context)
        made.append((node, context))
        return node
    yield make
    for node, context in made:
        node.destroy_node()
        rclpy.try_shutdown(context=context)


def test_every_field_has_a_descriptor_with_its_range_and_unit(node_of):
    node = node_of()
    cfg = declare_config(node, Demo, dynamic=('rate_hz',))
    assert cfg == Demo()
    rate = node.describe_parameter('rate_hz')
    assert rate.description == 'how often; range [0.5, 50.0] Hz'
    assert (rate.floating_point_range[0].from_value, rate.floating_point_range[0].to_value) \
        == (0.5, 50.0)
    assert not rate.read_only
    count = node.describe_parameter('count')
    assert (count.integer_range[0].from_value, count.integer_range[0].to_value) == (1, 5)
    assert count.read_only
    assert "one of 'a', 'b'" in node.describe_parameter('mode').additional_constraints
    assert node.describe_parameter('gains_n_m').description == 'range [0.0, 9.0] N/m; 2 elements'
    assert node.describe_parameter('contact_force').description == 'range [0.0, 20.0] N'


NODE_CONFIGS = ('uav_tilt_sim.plant_node:PlantNodeConfig',
                'uav_tilt_control.controller_node:ControllerNodeConfig',
                'uav_tilt_vision.vision_node:VisionNodeConfig',
                'uav_tilt_tools.graph.foxglove_bridge:FoxgloveConfig')


@pytest.mark.parametrize('path', NODE_CONFIGS)
def test_counts_are_not_given_a_physical_unit(path):
    # an integer parameter counts something (or pixels): '_n' in `confirm_n` is not newtons
    module, name = path.split(':')
    fields = fields_flat(getattr(importlib.import_module(module), name))
    units = {field: unit_of(field, meta) for field, (default, meta) in fields.items()
             if isinstance(default, int) and not isinstance(default, bool)}
    assert units and all(unit in ('', 'px') for unit in units.values()), units


@pytest.mark.parametrize('path', NODE_CONFIGS[:3] + ('uav_tilt_tools.bag.recorder_node:'
                                                     'RecorderConfig',))
def test_the_readme_names_every_parameter_of_the_nodes(path):
    module, name = path.split(':')
    text = (pathlib.Path(REPO) / 'README.md').read_text()
    listed = text.split('### Parameters', 1)[1].split('\n## ', 1)[0]
    fields = fields_flat(getattr(importlib.import_module(module), name))
    missing = {field.split('.')[0] for field in fields
               if f"`{field.split('.')[0]}{'.*' if '.' in field else ''}`" not in listed}
    assert not missing, missing


@pytest.mark.parametrize('arg, words', [
    ('rate_hz:=2', ["'rate_hz'", 'floating-point']),
    ('rate_hz:=99.0', ["'rate_hz'", '99.0', '[0.5, 50.0]']),
    ('count:=2.0', ["'count'", 'integer']),
    ('gains_n_m:=[1, 2]', ["'gains_n_m'", 'floating-point']),
    ('mode:=7', ["'mode'", 'string']),
])
def test_a_bad_start_value_is_one_config_error(node_of, arg, words):
    with pytest.raises(ConfigError) as err:
        declare_config(node_of('-p', arg), Demo)
    assert '\n' not in str(err.value)
    for word in words:
        assert word in str(err.value)


def test_a_change_at_run_time_is_honoured_or_refused_with_a_reason(node_of):
    node = node_of()
    seen = []
    cfg = declare_config(node, Demo, dynamic=('rate_hz',), on_change=seen.append)
    ok, = node.set_parameters([Parameter('rate_hz', value=10.0)])
    assert ok.successful and cfg.rate_hz == 10.0 and seen == [{'rate_hz': 10.0}]
    for value in (99.0, 3):      # out of range, wrong type: refused, nothing changes
        result, = node.set_parameters([Parameter('rate_hz', value=value)])
        assert not result.successful and result.reason
    read_only, = node.set_parameters([Parameter('count', value=4)])
    assert not read_only.successful and 'read-only' in read_only.reason
    assert cfg.rate_hz == 10.0 and cfg.count == 3 and len(seen) == 1


PARENT_CHECK = ('import os; from uav_tilt_common import parent_watch; '
                'armed = parent_watch.die_with_parent(); '
                'print(armed, os.environ.get(parent_watch.PARENT_ENV))')


@pytest.mark.parametrize('parent, code, out', [
    ('mine', 0, 'True None'),       # armed, and not passed on
    ('1', 128 + signal.SIGTERM, ''),  # not its parent: that one is gone, so it goes too
    ('', 0, 'False None'),          # not started by launch.sh: left alone
])
def test_the_parent_watch(parent, code, out):
    env = dict(os.environ, UAV_TILT_PARENT_PID=str(os.getpid()) if parent == 'mine' else parent)
    result = subprocess.run([sys.executable, '-c', PARENT_CHECK], env=env, capture_output=True,
                            text=True, timeout=60)
    assert (result.returncode, result.stdout.strip()) == (code, out)


# A node started by a launcher, whose shutdown hangs: SIGTERM (the parent-death signal) is
# ignored and the main thread sleeps on.
HUNG_NODE = ('import signal, sys, time; from uav_tilt_common import parent_watch; '
             'assert parent_watch.die_with_parent(); '
             'signal.signal(signal.SIGTERM, signal.SIG_IGN); '
             'print("armed", file=sys.stderr, flush=True); time.sleep(120)')
# The launcher: exports its pid and grace as launch.sh does, starts the node, prints its pid.
LAUNCHER = ('import os, subprocess, sys, time; '
            'os.environ["UAV_TILT_PARENT_PID"] = str(os.getpid()); '
            'os.environ["UAV_TILT_GRACE_S"] = sys.argv[1]; '
            'node = subprocess.Popen([sys.executable, "-c", sys.argv[2]], '
            'stderr=open(sys.argv[3], "w")); '
            'print(node.pid, flush=True); time.sleep(120)')


@pytest.mark.parametrize('grace_s', [0.5, 2.0])
def test_a_node_whose_shutdown_hangs_ends_itself_after_the_grace(tmp_path, grace_s):
    log_path = tmp_path / 'node.log'
    launcher = subprocess.Popen([sys.executable, '-c', LAUNCHER, str(grace_s), HUNG_NODE,
                                 str(log_path)], stdout=subprocess.PIPE, text=True)
    node = int(launcher.stdout.readline())
    try:
        deadline = time.monotonic() + 60.0
        while 'armed' not in log_path.read_text() and time.monotonic() < deadline:
            time.sleep(0.05)
        assert 'armed' in log_path.read_text(), log_path.read_text()
        launcher.kill()
        launcher.wait()
        killed = time.monotonic()
        while alive(node) and time.monotonic() - killed < grace_s + 10.0:
            time.sleep(0.02)
        took_s = time.monotonic() - killed
    finally:
        launcher.kill()
        if alive(node):
            os.kill(node, signal.SIGKILL)
    log = log_path.read_text()
    # Given its grace to shut down cleanly, and not much more: the stacks say where it hung.
    assert grace_s <= took_s < grace_s + 3.0, (took_s, log)
    assert 'parent (pid' in log and 'Timeout' in log and '(most recent call first)' in log


@pytest.mark.parametrize('namespace', ['', 'uav', 'a/b'])
@pytest.mark.parametrize('key', ['plant', '/plant', 'uav/plant', '/uav/plant', '/**/plant',
                                 '/**', '/*/plant', '/*', '/uav/*', '/**/vision', '/a/*/plant',
                                 '/a/**/plant'])
def test_a_file_section_applies_where_rclpy_applies_it(tmp_path, key, namespace):
    path = tmp_path / 'params.yaml'
    path.write_text(yaml.safe_dump({key: {'ros__parameters': {'rate_hz': 7.0}}}))
    context = rclpy.Context()
    rclpy.init(args=['--ros-args', '--params-file', str(path)], context=context)
    try:
        node = rclpy.create_node('plant', namespace=namespace, context=context,
                                 automatically_declare_parameters_from_overrides=True)
        applied = node.has_parameter('rate_hz')
        assert section_applies(key, node.get_fully_qualified_name()) == applied
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)


def test_the_parameters_files_are_those_among_the_ros_arguments():
    argv = ['node', '--params-file', 'not_ros.yaml', '--ros-args', '-p', 'a:=1',
            '--params-file', 'one.yaml', '-r', '__ns:=/uav', '--params-file', 'two.yaml', '--',
            '--params-file', 'after.yaml', '--ros-args', '--params-file', 'three.yaml']
    assert params_files(argv) == ['one.yaml', 'two.yaml', 'three.yaml']
    assert params_files(['node', '--ros-args', '--params-file']) == []
