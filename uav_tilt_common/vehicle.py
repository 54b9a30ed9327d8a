"""Physical parameters of the tilting-rotor H quadrotor, shared by plant and controller."""
import dataclasses

import numpy as np
from scipy.spatial.transform import Rotation

from uav_tilt_common.config import ConfigError, param
from uav_tilt_common.pose import Pose

# Optical axes (x right, y down, z forward) in FLU for a camera looking along +x_FLU.
_R_FLU_OPTICAL = np.array([
    [0.0, 0.0, 1.0],
    [-1.0, 0.0, 0.0],
    [0.0, -1.0, 0.0],
])


@dataclasses.dataclass
class VehicleParams:
    """Vehicle model. Lengths in m, masses in kg, inertia in kg m^2 (FLU body axes)."""

    mass_kg: float = param(1.6, lo=0.2, hi=20.0)
    inertia_kgm2: list = param([0.021, 0.018, 0.034], lo=1e-5, hi=10.0, length=3)
    l1_m: float = param(0.16, lo=0.02, hi=1.0)         # half rotor spacing along an arm
    l2_m: float = param(0.18, lo=0.02, hi=1.0)         # half spacing between the two arms
    k_m: float = param(0.016, lo=0.0, hi=0.2)          # rotor torque/thrust ratio
    f_max_n: float = param(9.0, lo=0.5, hi=100.0)      # thrust bound per rotor
    thrust_tau_s: float = param(0.025, lo=0.0, hi=0.5)  # first-order rotor lag
    servo_bandwidth_hz: float = param(8.0, lo=0.5, hi=100.0)
    servo_rate_rad_s: float = param(5.0, lo=0.1, hi=50.0)
    tilt_limit_rad: float = param(1.22, lo=0.05, hi=1.5)  # about 70 degrees
    tool_tip_x_m: float = param(0.45, lo=0.1, hi=2.0)   # tool tip ahead of the rotor centroid
    tool_tip_radius_m: float = param(0.012, lo=0.002, hi=0.05)
    tool_mass_kg: float = param(0.06, lo=0.0, hi=2.0)
    arm_mass_kg: float = param(0.16, lo=0.01, hi=5.0)   # each arm with its two rotors
    camera_xyz_m: list = param([0.12, 0.0, 0.07], lo=-1.0, hi=1.0, length=3)
    camera_pitch_rad: float = param(0.0, lo=-0.8, hi=0.8)  # positive looks down

    @property
    def hover_thrust_n(self) -> float:
        """Per-rotor thrust that holds the vehicle at zero tilt."""
        return self.mass_kg * GRAVITY / 4.0

    def camera_in_base(self) -> Pose:
        """Pose of ``camera_color_optical_frame`` in base_link: the camera looks along
        +x_FLU, pitched down by ``camera_pitch_rad`` (a positive rotation about +y_FLU turns
        x_FLU downwards), from ``camera_xyz_m``."""
        R_pitch = Rotation.from_euler('y', self.camera_pitch_rad).as_matrix()
        return Pose(R_pitch @ _R_FLU_OPTICAL, np.asarray(self.camera_xyz_m, dtype=float))


GRAVITY = 9.80665


def check_vehicle(vehicle: VehicleParams) -> None:
    """ConfigError for a vehicle no plant builds (:func:`check_body`) or whose weight is more
    than its four rotors lift (``f_max_n`` each)."""
    check_body(vehicle)
    lift_kg = 4 * vehicle.f_max_n / GRAVITY
    if vehicle.mass_kg >= lift_kg:
        raise ConfigError(f"parameter 'vehicle.mass_kg' = {vehicle.mass_kg!r} is more than "
                          f"its four rotors lift (4 vehicle.f_max_n = "
                          f"{4 * vehicle.f_max_n:g} N: {lift_kg:.3g} kg)")


def check_body(vehicle: VehicleParams) -> None:
    """ConfigError for a vehicle whose hub (the mass less the two arms and the tool) would
    be a tenth of the mass or less."""
    rest_kg = 2 * vehicle.arm_mass_kg + vehicle.tool_mass_kg
    if vehicle.mass_kg - rest_kg <= 0.1 * vehicle.mass_kg:
        raise ConfigError(f"parameter 'vehicle.mass_kg' = {vehicle.mass_kg!r} leaves the hub "
                          f"no more than a tenth of it after the arms and the tool "
                          f"(2 vehicle.arm_mass_kg + vehicle.tool_mass_kg = {rest_kg:g} kg): "
                          f"it must be more than {rest_kg / 0.9:.3g} kg")
