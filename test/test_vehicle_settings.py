"""`vehicle.*` wherever a flight is set up in-process (`uav-tilt fly --set`, `uav-tilt campaign
--set`, the Gymnasium environment's options), by the node parameters' names: the vehicle
flown (the plant's body, its truth) and the controller's model of it alike (DESIGN section
6); and the environment flies a scenario file when given one."""
import dataclasses
import json

import numpy as np
import pytest
import yaml

from uav_tilt_common.config import ConfigError
from uav_tilt_common.vehicle import VehicleParams
from uav_tilt_control.controller_core import ControllerConfig
from uav_tilt_sim.bullet import pybullet as p
from uav_tilt_sim.plant import Plant, PlantCoreConfig
from uav_tilt_sim.randomise import random_draw
from uav_tilt_sim.scenario import load_scenario
from uav_tilt_tools import cli
from uav_tilt_tools.campaign import run as campaign_run
from uav_tilt_tools.campaign.store import ARGS_FILE
from uav_tilt_tools.gym.env import ContactInspectionEnv
from uav_tilt_tools.runner import inprocess

NOMINAL = VehicleParams()
# masses the mission flies: the default 5 N push within what the impedance law reaches
# (mass x accel_limit_mps2, 6 m/s^2: more than 0.83 kg) and the hover well within the rotors
MASS_KG = (1.0, 2.4)


def body_mass_kg(plant):
    """The vehicle's mass as PyBullet simulates it: its base and every link."""
    return sum(p.getDynamicsInfo(plant.body, link, physicsClientId=plant.client)[0]
               for link in range(-1, p.getNumJoints(plant.body, physicsClientId=plant.client)))


@pytest.fixture
def flown(monkeypatch):
    """The (truth's body mass, controller's model mass) of every in-process flight, taken as
    it closes."""
    seen = []
    close = inprocess.Flight.close

    def spy(self):
        seen.append((body_mass_kg(self.plant), self.core.vehicle.mass_kg))
        close(self)

    monkeypatch.setattr(inprocess.Flight, 'close', spy)
    return seen


def run_cli(capsys, argv):
    code = cli.main(argv)
    out, err = capsys.readouterr()
    return code, out, [line for line in err.splitlines() if line.strip()]


def test_fly_flies_the_vehicle_it_is_set_to_and_inspects(capsys, flown):
    """Was: "unknown parameter 'vehicle'". Ground truth for speed."""
    mass_kg = float(np.random.default_rng().uniform(*MASS_KG))
    scenario = load_scenario('config/scenarios/default.yaml')
    code, out, err = run_cli(capsys, ['fly', '--scenario', 'config/scenarios/default.yaml',
                                      '--target-source', 'ground_truth',
                                      '--set', f'vehicle.mass_kg={mass_kg!r}'])
    result = json.loads(out)
    assert code == 0 and result['failure'] is None, (mass_kg, result['failure'], err)
    # the bar: within 1 cm of the POI, the push within 0.1 N mean and 0.2 N RMS of 5 N
    assert result['poi_error_max_m'] < 0.01
    assert abs(result['force_mean_n'] - 5.0) < 0.1 and result['force_rms_error_n'] < 0.2
    ((truth_kg, model_kg),) = flown
    assert truth_kg == pytest.approx(mass_kg * scenario.mismatch.mass_scale, rel=1e-9)
    assert model_kg == mass_kg


@pytest.mark.parametrize('setting, words', [
    ('vehicle.mass_kg=0.4', ['vehicle.mass_kg', 'hub']),        # arms and tool: 0.38 kg
    ('vehicle.mass_kg=3.8', ['vehicle.mass_kg', 'rotors lift']),    # 4 x 9 N: 3.67 kg
    ('vehicle.mass_kg=25', ['vehicle.mass_kg', 'out of range']),
    # the push the one-touch inspection asks for is more than this vehicle pushes
    ('vehicle.mass_kg=0.8', ["'contact_force' = 5.0", 'vehicle.mass_kg']),
    ('vehicle.mas_kg=1.0', ["'vehicle.mas_kg'", "'vehicle.mass_kg'"]),
])
def test_a_vehicle_that_cannot_fly_the_mission_is_one_line(capsys, setting, words):
    for argv in (['fly', '--scenario', 'config/scenarios/default.yaml'],
                 ['campaign', '--n', '1']):
        code, out, err = run_cli(capsys, [*argv, '--set', setting])
        assert code == 2 and out == '' and len(err) == 1, err
        assert err[0].startswith(f'uav-tilt {argv[0]}:') and all(w in err[0] for w in words)


