"""The PyBullet plant: hover, the article's decoupling, contact sensing, determinism."""
import subprocess
import sys

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from uav_tilt_common.state import ActuatorCommand
from uav_tilt_common.vehicle import GRAVITY
from uav_tilt_sim.plant import Plant, PlantCoreConfig
from uav_tilt_sim.scenario import load_scenario


def make_plant(start, drag=0.0, **scenario_changes):
    scenario = load_scenario()
    scenario.start_xyz_m = list(start)
    scenario.wind.drag_n_s2_per_m2 = drag
    for key, value in scenario_changes.items():
        setattr(scenario, key, value)
    return Plant(PlantCoreConfig(), scenario)


def euler_deg(plant):
    return Rotation.from_quat(plant.state().q_map_base).as_euler('ZYX', degrees=True)


@pytest.fixture
def plant_factory():
    plants = []

    def factory(*args, **kwargs):
        plants.append(make_plant(*args, **kwargs))
        return plants[-1]
    yield factory
    for plant in plants:
        plant.close()


def test_equal_thrusts_hover_in_place(plant_factory):
    plant = plant_factory([0.0, 0.0, 1.0])
    hover = np.full(4, plant.mass_kg * GRAVITY / 4)
    plant.set_actuator_state(hover, 0.0, 0.0)
    start = plant.state().p_map.copy()
    for _ in range(600):    # 2 s at 300 Hz
        plant.step(ActuatorCommand(hover))
        assert np.linalg.norm(plant.state().p_map - start) < 0.01


@pytest.mark.parametrize('alpha_deg', [8.0, 20.0])
def test_tilted_arms_accelerate_forward_without_pitching(plant_factory, alpha_deg):
    plant = plant_factory([0.0, 0.0, 1.5])
    alpha = np.radians(alpha_deg)
    thrust = plant.mass_kg * GRAVITY / (4 * np.cos(alpha))   # vertical sum = m g
    plant.set_actuator_state(np.full(4, thrust), alpha, alpha)
    times, xs = [], []
    for _ in range(300):    # 1 s
        plant.step(ActuatorCommand(np.full(4, thrust), alpha, alpha))
        times.append(plant.t_s)
        xs.append(plant.state().p_map[0])
        assert abs(euler_deg(plant)[1]) < 0.5
    # x = a t^2 / 2 with m a = 4 F sin(alpha)
    a_measured = np.polyfit(np.square(times) / 2, xs, 1)[0]
    a_expected = 4 * thrust * np.sin(alpha) / plant.mass_kg
    assert a_measured == pytest.approx(a_expected, rel=0.05)


def test_held_push_reads_back_on_the_force_torque_sensor(plant_factory):
    probe = make_plant([0.0, 0.0, 1.5])
    poi = probe.world.target_poi_map
    tip_x = probe.vehicle.tool_tip_x_m
    probe.close()
    # Start with the tip 1 cm from the target's face, then push with the arms tilted.
    plant = plant_factory([poi[0] - tip_x - 0.01, poi[1], poi[2]])
    push_n = 5.0
    weight_n = plant.mass_kg * GRAVITY
    alpha = np.arctan2(push_n, weight_n)
    thrust = np.hypot(push_n, weight_n) / 4
    plant.set_actuator_state(np.full(4, thrust), alpha, alpha)
    readings = []
    for tick in range(900):
        plant.step(ActuatorCommand(np.full(4, thrust), alpha, alpha))
        sensors = plant.read_sensors()
        if tick >= 600:
            readings.append(sensors.ee_force_n)
            assert sensors.in_contact
    mean = np.mean(readings, axis=0)
    # The wall pushes back along -x_FLU with the push, in ee_link axes.
    assert mean[0] == pytest.approx(-push_n, rel=0.02)
    assert np.linalg.norm(mean[1:]) < 0.02 * push_n


def test_same_scenario_and_seed_give_the_same_trajectory():
    def run():
        scenario_changes = {}
        plant = make_plant([0.0, 0.0, 1.0], drag=0.04, **scenario_changes)
        plant.scenario.wind.gust_std_m_s = 1.0
        plant.scenario.noise.imu_gyro_rad_s = 0.01
        thrust = np.array([4.0, 3.9, 4.1, 4.0])
        trace = []
        for _ in range(150):
            plant.step(ActuatorCommand(thrust, 0.1, -0.05))
            trace.append(np.concatenate([plant.state().p_map, plant.read_sensors().gyro_rad_s]))
        plant.close()
        return np.array(trace)
    assert np.array_equal(run(), run())


def test_rotor_lag_and_servo_rate_limit(plant_factory):
    plant = plant_factory([0.0, 0.0, 1.0])
    v = plant.vehicle
    plant.step(ActuatorCommand(np.full(4, 4.0), 0.5, -0.5))
    # after one tick (4 substeps) the first-order lag has covered 1 - exp(-dt/tau)
    expected = 4.0 * (1 - np.exp(-plant.dt_tick / v.thrust_tau_s))
    assert np.allclose(plant.rotors.thrusts_n, expected, rtol=1e-9)
    for _ in range(29):
        plant.step()
    tilts = plant.read_sensors().tilts_rad
    # 0.1 s at <= 5 rad/s cannot exceed 0.5 rad; it must be well on the way.
    assert 0.25 < tilts[0] <= 0.5 + 1e-3 and -0.5 - 1e-3 <= tilts[1] < -0.25


