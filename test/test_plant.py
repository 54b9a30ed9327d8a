"""The PyBullet plant: hover, the article's decoupling, contact sensing, determinism."""
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
