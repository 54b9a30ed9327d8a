"""Attitude setpoint from a map force, and the PX4-style attitude/rate PID cascade.

The body cannot push along y_FLU, so the setpoint keeps the commanded yaw and pitch and picks
the roll that puts the commanded force in the x_FLU-z_FLU plane (DESIGN section 2); the x_FLU
part is then made by tilting the arms, not by pitching.
"""
import dataclasses
import math

import numpy as np

from uav_tilt_common.config import param
from uav_tilt_common.geometry import cross3, euler_zyx_to_matrix, matrix_to_quat, quat_to_rotvec
from uav_tilt_common.state import VehicleState
from uav_tilt_control import frames


@dataclasses.dataclass
class AttitudeConfig:
    """Gains are per FLU axis in rad/s^2 units (the torque is J times the PID output)."""

    roll_limit_rad: float = param(0.6, lo=0.05, hi=1.2)
    att_p: list = param([9.0, 9.0, 4.0], lo=0.0, hi=50.0, length=3)            # 1/s
    rate_limit_rad_s: list = param([4.0, 4.0, 2.0], lo=0.1, hi=20.0, length=3)
    rate_p: list = param([28.0, 28.0, 12.0], lo=0.0, hi=500.0, length=3)       # 1/s
    rate_i: list = param([40.0, 40.0, 5.0], lo=0.0, hi=500.0, length=3)        # 1/s^2
    rate_d: list = param([0.3, 0.3, 0.0], lo=0.0, hi=5.0, length=3)            # 1 (s/s)
    rate_i_limit: list = param([20.0, 20.0, 5.0], lo=0.0, hi=100.0, length=3)    # rad/s^2
    accel_limit: list = param([80.0, 80.0, 20.0], lo=0.1, hi=1000.0, length=3)  # rad/s^2
    d_cutoff_hz: float = param(30.0, lo=1.0, hi=150.0)


def attitude_setpoint(force_map, yaw_rad, pitch_rad=0.0, roll_limit_rad=0.6):
    """Attitude R_map_base_d with the given yaw and pitch whose roll removes the y_FLU force.

    Returns (R_map_base_d, thrust_x_flu, thrust_z_flu): the force expressed in the desired
    body frame. With |roll| at its limit the remaining y_FLU part is dropped.
    """
    force = np.asarray(force_map, dtype=float)
    f_yp = euler_zyx_to_matrix(yaw_rad, pitch_rad, 0.0).T @ force
    # Rx(roll)^T f_yp has y = cos*f_y + sin*f_z = 0; the |f_z| choice keeps roll small (and
    # defined) when the force points down, where the rotors cannot follow anyway.
    roll_rad = math.atan2(-f_yp[1], abs(f_yp[2]))
    roll_rad = min(max(roll_rad, -roll_limit_rad), roll_limit_rad)
    R_map_base_d = euler_zyx_to_matrix(yaw_rad, pitch_rad, roll_rad)
    f_body = R_map_base_d.T @ force
    return R_map_base_d, float(f_body[0]), float(f_body[2])


class AttitudePid:
    """Attitude error -> body-rate setpoint (P) -> rate PID -> body torque (FLU, N m).

    The rate PID has its derivative on the measured rate, low-pass filtered, and an integrator
    that is clamped and frozen while the output saturates (anti-windup).
    """

    def __init__(self, inertia_kgm2, config: AttitudeConfig = None):
        self.config = config or AttitudeConfig()
        self.inertia = np.asarray(inertia_kgm2, dtype=float)
        # the per-axis gains as arrays once, not per tick (the configuration is fixed)
        cfg = self.config
        self._att_p = np.asarray(cfg.att_p, dtype=float)
        self._rate_limit = np.asarray(cfg.rate_limit_rad_s, dtype=float)
        self._rate_p = np.asarray(cfg.rate_p, dtype=float)
        self._rate_i = np.asarray(cfg.rate_i, dtype=float)
        self._rate_d = np.asarray(cfg.rate_d, dtype=float)
        self._i_limit = np.asarray(cfg.rate_i_limit, dtype=float)
        self._accel_limit = np.asarray(cfg.accel_limit, dtype=float)
        self.reset()

    def reset(self):
        """Clear integrator and derivative-filter state."""
        self.integral = np.zeros(3)
        self._rate_prev = None
        self._d_rate = np.zeros(3)

    def update(self, R_map_base_d, state: VehicleState, dt_s):
        """One control tick; returns the body torque (FLU, N m)."""
        cfg = self.config
        R_map_base = frames.quat_matrix(state.q_map_base)
        # Error rotation expressed in the body: R_base_base_d as a rotation vector.
        err_rotvec = quat_to_rotvec(matrix_to_quat(R_map_base.T @ R_map_base_d))
        limit = self._rate_limit
        rate_sp = np.minimum(np.maximum(self._att_p * err_rotvec, -limit), limit)

        rate = np.asarray(state.w_base, dtype=float)
        if self._rate_prev is not None:
            raw = (rate - self._rate_prev) / dt_s
            blend = 1.0 - math.exp(-2.0 * math.pi * cfg.d_cutoff_hz * dt_s)
            self._d_rate += blend * (raw - self._d_rate)
        self._rate_prev = rate.copy()

        rate_err = rate_sp - rate
        accel = self._rate_p * rate_err + self.integral - self._rate_d * self._d_rate
        accel_limit = self._accel_limit
        saturated = np.abs(accel) >= accel_limit
        # Integrate only where the output is free, or where integrating unwinds it.
        unwinding = np.sign(rate_err) != np.sign(accel)
        grow = np.where(~saturated | unwinding, self._rate_i * rate_err * dt_s, 0.0)
        i_limit = self._i_limit
        self.integral = np.minimum(np.maximum(self.integral + grow, -i_limit), i_limit)
        accel = np.minimum(np.maximum(accel, -accel_limit), accel_limit)
        # Gyroscopic term so the gains act on a decoupled double integrator.
        return self.inertia * accel + cross3(rate, self.inertia * rate)
