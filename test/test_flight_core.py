"""FlightCore closed loop on an in-test 6-DoF rigid body (a stand-in for the PyBullet plant)."""
import dataclasses
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from uav_tilt_common.config import from_dict
from uav_tilt_common.geometry import rotor_wrench_flu
from uav_tilt_common.state import VehicleState
from uav_tilt_common.vehicle import GRAVITY, VehicleParams
from uav_tilt_control.flight_core import FlightCore, FlightCoreConfig
from uav_tilt_control.impedance import contact_depth_for_force
from uav_tilt_control.types import ImpedanceSetpoint

VEHICLE = VehicleParams()
CONTROL_DT_S = 1.0 / 300.0
SUBSTEPS = 4   # physics at 1200 Hz


class RigidBody:
    """Euler-integrated rigid body with first-order rotors and rate-limited tilt servos."""

    def __init__(self, p_map, disturbance_torque_flu=(0.0, 0.0, 0.0), wall_x_m=np.inf):
        v = VEHICLE
        self.p, self.v = np.array(p_map, dtype=float), np.zeros(3)
        self.rot, self.w = Rotation.identity(), np.zeros(3)
        self.inertia = np.asarray(v.inertia_kgm2)
        self.thrusts = np.full(4, v.hover_thrust_n)
        self.tilt = np.zeros(2)
        self.servo_tau_s = 1.0 / (2.0 * np.pi * v.servo_bandwidth_hz)
        self.t_s = 0.0
        # Stands for a centre of mass off the rotor centroid, which the integrators must hold.
        self.disturbance_torque_flu = np.asarray(disturbance_torque_flu, dtype=float)
        # A stiff, damped wall x_map <= wall_x_m touched only by the tool tip.
        self.wall_x_m = wall_x_m
        self.f_contact_map = np.zeros(3)

    def state(self):
        return VehicleState(self.t_s, self.p.copy(), self.rot.as_quat(), self.v.copy(),
                            self.w.copy())

    def advance(self, command, dt_s):
        v, h = VEHICLE, dt_s / SUBSTEPS
        tilt_cmd = np.array([command.alpha_rad, command.beta_rad])
        for _ in range(SUBSTEPS):
            self.thrusts += (command.thrusts_n - self.thrusts) * h / v.thrust_tau_s
            tilt_rate = np.clip((tilt_cmd - self.tilt) / self.servo_tau_s,
                                -v.servo_rate_rad_s, v.servo_rate_rad_s)
            self.tilt += tilt_rate * h
            force_flu, torque_flu = rotor_wrench_flu(self.thrusts, self.tilt[0], self.tilt[1],
                                                     v.l1_m, v.l2_m, v.k_m)
            self.f_contact_map = self._wall_force()
            accel = (self.rot.apply(force_flu) + self.f_contact_map) / v.mass_kg - [
                0.0, 0.0, GRAVITY]
            torque_flu = torque_flu + self.disturbance_torque_flu
            w_dot = (torque_flu - np.cross(self.w, self.inertia * self.w)) / self.inertia
            self.v += accel * h
            self.p += self.v * h
            self.w += w_dot * h
            self.rot = self.rot * Rotation.from_rotvec(self.w * h)
        self.t_s += dt_s

    def _wall_force(self, k_n_m=3000.0, c_n_s_m=30.0):
        # The tip lies on the x_FLU axis through the centre of mass: the push makes no torque.
        tip_x_m = self.p[0] + self.rot.apply([VEHICLE.tool_tip_x_m, 0.0, 0.0])[0]
        depth_m = tip_x_m - self.wall_x_m
        if depth_m <= 0.0:
            return np.zeros(3)
        return np.array([-max(k_n_m * depth_m + c_n_s_m * self.v[0], 0.0), 0.0, 0.0])


# Gravity torque of a centre of mass 1 cm behind and 0.5 cm right of the rotor centroid.
COM_TORQUE_FLU = VEHICLE.mass_kg * GRAVITY * np.array([0.005, -0.01, 0.0])


