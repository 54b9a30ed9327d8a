"""Errors that suggest: an unknown key or name anywhere (a config's dotted or nested key, a
scenario file, a plan file, `fly --set`, the Gymnasium options, a topic) is answered with
the close match, when there is one."""
import os

import pytest
import yaml

from ros_graph import REPO
from uav_tilt_common.config import ConfigError, from_dict, load_yaml
from uav_tilt_control.controller_core import ControllerConfig
from uav_tilt_sim.scenario import Scenario, load_scenario
from uav_tilt_tools import cli
from uav_tilt_tools.graph.topic_tool import not_appeared, rate_lines

SCENARIO = os.path.join(REPO, 'config', 'scenarios', 'default.yaml')
PLAN_SCENARIO = os.path.join(REPO, 'config', 'scenarios', 'plan.yaml')


def refusal(cls, data):
    with pytest.raises(ConfigError) as err:
        from_dict(cls, data)
    return str(err.value)


@pytest.mark.parametrize('data, line', [
    ({'contact_forc': 4.0},
     "unknown parameter 'contact_forc' (did you mean 'contact_force'?)"),
    # dotted, the misspelt part first, last, or in between
    ({'mision.contact.hold_time_s': 3.0},
     "unknown parameter 'mision.contact.hold_time_s' (did you mean "
     "'mission.contact.hold_time_s'?)"),
    ({'mission.contact.hold_tme_s': 3.0},
     "unknown parameter 'mission.contact.hold_tme_s' (did you mean "
     "'mission.contact.hold_time_s'?)"),
    ({'mission.contatc.hold_time_s': 3.0},
     "unknown parameter 'mission.contatc.hold_time_s' (did you mean "
     "'mission.contact.hold_time_s'?)"),
    # nested as a YAML file has it
    ({'mission': {'contact': {'hold_tme_s': 3.0}}},
     "unknown parameter 'mission.contact.hold_tme_s' (did you mean "
     "'mission.contact.hold_time_s'?)"),
    # a group misspelt with several keys under it: the group
    ({'mision': {'contact': {}, 'flight': {}}},
     "unknown parameter 'mision' (did you mean 'mission'?)"),
    # a leaf in the wrong group, or without its group: the one place it has
    ({'hold_time_s': 3.0},
     "unknown parameter 'hold_time_s' (did you mean 'mission.contact.hold_time_s'?)"),
    # nothing close: no guess
    ({'zz_bogus': 1}, "unknown parameter 'zz_bogus'"),
])
def test_an_unknown_config_key_gets_the_close_match(data, line):
    assert refusal(ControllerConfig, data) == line


def test_a_moved_parameter_still_says_where_it_went():
    assert refusal(ControllerConfig, {'mission.standoff_m': 0.5}) == (
        "parameter 'mission.standoff_m' has moved: it is now 'mission.contact.standoff_m'")


@pytest.mark.parametrize('text, words', [
    ('wall:\n  stifness_n_per_m: 5000.0\n',
     "unknown parameter 'wall.stifness_n_per_m' (did you mean 'wall.stiffness_n_per_m'?)"),
    ('objects:\n  - {cls: bolt_plate, u_m: 0.0, v_m: 1.5, tagret: true}\n',
     "unknown parameter 'objects[0].tagret' (did you mean 'objects[0].target'?)"),
    ('texture_sed: 3\n', "(did you mean 'texture_seed'?)"),
    ('wind:\n  gust_std: 0.5\n', "(did you mean 'wind.gust_std_m_s'?)"),
])
def test_a_scenario_file_key_gets_the_close_match(tmp_path, text, words):
    path = tmp_path / 'world.yaml'
    path.write_text(text)
    with pytest.raises(ConfigError) as err:
        load_scenario(str(path))
    assert words in str(err.value)
    with pytest.raises(ConfigError, match='did you mean'):
        load_yaml(Scenario, path)


def fly(capsys, *args):
    """`uav-tilt fly ...` in this process: (exit code, stderr)."""
    code = cli.main(['fly', *args])
    return code, capsys.readouterr().err


@pytest.mark.parametrize('task, words', [
    ({'touch': {'target': 'plate_a', 'near_uv_m': [-0.4, 1.5], 'force_n': 5.0,
                'hold_sec': 3.0}},
     "unknown parameter 'tasks[0].touch.hold_sec' (did you mean 'tasks[0].touch.hold_s'?)"),
    ({'slide': {'from_uv_m': [1.3, 1.0], 'to_uv_m': [1.3, 2.0], 'sped_m_s': 0.1}},
     "(did you mean 'tasks[0].slide.speed_m_s'?)"),
    ({'touh': {'target': 'plate_a', 'near_uv_m': [-0.4, 1.5]}}, "(did you mean 'touch'?)"),
])
def test_a_plan_file_key_gets_the_close_match(tmp_path, capsys, task, words):
    plan = tmp_path / 'plan.yaml'
    plan.write_text(yaml.safe_dump({'tasks': [task]}))
    code, err = fly(capsys, '--scenario', PLAN_SCENARIO, '--plan', str(plan))
    assert code == 2 and words in err, err


@pytest.mark.parametrize('pair, words', [
    ('contact_forc=4.0', "unknown parameter 'contact_forc' (did you mean 'contact_force'?)"),
    ('mission.contact.hold_tme_s=3', "(did you mean 'mission.contact.hold_time_s'?)"),
])
def test_fly_set_gets_the_close_match(capsys, pair, words):
    code, err = fly(capsys, '--scenario', SCENARIO, '--set', pair)
    assert code == 2 and err.startswith('uav-tilt fly: ') and words in err, err


def test_a_gym_option_gets_the_close_match():
    gym_env = pytest.importorskip('uav_tilt_tools.gym.env')
    with pytest.raises(ConfigError, match=r"unknown parameter 'action_rate_h' "
                                          r"\(did you mean 'action_rate_hz'\?\)"):
        gym_env.ContactInspectionEnv(action_rate_h=30.0)
    with pytest.raises(ConfigError, match=r"unknown parameter 'controller.contact_forc' "
                                          r"\(did you mean 'controller.contact_force'\?\)"):
        gym_env.ContactInspectionEnv(controller={'contact_forc': 4.0})


def test_a_topic_that_did_not_appear_gets_the_graph_s_nearest_name():
    graph = ['/clock', '/uav/controller/status', '/uav/plant/status', '/uav/imu']
    assert not_appeared('/uav/controler/status', 3.0, graph) == (
        'topic /uav/controler/status did not appear within 3.0 s '
        '(did you mean /uav/controller/status?)')
    assert not_appeared('/uav/no/such/thing', 3.0, graph) == (
        'topic /uav/no/such/thing did not appear within 3.0 s')


def test_topic_hz_says_which_clock_it_measures():
    # 300 Hz of sim time heard at 0.7 of real time: 210 Hz on the wall clock
    stamps = [i / 300 for i in range(301)]
    arrivals = [100.0 + t / 0.7 for t in stamps]
    lines = rate_lines(arrivals, stamps, sim_clock=True)
    assert lines[0] == 'average rate: 210.000 Hz (wall clock)'
    assert lines[2].startswith('rate per second of sim time: 300.000 Hz')
    assert 'the header stamps: 300.000 Hz' in rate_lines(arrivals, stamps, False)[2]
    # no stamps (a message without a header): the wall clock's rate, and why no other
    lines = rate_lines(arrivals, [], sim_clock=True)
    assert 'wall clock' in lines[0] and lines[2].startswith('no rate per second of sim time')
    assert rate_lines(arrivals[:1], stamps[:1], True) is None
