"""Impedance law on a point mass: the closed loop is eq. (6), M e'' + C e' + K e = F_c."""
import dataclasses

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from uav_tilt_common.config import ConfigError, from_dict
from uav_tilt_common.vehicle import GRAVITY, VehicleParams
from uav_tilt_control.impedance import (ContactGains, ImpedanceConfig, ImpedanceController,
                                        ImpedanceGains, contact_depth_for_force)
from uav_tilt_control.types import ImpedanceSetpoint

MASS_KG = VehicleParams().mass_kg
DT_S = 1.0 / 300.0


def _simulate(controller, setpoint, f_ext_map, duration_s, p0_map=None):
    """Point mass under F_p + gravity + F_ext (semi-implicit Euler at the control rate).

    The controller sees the same F_ext as its contact measurement. Returns positions (map).
    """
    p = np.zeros(3) if p0_map is None else np.array(p0_map, dtype=float)
    v = np.zeros(3)
    gravity = np.array([0.0, 0.0, -MASS_KG * GRAVITY])
    out = []
    for _ in range(int(round(duration_s / DT_S))):
        f_p = controller.update(p, v, setpoint, f_ext_map, DT_S)
        v = v + (f_p + gravity + f_ext_map) / MASS_KG * DT_S
        p = p + v * DT_S
        out.append(p.copy())
    return np.array(out)


def _zeta_from_overshoot(overshoot_ratio):
    log = np.log(overshoot_ratio)
    return -log / np.sqrt(np.pi ** 2 + log ** 2)


def _config(wn, zeta, **kwargs):
    gains = ImpedanceGains(wn_rad_s=list(wn), zeta=list(zeta))
    return ImpedanceConfig(free=gains, contact=gains, accel_limit_mps2=50.0, **kwargs)


def test_force_step_displaces_by_f_over_k_with_configured_damping():
    zeta = 0.35
    cfg = _config([3.0, 3.0, 2.0], [0.9, 0.9, zeta])
    controller = ImpedanceController(MASS_KG, cfg)
    k, _ = controller.gains(contact=True)
    f_ext = np.array([0.0, 0.0, 4.0])
    z = _simulate(controller, ImpedanceSetpoint(contact_gains=True), f_ext, 12.0)[:, 2]
    static = f_ext[2] / k[2]
    assert abs(z[-1] - static) < 0.02 * static
    zeta_est = _zeta_from_overshoot((z.max() - static) / static)
    assert abs(zeta_est - zeta) < 0.05


def test_position_step_settles_on_setpoint_in_free_flight():
    controller = ImpedanceController(MASS_KG, ImpedanceConfig())
    setpoint = ImpedanceSetpoint(lambda_d_t=np.array([1.0, -0.5, 1.5]))
    p = _simulate(controller, setpoint, np.zeros(3), 10.0)
    np.testing.assert_allclose(p[-1], setpoint.lambda_d_t, atol=1e-3)


def test_rotated_target_frame_gives_same_error_dynamics():
    cfg = _config([3.0, 2.0, 1.5], [0.7, 0.5, 0.3])
    origin = np.array([2.0, -1.0, 1.5])
    lambda_d = np.array([0.1, -0.2, 0.5])
    f_ext_t = np.array([1.0, -0.5, 3.0])
    reference = None
    for seed in range(4):
        R_map_t = np.eye(3) if seed == 0 else Rotation.random(random_state=seed).as_matrix()
        setpoint = ImpedanceSetpoint(R_map_t=R_map_t, origin_map=origin, lambda_d_t=lambda_d,
                                     contact_gains=True)
        p_map = _simulate(ImpedanceController(MASS_KG, cfg), setpoint, R_map_t @ f_ext_t, 15.0,
                          p0_map=origin + R_map_t @ lambda_d)
        e_t = (p_map - origin) @ R_map_t - lambda_d
        if reference is None:
            reference = e_t
        else:
            np.testing.assert_allclose(e_t, reference, atol=1e-9)
    k, _ = ImpedanceController(MASS_KG, cfg).gains(contact=True)
    # Selective: each axis of t settles towards its own F_c / K.
    np.testing.assert_allclose(reference[-1], f_ext_t / k, rtol=0.05)


