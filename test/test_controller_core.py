"""ControllerCore without a plant: wiring, frames, guards (the closed loop is test_closed_loop)."""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from uav_tilt_common.config import ConfigError, from_dict
from uav_tilt_common.planes import Plane
from uav_tilt_common.state import VehicleState
from uav_tilt_common.vehicle import GRAVITY, VehicleParams
from uav_tilt_control.controller_core import ControllerConfig, ControllerCore
from uav_tilt_control.impedance import contact_depth_for_force
from uav_tilt_control.types import ImpedanceSetpoint

VEHICLE = VehicleParams()
DT_S = 1.0 / 300.0
WALL_NORMAL = np.array([-1.0, 0.0, 0.0])     # a wall ahead (+x), facing the vehicle


def _state(t_s, yaw_rad=0.0, p=(0.0, 0.0, 0.1)):
    return VehicleState(t_s, np.array(p, dtype=float),
                        Rotation.from_euler('z', yaw_rad).as_quat(), np.zeros(3), np.zeros(3))


def _core(**kw):
    core = ControllerCore(VEHICLE, from_dict(ControllerConfig, dict(
        target_source='ground_truth', **kw)))
    # target frame z_t = the wall normal
    q_map_t = Rotation.from_matrix(np.column_stack([[0, -1, 0], [0, 0, 1], WALL_NORMAL]))
    assert core.on_ground_truth_target([2.5, 0.0, 1.5], q_map_t.as_quat())
    return core


def test_the_law_holds_the_mission_s_push_with_its_own_contact_k_z():
    core = _core(**{'flight.impedance.contact.wn_rad_s': [4.0, 4.0, 5.0],
                    'contact_force': 3.0})
    k_z = VEHICLE.mass_kg * 5.0 ** 2
    assert core.mission.contact_force_n == 3.0
    law, weight_n = core.flight.impedance, VEHICLE.mass_kg * GRAVITY
    push = ImpedanceSetpoint(lambda_d_t=np.array([0.0, 0.0, 1.5]), push_n=3.0,
                             contact_gains=True)
    # at rest push / K_z behind the reference: no spring force, the weight alone
    at_depth = law.update(np.array([0.0, 0.0, 1.5 - contact_depth_for_force(3.0, k_z)]),
                          np.zeros(3), push, np.zeros(3), 1.0 / 300.0)
    np.testing.assert_allclose(at_depth, [0.0, 0.0, weight_n], atol=1e-9)
    # at the reference itself the spring pulls back with the push
    at_reference = law.update(np.array([0.0, 0.0, 1.5]), np.zeros(3), push, np.zeros(3),
                              1.0 / 300.0)
    np.testing.assert_allclose(at_reference, [0.0, 0.0, weight_n - 3.0], atol=1e-9)


def test_contact_force_at_or_above_the_force_limit_is_refused():
    with pytest.raises(ConfigError, match='contact_force'):
        _core(contact_force=16.0)


def test_idle_and_before_odometry_the_rotors_are_off():
    core = _core()
    command, status = core.tick(0.0, np.zeros(3), DT_S)
    assert np.all(command.thrusts_n == 0.0) and status['input_fault']
    core.on_odometry(_state(0.0))
    command, status = core.tick(0.0, np.zeros(3), DT_S)
    assert status['mode'] == 'IDLE' and np.all(command.thrusts_n == 0.0)


def test_autostart_takes_off_and_commands_stay_finite_and_non_negative():
    core = _core(autostart='inspect')
    for k in range(300):
        core.on_odometry(_state(k * DT_S))
        gyro = np.full(3, np.nan) if k == 150 else np.zeros(3)
        command, status = core.tick(k * DT_S, gyro, DT_S)
        assert np.all(np.isfinite(command.as_array()))
        assert np.all(command.thrusts_n >= 0.0)
    assert status['mode'] == 'TAKEOFF'
    assert np.sum(command.thrusts_n) > 0.0