def _joint_force_map(plant):
    """The contact force on the tool from the tool joint's reaction (a second, independent
    reading): the joint holds the tool against the contact and its weight, quasi-static."""
    import pybullet as p
    from uav_tilt_sim import vehicle_body
    reaction = p.getJointState(plant.body, vehicle_body.TOOL, physicsClientId=plant.client)[2]
    R_map_base = Rotation.from_quat(plant.state().q_map_base).as_matrix()
    return -R_map_base @ np.array(reaction[:3]) + [0.0, 0.0, plant.vehicle.tool_mass_kg * GRAVITY]


def _pressing_flight(tmp_path, on):
    """A Flight holding the tool on a bolt plate ('plate') or sliding it up the bare wall
    ('wall', 0.1 m/s with 5 N, friction 0.4), the tool joint's reaction sensor on."""
    import pybullet as p
    import yaml
    from uav_tilt_common.config import from_dict
    from uav_tilt_control.controller_core import ControllerConfig
    from uav_tilt_control.mission import Mode
    from uav_tilt_sim import vehicle_body
    from uav_tilt_tools.runner.inprocess import Flight
    from uav_tilt_tools.runner.site_params import site_overrides
    scenario = load_scenario()
    scenario.wall.friction = 0.4
    values = {'target_source': 'ground_truth', 'mission.contact.hold_time_s': 30.0}
    if on == 'plate':
        # the plate's friction is loaded by an unmeasured push, which the disturbance
        # observer would otherwise take over from it
        values['flight.disturbance.tau_s'] = 0.0
    if on == 'wall':
        plan = tmp_path / 'plan.yaml'
        plan.write_text(yaml.safe_dump({'tasks': [{'slide': {
            'from_uv_m': [1.5, 1.0], 'to_uv_m': [1.5, 2.0], 'speed_m_s': 0.1}}]}))
        values.update(site_overrides(scenario), plan_file=str(plan))
    flight = Flight(scenario, from_dict(ControllerConfig, values))
    p.enableJointForceTorqueSensor(flight.plant.body, vehicle_body.TOOL, True,
                                   physicsClientId=flight.plant.client)
    flight.step()
    assert flight.core.inspect()[0]
    pushing = Mode.SLIDE if on == 'wall' else Mode.HOLD
    assert flight.run(60.0, until=lambda f: f.core.mission.mode == pushing)
    return flight


@pytest.mark.parametrize('on', ['plate', 'wall'])
def test_the_force_torque_sensor_reads_friction_with_its_sign(tmp_path, on):
    """PyBullet reports a contact's friction along directions that depend on the pair: the
    F/T must read it on the tool whatever the body touched, as the tool joint carries it."""
    flight = _pressing_flight(tmp_path, on)
    plant = flight.plant
    normal = plant.world.R_map_wall[:, 2]
    try:
        if on == 'plate':
            plant.external_force_map = np.array([0.0, 0.0, 3.0])   # static friction holds
        else:
            flight.run(2.0)                                         # past the speed-up
        readings, joint, slip = [], [], []
        prev_tip = plant.tool_tip_map()
        for _ in range(300):
            flight.step()
            force_ee, _ = plant.contact_wrench_ee()
            readings.append(Rotation.from_quat(plant.state().q_map_base).apply(force_ee))
            joint.append(_joint_force_map(plant))
            tip = plant.tool_tip_map()
            slip.append((tip - prev_tip) / plant.dt_tick)
            prev_tip = tip
        readings, joint, slip = np.array(readings), np.array(joint), np.array(slip)
        tangential = readings - np.outer(readings @ normal, normal)
        assert np.abs(tangential).max() > 0.5         # a real tangential load
        # within the tool's inertia (60 g): the same force, friction sign included
        assert np.abs(readings - joint).max() < 0.1
        if on == 'wall':
            # sliding: friction opposes the slip, with the wall's coefficient
            sliding = np.linalg.norm(slip, axis=1) > 0.05
            assert sliding.sum() > 100
            assert np.all(np.sum(tangential[sliding] * slip[sliding], axis=1) < 0.0)
            ratio = np.linalg.norm(tangential[sliding], axis=1) / (readings[sliding] @ normal)
            assert np.median(ratio) == pytest.approx(0.4, rel=0.03)
    finally:
        flight.close()


def test_importing_the_simulator_prints_nothing():
    """pybullet's C module prints its build time on stderr at import: every command would
    start with that line above its own one-line errors (uav_tilt_sim.bullet hides it)."""
    out = subprocess.run([sys.executable, '-c',
                          'import uav_tilt_sim.plant, uav_tilt_vision.training.dataset'],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and out.stdout == '' and out.stderr == '', out