def _fly(setpoint, duration_s, body=None, warmup_s=0.0, return_forces=False):
    """Close the loop; returns times, positions (map) and (yaw, pitch, roll) per tick.

    During ``warmup_s`` the vehicle holds its start pose (integrators settle, not recorded).
    """
    body = body or RigidBody((0.0, 0.0, 1.5), COM_TORQUE_FLU)
    core = FlightCore(VEHICLE)
    hold = ImpedanceSetpoint(lambda_d_t=body.p.copy(), yaw_rad=setpoint.yaw_rad)
    for _ in range(int(round(warmup_s / CONTROL_DT_S))):
        body.advance(core.step(body.state(), hold, np.zeros(3), CONTROL_DT_S)[0], CONTROL_DT_S)
    t0_s = body.t_s
    times, positions, euler, forces = [], [], [], []
    for _ in range(int(round(duration_s / CONTROL_DT_S))):
        command, diagnostics = core.step(body.state(), setpoint, body.f_contact_map,
                                         CONTROL_DT_S)
        assert not diagnostics['input_fault']
        body.advance(command, CONTROL_DT_S)
        forces.append(body.f_contact_map.copy())
        times.append(body.t_s - t0_s)
        positions.append(body.p.copy())
        euler.append(body.rot.as_euler('ZYX'))
    if return_forces:
        return np.array(times), np.array(positions), np.array(euler), np.array(forces)
    return np.array(times), np.array(positions), np.array(euler)


def test_hover_holds():
    setpoint = ImpedanceSetpoint(lambda_d_t=np.array([0.0, 0.0, 1.5]))
    t, p, euler = _fly(setpoint, 4.0)
    # The centre-of-mass torque appears at t = 0; the integrators take it over.
    assert np.max(np.abs(p - [0.0, 0.0, 1.5])) < 0.05
    assert np.max(np.abs(p[t >= 3.0] - [0.0, 0.0, 1.5])) < 0.005
    assert np.degrees(np.max(np.abs(euler[t >= 3.0]))) < 0.2


def test_hover_recovers_from_a_tilted_low_start():
    body = RigidBody((0.3, -0.2, 1.2), COM_TORQUE_FLU)
    body.rot = Rotation.from_euler('ZYX', [0.2, 0.15, -0.25])
    setpoint = ImpedanceSetpoint(lambda_d_t=np.array([0.0, 0.0, 1.5]))
    t, p, euler = _fly(setpoint, 4.0, body)
    assert np.all(np.abs(p[t >= 3.0] - [0.0, 0.0, 1.5]) < 0.02)
    assert np.degrees(np.max(np.abs(euler[t >= 3.0]))) < 0.5


def test_forward_step_settles_by_tilting_not_pitching():
    setpoint = ImpedanceSetpoint(lambda_d_t=np.array([1.0, 0.0, 1.5]))
    t, p, euler = _fly(setpoint, 4.0, warmup_s=2.0)
    assert np.all(np.abs(p[t >= 3.0] - [1.0, 0.0, 1.5]) < 0.05)
    assert p[:, 0].max() < 1.10
    assert np.degrees(np.abs(euler[:, 1])).max() < 2.0


def test_lateral_step_settles_by_rolling():
    setpoint = ImpedanceSetpoint(lambda_d_t=np.array([0.0, 1.0, 1.5]))
    t, p, euler = _fly(setpoint, 5.0, warmup_s=2.0)
    assert np.all(np.abs(p[t >= 4.0] - [0.0, 1.0, 1.5]) < 0.05)
    assert p[:, 1].max() < 1.15
    # Moving towards +y_map (left) needs the body leaning left: negative roll about x_FLU.
    assert euler[:, 2].min() < np.radians(-3.0)
    assert np.degrees(np.abs(euler[:, 0])).max() < 2.0


def test_yawed_forward_step_moves_along_the_heading():
    yaw = np.radians(60.0)
    heading = np.array([np.cos(yaw), np.sin(yaw), 0.0])
    setpoint = ImpedanceSetpoint(lambda_d_t=np.array([0.0, 0.0, 1.5]) + heading, yaw_rad=yaw)
    body = RigidBody((0.0, 0.0, 1.5), COM_TORQUE_FLU)
    body.rot = Rotation.from_euler('z', yaw)
    t, p, euler = _fly(setpoint, 3.5, body, warmup_s=2.0)
    assert np.degrees(np.abs(euler[:, 1])).max() < 2.0
    assert np.all(np.abs(p[t >= 3.0] - setpoint.lambda_d_t) < 0.05)


