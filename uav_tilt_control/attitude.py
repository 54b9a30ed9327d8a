"""Attitude setpoint from a map force, and the PX4-style attitude/rate PID cascade.

The body cannot push along y_FLU, so the setpoint keeps the commanded yaw and pitch and picks
the roll that puts the commanded force in the x_FLU-z_FLU plane (DESIGN section 2); the x_FLU
part is then made by tilting the arms, not by pitching.
"""
import dataclasses
import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from uav_tilt_common.config import param
from uav_tilt_common.geometry import (euler_zyx_to_matrix, matrix_to_quat, quat_multiply,
                                      quat_to_rotvec)
from uav_tilt_common.state import VehicleState
from uav_tilt_control.lowpass import cutoff_tau_s, lowpass_weight


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


def attitude_setpoint(force_map: ArrayLike, yaw_rad: float, pitch_rad: float = 0.0,
                      roll_limit_rad: float = 0.6) -> tuple[NDArray[np.float64], float, float]:
    """Attitude R_map_base_d with the given yaw and pitch whose roll removes the y_FLU force.

    Returns (R_map_base_d, thrust_x_flu, thrust_z_flu): the force expressed in the desired
    body frame. With |roll| at its limit the remaining y_FLU part is dropped.
    """
    force = np.asarray(force_map, dtype=float)
    fx, fy, fz = force.tolist()
    # f_yp = (Rz(yaw) Ry(pitch))^T force; only its y and z are needed
    cy, sy = math.cos(yaw_rad), math.sin(yaw_rad)
    cp, sp = math.cos(pitch_rad), math.sin(pitch_rad)
    f_yp_y = -sy * fx + cy * fy
    f_yp_z = cy * sp * fx + sy * sp * fy + cp * fz
    # Rx(roll)^T f_yp has y = cos*f_y + sin*f_z = 0; the |f_z| choice keeps roll small (and
    # defined) when the force points down, where the rotors cannot follow anyway.
    roll_rad = math.atan2(-f_yp_y, abs(f_yp_z))
    roll_rad = min(max(roll_rad, -roll_limit_rad), roll_limit_rad)
    R_map_base_d = euler_zyx_to_matrix(yaw_rad, pitch_rad, roll_rad)
    f_body = R_map_base_d.T @ force
    return R_map_base_d, float(f_body[0]), float(f_body[2])


class AttitudePid:
    """Attitude error -> body-rate setpoint (P) -> rate PID -> body torque (FLU, N m).

    The rate PID has its derivative on the measured rate, low-pass filtered, and an integrator
    that is clamped and frozen while the output saturates (anti-windup).
    """

    def __init__(self, inertia_kgm2: ArrayLike, config: AttitudeConfig | None = None) -> None:
        self.config = config or AttitudeConfig()
        self.inertia = np.asarray(inertia_kgm2, dtype=float)
        # Per-axis gains as float lists once: the tick runs on plain floats, as numpy's
        # per-call cost on 3-vectors would be most of it.
        cfg = self.config
        self._inertia = self.inertia.tolist()
        self._axes = list(zip(*(list(map(float, g)) for g in (
            cfg.att_p, cfg.rate_limit_rad_s, cfg.rate_p, cfg.rate_i, cfg.rate_d,
            cfg.rate_i_limit, cfg.accel_limit))))
        self.reset()

    def reset(self) -> None:
        """Clear integrator and derivative-filter state."""
        self.integral = np.zeros(3)
        self._rate_prev: list[float] | None = None
        self._d_rate = np.zeros(3)

    def update(self, R_map_base_d: ArrayLike, state: VehicleState,
               dt_s: float) -> NDArray[np.float64]:
        """One control tick; returns the body torque (FLU, N m)."""
        x, y, z, w = np.asarray(state.q_map_base, dtype=float).tolist()
        norm = math.sqrt(x * x + y * y + z * z + w * w)
        # Error rotation expressed in the body, R_base_base_d = R_map_base^T R_map_base_d,
        # as a rotation vector: q_map_base^-1 * q_map_base_d.
        err_rotvec = quat_to_rotvec(quat_multiply(
            (-x / norm, -y / norm, -z / norm, w / norm), matrix_to_quat(R_map_base_d))).tolist()
        rate = np.asarray(state.w_base, dtype=float).tolist()
        prev, d_rate, integral = self._rate_prev, self._d_rate.tolist(), self.integral.tolist()
        if prev is not None:
            blend = lowpass_weight(dt_s, cutoff_tau_s(self.config.d_cutoff_hz))
            d_rate = [d + blend * ((r - r0) / dt_s - d) for d, r, r0 in zip(d_rate, rate, prev)]
        self._rate_prev = rate

        accel = []
        for i, (att_p, rate_limit, rate_p, rate_i, rate_d, i_limit, accel_limit) in enumerate(
                self._axes):
            rate_sp = min(max(att_p * err_rotvec[i], -rate_limit), rate_limit)
            rate_err = rate_sp - rate[i]
            a = rate_p * rate_err + integral[i] - rate_d * d_rate[i]
            # Integrate only where the output is free, or where integrating unwinds it.
            if abs(a) < accel_limit or _sign(rate_err) != _sign(a):
                integral[i] = min(max(integral[i] + rate_i * rate_err * dt_s, -i_limit),
                                  i_limit)
            accel.append(min(max(a, -accel_limit), accel_limit))
        self._d_rate, self.integral = np.array(d_rate), np.array(integral)
        # Gyroscopic term so the gains act on a decoupled double integrator.
        j0, j1, j2 = self._inertia
        w0, w1, w2 = rate
        h0, h1, h2 = j0 * w0, j1 * w1, j2 * w2
        return np.array([j0 * accel[0] + (w1 * h2 - w2 * h1),
                         j1 * accel[1] + (w2 * h0 - w0 * h2),
                         j2 * accel[2] + (w0 * h1 - w1 * h0)])


def _sign(x: float) -> int:
    return (x > 0.0) - (x < 0.0)
