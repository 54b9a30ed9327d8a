"""The inspection on structures (DESIGN section 5), in process with the ground truth of the
target: each kind of structure, drawn fresh with a campaign's wind, noise, mismatch,
stiffness and friction, inspected to the bar with the tool square on the surface; a touch
the tool cannot sit square on refused before flight."""
import math

import numpy as np
import pytest

from structure_worlds import kind_world, write_world
from uav_tilt_common.config import ConfigError
from uav_tilt_control.mission import MissionConfig
from uav_tilt_sim.randomise import random_draw
from uav_tilt_sim.scenario import load_scenario
from uav_tilt_tools.metrics.tasks import FORCE_MEAN_BAR_N, FORCE_RMS_BAR_N, POI_BAR_M
from uav_tilt_tools.runner.fly import check_mission, fly

pytestmark = pytest.mark.slow

# An ultrasonic thickness probe reads only when it sits square: within this of the normal
# (an airborne ultrasound inspection system reports 2.7 degrees).
SQUARE_DEG = 2.0
KINDS = ('pipe', 'tank', 'corner', 'pillar', 'mesh', 'wall')


def fresh_seed():
    return int(np.random.SeedSequence().generate_state(1)[0] % 2**31)


@pytest.mark.parametrize('kind', KINDS)
def test_each_kind_is_inspected_to_the_bar_square_on_its_surface(tmp_path, kind):
    seed = fresh_seed()
    if kind == 'wall':      # a campaign's wall world: the angle is reported for it too
        scenario, _ = random_draw(seed)
    else:
        scenario = load_scenario(write_world(tmp_path, *kind_world(
            kind, np.random.default_rng(seed), tmp_path), seed=seed))
    check_mission(scenario)         # as `uav-tilt fly` checks it before it flies
    result = fly(scenario, target_source='ground_truth')
    margins = dict(seed=seed, poi_m=POI_BAR_M - (result['poi_error_max_m'] or math.inf),
                   square_deg=SQUARE_DEG - (result['tool_normal_angle_max_deg'] or math.inf))
    print(kind, margins)
    assert result['failure'] is None and result['success'], (kind, seed, result['failure'])
    assert result['contact_lost'] == 0
    assert result['poi_error_max_m'] <= POI_BAR_M
    assert abs(result['force_mean_n'] - result['force_setpoint_n']) <= FORCE_MEAN_BAR_N
    assert result['force_rms_error_n'] <= FORCE_RMS_BAR_N
    assert result['tool_normal_angle_max_deg'] <= SQUARE_DEG, margins


def test_a_pipe_s_top_and_underside_are_refused_with_the_reachable_range(tmp_path):
    """The tool pushes along the body's forward axis, which pitches at most
    contact.max_pitch_rad: a target on the top or the underside of a pipe is refused
    before anything flies, the message giving the range; one on its side is flown."""
    limit_deg = math.degrees(MissionConfig().contact.max_pitch_rad)
    rng = np.random.default_rng(fresh_seed())
    structures, objects = kind_world('pipe', rng, tmp_path)
    for angle, refused in ((rng.uniform(limit_deg + 1, 90), True),
                           (-rng.uniform(limit_deg + 1, 90), True),
                           (rng.uniform(-limit_deg + 1, limit_deg - 1), False)):
        objects[0]['angle_deg'] = float(angle)
        scenario = load_scenario(write_world(tmp_path, structures, objects))
        if not refused:
            check_mission(scenario)
            continue
        with pytest.raises(ConfigError) as err:
            check_mission(scenario)
        message = str(err.value)
        assert f'{abs(angle):.1f} deg {"up" if angle > 0 else "down"}' in message
        assert f'within {limit_deg:.1f} deg of horizontal' in message