def test_a_plant_with_too_light_a_hub_is_one_line_not_a_traceback():
    scenario = load_scenario()
    with pytest.raises(ConfigError, match="'vehicle.mass_kg' = 0.4 .* hub"):
        Plant(PlantCoreConfig(vehicle=VehicleParams(mass_kg=0.4)), scenario)


def test_campaign_flies_every_run_with_the_vehicle_it_is_set_to(tmp_path, capsys, flown,
                                                                monkeypatch):
    """`campaign --set` as fly's; its runs in this process (the local backend's pool would
    hide them from the spy), a moment of flight each; a resume with other settings is
    another campaign."""
    monkeypatch.setattr(campaign_run, 'local_runs',
                        lambda run_one, jobs, workers, address: (run_one(j) for j in jobs))
    rng = np.random.default_rng()
    mass_kg = float(rng.uniform(*MASS_KG))
    seed = int(rng.integers(0, 2**31 - 1))
    argv = ['campaign', '--n', '2', '--seed', str(seed), '--duration', '0.2', '--out',
            str(tmp_path), '--set', f'vehicle.mass_kg={mass_kg!r}']
    code, out, err = run_cli(capsys, argv)
    assert code == 0, err
    runs = json.loads(out)['runs']
    assert [truth for truth, _ in flown] == pytest.approx(
        [mass_kg * run['mass_scale'] for run in runs], rel=1e-9)
    assert [model for _, model in flown] == [mass_kg] * 2
    assert json.loads((tmp_path / ARGS_FILE).read_text())['settings'] == {
        'vehicle.mass_kg': mass_kg}
    code, out, err = run_cli(capsys, [*argv[:-1], 'vehicle.mass_kg=1.7', '--resume'])
    assert code == 2 and out == '' and 'holds the campaign' in err[0], err


def test_the_environment_flies_its_vehicle_and_a_scenario_file(tmp_path):
    """`vehicle.mass_kg` and `scenario` as gymnasium.make options: a fresh world of the
    campaign's written to a file, flown at each reset with a seed of the environment's."""
    rng = np.random.default_rng()
    mass_kg = float(rng.uniform(*MASS_KG))
    world = random_draw(int(rng.integers(0, 2**31 - 1)))[0]
    path = tmp_path / 'world.yaml'
    path.write_text(yaml.safe_dump(dataclasses.asdict(world)))
    env = ContactInspectionEnv(start='takeoff', scenario=str(path),
                               **{'vehicle.mass_kg': mass_kg})
    try:
        seeds = []
        for _ in range(2):
            _, info = env.reset(seed=int(rng.integers(0, 2**31 - 1)))
            plant = env.flight.plant
            flown = plant.scenario
            assert dataclasses.replace(flown, seed=world.seed) == world
            assert flown.seed == info['world_seed']
            assert body_mass_kg(plant) == pytest.approx(mass_kg * world.mismatch.mass_scale,
                                                        rel=1e-9)
            assert env.flight.core.vehicle.mass_kg == mass_kg
            seeds.append(info['world_seed'])
        assert seeds[0] != seeds[1]
    finally:
        env.close()
    # without one, the campaign's random worlds; a bad one refused at make with one line
    assert ContactInspectionEnv().scenario is None
    with pytest.raises(ConfigError, match="'scenario' = .*no/such.yaml"):
        ContactInspectionEnv(scenario='no/such.yaml')
    with pytest.raises(ConfigError, match="'vehicle.mass_kg' = 3.8 .* rotors lift"):
        ContactInspectionEnv(vehicle={'mass_kg': 3.8})
    with pytest.raises(ConfigError, match="'contact_force' = 5.0"):
        ContactInspectionEnv(vehicle={'mass_kg': 0.8}, controller=ControllerConfig())