def test_autostart_with_the_target_from_vision_waits_for_vision():
    core = ControllerCore(VEHICLE, from_dict(ControllerConfig, dict(autostart='inspect')))
    for k in range(30):
        core.on_odometry(_state(k * DT_S))
        status = core.tick(k * DT_S, np.zeros(3), DT_S)[1]
        assert status['mode'] == 'IDLE'
    core.on_target_candidates(30 * DT_S, [])        # a frame without a target
    core.on_odometry(_state(30 * DT_S))
    assert core.tick(30 * DT_S, np.zeros(3), DT_S)[1]['mode'] == 'TAKEOFF'


def test_a_held_autostart_waits_until_released():
    # the node holds it (hold_until_recorded) until a recorder listens to the status
    core = _core(autostart='inspect')
    core.autostart_held = True
    for k in range(30):
        core.on_odometry(_state(k * DT_S))
        assert core.tick(k * DT_S, np.zeros(3), DT_S)[1]['mode'] == 'IDLE'
    core.autostart_held = False
    core.on_odometry(_state(30 * DT_S))
    assert core.tick(30 * DT_S, np.zeros(3), DT_S)[1]['mode'] == 'TAKEOFF'


def test_wrench_is_rotated_to_map_and_the_push_is_positive():
    # facing the wall, yawed: the wall pushes back along -x_FLU = +normal
    core = _core()
    core.on_odometry(_state(0.0, yaw_rad=0.0))
    core.on_wrench([-4.0, 0.0, 0.0], np.zeros(3))
    core.tick(0.0, np.zeros(3), DT_S)
    assert core.f_normal_n == pytest.approx(4.0)
    # yawed 90 deg the same reading is a force along -y_map: no push on this wall
    core.on_odometry(_state(DT_S, yaw_rad=np.pi / 2))
    core.on_wrench([-4.0, 0.0, 0.0], np.zeros(3))
    core.tick(DT_S, np.zeros(3), DT_S)
    assert core.f_normal_n == pytest.approx(0.0, abs=1e-9)


def test_ground_truth_is_ignored_with_vision_and_no_target_frames_are_counted():
    core = ControllerCore(VEHICLE, ControllerConfig(target_source='vision'))
    assert not core.on_ground_truth_target([2.5, 0.0, 1.5], [0.0, 0.0, 0.0, 1.0])
    core.on_odometry(_state(0.0))
    # a frame without candidates: vision saw no target
    assert not core.on_target_candidates(0.0, [])
    assert core.estimator.counters['no_target'] == 1
    _, status = core.tick(0.0, np.zeros(3), DT_S)
    assert not status['target_valid'] and status['target_source'] == 'vision'


def test_planes_reach_the_mission_in_map_with_the_pose_at_their_stamp():
    core = ControllerCore(VEHICLE, ControllerConfig(target_source='vision'))
    seen = []
    core.mission.observe_plane = lambda p, n, share: seen.append((p, n, share))
    # yawed to +y, moving 0.2 m along x between the odometry states: the frame's stamp is
    # halfway, so the plane is placed from x = 1.1
    core.on_odometry(_state(0.0, np.pi / 2, (1.0, 2.0, 1.5)))
    core.on_odometry(_state(0.1, np.pi / 2, (1.2, 2.0, 1.5)))
    plane = Plane(np.array([0.0, 0.0, 3.0]), np.array([0.0, 0.0, -1.0]), 0.4)
    assert core.on_planes(0.05, [plane]) == 1
    (p_map, n_map, share), = seen
    camera = VEHICLE.camera_in_base()
    # the optical axis is the body's x (now map +y); the plane 3 m along it, facing back
    cam_map = np.array([1.1 - camera.p[1], 2.0 + camera.p[0], 1.5 + camera.p[2]])
    np.testing.assert_allclose(p_map, cam_map + [0.0, 3.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(n_map, [0.0, -1.0, 0.0], atol=1e-9)
    assert share == 0.4
    # a frame older than the pose history, or a broken stamp: nothing moved
    assert core.on_planes(-5.0, [plane]) == 0 and core.on_planes(float('nan'), [plane]) == 0
    assert len(seen) == 1