def test_contact_feedforward_option_cancels_the_contact_force():
    cfg = _config([3.0, 3.0, 2.0], [0.9, 0.9, 0.9], contact_feedforward=True)
    z = _simulate(ImpedanceController(MASS_KG, cfg), ImpedanceSetpoint(),
                  np.array([0.0, 0.0, 4.0]), 10.0)[:, 2]
    # The article's literal eq. (5) turns the law into stiff position holding.
    assert abs(z[-1]) < 1e-3


def test_accel_limit_bounds_the_command():
    cfg = ImpedanceConfig(accel_limit_mps2=3.0)
    controller = ImpedanceController(MASS_KG, cfg)
    f_p = controller.update(np.array([100.0, 0.0, 0.0]), np.zeros(3), ImpedanceSetpoint(),
                            np.zeros(3), DT_S)
    hover = np.array([0.0, 0.0, MASS_KG * GRAVITY])
    assert np.linalg.norm(f_p - hover) == pytest.approx(MASS_KG * 3.0, rel=1e-12)


def test_kc_mode_and_contact_depth():
    gains = ImpedanceGains(mode='kc', k_n_m=[50.0, 50.0, 12.5], c_n_s_m=[9.0, 9.0, 4.0])
    k, c = gains.k_c(MASS_KG)
    np.testing.assert_array_equal(k, [50.0, 50.0, 12.5])
    np.testing.assert_array_equal(c, [9.0, 9.0, 4.0])
    wn_gains = ImpedanceGains(wn_rad_s=[2.0, 2.0, 2.0], zeta=[0.5, 0.5, 0.5])
    k, c = wn_gains.k_c(2.0)
    np.testing.assert_allclose(k, 8.0)
    np.testing.assert_allclose(c, 4.0)
    assert contact_depth_for_force(5.0, 12.5) == pytest.approx(0.4)
    with pytest.raises(ValueError):
        contact_depth_for_force(5.0, 0.0)


def test_config_defaults_survive_loading_and_are_consistent():
    assert from_dict(ImpedanceConfig, {}) == ImpedanceConfig()
    cfg = from_dict(ImpedanceConfig, {'contact.mode': 'kc', 'contact.k_n_m': [40.0, 40.0, 8.0]})
    assert cfg.contact.k_c(MASS_KG)[0][2] == 8.0 and cfg.free == ImpedanceGains()
    with pytest.raises(ConfigError):
        from_dict(ImpedanceConfig, {'contact.zeta': [0.9, 0.9, -1.0]})
    # The direct K, C defaults describe the same spring-damper as wn, zeta for the vehicle.
    for gains in (ImpedanceGains(), ContactGains()):
        k_c_direct = dataclasses.replace(gains, mode='kc').k_c(MASS_KG)
        np.testing.assert_allclose(k_c_direct, gains.k_c(MASS_KG), rtol=1e-9)
    # Selective contact set: the normal z_t is more compliant than the wall axes.
    k, _ = ContactGains().k_c(MASS_KG)
    assert k[2] < k[0] and k[2] < k[1]


def test_hover_estimator_removes_the_altitude_offset_of_a_mass_mismatch():
    """A plant 8% heavier than the model: without the estimator the vehicle sags by
    0.08 M g / K_z; with it the vertical error vanishes, while horizontal compliance stays."""
    true_mass = 1.08 * MASS_KG
    weight_error = np.array([0.0, 0.0, -(true_mass - MASS_KG) * GRAVITY])
    f_push = np.array([1.0, 0.0, 0.0])

    def final_position(tau_s):
        cfg = dataclasses.replace(ImpedanceConfig(), hover_estimator_tau_s=tau_s)
        controller = ImpedanceController(MASS_KG, cfg)
        # The model's missing weight acts like an external downward force.
        p = _simulate(controller, ImpedanceSetpoint(), weight_error + f_push, 30.0)[-1]
        return p, controller.gains(contact=False)[0]

    p_off, k = final_position(0.0)
    assert p_off[2] == pytest.approx(weight_error[2] / k[2], rel=0.02)
    p_on, _ = final_position(2.0)
    assert abs(p_on[2]) < 0.01 * abs(p_off[2])
    assert p_on[0] == pytest.approx(f_push[0] / k[0], rel=0.02)


