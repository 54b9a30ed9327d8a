"""A scenario is checked for what the mission needs, before anything flies (DESIGN section 5):
an inspection without a designated target, a plan naming a target id the scenario lacks,
and two objects that overlap on the wall are each one ConfigError line, exit code 2; on
fresh random worlds."""
import dataclasses
import string
import subprocess

import numpy as np
import pytest
import yaml

from uav_tilt_common.config import ConfigError
from uav_tilt_sim.randomise import random_draw
from uav_tilt_sim.scenario import ObjectConfig, check_scenario, check_target, load_scenario
from uav_tilt_sim.textures import OBJECT_SIZE_M
from uav_tilt_tools import cli
from uav_tilt_tools.gym.env import ContactInspectionEnv
from uav_tilt_tools.runner import site_params

PLAN_SCENARIO = 'config/scenarios/plan.yaml'


def refusal(capsys, argv):
    """(exit code, stdout, the lines on stderr) of `uav-tilt ARGV` run in this process."""
    code = cli.main(argv)
    out, err = capsys.readouterr()
    return code, out, [line for line in err.splitlines() if line.strip()]


def fresh_world(rng):
    """A random world of the campaign's, on a fresh seed."""
    return random_draw(int(rng.integers(0, 2**31 - 1)))[0]


def written(tmp_path, name, scenario):
    """``scenario`` as a YAML file in tmp_path; its path."""
    path = tmp_path / name
    path.write_text(yaml.safe_dump(dataclasses.asdict(scenario)))
    return str(path)


def test_an_inspection_without_a_target_is_refused_before_it_flies(tmp_path, capsys):
    """Was: flown, with vision "success": true and nothing scored; with ground truth 73 s to
    target_not_found. The plant alone still builds the world (a hover needs no target)."""
    rng = np.random.default_rng()
    scenario = fresh_world(rng)
    check_target(scenario)
    untargeted = dataclasses.replace(scenario, objects=[
        dataclasses.replace(o, target=False) for o in scenario.objects])
    path = written(tmp_path, 'untargeted.yaml', untargeted)
    for source in ('vision', 'ground_truth'):
        code, out, err = refusal(capsys, ['fly', '--scenario', path, '--target-source', source])
        assert code == 2 and out == '' and len(err) == 1, err
        assert err[0].startswith('uav-tilt fly:') and all(
            w in err[0] for w in ("'objects'", 'no target', "'target: true'")), err
    # launch.sh reads it before anything starts; without --mission the plant may hover in it
    assert site_params.main([path, 'inspect']) == 2
    assert 'no target' in capsys.readouterr().err
    assert site_params.main([path, '']) == 0
    capsys.readouterr()
    launched = subprocess.run(['scripts/launch.sh', '--scenario', path, '--mission', 'inspect'],
                              capture_output=True, text=True, timeout=120)
    assert launched.returncode == 2, launched.stderr
    assert 'no target' in launched.stderr
    with pytest.raises(ConfigError, match="'objects' designates no target"):
        ContactInspectionEnv(scenario=path)
    # the same world with its target is taken
    code, out, err = refusal(capsys, ['fly', '--scenario', written(tmp_path, 'ok.yaml', scenario),
                                      '--target-source', 'ground_truth', '--duration', '0.1'])
    assert code == 1 and '"not_completed"' in out, err


def test_a_plan_naming_an_id_the_scenario_lacks_is_refused(tmp_path, capsys):
    rng = np.random.default_rng()
    ids = [o.id for o in load_scenario(PLAN_SCENARIO).objects if o.target]
    letters = list(string.ascii_lowercase)
    missing = ''.join(rng.choice(letters, size=int(rng.integers(3, 9))))
    assert missing not in ids
    plan = tmp_path / 'plan.yaml'
    plan.write_text(yaml.safe_dump({'tasks': [
        {'touch': {'target': str(rng.choice(ids)), 'near_uv_m': [-0.4, 1.5]}},
        {'touch': {'target': missing, 'near_uv_m': [0.45, 1.65]}}]}))
    surveyed = f"site.target_ids=[{', '.join([*ids, missing])}]"
    for argv in (['fly', '--scenario', PLAN_SCENARIO, '--plan', str(plan)],
                 # a site that the user says has the id: the scenario still lacks it
                 ['fly', '--scenario', PLAN_SCENARIO, '--plan', str(plan), '--set', surveyed],
                 ['campaign', '--n', '1', '--scenario', PLAN_SCENARIO, '--plan', str(plan)]):
        code, out, err = refusal(capsys, argv)
        assert code == 2 and out == '' and len(err) == 1, (argv, err)
        assert all(w in err[0] for w in ('tasks[1] (touch)', f"'target' = '{missing}'")), err


def test_overlapping_objects_are_refused_and_objects_apart_are_taken(tmp_path, capsys):
    """Each class is a 0.2 m square panel: a second object whose centre lies closer than that
    to another's along both of the wall's axes overlaps it (a gauge on the target's spot was
    accepted); one that far along either axis only touches it."""
    rng = np.random.default_rng()
    taken = 0
    for _ in range(20):
        scenario = fresh_world(rng)
        k = int(rng.integers(len(scenario.objects)))
        base = scenario.objects[k]
        cls = str(rng.choice(['bolt_plate', 'gauge', 'hazard_sign']))
        du, dv = (float(x) for x in rng.uniform(-0.99, 0.99, 2) * OBJECT_SIZE_M)
        du = float(-abs(du) * np.sign(base.u_m))    # towards the middle: on the wall
        over = ObjectConfig(cls=cls, u_m=base.u_m + du, v_m=base.v_m + dv)
        bad = dataclasses.replace(scenario, objects=[*scenario.objects, over])
        j = len(scenario.objects)
        with pytest.raises(ConfigError, match=rf"'objects\[{j}\]' .* overlaps 'objects\["):
            check_scenario(bad)
        # beside it along u or v, a hair more than the side away: taken, if clear of the rest
        axis = int(rng.integers(2))
        step = float(rng.choice([-1.0, 1.0])) * OBJECT_SIZE_M * 1.001
        beside = ObjectConfig(cls=cls, u_m=base.u_m + (step if axis == 0 else du),
                              v_m=base.v_m + (step if axis == 1 else dv))
        others = [o for o in scenario.objects if o is not base]
        wall = scenario.wall
        on_wall = abs(beside.u_m) <= wall.width_m / 2 and 0.0 <= beside.v_m <= wall.height_m
        if on_wall and all(max(abs(o.u_m - beside.u_m), abs(o.v_m - beside.v_m))
                           >= OBJECT_SIZE_M for o in others):
            check_scenario(dataclasses.replace(scenario, objects=[*scenario.objects, beside]))
            taken += 1
    assert taken >= 5
    code, out, err = refusal(capsys, ['fly', '--scenario', written(tmp_path, 'over.yaml', bad),
                                      '--target-source', 'ground_truth'])
    assert code == 2 and out == '' and len(err) == 1 and 'overlaps' in err[0], err
