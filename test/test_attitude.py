"""Attitude setpoint geometry and the attitude/rate PID on a simulated rigid body."""
import numpy as np
from scipy.spatial.transform import Rotation

from uav_tilt_common.state import VehicleState
from uav_tilt_common.vehicle import VehicleParams
from uav_tilt_control.attitude import AttitudeConfig, AttitudePid, attitude_setpoint

INERTIA = np.asarray(VehicleParams().inertia_kgm2)
TORQUE_TAU_S = VehicleParams().thrust_tau_s
DT_S = 1.0 / 300.0


def _state(rot, w_base):
    return VehicleState(0.0, np.zeros(3), rot.as_quat(), np.zeros(3), w_base.copy())


def _simulate(pid, rot0, R_d, duration_s, substeps=4):
    """Rigid body (Euler's equations) with a first-order lag on the applied torque.

    Returns the attitude after each control tick.
    """
    rot, w = rot0, np.zeros(3)
    torque_applied = np.zeros(3)
    attitudes = []
    h = DT_S / substeps
    for _ in range(int(round(duration_s / DT_S))):
        torque_cmd = pid.update(R_d, _state(rot, w), DT_S)
        for _ in range(substeps):
            torque_applied += (torque_cmd - torque_applied) * h / TORQUE_TAU_S
            w_dot = (torque_applied - np.cross(w, INERTIA * w)) / INERTIA
            w = w + w_dot * h
            rot = rot * Rotation.from_rotvec(w * h)
        attitudes.append(rot)
    return attitudes


def _error_deg(attitudes, R_d):
    target = Rotation.from_matrix(R_d)
    return np.array([np.degrees((target.inv() * rot).magnitude()) for rot in attitudes])


def test_roll_step_converges_without_overshoot():
    attitudes = _simulate(AttitudePid(INERTIA), Rotation.from_euler('x', 20.0, degrees=True),
                          np.eye(3), 1.5)
    t = np.arange(1, len(attitudes) + 1) * DT_S
    assert np.all(_error_deg(attitudes, np.eye(3))[t >= 1.0] < 0.5)
    roll_deg = np.array([rot.as_euler('ZYX', degrees=True)[2] for rot in attitudes])
    assert -roll_deg.min() < 0.15 * 20.0


def test_yaw_and_mixed_steps_converge():
    rng = np.random.default_rng(3)
    for _ in range(3):
        rot0 = Rotation.from_rotvec(rng.normal(size=3) * 0.25)
        R_d = Rotation.from_euler('ZYX', [rng.uniform(-0.5, 0.5), 0.0, 0.1]).as_matrix()
        errors = _error_deg(_simulate(AttitudePid(INERTIA), rot0, R_d, 3.0), R_d)
        assert errors[-1] < 0.5


def test_integrator_does_not_wind_up_when_saturated():
    cfg = AttitudeConfig()
    pid = AttitudePid(INERTIA, cfg)
    state = _state(Rotation.from_euler('x', 60.0, degrees=True), np.zeros(3))
    for _ in range(3000):   # 10 s of an error the body never corrects
        torque = pid.update(np.eye(3), state, DT_S)
    assert np.all(np.abs(pid.integral) <= np.asarray(cfg.rate_i_limit) + 1e-12)
    # While the output is saturated the integrator is frozen, not clamped at its bound.
    assert abs(torque[0]) == cfg.accel_limit[0] * INERTIA[0]
    assert abs(pid.integral[0]) < cfg.rate_i_limit[0]


def test_setpoint_step_has_no_derivative_kick():
    cfg = AttitudeConfig(rate_i=[0.0, 0.0, 0.0])
    pid = AttitudePid(INERTIA, cfg)
    state = _state(Rotation.identity(), np.zeros(3))
    pid.update(np.eye(3), state, DT_S)
    step_rad = 0.02   # small enough that the rate setpoint is not limited
    torque = pid.update(Rotation.from_euler('x', step_rad).as_matrix(), state, DT_S)
    # Pure P response on the rate error: J * rate_p * att_p * step, no D term.
    expected = INERTIA[0] * cfg.rate_p[0] * cfg.att_p[0] * step_rad
    assert abs(torque[0] - expected) < 1e-9


def test_attitude_setpoint_removes_lateral_force():
    rng = np.random.default_rng(11)
    for _ in range(300):
        yaw, pitch = rng.uniform(-np.pi, np.pi), rng.uniform(-0.3, 0.3)
        force = np.array([rng.uniform(-8, 8), rng.uniform(-8, 8), rng.uniform(10, 30)])
        R, fx, fz = attitude_setpoint(force, yaw, pitch, roll_limit_rad=1.2)
        yaw_got, pitch_got, roll_got = Rotation.from_matrix(R).as_euler('ZYX')
        assert abs(np.angle(np.exp(1j * (yaw_got - yaw)))) < 1e-9
        assert abs(pitch_got - pitch) < 1e-9
        f_body = R.T @ force
        assert abs(f_body[1]) < 1e-9
        np.testing.assert_allclose([fx, fz], f_body[[0, 2]], atol=1e-12)
        np.testing.assert_allclose(R @ [fx, 0.0, fz], force, atol=1e-9)
        assert fz > 0.0


def test_attitude_setpoint_degenerate_and_limited():
    for force in ([0.0, 0.0, 0.0], [1e-300, 0.0, 0.0], [0.0, 5.0, -20.0], [0.0, 100.0, 1.0]):
        R, fx, fz = attitude_setpoint(force, 0.3, 0.0, roll_limit_rad=0.6)
        roll = Rotation.from_matrix(R).as_euler('ZYX')[2]
        assert np.all(np.isfinite(R)) and np.isfinite(fx) and np.isfinite(fz)
        assert abs(roll) <= 0.6 + 1e-12
    # Negative roll (left side down) brings a force along +y_map under the body at yaw 0.
    R, _, _ = attitude_setpoint([0.0, 3.0, 15.0], 0.0)
    assert Rotation.from_matrix(R).as_euler('ZYX')[2] < 0.0