def test_contact_push_equals_k_z_times_depth():
    """Eq. (6) at rest: the wall pushes back with K_z * depth, and the vehicle does not pitch."""
    wall_x_m, force_d_n = 2.0, 3.0
    core_k_z = FlightCore(VEHICLE).impedance.gains(contact=True)[0][2]
    depth_m = contact_depth_for_force(force_d_n, core_k_z)
    # Target frame t: origin on the wall, z_t out of the wall (-x_map), x_t up.
    R_map_t = np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])
    setpoint = ImpedanceSetpoint(R_map_t=R_map_t, origin_map=np.array([wall_x_m, 0.0, 1.5]),
                                 lambda_d_t=np.array([0.0, 0.0, VEHICLE.tool_tip_x_m - depth_m]),
                                 contact_gains=True)
    body = RigidBody((wall_x_m - VEHICLE.tool_tip_x_m - 0.3, 0.0, 1.5), COM_TORQUE_FLU,
                     wall_x_m=wall_x_m)
    t, p, euler, forces = _fly(setpoint, 3.0, body, warmup_s=1.0, return_forces=True)
    push_n = -forces[t >= 2.0, 0]
    assert np.all(np.abs(push_n - force_d_n) < 0.03 * force_d_n)
    assert np.degrees(np.abs(euler[:, 1])).max() < 2.0
    np.testing.assert_allclose(p[-1, 1:], [0.0, 1.5], atol=0.01)


def test_config_loads_with_its_defaults():
    assert from_dict(FlightCoreConfig, {}) == FlightCoreConfig()


def test_non_finite_inputs_give_a_safe_command():
    core = FlightCore(VEHICLE)
    state = RigidBody((0.0, 0.0, 1.5)).state()
    state.v_map[1] = np.nan
    command, diagnostics = core.step(state, ImpedanceSetpoint(), np.zeros(3), CONTROL_DT_S)
    assert diagnostics['input_fault']
    np.testing.assert_allclose(command.thrusts_n, VEHICLE.hover_thrust_n)
    assert command.alpha_rad == 0.0 and command.beta_rad == 0.0
    good = RigidBody((0.0, 0.0, 1.5)).state()
    for bad_contact, bad_dt in (([np.inf, 0.0, 0.0], CONTROL_DT_S), (np.zeros(3), 0.0)):
        command, diagnostics = core.step(good, ImpedanceSetpoint(), bad_contact, bad_dt)
        assert diagnostics['input_fault']
        assert np.all(np.isfinite(command.as_array()))


@pytest.mark.parametrize('lowest_n, highest_n', [(0.0, 3.0), (5.0, 15.0)])
def test_leaving_the_ground_hands_the_learnt_weight_to_the_observer(lowest_n, highest_n):
    # what the hover-thrust estimator learnt on the climb starts the observer's vertical
    # estimate: the thrust does not step, and the error is not counted twice. A weight error
    # beyond the observer's bound (4 N; a vehicle up to twice, or half, the model's mass:
    # up to 15.7 N) leaves it the rest.
    body = RigidBody((0.0, 0.0, 1.0))
    core = FlightCore(VEHICLE)
    climbing = ImpedanceSetpoint(lambda_d_t=body.p.copy(), airborne=False)
    specific = np.array([0.0, 0.0, GRAVITY])
    core.step(body.state(), climbing, np.zeros(3), CONTROL_DT_S, specific)
    rng = np.random.default_rng()
    learnt_n = float(rng.choice([-1.0, 1.0]) * rng.uniform(lowest_n, highest_n))
    core.impedance.f_hover_n = learnt_n
    before = core.step(body.state(), climbing, np.zeros(3), CONTROL_DT_S, specific)[0]
    airborne = dataclasses.replace(climbing, airborne=True)
    after = core.step(body.state(), airborne, np.zeros(3), CONTROL_DT_S, specific)[0]
    limit_n = core.disturbance.config.limit_n
    handed_n = math.copysign(min(abs(learnt_n), limit_n), learnt_n)
    assert core.impedance.f_hover_n == pytest.approx(learnt_n - handed_n, abs=1e-9)
    # one tick of the observer's filter (0.15 s) moves it by 2% of what it now sees
    assert core.disturbance.f_ext_map[2] == pytest.approx(-handed_n, abs=0.03 * abs(handed_n))
    assert after.thrusts_n.sum() == pytest.approx(before.thrusts_n.sum(),
                                                  abs=0.03 * abs(handed_n))
    assert after.thrusts_n.sum() == pytest.approx(before.thrusts_n.sum(),
                                                  abs=0.03 * abs(learnt_n))
