"""Each way a start parameter can be wrong stops the node with one line naming it, exit code
2 and no traceback, before it says it is up: a value of the wrong type (rclpy's own
exception otherwise), out of range, not a choice, a file that is not there, a name the node
does not have, or a parameters file that is no YAML or whose section misses the node."""
import pathlib
import subprocess
import sys

import pytest
import yaml

from ros_graph import REPO


@pytest.mark.parametrize('module, value, words', [
    ('uav_tilt_sim.plant_node', 'rtf:=1', ["'rtf'", 'floating-point', '1.0']),
    ('uav_tilt_sim.plant_node', 'scenario_file:=/nonexistent/windy.yaml',
     ["'scenario_file'", '/nonexistent/windy.yaml', 'no such file']),
    ('uav_tilt_sim.plant_node', 'mode:=fast', ["'mode'", "'fast'", "'lockstep'"]),
    ('uav_tilt_control.controller_node', 'contact_force:=4', ["'contact_force'", '4']),
    ('uav_tilt_control.controller_node', 'mission.contact.hold_time_s:=-1.0',
     ["'mission.contact.hold_time_s'", '-1.0', '[0.0, 600.0]']),
    ('uav_tilt_vision.vision_node', 'detect_every:=2.5', ["'detect_every'", 'integer']),
    ('uav_tilt_tools.bag.recorder_node', 'flush_period_s:=often',
     ["'flush_period_s'", 'often']),
    # files the node would write only at exit, or cannot make at all
    ('uav_tilt_sim.plant_node', 'summary_file:=/nonexistent/dir/timing.json',
     ["'summary_file'", 'No such file']),
    ('uav_tilt_tools.bag.recorder_node', 'output:=/proc/run.mcap',
     ["'output'", '/proc/run.mcap']),
    ('uav_tilt_control.controller_node', 'contact_force:=0.5',
     ["'contact_force'", '0.5', '(1, 9.6)']),
    # a misspelt name would leave its parameter at the default without a word
    ('uav_tilt_vision.vision_node', 'detect_evry:=3',
     ["unknown parameter 'detect_evry'", "'detect_every'"]),
    ('uav_tilt_control.controller_node', 'mission.hold_time:=3.0',
     ["unknown parameter 'mission.hold_time'", "'mission.contact.hold_time_s'"]),
    # a parameter of the mission's old flat group: its new place
    ('uav_tilt_control.controller_node', 'mission.hold_time_s:=3.0',
     ["'mission.hold_time_s' has moved", "'mission.contact.hold_time_s'"]),
    ('uav_tilt_tools.graph.foxglove_bridge', 'prot:=8765', ["unknown parameter 'prot'"]),
])
def test_a_bad_parameter_is_one_line_and_exit_code_2(tmp_path, module, value, words):
    fatal_line(tmp_path, module, '-p', value, words=words)


def fatal_line(tmp_path, module, *ros_args, words):
    """Run the node in the graph's namespace; it must stop with exit code 2 and one FATAL
    line holding ``words``, before it says it is up."""
    result = subprocess.run([sys.executable, '-m', module, '--ros-args', '-r', '__ns:=/uav',
                             *ros_args], cwd=tmp_path, capture_output=True, text=True,
                            timeout=120)
    output = result.stdout + result.stderr
    assert result.returncode == 2, output
    assert 'Traceback' not in output and ' up:' not in output, output
    fatal = [line for line in output.splitlines() if 'FATAL' in line]
    assert len(fatal) == 1, output
    for word in words:
        assert word in fatal[0], fatal[0]


NODES = [('uav_tilt_sim.plant_node', 'plant'), ('uav_tilt_control.controller_node', 'controller'),
         ('uav_tilt_vision.vision_node', 'vision')]


@pytest.mark.parametrize('module, name', NODES)
def test_the_shipped_parameters_file_reaches_the_node_in_its_namespace(tmp_path, module, name):
    # the shipped file with one misspelt name: refused only if the file reaches the node
    sections = yaml.safe_load((pathlib.Path(REPO) / 'config' / f'{name}.yaml').read_text())
    (section,) = sections.values()
    section['ros__parameters']['zz_misspelt'] = 1.0
    path = tmp_path / f'{name}.yaml'
    path.write_text(yaml.safe_dump(sections))
    fatal_line(tmp_path, module, '--params-file', str(path),
               words=["unknown parameter 'zz_misspelt'"])


@pytest.mark.parametrize('module, name', NODES)
def test_a_parameters_file_keyed_without_the_namespace_is_refused(tmp_path, module, name):
    # rcl gives section 'plant' to a node /plant only: none of it would reach /uav/plant
    path = tmp_path / 'params.yaml'
    path.write_text(yaml.safe_dump({'other': {'ros__parameters': {'x': 1}},
                                    name: {'ros__parameters': {}}}))
    fatal_line(tmp_path, module, '--params-file', str(path),
               words=[str(path), f"'{name}'", f"'/uav/{name}'", f"'/**/{name}'"])


@pytest.mark.parametrize('text, words', [
    (None, ["Couldn't parse params file", 'missing.yaml']),
    ('/**/plant:\n  ros__parameters:\n    rtf: [1.0\n', ["Couldn't parse params file"]),
])
def test_a_parameters_file_that_is_no_yaml_is_one_line(tmp_path, text, words):
    path = tmp_path / 'missing.yaml'
    if text is not None:
        path.write_text(text)
    fatal_line(tmp_path, 'uav_tilt_sim.plant_node', '--params-file', str(path), words=words)


def test_a_file_for_the_whole_graph_is_taken_by_each_node(tmp_path):
    # sections for other nodes beside the node's own: the usual one-file launch
    path = tmp_path / 'graph.yaml'
    path.write_text(yaml.safe_dump({'/**/controller': {'ros__parameters': {'autostart': 'no'}},
                                    '/uav/plant': {'ros__parameters': {'zz_misspelt': 1.0}}}))
    fatal_line(tmp_path, 'uav_tilt_sim.plant_node', '--params-file', str(path),
               words=["unknown parameter 'zz_misspelt'"])


@pytest.mark.parametrize('output, held', [
    ('runs/gt', 'recording.mcap'), ('runs/gt/recording.mcap', 'recording.mcap'),
    # another tool's bag in the folder (`ros2 bag record -o runs/gt`): neither its index nor
    # its data is mixed with a new recording
    ('runs/gt', 'metadata.yaml'), ('runs/gt', 'gt_0.mcap')])
def test_a_recording_is_never_overwritten(tmp_path, output, held):
    earlier = tmp_path / 'runs' / 'gt' / held
    earlier.parent.mkdir(parents=True)
    earlier.write_bytes(b'an earlier run')
    fatal_line(tmp_path, 'uav_tilt_tools.bag.recorder_node', '-p', f'output:={output}',
               words=["'output'", str(earlier.relative_to(tmp_path)), 'never overwritten'])
    assert earlier.read_bytes() == b'an earlier run'
