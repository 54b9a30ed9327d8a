"""`uav-tilt fly`, `campaign` and `bench` refuse what they cannot run with one line and exit
code 2 before running anything (DESIGN section 5-7), and fly what they can: a world
without a target, and every summary.json key."""
import json
import os

import pytest
import yaml
from rosbags.rosbag2 import Reader

from uav_tilt_tools import cli
from uav_tilt_tools.bag.folder import METADATA_FILE, RECORDING_FILE
from uav_tilt_tools.report.summary import SUMMARY_KEYS
from uav_tilt_tools.runner.fly import check_world, fly
from uav_tilt_sim.scenario import load_scenario

PLAN = {'tasks': [{'touch': {'target': 'plate_a', 'near_uv_m': [-0.4, 1.5]}}]}


def refusal(capsys, argv):
    """(exit code, stdout, the lines on stderr) of `uav-tilt ARGV` run in this process."""
    try:
        code = cli.main(argv)
    except SystemExit as stop:          # argparse's own refusals
        code = stop.code
    out, err = capsys.readouterr()
    return code, out, [line for line in err.splitlines() if line.strip()]


def written(tmp_path, name, data):
    """A file of YAML ``data`` (or raw bytes) in tmp_path; its path."""
    path = tmp_path / name
    if isinstance(data, bytes):
        path.write_bytes(data)
    else:
        path.write_text(yaml.safe_dump(data) if not isinstance(data, str) else data)
    return str(path)


@pytest.mark.parametrize('scenario, words', [
    ({'seed': float('inf')}, ["'seed'", 'finite']),
    ({'texture_seed': float('-inf')}, ["'texture_seed'", 'finite']),
    ({'wall': 0}, ["'wall'", 'mapping']),
    ({'wall': []}, ["'wall'", 'mapping']),
    (b'\xff\xfe not text', ['scenario', 'utf-8']),
    # empty (a bare wall would be flown), or no mapping (its text is not repeated)
    ('', ['scenario.yaml', 'empty']),
    ('# nothing yet\n', ['scenario.yaml', 'empty']),
    ('root:x:0:0:root:/root:/bin/bash\n' * 3, ['scenario.yaml', 'a str', 'mapping']),
    ([1, 2], ['scenario.yaml', 'a list', 'mapping']),
])
def test_a_bad_scenario_file_is_one_line(tmp_path, capsys, scenario, words):
    path = written(tmp_path, 'scenario.yaml', scenario)
    code, out, err = refusal(capsys, ['fly', '--scenario', path])
    assert code == 2 and out == '' and len(err) == 1, err
    assert err[0].startswith('uav-tilt fly:') and all(w in err[0] for w in words), err
    assert 'root:' not in err[0] and '[1, 2]' not in err[0]    # the file is not repeated


def test_a_start_in_the_wall_is_one_line(tmp_path, capsys):
    """The tool reaches tool_tip_x_m = 0.45 m ahead: facing a wall 0.3 m away it is in it.
    Refused before anything flies (was: takeoff_timeout after 34 s)."""
    for name in ('default', 'plan'):
        scenario = yaml.safe_load(open(f'config/scenarios/{name}.yaml', encoding='utf-8'))
        wall_x = scenario['wall']['position_m'][0]
        scenario.update(start_xyz_m=[wall_x - 0.3, 0.0, 0.0], start_yaw_deg=0.0)
        path = written(tmp_path, f'{name}.yaml', scenario)
        argv = (['fly', '--scenario', path, '--target-source', 'ground_truth'] if name ==
                'default' else ['campaign', '--n', '1', '--scenario', path, '--plan',
                                'config/plans/inspection.yaml'])
        code, out, err = refusal(capsys, argv)
        assert code == 2 and out == '' and len(err) == 1, err
        assert err[0].startswith(f'uav-tilt {argv[0]}:') and all(
            w in err[0] for w in ("'start_xyz_m'", 'in the wall', '0.45 m ahead')), err
        # turned away, the same start is clear of the wall (the hub reaches 0.08 m)
        scenario['start_yaw_deg'] = 180.0
        written(tmp_path, f'{name}.yaml', scenario)
        check_world(load_scenario(path))


