"""Selective impedance law in the target frame t (article eq. (3)-(6), DESIGN section 2).

The plant is eq. (3): M lambda'' = F_p + F_g + F_c. The article's eq. (5) also subtracts the
measured contact force F_c; together with (3) that cancels F_c and gives M e'' + C e' + K e = 0,
a pure position controller that would push with whatever force holds the desired position,
not the impedance model (6). The design target is (6), M e'' + C e' + K e = F_c, so by default
F_c is NOT fed forward:

    F_p = -F_g + M lambda_d'' - C e' - K e.

The steady contact force then is K_z times the depth of the desired position behind the
surface (:func:`contact_depth_for_force`). ``contact_feedforward = True`` restores the
article's literal (5) for comparison.
"""
import dataclasses
import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from uav_tilt_common.config import nested, param
from uav_tilt_common.vehicle import GRAVITY
from uav_tilt_control.lowpass import cutoff_tau_s, lowpass_weight
from uav_tilt_control.types import ImpedanceSetpoint

# (K, C): the stiffness and damping diagonals along (x_t, y_t, z_t)
Gains = tuple[NDArray[np.float64], NDArray[np.float64]]


@dataclasses.dataclass
class ImpedanceGains:
    """Diagonal K, C along (x_t, y_t, z_t), given directly or as natural frequency/damping."""

    mode: str = param('wn_zeta', choices=['wn_zeta', 'kc'])
    wn_rad_s: list = param([2.5, 2.5, 2.5], lo=0.05, hi=30.0, length=3)
    zeta: list = param([0.9, 0.9, 0.9], lo=0.05, hi=5.0, length=3)
    # The 'kc' defaults equal the 'wn_zeta' ones for the default 1.6 kg vehicle.
    k_n_m: list = param([10.0, 10.0, 10.0], lo=0.0, hi=1e4, length=3)
    c_n_s_m: list = param([7.2, 7.2, 7.2], lo=0.0, hi=1e4, length=3)

    def k_c(self, mass_kg: float) -> Gains:
        """(K, C) diagonals for mass M: K = M wn^2, C = 2 zeta M wn in ``wn_zeta`` mode."""
        if self.mode == 'kc':
            return np.asarray(self.k_n_m, dtype=float), np.asarray(self.c_n_s_m, dtype=float)
        wn = np.asarray(self.wn_rad_s, dtype=float)
        return mass_kg * wn ** 2, 2.0 * np.asarray(self.zeta, dtype=float) * mass_kg * wn


@dataclasses.dataclass
class ContactGains(ImpedanceGains):
    """Contact defaults: stiff along the wall, compliant and well damped along the normal."""

    wn_rad_s: list = param([4.0, 4.0, 2.5], lo=0.05, hi=30.0, length=3)
    zeta: list = param([0.9, 0.9, 1.0], lo=0.05, hi=5.0, length=3)
    k_n_m: list = param([25.6, 25.6, 10.0], lo=0.0, hi=1e4, length=3)
    c_n_s_m: list = param([11.52, 11.52, 8.0], lo=0.0, hi=1e4, length=3)


@dataclasses.dataclass
class ImpedanceConfig:
    """Free-flight and contact gain sets, contact-force filter and command limits."""

    free: ImpedanceGains = nested(ImpedanceGains)
    contact: ContactGains = nested(ContactGains)
    contact_cutoff_hz: float = param(10.0, lo=0.1, hi=150.0)
    contact_feedforward: bool = param(False)
    accel_limit_mps2: float = param(6.0, lo=0.1, hi=50.0)
    # Hover-thrust estimation (as PX4 does): a slow integrator on the vertical error learns
    # the real weight, so a mass mismatch leaves no altitude offset. 0 disables it. Its
    # bound, a fraction of the nominal weight, spans the vehicles a scenario may be (half to
    # twice the nominal mass): at 0.3 a vehicle of 0.6 hovered 0.3 m above its setpoint.
    hover_estimator_tau_s: float = param(2.0, lo=0.0, hi=100.0)
    hover_estimator_limit: float = param(1.0, lo=0.0, hi=1.0)
    # Learn only when the vertical error is quasi-static: a moving error is a manoeuvre,
    # not a weight error (the integrator would wind up and overshoot).
    hover_estimator_speed_m_s: float = param(0.05, lo=0.0, hi=10.0)
    # The push asked for (ImpedanceSetpoint.push_n) is trimmed by the measured one with this
    # time constant while the setpoint says so (HOLD, SLIDE): a soft wall, which gives way,
    # still gets the push; 0 disables the trim.
    force_tau_s: float = param(0.5, lo=0.0, hi=60.0)


