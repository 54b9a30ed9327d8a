"""Sensor noise models: the spread each one promises, and streams that do not share draws."""
import numpy as np
import pytest

from uav_tilt_sim.scenario import NoiseConfig
from uav_tilt_sim.sensors import SensorModel


def test_depth_noise_grows_with_range_squared_and_leaves_nothing_seen_alone():
    std = 0.002
    seed = int(np.random.SeedSequence().entropy % 2**31)     # a fresh draw every run
    model = SensorModel(NoiseConfig(depth_m=std), seed)
    depth = np.full((240, 320), np.inf, dtype=np.float32)
    depth[:80] = 0.5
    depth[80:160] = 4.0
    noisy = model.depth(depth)
    assert noisy.dtype == np.float32 and noisy.shape == depth.shape
    assert np.isinf(noisy[160:]).all()
    for rows, range_m in ((slice(0, 80), 0.5), (slice(80, 160), 4.0)):
        error = noisy[rows].astype(float) - range_m
        expected = std * range_m ** 2
        # 25,600 draws: the sample std within 2%, the mean within 5 standard errors
        assert error.std() == pytest.approx(expected, rel=0.02)
        assert abs(error.mean()) < 5 * expected / np.sqrt(error.size)


def test_reading_the_camera_does_not_change_the_imus_noise():
    noise = NoiseConfig(imu_gyro_rad_s=0.01, depth_m=0.002)
    quiet, busy = SensorModel(noise, seed=5), SensorModel(noise, seed=5)
    busy.depth(np.ones((24, 32), dtype=np.float32))
    assert np.array_equal(quiet.gyro(np.zeros(3)), busy.gyro(np.zeros(3)))
