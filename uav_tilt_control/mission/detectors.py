"""The mission's detectors, each with its own state (as PX4's land and failure detectors and
its geofence): persistence, landing, upset, a bump in free flight, and the geofence."""
import math

import numpy as np

from uav_tilt_common.state import VehicleState
from uav_tilt_common.vehicle import GRAVITY, VehicleParams
from uav_tilt_control.lowpass import lowpass_weight
from uav_tilt_control.mission.config import (BumpConfig, FailsafeConfig, LandConfig,
                                             MissionConfig)


class Persistence:
    """Whether a condition has held for a while (PX4's systemlib::Hysteresis, one way):
    :meth:`update` each tick says so once it has held ``hold_s`` since it began."""

    def __init__(self) -> None:
        self.since_s: float | None = None

    def reset(self) -> None:
        self.since_s = None

    def update(self, holds: bool, now_s: float, hold_s: float) -> bool:
        if not holds:
            self.since_s = None
            return False
        if self.since_s is None:
            self.since_s = now_s
            return False
        return now_s - self.since_s >= hold_s


class BumpDetector:
    """The F/T force on the vehicle (map), low-passed over ``bump.tau_s``: a touch lasts
    longer than the sensor's noise."""

    def __init__(self, config: BumpConfig) -> None:
        self.config = config
        self.f_contact_map = np.zeros(3)

    def update(self, f_contact_map: np.ndarray | None, dt_s: float) -> None:
        """Take one F/T reading (None or non-finite: none, a broken sensor proves nothing)."""
        f_map = np.zeros(3) if f_contact_map is None or not np.all(
            np.isfinite(f_contact_map)) else np.asarray(f_contact_map, dtype=float)
        self.f_contact_map = self.f_contact_map + lowpass_weight(
            dt_s, self.config.tau_s) * (f_map - self.f_contact_map)

    def bump(self) -> np.ndarray | None:
        """The force when it says the tool touched something (above ``bump.threshold_n``),
        else None."""
        touched = float(np.linalg.norm(self.f_contact_map))
        return self.f_contact_map if touched > self.config.threshold_n else None


class LandDetector:
    """Landed: low above the ground, or stopped on something higher, and still, for
    ``land.detect_s``."""

    def __init__(self, config: LandConfig, vehicle: VehicleParams) -> None:
        self.config = config
        self.vehicle = vehicle
        self._persistence = Persistence()

    def reset(self) -> None:
        self._persistence.reset()

    def update(self, now_s: float, z_m: float, ref_z_m: float, speed_m_s: float,
               thrust_up_n: float | None, bumped: bool) -> str:
        """'' while not landed, else how it landed."""
        cfg = self.config
        low = z_m < cfg.ground_z_m + cfg.detect_height_m
        # Or stopped on something higher (a roof, a box; ground_z_m set too low, odometry
        # drifting up): that far above its descending setpoint, asking for less thrust than
        # any vehicle it may be weighs, and still. Being above the setpoint alone says
        # nothing: a vehicle lighter than the controller's model hovers there until the
        # hover-thrust estimate has learnt its weight. Resting on its gear, not hanging by
        # its tool, which would fall once the rotors stop.
        thrust_low = thrust_up_n is not None and thrust_up_n < (
            cfg.detect_thrust_ratio * self.vehicle.mass_kg * GRAVITY)
        held = z_m > ref_z_m + cfg.detect_height_m and thrust_low and not bumped
        slow = speed_m_s < cfg.detect_speed_m_s
        if not self._persistence.update((low or held) and slow, now_s, cfg.detect_s):
            return ''
        return 'landed' if low else f'landed {z_m - cfg.ground_z_m:.2f} m above ground_z_m'


class UpsetDetector:
    """Tilted past ``failsafe.upset_tilt_rad`` for ``failsafe.upset_s``."""

    def __init__(self, config: FailsafeConfig) -> None:
        self.config = config
        self._persistence = Persistence()

    def update(self, now_s: float, state: VehicleState, flying: bool) -> bool:
        tilted = cos_tilt_of(state) < math.cos(self.config.upset_tilt_rad)
        return self._persistence.update(flying and tilted, now_s, self.config.upset_s)


class Geofence:
    """Where hover setpoints may go: within ``failsafe.fence_radius_m`` of the last take-off
    and ``failsafe.fence_height_m`` above the ground."""

    def __init__(self, config: MissionConfig) -> None:
        self.config = config
        self.home_map: np.ndarray | None = None     # where it last took off

    def outside(self, p_map: np.ndarray) -> str:
        """Why ``p_map`` is outside the geofence, or ''."""
        cfg, ground_z_m = self.config.failsafe, self.config.land.ground_z_m
        if p_map[2] - ground_z_m > cfg.fence_height_m:
            return f'{p_map[2] - ground_z_m:g} m above the ground (fence_height_m ' \
                   f'{cfg.fence_height_m:g})'
        if self.home_map is not None:
            radius_m = float(np.hypot(*(p_map[:2] - self.home_map[:2])))
            if radius_m > cfg.fence_radius_m:
                return f'{radius_m:g} m from the take-off (fence_radius_m {cfg.fence_radius_m:g})'
        return ''


def cos_tilt_of(state: VehicleState) -> float:
    """Cosine of the angle between the body's z axis and the vertical."""
    x, y, z, w = np.asarray(state.q_map_base, dtype=float).tolist()
    return 1.0 - 2.0 * (x * x + y * y) / (x * x + y * y + z * z + w * w)