def test_fly_records_a_bag_that_the_report_reads_and_never_overwrites_it(tmp_path, capsys):
    """`fly --record DIR`: the flight as the recorder writes the node graph's run, a rosbag2
    bag that `uav-tilt report DIR` scores as fly did; a second flight into DIR is refused."""
    run = tmp_path / 'runs' / 'mine'
    argv = ['fly', '--scenario', 'config/scenarios/default.yaml', '--target-source',
            'ground_truth', '--duration', '3', '--record', str(run)]
    code, out, _ = refusal(capsys, argv)
    flown = json.loads(out)
    assert code == 1 and flown['failure']['reason'] == 'not_completed'    # 3 s: no touch
    assert sorted(os.listdir(run)) == sorted([RECORDING_FILE, METADATA_FILE])
    with Reader(run) as bag:
        ticks = {c.topic: c.msgcount for c in bag.connections}['/clock']
    assert ticks == flown['ticks']
    code, out, err = refusal(capsys, ['report', str(run)])
    reported = json.loads(out)
    assert code == 1 and reported['failure']['reason'] == 'not_completed', err
    # the mission began on the same tick in both (the recording's statuses come at 10 Hz)
    assert reported['mission_time_s'] == pytest.approx(flown['mission_time_s'], abs=1e-6)
    recorded = (run / RECORDING_FILE).read_bytes()
    code, out, err = refusal(capsys, argv)
    assert code == 2 and out == '' and len(err) == 1 and 'never overwritten' in err[0], err
    assert (run / RECORDING_FILE).read_bytes() == recorded


@pytest.mark.parametrize('plan, words', [
    ({**PLAN, 1: 'x'}, ["one key 'tasks'", "'1'"]),
    ({'tasks': PLAN['tasks'][0]}, ["'tasks'", 'must be a list']),
    (b'\xff\xfe not text', ['cannot be read', 'utf-8']),
])
def test_a_bad_plan_file_is_one_line(tmp_path, capsys, plan, words):
    path = written(tmp_path, 'plan.yaml', plan)
    for argv in (['fly', '--scenario', 'config/scenarios/plan.yaml', '--plan', path],
                 ['campaign', '--n', '1', '--scenario', 'config/scenarios/plan.yaml',
                  '--plan', path]):
        code, out, err = refusal(capsys, argv)
        assert code == 2 and out == '' and len(err) == 1, err
        assert all(w in err[0] for w in words), err


@pytest.mark.parametrize('args, words', [
    # a push the touch would not feel, or one over the force limit, as a plan's is refused
    (['--set', 'contact_force=0'], ["'contact_force' = 0.0", '(1, 9.6)']),
    (['--set', 'contact_force=18'], ["'contact_force' = 18.0", '(1, 9.6)']),
    # more than the vehicle pushes (1.6 kg at the impedance law's 6 m/s^2), under the limit
    (['--set', 'contact_force=12'], ["'contact_force' = 12.0", 'accel_limit_mps2']),
    (['--set', 'contact_force=[1'], ['--set', 'contact_force=[1']),
    (['--set', 'target_source=vision'], ['--target-source']),
    # the plan is --plan's: a second one in --set was left unflown without a word
    (['--plan', 'config/plans/inspection.yaml', '--set', 'plan_file=other.yaml'], ['--plan']),
    (['--plan', 'config/plans/inspection.yaml', '--hint', '0', '1'], ['--hint', 'near_uv_m']),
    # a hint is good to 0.3 m: one farther off the 5 m x 3.5 m wall is a mistake
    (['--hint', '100', '100'], ["'site.target_hint_uv_m'", 'off the wall']),
    (['--hint', '2.85', '1.0'], ["'site.target_hint_uv_m'", 'off the wall']),
])
def test_a_bad_controller_setting_is_one_line(capsys, args, words):
    code, out, err = refusal(capsys, ['fly', '--scenario', 'config/scenarios/default.yaml',
                                      '--target-source', 'ground_truth', *args])
    assert code == 2 and out == '' and len(err) == 1, err
    assert err[0].startswith('uav-tilt fly:') and all(w in err[0] for w in words), err


