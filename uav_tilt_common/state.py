"""Plain data exchanged between the cores (numpy, SI units, frames in the names)."""
import dataclasses

import numpy as np
from numpy.typing import ArrayLike, NDArray


@dataclasses.dataclass
class VehicleState:
    """Rigid-body state of ``base_link`` (origin at the rotor centroid = centre of mass)."""

    t_s: float
    p_map: np.ndarray          # position in map (ENU), m
    q_map_base: np.ndarray     # orientation quaternion (x, y, z, w), base_link -> map
    v_map: np.ndarray          # linear velocity in map, m/s
    w_base: np.ndarray         # angular velocity in base_link (FLU), rad/s


@dataclasses.dataclass
class ActuatorCommand:
    """Rotor thrusts [N] (rotor_1..4 of DESIGN section 2) and tilt angles [rad]."""

    thrusts_n: np.ndarray                  # shape (4,)
    alpha_rad: float = 0.0                 # tilt_front
    beta_rad: float = 0.0                  # tilt_rear

    def as_array(self) -> NDArray[np.float64]:
        """Six values in ACTUATOR_NAMES order."""
        return np.concatenate([self.thrusts_n, [self.alpha_rad, self.beta_rad]])

    @classmethod
    def from_array(cls, values: ArrayLike) -> 'ActuatorCommand':
        """Inverse of :meth:`as_array`."""
        values = np.asarray(values, dtype=float)
        return cls(values[:4].copy(), float(values[4]), float(values[5]))
