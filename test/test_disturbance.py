"""The external-force observer: it finds what nobody commanded or measured, not the contact."""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from uav_tilt_control.disturbance import DisturbanceConfig, DisturbanceObserver

MASS_KG, TAU_S, DT_S = 1.6, 0.025, 1.0 / 300.0


def _run(f_ext, f_contact, seconds=2.0, config=None, yaw=0.4, airborne=True, obs=None):
    """A point mass under a thrust that follows its command with the rotor lag, an external
    force and a contact force; the observer (a new one, or ``obs`` going on) sees the IMU's
    specific force and the F/T."""
    obs = obs or DisturbanceObserver(MASS_KG, TAU_S, config or DisturbanceConfig())
    R = Rotation.from_euler('z', yaw).as_matrix()
    thrust = np.array([0.0, 0.0, MASS_KG * 9.81])
    rng = np.random.default_rng(0)
    for k in range(int(seconds / DT_S)):
        cmd = np.array([0.3 * np.sin(k * DT_S * 3), 0.0, MASS_KG * 9.81])  # manoeuvring
        obs.commanded(cmd)
        thrust = thrust + (1 - np.exp(-DT_S / TAU_S)) * (cmd - thrust)
        specific = R.T @ (thrust + f_ext + f_contact) / MASS_KG + rng.normal(0, 0.02, 3)
        obs.update(R, specific, f_contact, DT_S, airborne)
    return obs


def test_finds_a_steady_external_force_while_manoeuvring():
    f = _run(np.array([1.2, -0.7, 0.3]), np.zeros(3)).f_ext_map
    np.testing.assert_allclose(f, [1.2, -0.7, 0.3], atol=0.03)


def test_leaves_the_measured_contact_force_out():
    f = _run(np.array([0.5, 0.0, 0.0]), np.array([-5.0, 0.4, 0.0])).f_ext_map
    np.testing.assert_allclose(f, [0.5, 0.0, 0.0], atol=0.03)


def test_axes_bound_and_off():
    f = _run(np.array([3.0, 0.0, 2.0]), np.zeros(3),
             config=DisturbanceConfig(axes=[1, 1, 0], limit_n=1.0)).f_ext_map
    assert f[2] == 0.0 and np.linalg.norm(f) == pytest.approx(1.0)
    off = _run(np.ones(3), np.zeros(3), config=DisturbanceConfig(tau_s=0.0))
    assert np.all(off.f_ext_map == 0.0)


def test_on_the_ground_the_vertical_axis_is_off():
    # the ground's reaction (here the whole weight the thrust does not carry) is no wind
    weight = np.array([0.0, 0.0, MASS_KG * 9.81])
    f = _run(np.array([0.5, -0.2, 0.0]) + weight, np.zeros(3), airborne=False).f_ext_map
    np.testing.assert_allclose(f, [0.5, -0.2, 0.0], atol=0.03)


def test_meeting_the_ground_holds_the_vertical_estimate_it_had_in_the_air():
    # in the air the vertical estimate carries what the weight model misses; landing, the
    # ground takes over part of the weight: the estimate keeps what it had, so the thrust
    # does not step when the landing starts
    rng = np.random.default_rng()
    f_air = rng.uniform(-1.0, 1.0, 3)
    obs = _run(f_air, np.zeros(3))
    np.testing.assert_allclose(obs.f_ext_map, f_air, atol=0.03)
    z_air = obs.f_ext_map[2]
    reaction = np.array([0.0, 0.0, rng.uniform(0.5, 1.0) * MASS_KG * 9.81])
    f_wind = rng.uniform(-1.0, 1.0, 3)
    f = _run(f_wind + reaction, np.zeros(3), airborne=False, obs=obs).f_ext_map
    np.testing.assert_allclose(f, [*f_wind[:2], z_air], atol=0.03)