def test_hover_estimator_is_frozen_in_contact():
    controller = ImpedanceController(MASS_KG, ImpedanceConfig())
    f_ext = np.array([0.0, 0.0, -2.0])
    z = _simulate(controller, ImpedanceSetpoint(contact_gains=True), f_ext, 20.0)[-1, 2]
    k, _ = controller.gains(contact=True)
    assert controller.f_hover_n == 0.0
    assert z == pytest.approx(f_ext[2] / k[2], rel=0.02)


def _push_on_a_wall(controller, push_n, k_wall_n_per_m, duration_s, trim):
    """A point mass held against a wall of stiffness ``k_wall_n_per_m`` (x = 1, normal -x)
    by a setpoint at the surface that asks for ``push_n``; returns the wall's pushes."""
    R_map_t = np.column_stack([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [-1.0, 0.0, 0.0]])
    setpoint = ImpedanceSetpoint(R_map_t=R_map_t, origin_map=np.array([1.0, 0.0, 0.0]),
                                 push_n=push_n, trim_push=trim, contact_gains=True)
    p, v = np.array([1.0, 0.0, 0.0]), np.zeros(3)
    gravity = np.array([0.0, 0.0, -MASS_KG * GRAVITY])
    pushes = []
    for _ in range(int(round(duration_s / DT_S))):
        f_wall = np.array([-k_wall_n_per_m * max(p[0] - 1.0, 0.0), 0.0, 0.0])
        f_p = controller.update(p, v, setpoint, f_wall, DT_S)
        v = v + (f_p + gravity + f_wall) / MASS_KG * DT_S
        p = p + v * DT_S
        pushes.append(-f_wall[0])
    return np.array(pushes)


def test_the_trim_gets_a_soft_wall_the_push_asked_for():
    # a wall that gives way takes part of the depth: the spring alone pushes less
    rng = np.random.default_rng()
    k_wall, push_n = float(np.exp(rng.uniform(np.log(30.0), np.log(300.0)))), rng.uniform(2, 8)
    config = ImpedanceConfig()
    k_z = config.contact.k_c(MASS_KG)[0][2]
    settle_s = 10.0 * config.force_tau_s + 8.0
    untrimmed = _push_on_a_wall(ImpedanceController(MASS_KG, config), push_n, k_wall,
                                settle_s, trim=False)
    # springs in series: the law's K_z and the wall's
    assert untrimmed[-1] == pytest.approx(push_n * k_wall / (k_wall + k_z), rel=0.01)
    trimmed = _push_on_a_wall(ImpedanceController(MASS_KG, config), push_n, k_wall, settle_s,
                              trim=True)
    assert trimmed[-1] == pytest.approx(push_n, abs=0.01 * push_n)


def test_the_trim_is_let_go_with_the_push():
    law = ImpedanceController(MASS_KG)
    _push_on_a_wall(law, 5.0, 50.0, 6.0, trim=True)
    assert law.trim_n > 0.5                     # it held the soft wall's missing push
    ratio = law.trim_n / 5.0
    hold = dict(R_map_t=np.eye(3), contact_gains=True)
    for push_n in np.linspace(5.0, 0.0, 50):
        law.update(np.zeros(3), np.zeros(3), ImpedanceSetpoint(push_n=push_n, **hold),
                   np.zeros(3), DT_S)
        assert law.trim_n == pytest.approx(ratio * push_n)
    assert law.trim_n == 0.0
