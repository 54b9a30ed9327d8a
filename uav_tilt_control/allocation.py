"""Control allocation of the tilting-rotor H quadrotor (article sec. 3.1, DESIGN section 2).

With alpha = beta the article's five equations (1)-(2) have a closed-form solution. They are
written in the article's frame P (x_P right, y_P forward); inputs and outputs here are FLU.
For a fixed tilt the four thrusts are linear in (F_total, tau_x_P, tau_y_P, tau_z_P), so the
saturation handling (give up yaw, then roll/pitch, then clip) is closed form too.
"""
import dataclasses
import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from uav_tilt_common.config import param
from uav_tilt_common.geometry import article_wrench_p
from uav_tilt_common.vehicle import VehicleParams

# Inputs beyond this are physically meaningless; bounding them keeps the arithmetic finite.
_INPUT_BOUND = 1e6


@dataclasses.dataclass
class AllocationConfig:
    """Allocation options. Differential tilt (alpha != beta) is not implemented."""

    min_thrust_n: float = param(0.0, lo=0.0, hi=10.0)  # keep rotors spinning if > 0


@dataclasses.dataclass
class AllocationResult:
    """Actuator values and what the allocator had to give up (requested - achieved)."""

    thrusts_n: np.ndarray         # rotor_1..4
    alpha_rad: float
    beta_rad: float
    saturated: bool
    force_given_up_n: np.ndarray  # (x_FLU, z_FLU)
    torque_given_up_nm: np.ndarray  # FLU

    @property
    def yaw_given_up_nm(self) -> float:
        """Yaw torque (z_FLU) that could not be produced."""
        return float(self.torque_given_up_nm[2])


class Allocator:
    """Maps a body force (x_FLU, z_FLU) and torque (FLU) to four thrusts and alpha = beta."""

    def __init__(self, vehicle: VehicleParams, config: AllocationConfig | None = None) -> None:
        self.vehicle = vehicle
        self.config = config or AllocationConfig()

    def allocate(self, force_flu_xz: ArrayLike, torque_flu: ArrayLike) -> AllocationResult:
        """Solve eq. (1)-(2) with alpha = beta; saturate as yaw, then roll/pitch, then clip."""
        # Plain floats: numpy's per-call cost on 2- and 4-vectors is most of a 300 Hz tick.
        v = self.vehicle
        f_lo, f_hi = self.config.min_thrust_n, v.f_max_n
        fx, fz = _sanitize(force_flu_xz, 2)
        tx, ty, tz = _sanitize(torque_flu, 3)
        f_total, tilt_rad = _total_and_tilt(fx, fz, v.tilt_limit_rad)
        f_total = min(max(float(f_total), 4.0 * f_lo), 4.0 * f_hi)
        s, c = math.sin(tilt_rad), math.cos(tilt_rad)

        # the torque in the article's frame P is (-ty, tx, tz)
        base = [f_total / 4.0] * 4
        roll_pitch = self._thrusts_from_torque_p(-ty, tx, 0.0, s, c)
        yaw = self._thrusts_from_torque_p(0.0, 0.0, tz, s, c)
        rp_scale = _max_feasible_scale(base, roll_pitch, f_lo, f_hi)
        with_rp = [b + rp_scale * d for b, d in zip(base, roll_pitch)]
        yaw_scale = _max_feasible_scale(with_rp, yaw, f_lo, f_hi)
        thrusts = [min(max(b + yaw_scale * d, f_lo), f_hi) for b, d in zip(with_rp, yaw)]

        f_y_p, f_z_p, tau_x_p, tau_y_p, tau_z_p = article_wrench_p(
            thrusts, tilt_rad, tilt_rad, v.l1_m, v.l2_m, v.k_m).tolist()
        force_lost = (fx - f_y_p, fz - f_z_p)
        torque_lost = (tx - tau_y_p, ty + tau_x_p, tz - tau_z_p)
        bound = 1e-9 * (1.0 + f_total)
        saturated = bool(rp_scale < 1.0 or yaw_scale < 1.0
                         or not (abs(force_lost[0]) <= bound and abs(force_lost[1]) <= bound))
        return AllocationResult(np.array(thrusts), tilt_rad, tilt_rad, saturated,
                                np.array(force_lost), np.array(torque_lost))

    def _thrusts_from_torque_p(self, tau_x_p: float, tau_y_p: float, tau_z_p: float, s: float,
                               c: float) -> list[float]:
        """Thrust increments (rotor_1..4) producing the P-frame torque at tilt (s, c)."""
        l1, l2, k = self.vehicle.l1_m, self.vehicle.l2_m, self.vehicle.k_m
        # eq. (2a): front sum minus rear sum; the total stays unchanged.
        front_minus_rear = tau_x_p / (l2 * c)
        # eq. (2b, 2c) in (d1, d2) = (F1 - F4, F2 - F3); determinant -2 l1 k, never singular,
        # so Cramer's rule (np.linalg.solve costs more than the rest of the 2x2 solve).
        a11, a12 = c * l1 + s * k, c * l1 - s * k
        a21, a22 = -(s * l1 - c * k), -(s * l1 + c * k)
        det = a11 * a22 - a12 * a21
        d1 = (tau_y_p * a22 - a12 * tau_z_p) / det
        d2 = (a11 * tau_z_p - a21 * tau_y_p) / det
        front, rear = front_minus_rear / 2.0, -front_minus_rear / 2.0
        return [0.5 * (front + d1), 0.5 * (rear + d2), 0.5 * (rear - d2), 0.5 * (front - d1)]


def _sanitize(values: ArrayLike, n: int) -> list[float]:
    """n finite, bounded floats (non-finite entries become 0)."""
    out = []
    for x in np.asarray(values, dtype=float).reshape(n).tolist():
        out.append(min(max(x, -_INPUT_BOUND), _INPUT_BOUND) if math.isfinite(x) else 0.0)
    return out


def _total_and_tilt(fx: float, fz: float, tilt_limit_rad: float) -> tuple[float, float]:
    """Total thrust and tilt for the force (fx, fz) in FLU: tan(alpha) = F_x / F_z."""
    if fz <= 0.0:
        # Thrust cannot point down: no force, and no reason to move the servos.
        return 0.0, 0.0
    tilt_rad = math.atan2(fx, fz)
    if abs(tilt_rad) <= tilt_limit_rad:
        return math.hypot(fx, fz), tilt_rad
    # Beyond the tilt limit keep the vertical component, which holds altitude.
    tilt_rad = min(max(tilt_rad, -tilt_limit_rad), tilt_limit_rad)
    return fz / math.cos(tilt_rad), tilt_rad


def _max_feasible_scale(base: Sequence[float], delta: Sequence[float], lo: float,
                        hi: float) -> float:
    """Largest s in [0, 1] with lo <= base + s * delta <= hi (base assumed feasible)."""
    scale = 1.0
    for b, d in zip(base, delta):
        if d > 0.0 and b + d > hi:
            scale = min(scale, (hi - b) / d)
        elif d < 0.0 and b + d < lo:
            scale = min(scale, (lo - b) / d)
    return max(scale, 0.0)
