"""External-force (disturbance) observer: wind and model errors, not the contact force.

Newton in map, with the IMU's specific force f (body frame, gravity excluded):

    M R f = F_thrust + F_contact + F_ext

F_thrust is what the rotors make of the previous commands (the allocated wrench through the
rotors' first-order lag), F_contact is what the F/T sensor measures, so the residual is the
force nobody commanded or measured: drag from wind and gusts, a mass error in
accelerations. Low-pass filtered, it is fed back with the opposite sign by the impedance law,
so the vehicle holds its reference against wind while the contact force, measured and thus
not in F_ext, still meets the compliance of eq. (6) (the push stays K_z times the depth).

On the ground (and while leaving or meeting it) the ground's reaction is a force nobody
measures either: there the vertical estimate stops learning and holds what it had (in the
air it carries the weight error too; dropping it would start a landing with a climb or a
dip of up to the error over K_z), and the hover-thrust estimator learns the rest.
"""
import dataclasses
import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from uav_tilt_common.config import param
from uav_tilt_control.lowpass import lowpass_weight


@dataclasses.dataclass
class DisturbanceConfig:
    """Filter and bounds of :class:`DisturbanceObserver` (0 ``tau_s`` disables it)."""

    tau_s: float = param(0.15, lo=0.0, hi=10.0)          # low-pass time constant
    limit_n: float = param(4.0, lo=0.0, hi=100.0)        # bound of |F_ext| fed back
    # Vertical too: a vertical gust is as large as a horizontal one, and in contact, where
    # the hover-thrust estimator is frozen, it would move the tool along the wall.
    axes: list = param([1.0, 1.0, 1.0], lo=0.0, hi=1.0, length=3)   # map x, y, z weights


class DisturbanceObserver:
    """Estimates F_ext [N, map]; call :meth:`update` every tick, read :attr:`f_ext_map`."""

    def __init__(self, mass_kg: float, thrust_tau_s: float,
                 config: DisturbanceConfig | None = None) -> None:
        self.config = config or DisturbanceConfig()
        self.mass_kg = float(mass_kg)
        self.thrust_tau_s = float(thrust_tau_s)
        self._axes = np.asarray(self.config.axes, dtype=float)
        self.reset()

    @property
    def vertical_active(self) -> bool:
        """Whether the vertical axis is estimated at all."""
        return self.config.tau_s > 0.0 and self._axes[2] > 0.0

    def reset(self) -> None:
        """Forget the estimate and the thrust model's state."""
        self.f_ext_map = np.zeros(3)
        self._f_thrust_map: NDArray[np.float64] | None = None  # what the rotors make now (model)
        self._f_cmd_map: NDArray[np.float64] | None = None     # the last command

    def commanded(self, f_thrust_map: ArrayLike) -> None:
        """The thrust force (map) just sent to the actuators."""
        self._f_cmd_map = np.asarray(f_thrust_map, dtype=float)

    def take_vertical(self, f_n: float) -> float:
        """Add ``f_n`` to the vertical estimate as far as ``limit_n`` leaves room beside the
        horizontal one; returns the part it could not take [N]."""
        f = self.f_ext_map
        room = math.sqrt(max(0.0, self.config.limit_n ** 2 - f[0] ** 2 - f[1] ** 2))
        wanted = f[2] + f_n
        f[2] = min(max(wanted, -room), room)
        return wanted - f[2]

    def update(self, R_map_base: ArrayLike, specific_force_base: ArrayLike,
               f_contact_map: ArrayLike, dt_s: float,
               airborne: bool = True) -> NDArray[np.float64]:
        """One tick: the IMU's specific force (body) and the measured contact force (map),
        both over the tick since the last command. Returns the filtered F_ext (map).

        ``airborne`` False: the ground may carry the vehicle, so the vertical estimate is
        held instead of learning its reaction."""
        tau = self.config.tau_s
        if tau <= 0.0 or self._f_cmd_map is None:
            return self.f_ext_map
        if self._f_thrust_map is None:
            self._f_thrust_map = self._f_cmd_map.copy()
        # the rotors (and servos) follow the command with a first-order lag
        lag = lowpass_weight(dt_s, self.thrust_tau_s)
        self._f_thrust_map = self._f_thrust_map + lag * (self._f_cmd_map - self._f_thrust_map)
        measured = self.mass_kg * (np.asarray(R_map_base) @ np.asarray(specific_force_base))
        residual = (measured - self._f_thrust_map - np.asarray(f_contact_map)) * self._axes
        if not airborne:
            residual[2] = self.f_ext_map[2]
        self.f_ext_map = self.f_ext_map + lowpass_weight(dt_s, tau) * (
            residual - self.f_ext_map)
        norm = math.sqrt(self.f_ext_map @ self.f_ext_map)
        if norm > self.config.limit_n:
            self.f_ext_map *= self.config.limit_n / norm
        return self.f_ext_map
