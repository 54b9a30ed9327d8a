"""Slides on curved surfaces, in process (`uav-tilt fly --plan`, the controller's site from
the scenario): on worlds drawn fresh as a structure campaign draws them (wind, noise,
mismatch, stiffness, friction), a slide on a pipe named by its id follows its path with the
push along the surface's normal there: force RMS error <= 0.3 N, the true tool tip within
1 cm of the path along the surface, contact never lost. Up a vertical pipe the tip rides
on the pipe's crest, at the drawn friction. Round a horizontal pipe's side the normal
pitches through 50 degrees over the path, which holds at frictions up to 0.3 (beyond, the
tip sticks and slips: docs/SLIDING.md). Slides across (round a tank at constant height,
along a horizontal pipe) need a yaw moment the vehicle does not have: docs/SLIDING.md."""
import dataclasses
import math

import numpy as np
import pytest
import yaml

from uav_tilt_control.mission import MissionConfig
from uav_tilt_sim.randomise_structures import structure_draw
from uav_tilt_tools.runner.fly import check_plan, fly

pytestmark = pytest.mark.slow

# the plan's slide: the task's push and speed, the bar (the shipped plan's slide bar)
FORCE_N, SPEED_M_S = 5.0, 0.1
FORCE_RMS_BAR_N, PATH_BAR_M = 0.3, 0.01
# the target plate sits on the path's surface: the line keeps this far from its middle
CLEAR_OF_TARGET_M = 0.3
# the frictions at which a slide whose normal turns holds (docs/SLIDING.md)
TURNING_FRICTION = (0.05, 0.3)


def fresh_seed():
    return int(np.random.SeedSequence().generate_state(1)[0] % 2**31)


def _slide_plan(kind, scenario):
    """The slide of ``kind`` on the world's pipe, clear of its target plate."""
    (pipe,) = scenario.structures
    (target,) = [o for o in scenario.objects if o.target]
    r = pipe.radius_m
    if kind == 'pipe':
        # round the side at the target's height, beside the target (towards the middle)
        axial = target.axial_m - math.copysign(CLEAR_OF_TARGET_M, target.axial_m)
        ends = [[r * math.radians(-25.0), axial], [r * math.radians(25.0), axial]]
    else:
        # up the crest that faces the start, from above the target
        u = r * math.radians(target.angle_deg)
        ends = [[u, target.axial_m + CLEAR_OF_TARGET_M],
                [u, target.axial_m + CLEAR_OF_TARGET_M + 0.6]]
    return {'tasks': [{'slide': {'on': pipe.id, 'from_uv_m': ends[0], 'to_uv_m': ends[1],
                                 'speed_m_s': SPEED_M_S, 'force_n': FORCE_N}}]}


@pytest.mark.parametrize('kind', ['pipe', 'vertical_pipe'])
def test_a_slide_on_a_pipe_follows_its_path_pushing_along_its_normal(tmp_path, kind):
    seed = fresh_seed()
    scenario, _, _ = structure_draw(seed, kind)
    if kind == 'pipe':
        friction = float(np.random.default_rng(seed).uniform(*TURNING_FRICTION))
        scenario = dataclasses.replace(scenario, structures=[
            dataclasses.replace(scenario.structures[0], friction=friction)])
    plan = tmp_path / 'slide.yaml'
    plan.write_text(yaml.safe_dump(_slide_plan(kind, scenario)))
    result = fly(scenario, 'ground_truth', check_plan(scenario, str(plan)))
    (slide,) = result['tasks']
    details = dict(seed=seed, radius_m=scenario.structures[0].radius_m,
                   friction=scenario.structures[0].friction,
                   **{k: slide[k] for k in ('reason', 'force_rms_error_n', 'path_max_error_m',
                                            'length_m', 'line_length_m')})
    print(kind, details)
    assert slide['success'] and slide['contact_lost'] == 0, details
    assert slide['force_rms_error_n'] <= FORCE_RMS_BAR_N, details
    assert slide['path_max_error_m'] <= PATH_BAR_M, details
    # the whole path, as the mission measures it along its points (to its own tolerance)
    tolerance_m = MissionConfig().slide.path_tolerance_m
    assert slide['length_m'] >= slide['line_length_m'] - tolerance_m, details