def contact_depth_for_force(force_n: float, k_z_n_m: float) -> float:
    """Depth [m] of the desired position behind the surface that pushes with ``force_n``.

    From eq. (6) at rest: K_z * e_z = F_c,z, so the push needs lambda_d,z = -F_d / K_z.
    """
    if k_z_n_m <= 0.0:
        raise ValueError(f'k_z_n_m = {k_z_n_m!r} must be positive to push with a spring')
    return force_n / k_z_n_m


class ImpedanceController:
    """Computes the thrust force F_p (map frame) from the impedance law in frame t."""

    def __init__(self, mass_kg: float, config: ImpedanceConfig | None = None) -> None:
        self.mass_kg = float(mass_kg)
        self.config = config or ImpedanceConfig()
        # the configuration is fixed once built, so the gains are too
        self._gains = {contact: (self.config.contact if contact else self.config.free).k_c(
            self.mass_kg) for contact in (False, True)}
        self.f_contact_map = np.zeros(3)
        self.f_tangential_map = np.zeros(3)    # fed forward this tick (sliding)
        self.f_hover_n = 0.0       # learnt weight correction, map z
        self.trim_n = 0.0          # the push's trim (force_tau_s), along -z_t
        self._push_n = 0.0         # the push asked for on the tick before
        # the reference it tracked on the last update, in frame t: the setpoint's with the
        # push's depth behind it
        self.lambda_d_t = np.zeros(3)
        self.dlambda_d_t = np.zeros(3)

    def reset(self) -> None:
        """Clear the contact-force filter, the push's trim and the hover-thrust estimate."""
        self.f_contact_map = np.zeros(3)
        self.f_tangential_map = np.zeros(3)
        self.f_hover_n = 0.0
        self.trim_n = 0.0
        self._push_n = 0.0

    def gains(self, contact: bool) -> Gains:
        """(K, C) diagonals of the contact or free-flight set."""
        return self._gains[bool(contact)]

    def update(self, p_map: ArrayLike, v_map: ArrayLike, setpoint: ImpedanceSetpoint,
               f_contact_map: ArrayLike, dt_s: float,
               f_ext_map: NDArray[np.float64] | None = None) -> NDArray[np.float64]:
        """F_p in map [N] for the state (p, v in map) and an ``ImpedanceSetpoint``.

        ``f_contact_map`` is the measured contact force on the vehicle (map frame); it is
        low-pass filtered and only used with ``contact_feedforward``. ``f_ext_map``: the
        estimated external force (wind; see ``disturbance``), compensated.
        """
        cfg = self.config
        blend = lowpass_weight(dt_s, cutoff_tau_s(cfg.contact_cutoff_hz))
        self.f_contact_map = self.f_contact_map + blend * (
            np.asarray(f_contact_map, dtype=float) - self.f_contact_map)

        R_map_t = np.asarray(setpoint.R_map_t, dtype=float)
        lambda_t = R_map_t.T @ (np.asarray(p_map, dtype=float) - setpoint.origin_map)
        dlambda_t = R_map_t.T @ np.asarray(v_map, dtype=float)   # the target is at rest
        lambda_d_t, dlambda_d_t = self._pushed(setpoint, R_map_t, f_contact_map, dt_s)
        self.lambda_d_t, self.dlambda_d_t = lambda_d_t, dlambda_d_t
        e_t = lambda_t - lambda_d_t
        de_t = dlambda_t - dlambda_d_t
        K, C = self.gains(setpoint.contact_gains)
        accel_t = np.asarray(setpoint.ddlambda_d_t, dtype=float) - (C * de_t + K * e_t) / (
            self.mass_kg)
        # A norm limit is frame independent, so the error dynamics stay the same in any t.
        norm = math.sqrt(accel_t @ accel_t)
        if norm > cfg.accel_limit_mps2:
            accel_t *= cfg.accel_limit_mps2 / norm
        self._estimate_hover(R_map_t @ e_t, R_map_t @ de_t, K, setpoint.contact_gains, dt_s)
        f_gravity_map = np.array([0.0, 0.0, -self.mass_kg * GRAVITY - self.f_hover_n])
        f_p_map = -f_gravity_map + R_map_t @ (self.mass_kg * accel_t)
        if cfg.contact_feedforward:
            f_p_map -= self.f_contact_map
        self.f_tangential_map = np.zeros(3)
        if setpoint.tangential_feedforward:
            # the wall's plane only: friction is cancelled, the push stays K_z times the depth
            f_t = R_map_t.T @ self.f_contact_map
            self.f_tangential_map = R_map_t @ np.array([f_t[0], f_t[1], 0.0])
            f_p_map -= self.f_tangential_map
        if f_ext_map is not None:
            f_p_map -= f_ext_map
        return f_p_map

    def _pushed(self, setpoint: ImpedanceSetpoint, R_map_t: NDArray[np.float64],
                f_contact_map: ArrayLike, dt_s: float
                ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(lambda_d, dlambda_d) in frame t with the push: the reference the push's
        depth behind it, push / K_z of the contact gains (eq. (6) at rest), the trim
        included; the trim follows the measured push along z_t while the setpoint says so,
        and is let go in proportion as the push is."""
        k_z = self._gains[True][0][2]
        push_n = float(setpoint.push_n)
        tau = self.config.force_tau_s
        if setpoint.trim_push:
            if tau > 0.0:
                f_n = float(np.asarray(f_contact_map, dtype=float) @ R_map_t[:, 2])
                self.trim_n += (push_n - f_n) * dt_s / tau
        elif push_n <= 0.0:
            self.trim_n = 0.0
        elif push_n < self._push_n:
            self.trim_n *= push_n / self._push_n
        self._push_n = push_n
        lambda_d_t = np.asarray(setpoint.lambda_d_t, dtype=float)
        dlambda_d_t = np.asarray(setpoint.dlambda_d_t, dtype=float)
        if push_n == 0.0 and self.trim_n == 0.0 and setpoint.dpush_n_s == 0.0:
            return lambda_d_t, dlambda_d_t
        z_t = np.array([0.0, 0.0, 1.0])
        return (lambda_d_t - contact_depth_for_force(push_n + self.trim_n, k_z) * z_t,
                dlambda_d_t - contact_depth_for_force(float(setpoint.dpush_n_s), k_z) * z_t)

    def _estimate_hover(self, e_map: NDArray[np.float64], de_map: NDArray[np.float64],
                        K_t: NDArray[np.float64], contact: bool, dt_s: float) -> None:
        """Integrate the vertical error into the weight estimate (free flight only).

        Frozen in contact, where a vertical share of the push on an inclined wall must stay
        the spring of eq. (6); horizontal axes keep their compliance: no integrator there.
        """
        tau = self.config.hover_estimator_tau_s
        if tau <= 0.0 or contact or abs(de_map[2]) > self.config.hover_estimator_speed_m_s:
            return
        k_z = float(K_t.max())
        limit = self.config.hover_estimator_limit * self.mass_kg * GRAVITY
        self.f_hover_n = min(max(self.f_hover_n - k_z / tau * float(e_map[2]) * dt_s, -limit),
                             limit)
