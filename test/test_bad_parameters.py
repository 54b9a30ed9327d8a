"""Each way a start parameter can be wrong stops the node with one line naming it, exit code
2 and no traceback: a value of the wrong type (rclpy's own exception otherwise), out of
range, not a choice, a file that is not there, or a name the node does not have."""
import subprocess
import sys

import pytest


@pytest.mark.parametrize('module, value, words', [
    ('uav_tilt_sim.plant_node', 'rtf:=1', ["'rtf'", 'floating-point', '1.0']),
    ('uav_tilt_sim.plant_node', 'scenario_file:=/nonexistent/windy.yaml',
     ["'scenario_file'", '/nonexistent/windy.yaml', 'no such file']),
    ('uav_tilt_sim.plant_node', 'mode:=fast', ["'mode'", "'fast'", "'lockstep'"]),
    ('uav_tilt_control.controller_node', 'contact_force:=4', ["'contact_force'", '4']),
    ('uav_tilt_control.controller_node', 'mission.hold_time_s:=-1.0',
     ["'mission.hold_time_s'", '-1.0', '[0.0, 600.0]']),
    ('uav_tilt_vision.vision_node', 'detect_every:=2.5', ["'detect_every'", 'integer']),
    ('uav_tilt_tools.recorder_node', 'flush_period_s:=often', ["'flush_period_s'", 'often']),
    # files the node would write only at exit, or cannot make at all
    ('uav_tilt_sim.plant_node', 'summary_file:=/nonexistent/dir/timing.json',
     ["'summary_file'", 'No such file']),
    ('uav_tilt_tools.recorder_node', 'output:=/proc/run.mcap', ["'output'", '/proc/run.mcap']),
    ('uav_tilt_control.controller_node', 'contact_force:=0.5',
     ["'contact_force'", '0.5', '(1.0, 15.0)']),
    # a misspelt name would leave its parameter at the default without a word
    ('uav_tilt_vision.vision_node', 'detect_evry:=3',
     ["unknown parameter 'detect_evry'", "'detect_every'"]),
    ('uav_tilt_control.controller_node', 'mission.hold_time:=3.0',
     ["unknown parameter 'mission.hold_time'", "'mission.hold_time_s'"]),
    ('uav_tilt_tools.foxglove_bridge', 'prot:=8765', ["unknown parameter 'prot'"]),
])
def test_a_bad_parameter_is_one_line_and_exit_code_2(tmp_path, module, value, words):
    result = subprocess.run([sys.executable, '-m', module, '--ros-args', '-r', '__ns:=/uav',
                             '-p', value], cwd=tmp_path, capture_output=True, text=True,
                            timeout=120)
    output = result.stdout + result.stderr
    assert result.returncode == 2, output
    assert 'Traceback' not in output
    fatal = [line for line in output.splitlines() if 'FATAL' in line]
    assert len(fatal) == 1, output
    for word in words:
        assert word in fatal[0], fatal[0]