@pytest.mark.parametrize('argv, words', [
    (['fly', '--scenario', 'config/scenarios/default.yaml', '--seed', '-1'], ['--seed']),
    (['fly', '--scenario', 'config/scenarios/default.yaml', '--seed', str(2**31)], ['--seed']),
    (['fly', '--scenario', 'config/scenarios/default.yaml', '--duration', '0'],
     ['--duration']),
    (['fly', '--scenario', 'config/scenarios/default.yaml', '--duration', 'nan'],
     ['--duration']),
    (['campaign', '--n', '0'], ['--n']),
    (['campaign', '--n', '-1'], ['--n']),
    (['campaign', '--workers', '-2'], ['--workers']),
    (['campaign', '--seed', '-1'], ['--seed']),
    (['campaign', '--duration', 'inf'], ['--duration']),
    (['bench', 'sim', '--seconds', 'nan'], ['--seconds']),
    (['bench', 'control', '--seconds', '0'], ['--seconds']),
    # an empty plan would fly the one-touch inspection instead
    (['fly', '--scenario', 'config/scenarios/plan.yaml', '--plan', ''], ['--plan']),
    (['campaign', '--scenario', 'config/scenarios/plan.yaml', '--plan', ' '], ['--plan']),
])
def test_a_bad_option_value_is_refused_by_the_parser(capsys, argv, words):
    code, out, err = refusal(capsys, argv)
    assert code == 2 and out == ''
    assert all(w in err[-1] for w in words) and 'error' in err[-1], err


@pytest.mark.parametrize('args', [
    ['--scenario', 'config/scenarios/plan.yaml', '--plan', 'config/plans/inspection.yaml'],
    ['--scenario', 'config/scenarios/default.yaml', '--hint', '1.5', '1.5'],
])
def test_a_site_value_set_by_the_user_wins_over_the_scenarios(capsys, args):
    """As launch.sh's --param: on a wall the user says is 1 m wide, a plan's slide at
    u = 1.3 m and a hint at u = 1.5 m are off it."""
    code, out, err = refusal(capsys, ['fly', '--target-source', 'ground_truth', '--duration',
                                      '0.5', *args, '--set', 'site.wall_width_m=1.0'])
    assert code == 2 and out == '' and len(err) == 1, err
    assert 'off the wall' in err[0] and (
        '[-0.5, 0.5]' in err[0] or 'site.wall_width_m 1.0' in err[0]), err


def test_a_hint_just_off_the_wall_is_within_its_error(capsys):
    # a target at the wall's edge, its hint 0.25 m beyond it: accepted (and flown briefly)
    code, out, err = refusal(capsys, ['fly', '--scenario', 'config/scenarios/default.yaml',
                                      '--target-source', 'ground_truth', '--hint', '2.75',
                                      '1.5', '--duration', '0.5'])
    assert code == 1 and '"not_completed"' in out, err


def test_a_world_without_a_target_is_flown_and_reported(tmp_path):
    path = written(tmp_path, 'no_target.yaml',
                   {'objects': [{'cls': 'gauge', 'u_m': 0.0, 'v_m': 1.5}]})
    result = fly(load_scenario(path), 'ground_truth', duration_s=3.0)
    assert set(SUMMARY_KEYS) <= result.keys()
    assert result['poi_error_m'] is None and result['max_force_n'] is not None
    assert result['failure']['reason'] == 'not_completed'
