"""Sensor noise models (IMU, mocap-like odometry, F/T, depth), seeded by the scenario.

Each sensor draws from its own random stream, ``default_rng([seed, stream])``, so how often
one is read (the camera renders or not, ticks re-sent before lockstep sync) never changes
another's noise, nor the wind (stream 0, uav_tilt_sim.plant).
"""
import numpy as np
from numpy.typing import ArrayLike, NDArray

from uav_tilt_common.geometry import quat_multiply, rotvec_to_quat
from uav_tilt_common.state import VehicleState
from uav_tilt_sim.scenario import NoiseConfig

RNG_STREAMS = {'imu': 1, 'odometry': 2, 'ft': 3, 'depth': 4}


class SensorModel:
    """Adds zero-mean Gaussian noise of the scenario's standard deviations."""

    def __init__(self, noise: NoiseConfig, seed: int) -> None:
        self.noise = noise
        self.rngs = {name: np.random.default_rng([seed, stream])
                     for name, stream in RNG_STREAMS.items()}

    def _add(self, sensor: str, value: ArrayLike, std: float) -> NDArray[np.float64]:
        value = np.asarray(value, dtype=float)
        if std <= 0.0:
            return value.copy()
        return value + std * self.rngs[sensor].standard_normal(value.shape)

    def gyro(self, w_base: ArrayLike) -> NDArray[np.float64]:
        """Angular rate in base_link."""
        return self._add('imu', w_base, self.noise.imu_gyro_rad_s)

    def accel(self, specific_force_base: ArrayLike) -> NDArray[np.float64]:
        """Specific force in base_link."""
        return self._add('imu', specific_force_base, self.noise.imu_accel_m_s2)

    def force(self, force: ArrayLike) -> NDArray[np.float64]:
        """F/T force."""
        return self._add('ft', force, self.noise.ft_force_n)

    def torque(self, torque: ArrayLike) -> NDArray[np.float64]:
        """F/T torque."""
        return self._add('ft', torque, self.noise.ft_torque_nm)

    def odometry(self, truth: VehicleState) -> VehicleState:
        """Mocap-like pose and velocity of base_link (its angular rate as noisy as the
        gyro's, from the odometry's own stream)."""
        q = truth.q_map_base
        if self.noise.odom_att_rad > 0.0:
            # geometry's per-tick helpers: scipy's Rotation was a sixth of a tick here
            delta = rotvec_to_quat(self._add('odometry', np.zeros(3), self.noise.odom_att_rad))
            q = quat_multiply(q, delta)
        return VehicleState(truth.t_s, self._add('odometry', truth.p_map, self.noise.odom_pos_m),
                            np.asarray(q, dtype=float),
                            self._add('odometry', truth.v_map, self.noise.odom_vel_m_s),
                            self._add('odometry', truth.w_base, self.noise.imu_gyro_rad_s))

    def depth(self, depth_m: NDArray[np.float32]) -> NDArray[np.float32]:
        """Metric depth image with noise growing with range squared (stereo-like)."""
        std = self.noise.depth_m
        if std <= 0.0:
            return depth_m
        # float32 draws and in-place products: a float64 image's draw was 1.8 ms a frame
        noisy = self.rngs['depth'].standard_normal(depth_m.shape, dtype=np.float32)
        with np.errstate(invalid='ignore'):     # inf (nothing seen) stays inf below
            noisy *= depth_m
            noisy *= depth_m
            noisy *= np.float32(std)
            noisy += depth_m
        return np.where(np.isfinite(depth_m), noisy, depth_m)

    def skip_depth(self, shape: tuple[int, int]) -> None:
        """Draw what :meth:`depth` draws for an image of ``shape``, and drop it."""
        if self.noise.depth_m > 0.0:
            self.rngs['depth'].standard_normal(shape, dtype=np.float32)
