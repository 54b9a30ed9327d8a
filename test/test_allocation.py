"""Allocation: exact inverse of the rotor model, PX4 saturation order, never NaN."""
import numpy as np

from uav_tilt_common.geometry import rotor_wrench_flu
from uav_tilt_common.vehicle import VehicleParams
from uav_tilt_control.allocation import AllocationConfig, Allocator

VEHICLE = VehicleParams()


def _wrench(result):
    force, torque = rotor_wrench_flu(result.thrusts_n, result.alpha_rad, result.beta_rad,
                                     VEHICLE.l1_m, VEHICLE.l2_m, VEHICLE.k_m)
    return force, torque


def test_round_trip_is_exact_for_unsaturated_wrenches():
    rng = np.random.default_rng(1)
    allocator = Allocator(VEHICLE)
    checked = 0
    for _ in range(500):
        force_xz = np.array([rng.uniform(-8, 8), rng.uniform(8, 25)])
        torque = rng.uniform(-0.3, 0.3, 3) * [1.0, 1.0, 0.3]
        result = allocator.allocate(force_xz, torque)
        if result.saturated:
            continue
        force, torque_got = _wrench(result)
        np.testing.assert_allclose(force, [force_xz[0], 0.0, force_xz[1]], atol=1e-9)
        np.testing.assert_allclose(torque_got, torque, atol=1e-9)
        assert result.alpha_rad == result.beta_rad
        np.testing.assert_allclose(result.torque_given_up_nm, 0.0, atol=1e-9)
        checked += 1
    assert checked > 300


def test_hover_is_equal_thrusts_at_zero_tilt():
    result = Allocator(VEHICLE).allocate([0.0, VEHICLE.mass_kg * 9.80665], np.zeros(3))
    np.testing.assert_allclose(result.thrusts_n, VEHICLE.hover_thrust_n, rtol=1e-12)
    assert result.alpha_rad == 0.0 and not result.saturated


def test_big_yaw_torque_gives_up_yaw_only():
    allocator = Allocator(VEHICLE)
    force_xz = np.array([3.0, 16.0])
    torque = np.array([0.2, -0.15, 5.0])   # far beyond the yaw authority
    result = allocator.allocate(force_xz, torque)
    force, torque_got = _wrench(result)
    assert result.saturated
    np.testing.assert_allclose(force[[0, 2]], force_xz, atol=1e-9)
    np.testing.assert_allclose(torque_got[:2], torque[:2], atol=1e-9)
    # Some yaw is still produced, in the commanded direction, and the rest is reported.
    assert 0.0 < torque_got[2] < torque[2]
    assert abs(result.yaw_given_up_nm - (torque[2] - torque_got[2])) < 1e-9
    # Yaw was pushed until a rotor hit a bound: no more was available.
    bound = np.isclose(result.thrusts_n, 0.0, atol=1e-9) | np.isclose(
        result.thrusts_n, VEHICLE.f_max_n, atol=1e-9)
    assert bound.any()


def test_big_roll_torque_is_scaled_keeping_its_direction_and_the_force():
    allocator = Allocator(VEHICLE)
    force_xz = np.array([0.0, 16.0])
    torque = np.array([20.0, 10.0, 0.0])
    result = allocator.allocate(force_xz, torque)
    force, torque_got = _wrench(result)
    assert result.saturated
    np.testing.assert_allclose(force[[0, 2]], force_xz, atol=1e-9)
    scale = torque_got[0] / torque[0]
    assert 0.0 < scale < 1.0
    np.testing.assert_allclose(torque_got[:2], scale * torque[:2], atol=1e-9)


def test_tilt_limit_keeps_vertical_force():
    allocator = Allocator(VEHICLE)
    result = allocator.allocate([50.0, 10.0], np.zeros(3))
    force, _ = _wrench(result)
    assert abs(result.alpha_rad - VEHICLE.tilt_limit_rad) < 1e-12
    assert abs(force[2] - 10.0) < 1e-9
    assert result.saturated and result.force_given_up_n[0] > 0.0


def test_garbage_inputs_never_give_nan_or_out_of_range_thrust():
    rng = np.random.default_rng(7)
    allocator = Allocator(VEHICLE, AllocationConfig(min_thrust_n=0.2))
    specials = [np.nan, np.inf, -np.inf, 1e308, -1e308, 0.0, 1e-300]
    for _ in range(2000):
        force = rng.normal(0, 1, 2) * 10.0 ** rng.uniform(-3, 300, 2)
        torque = rng.normal(0, 1, 3) * 10.0 ** rng.uniform(-3, 300, 3)
        if rng.random() < 0.3:
            force[rng.integers(2)] = rng.choice(specials)
            torque[rng.integers(3)] = rng.choice(specials)
        result = allocator.allocate(force, torque)
        assert np.all(np.isfinite(result.thrusts_n))
        assert np.all(result.thrusts_n >= 0.2) and np.all(result.thrusts_n <= VEHICLE.f_max_n)
        assert abs(result.alpha_rad) <= VEHICLE.tilt_limit_rad
        assert np.all(np.isfinite(result.torque_given_up_nm))
        assert np.all(np.isfinite(result.force_given_up_n))
