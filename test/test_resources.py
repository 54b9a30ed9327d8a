"""Package files are found from a source checkout (the installed case: test_colcon.py), and a
file that is not there is one clear line."""
import pytest

from ros_graph import REPO
from uav_tilt_common import resources
from uav_tilt_common.config import ConfigError, from_dict
from uav_tilt_control.controller_core import ControllerConfig, plan_of
from uav_tilt_sim.scenario import load_scenario
from uav_tilt_tools.runner.site_params import site_overrides


def test_from_the_source_tree_the_files_are_the_checkout(tmp_path, monkeypatch):
    assert str(resources.source_root()) == REPO and str(resources.share_dir()) == REPO
    monkeypatch.chdir(tmp_path)     # a relative path not in the working directory
    assert resources.resolve('config/scenarios/windy.yaml', 'scenario_file') == \
        resources.share_dir() / 'config' / 'scenarios' / 'windy.yaml'
    mine = tmp_path / 'config' / 'scenarios' / 'windy.yaml'
    mine.parent.mkdir(parents=True)
    mine.write_text('seed: 9\n')
    # ... unless it is there: the working directory comes first.
    assert resources.resolve('config/scenarios/windy.yaml', 'scenario_file') == mine
    assert load_scenario('config/scenarios/windy.yaml').seed == 9


@pytest.mark.parametrize('path', ['missing.yaml', '/nonexistent/missing.yaml'])
def test_a_missing_scenario_is_one_line_naming_the_parameter(path):
    with pytest.raises(ConfigError) as err:
        load_scenario(path)
    message = str(err.value)
    assert '\n' not in message and "'scenario_file'" in message and 'no such file' in message
    # where it was looked for, each place once (from the checkout, the working directory is
    # the share folder)
    looked = message.split('no such file (')[1].rstrip(')').split(' or ')
    assert len(looked) == len(set(looked)) >= 1


def test_a_folder_given_for_a_file_is_named_so(tmp_path):
    with pytest.raises(ConfigError, match=f'{tmp_path} is a folder, not a file'):
        load_scenario(str(tmp_path))


def test_an_unreadable_scenario_is_one_line(tmp_path):
    bad = tmp_path / 'bad.yaml'
    bad.write_text('wall: [unclosed\n')
    with pytest.raises(ConfigError) as err:
        load_scenario(str(bad))
    assert '\n' not in str(err.value) and "'scenario_file'" in str(err.value)


def test_a_plan_is_found_like_a_scenario(tmp_path, monkeypatch):
    # `-p plan_file:=config/plans/inspection.yaml` from any folder, as `ros2 run` users do
    monkeypatch.chdir(tmp_path)
    site = site_overrides(load_scenario('config/scenarios/plan.yaml'))
    cfg = from_dict(ControllerConfig, {**site, 'autostart': 'plan',
                                       'plan_file': 'config/plans/inspection.yaml'})
    assert [task.kind for task in plan_of(cfg)] == ['touch', 'touch', 'slide']
    with pytest.raises(ConfigError) as err:
        plan_of(from_dict(ControllerConfig, {**site, 'autostart': 'plan',
                                             'plan_file': 'missing.yaml'}))
    assert "'plan_file'" in str(err.value) and 'no such file' in str(err.value)
