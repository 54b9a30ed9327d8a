"""Tests for uav_tilt_control.mission, driven by a synthetic perfect tracker.

The "vehicle" is wherever the previous setpoint put it, except that the wall stops the tool
tip and the ground stops the body; while pushed against the wall with contact gains it
measures the impedance spring force K_z * (tool_tip_x - lambda_d_z).
"""
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from uav_tilt_common.config import ConfigError, from_dict
from uav_tilt_common.state import VehicleState
from uav_tilt_common.vehicle import GRAVITY, VehicleParams
from uav_tilt_common.modes import Mode
from uav_tilt_control.impedance import ImpedanceConfig
from uav_tilt_control.obstacles import ObstacleBox
from uav_tilt_control.mission import Mission, MissionConfig
from uav_tilt_control.trajectory import MinJerk
from uav_tilt_control.target_estimator import TargetEstimate

DT_S = 0.01
P_POI = np.array([3.0, 0.5, 1.5])
NORMAL = np.array([-1.0, 0.0, 0.0])
GEAR_Z_M = 0.1          # body origin height when standing on the ground
VEHICLE = VehicleParams()
WEIGHT_N = VEHICLE.mass_kg * GRAVITY
PERFECT = TargetEstimate(P_POI, NORMAL, 0.02, True)
# the impedance law's contact K_z, with which it holds a push as a depth (eq. (6) at rest)
K_Z_N_PER_M = ImpedanceConfig().contact.k_c(VEHICLE.mass_kg)[0][2]


def pushed_t(sp):
    """(lambda_d, dlambda_d) in frame t as the impedance law tracks them: the push held
    push_n / K_z behind the setpoint's reference."""
    z_t = np.array([0.0, 0.0, 1.0])
    return sp.lambda_d_t - sp.push_n / K_Z_N_PER_M * z_t, \
        sp.dlambda_d_t - sp.dpush_n_s / K_Z_N_PER_M * z_t


class Flight:
    """Mission + perfect tracker + wall + ground, stepped at DT_S.

    ``target``: what vision reports each tick (:meth:`seen`); ``wall``: (a point on it, its
    normal, how far from that point it reaches), by default the target's, within 1 m;
    ``plan``: the mission's plan; ``obstacles``: the site's; :attr:`thrust_up_n`: the
    vertical thrust the flight core asks for, the model's weight (a vehicle as heavy as its
    model, in the air) unless a test sets it.
    """

    def __init__(self, config=None, target=PERFECT, plan=None, wall=None, obstacles=()):
        self.config = config or MissionConfig()
        self.target = target
        self.wall = wall or (target.p_poi_map, target.normal_map, 1.0)
        self.mission = Mission(VEHICLE, self.config, plan=plan, obstacles=obstacles)
        self.t_s = 0.0
        self.p = np.array([0.0, 0.0, GEAR_Z_M])
        self.v = np.zeros(3)
        self.q = np.array([0.0, 0.0, 0.0, 1.0])
        self.force_n = 0.0
        self.thrust_up_n = WEIGHT_N
        self.modes = [Mode.IDLE]
        self.log = []
        self.phases = []        # the mission's phase at each logged tick
        self.forces = []        # the simulated F/T reading at each logged tick
        self.attitudes = []     # the vehicle's attitude (quaternion) at each logged tick
        self.step()

    def state(self):
        return VehicleState(self.t_s, self.p.copy(), self.q.copy(), self.v.copy(), np.zeros(3))

    def seen(self):
        """The target vision reports this tick."""
        return self.target

    def step(self, target='default', force_n=None, odom_age_s=0.0, f_map=None):
        """One tick; ``target`` overrides :meth:`seen`, ``force_n`` the simulated F/T
        reading; ``f_map`` gives its whole force on the vehicle (map)."""
        target = self.seen() if target == 'default' else target
        f = self.force_n if force_n is None else force_n
        sp = self.mission.update(self.t_s, self.state(), target, f, odom_age_s, f_map,
                                 self.thrust_up_n)
        self.log.append((self.t_s, self.mission.mode, sp, self.p.copy()))
        self.phases.append(self.mission.phase)
        self.forces.append(self.force_n)
        self.attitudes.append(self.q.copy())
        if self.mission.mode != self.modes[-1]:
            self.modes.append(self.mission.mode)
        self._track(sp)
        self.t_s += DT_S
        return sp

    def _track(self, sp):
        lambda_t, dlambda_t = pushed_t(sp)
        p = sp.origin_map + sp.R_map_t @ lambda_t
        v = sp.R_map_t @ dlambda_t
        self.force_n = 0.0
        point, normal, reach_m = self.wall
        gap = (p - point) @ normal - VEHICLE.tool_tip_x_m
        if gap < 0.0 and np.linalg.norm(p - point) < reach_m:
            p = p - gap * normal
            v = v - (v @ normal) * normal
            if sp.contact_gains:
                self.force_n = -gap * K_Z_N_PER_M
        if p[2] < GEAR_Z_M:
            p[2], v = GEAR_Z_M, np.zeros(3)
        self.p, self.v = p, v
        self.q = Rotation.from_euler('ZY', [sp.yaw_rad, sp.pitch_rad]).as_quat()

    def touch(self, f_map, **kw):
        """Hold the F/T force ``f_map`` on the vehicle, as a touch does, until the mission
        reacts (its mode or phase changes), which must be within :func:`touch_ticks`.
        Returns where the vehicle was when it reacted."""
        before = (self.mission.mode, self.mission.phase)
        for _ in range(touch_ticks(self.config, f_map, DT_S)):
            p = self.p.copy()
            self.step(f_map=f_map, **kw)
            if (self.mission.mode, self.mission.phase) != before:
                return p
        raise AssertionError(f'{f_map} N held: no reaction in {before}')

    def run_until(self, predicate, timeout_s=400.0, **kw):
        t_end = self.t_s + timeout_s
        while not predicate(self):
            assert self.t_s < t_end, f'timed out in {self.mission.mode}'
            self.step(**kw)

    def run_for(self, duration_s, **kw):
        for _ in range(int(round(duration_s / DT_S))):
            self.step(**kw)

    def run_to(self, mode, timeout_s=60.0, **kw):
        self.run_until(lambda f: f.mission.mode == mode, timeout_s, **kw)


def touch_ticks(config, f_map, dt_s):
    """Ticks of ``dt_s`` in which a force ``f_map`` held from rest is felt: its first-order
    low-pass (free_flight_contact_tau_s) passes free_flight_contact_n after
    tau ln(F / (F - F_min)), so within the tick after that."""
    f_n = float(np.linalg.norm(f_map))
    felt_s = config.bump.tau_s * math.log(
        f_n / (f_n - config.bump.threshold_n))
    return math.floor(felt_s / dt_s) + 1


def _hovering(config=None):
    flight = Flight(config)
    assert flight.mission.takeoff()[0]
    flight.run_to(Mode.HOVER)
    return flight


def _in_mode(mode, config=None):
    flight = Flight(config)
    assert flight.mission.inspect()[0]
    flight.run_to(mode, timeout_s=120.0)
    return flight


# a wall leaning back, north of the start point: the tool must yaw and pitch down to face it
INCLINED = TargetEstimate(np.array([-1.0, 2.5, 1.8]),
                          np.array([0.0, -0.9, 0.3]) / np.hypot(0.9, 0.3), 0.02, True)


@pytest.mark.parametrize('target', [PERFECT, INCLINED])
def test_happy_path_visits_every_mode_and_succeeds(target):
    flight = Flight(target=target)
    ok, _ = flight.mission.inspect()
    assert ok
    flight.run_until(lambda f: f.mission.mode == Mode.IDLE, 150.0)
    assert flight.modes == [Mode.IDLE, Mode.TAKEOFF, Mode.HOVER, Mode.SEARCH, Mode.APPROACH,
                            Mode.CONTACT, Mode.HOLD, Mode.RETREAT, Mode.LAND, Mode.IDLE]
    status = flight.mission.status
    assert status['success'] and status['inspection_completed']
    assert status['contact_lost'] == 0 and status['failsafe_reason'] == ''

    cfg, tip = flight.config, VEHICLE.tool_tip_x_m
    by_mode = {}
    for t, mode, sp, p in flight.log:
        by_mode.setdefault(mode, []).append((t, sp, p))
    # the ground may carry the vehicle before and while it takes off and lands, not between
    airborne = {mode: {sp.airborne for _, sp, _ in ticks} for mode, ticks in by_mode.items()}
    assert [airborne.pop(m) for m in (Mode.IDLE, Mode.TAKEOFF, Mode.LAND)] == [{False}] * 3
    assert all(flags == {True} for flags in airborne.values())
    # the standoff point: tool tip standoff_m from the surface, on the normal through the POI
    _, sp_end, p_end = by_mode[Mode.APPROACH][-1]
    r = p_end - target.p_poi_map
    assert r @ target.normal_map == pytest.approx(cfg.contact.standoff_m + tip,
                                                  abs=cfg.flight.arrive_tol_m)
    assert np.linalg.norm(np.cross(r, target.normal_map)) < cfg.flight.arrive_tol_m
    # the tool (x_FLU) points into the wall along the normal, so it reaches the POI
    x_flu = Rotation.from_euler('ZY', [sp_end.yaw_rad, sp_end.pitch_rad]).apply([1, 0, 0])
    np.testing.assert_allclose(x_flu, -target.normal_map, atol=cfg.flight.arrive_yaw_tol_rad)
    # HOLD: desired position behind the surface by F_d / K_z, held for hold_time_s
    hold = by_mode[Mode.HOLD]
    mission = flight.mission
    assert pushed_t(hold[-1][1])[0][2] == pytest.approx(tip - mission.contact_force_n
                                                        / K_Z_N_PER_M)
    assert hold[-1][0] - hold[0][0] == pytest.approx(cfg.contact.hold_time_s, abs=2 * DT_S)
    # compliant in contact, and while the retreat reference is still behind the surface
    assert all(sp.contact_gains == (mode in (Mode.CONTACT, Mode.HOLD) or (
        mode == Mode.RETREAT and pushed_t(sp)[0][2] < tip)) for _, mode, sp, _ in flight.log)
    assert any(mode == Mode.RETREAT and sp.contact_gains for _, mode, sp, _ in flight.log)
    assert flight.p[2] == pytest.approx(GEAR_Z_M)


class NoisyFlight(Flight):
    """A Flight whose odometry velocity and F/T force carry white noise of ``sigma_v_m_s``
    and ``sigma_f_n`` per axis, drawn afresh every tick."""

    def __init__(self, sigma_v_m_s, sigma_f_n, config=None):
        self.rng = np.random.default_rng()
        self.sigma_v_m_s, self.sigma_f_n = sigma_v_m_s, sigma_f_n
        super().__init__(config)

    def state(self):
        state = super().state()
        state.v_map = state.v_map + self.sigma_v_m_s * self.rng.normal(size=3)
        return state

    def step(self, target='default', force_n=None, odom_age_s=0.0, f_map=None):
        noise = self.sigma_f_n * self.rng.normal(size=3)
        force_n = (self.force_n if force_n is None else force_n) + noise @ NORMAL
        f_map = noise if f_map is None else f_map + noise
        return super().step(target, force_n, odom_age_s, f_map)


def test_sensor_noise_in_free_flight_is_no_touch_and_the_vehicle_lands():
    # Fresh noise where the raw samples decide wrong: the F/T's 3-axis norm past 1 N once
    # in a thousand ticks or more (2.9-4 sigma), a third or more of the velocity samples
    # past the 0.1 m/s of arrival and landing.
    rng = np.random.default_rng()
    flight = NoisyFlight(rng.uniform(0.04, 0.08), rng.uniform(0.25, 0.35))
    cfg = flight.config
    assert flight.mission.takeoff()[0]
    flight.run_to(Mode.HOVER, timeout_s=20.0)
    flight.run_for(30.0)
    assert flight.mission.land()[0]
    flight.run_until(lambda f: f.p[2] == GEAR_Z_M, 30.0)
    touchdown_s = flight.t_s
    flight.run_to(Mode.IDLE, timeout_s=10.0)
    assert flight.modes == [Mode.IDLE, Mode.TAKEOFF, Mode.HOVER, Mode.LAND, Mode.IDLE]
    assert not [e for e in flight.mission.events if e['reason'].startswith('touched')]
    # landed as without noise: once the low-passed speed has fallen from the descent's to
    # land_detect_speed_m_s, land_detect_s later
    settle_s = cfg.flight.speed_tau_s * math.log(cfg.land.descent_rate_m_s
                                                 / cfg.land.detect_speed_m_s)
    assert flight.t_s - touchdown_s <= settle_s + cfg.land.detect_s + 3 * DT_S


def test_a_noisy_f_t_makes_the_touch_firmer_not_false():
    # F/T noise that passes touch_threshold_n (0.4 N) on two ticks in a row every second or
    # so: the touch is felt where the tool really meets the wall, and the inspection works.
    # Its 4 sigma (1-2 N) is more than touch_overrun_n (1 N), the push the creep reaches
    # past the estimated surface: it must push harder to feel the wall.
    rng = np.random.default_rng()
    sigma_f_n = rng.uniform(0.25, 0.5)
    flight = NoisyFlight(0.0, sigma_f_n)
    assert 4.0 * sigma_f_n >= flight.config.contact.touch_overrun_n
    assert flight.mission.inspect()[0]
    pressed_at_n = []
    while flight.mission.mode != Mode.IDLE:
        assert flight.t_s < 150.0, flight.mission.mode
        was = flight.mission.phase
        truth_n = flight.force_n            # the wall's push this tick, before the noise
        flight.step()
        if was == 'touch' and flight.mission.phase == 'press':
            pressed_at_n.append(truth_n)
    assert flight.modes == [Mode.IDLE, Mode.TAKEOFF, Mode.HOVER, Mode.SEARCH, Mode.APPROACH,
                            Mode.CONTACT, Mode.HOLD, Mode.RETREAT, Mode.LAND, Mode.IDLE]
    assert flight.mission.status['success'], sigma_f_n
    # felt once the wall pushed: within the noise of 4 sigma, not on noise alone
    assert len(pressed_at_n) == 1 and pressed_at_n[0] > 0.0, (sigma_f_n, pressed_at_n)


def test_references_are_consistent_and_speed_limited():
    flight = Flight()
    flight.mission.inspect()
    flight.run_until(lambda f: f.mission.mode == Mode.IDLE, 150.0)
    cfg = flight.config
    v_max = max(cfg.flight.climb_speed_m_s, cfg.contact.approach_speed_m_s,
                cfg.land.descent_rate_m_s)
    prev = None
    for (t, mode, sp, _), phase in zip(flight.log, flight.phases):
        p_map = sp.origin_map + sp.R_map_t @ sp.lambda_d_t
        v_map = sp.R_map_t @ sp.dlambda_d_t
        a_map = sp.R_map_t @ sp.ddlambda_d_t
        assert np.linalg.norm(v_map) <= v_max * (1 + 1e-9)
        if phase in ('touch', 'align', 'press'):
            # by design not a smooth segment: a guarded move at constant speed, then a
            # quasi-static press whose depth starts with the contact threshold's share
            prev = None
        elif prev is not None:
            # trapezoidal rule: the error is bounded by the jerk, tiny for these segments
            assert np.allclose(p_map - prev[0], 0.5 * (v_map + prev[1]) * DT_S, atol=1e-5)
            assert np.allclose(v_map - prev[1], 0.5 * (a_map + prev[2]) * DT_S, atol=1e-4)
        if phase not in ('touch', 'align', 'press'):
            prev = (p_map, v_map, a_map)


def test_nan_setpoint_rejected_and_counted():
    flight = _hovering()
    ok, msg = flight.mission.set_hover_setpoint([np.nan, 0.0, 2.0], 0.0)
    assert not ok and msg
    ok, _ = flight.mission.set_hover_setpoint([0.0, 0.0, 2.0], np.inf)
    assert not ok
    # under ground, or low enough for the landing detector to call it landed
    cfg = flight.mission.config
    for z in (-50.0, cfg.land.ground_z_m + 1.9 * cfg.land.detect_height_m):
        ok, msg = flight.mission.set_hover_setpoint([0.0, 0.0, z], 0.0)
        assert not ok and 'lowest hover' in msg, msg
    assert flight.mission.status['rejected_setpoints'] == 4
    # outside the geofence: too far from the take-off, too high
    home = flight.p.copy()
    radius_m, height_m = cfg.failsafe.fence_radius_m, cfg.failsafe.fence_height_m
    for p, why in (([home[0] + radius_m + 0.1, home[1], 2.0], 'fence_radius_m'),
                   ([home[0], home[1] - 1e12, 2.0], 'fence_radius_m'),
                   ([home[0], home[1], cfg.land.ground_z_m + height_m + 0.1], 'fence_height_m')):
        ok, msg = flight.mission.set_hover_setpoint(p, 0.0)
        assert not ok and 'geofence' in msg and why in msg, msg
    assert flight.mission.status['rejected_setpoints'] == 7
    assert flight.mission.set_hover_setpoint([home[0] + 0.7 * radius_m, home[1], 2.0], 0.0)[0]
    assert flight.mission.mode == Mode.HOVER
    ok, _ = flight.mission.set_hover_setpoint([1.0, -1.0, 2.0], 0.5)
    assert ok
    flight.run_for(10.0)
    np.testing.assert_allclose(flight.p, [1.0, -1.0, 2.0], atol=1e-6)
    assert flight.log[-1][2].yaw_rad == pytest.approx(0.5)
    assert flight.mission.mode == Mode.HOVER


def test_stale_odometry_blind_descent_then_idle():
    flight = _hovering()
    z0 = flight.p[2]
    frozen = flight.state()
    sps = []
    while flight.mission.mode != Mode.IDLE and len(sps) < 3000:
        sps.append(flight.mission.update(flight.t_s, frozen, PERFECT, 0.0, 0.2))
        flight.t_s += DT_S
        if len(sps) == 1:
            assert flight.mission.mode == Mode.FAILSAFE_LAND
    cfg = flight.config
    status = flight.mission.status
    assert status['failsafe_reason'] == 'odometry_stale' and not status['success']
    assert flight.mission.mode == Mode.IDLE
    v_z = np.array([sp.dlambda_d_t[2] for sp in sps])
    assert np.all(v_z <= 1e-12)
    assert v_z.min() == pytest.approx(-cfg.failsafe.descent_rate_m_s, rel=1e-3)
    assert all(sp.pitch_rad == 0.0 and not sp.contact_gains for sp in sps)
    assert sps[-1].lambda_d_t[2] == pytest.approx(cfg.land.ground_z_m)
    # blind: idle only after the whole descent plus the margin
    t_descent = 1.875 * (z0 - cfg.land.ground_z_m) / cfg.failsafe.descent_rate_m_s
    assert len(sps) * DT_S >= t_descent + cfg.failsafe.land_margin_s


def test_nonfinite_state_counts_as_stale():
    flight = _hovering()
    bad = flight.state()
    bad.p_map[0] = np.nan
    flight.mission.update(flight.t_s, bad, PERFECT, 0.0, 0.0)
    assert flight.mission.mode == Mode.FAILSAFE_LAND


def test_force_above_limit_retreats_then_lands():
    flight = _in_mode(Mode.HOLD)
    flight.step(force_n=flight.config.failsafe.force_limit_n + 1.0)
    assert flight.mission.mode == Mode.RETREAT
    assert flight.mission.status['failsafe_reason'] == 'force_limit'
    flight.run_to(Mode.IDLE)
    assert flight.modes[-3:] == [Mode.RETREAT, Mode.LAND, Mode.IDLE]
    assert not flight.mission.status['success']


def test_target_lost_during_approach_holds_then_retreats():
    """Unseen on the way (a view the camera or the detector misses), the target is flown
    to on its locked estimate; it is lost only at the standoff, facing it, and the vehicle
    waits there as long as it would have after losing sight of it."""
    cfg = MissionConfig()
    flight = _in_mode(Mode.APPROACH, cfg)
    flight.run_for(1.0)
    t_lost = flight.t_s
    flight.run_to(Mode.TARGET_LOST, target=None, timeout_s=60.0)
    assert flight.t_s - t_lost > 2 * cfg.contact.target_lost_retreat_s      # it flew on
    standoff_t = np.array([0.0, 0.0, cfg.contact.standoff_m + VEHICLE.tool_tip_x_m])
    p_t = flight.mission.reference.to_frame(flight.p)
    assert np.linalg.norm(p_t - standoff_t) < cfg.flight.arrive_tol_m + 1e-9
    t_there = flight.t_s
    flight.run_for(1.5, target=None)
    assert flight.mission.mode == Mode.TARGET_LOST
    assert np.linalg.norm(flight.log[-1][2].dlambda_d_t) < 1e-9   # holding still
    flight.run_to(Mode.RETREAT, target=None, timeout_s=5.0)
    assert flight.t_s - t_there == pytest.approx(
        cfg.contact.target_lost_retreat_s - cfg.contact.target_lost_hold_s, abs=2 * DT_S)
    assert flight.mission.status['failsafe_reason'] == 'target_lost'


def test_target_lost_in_contact_holds_then_retreats():
    """Seen and then lost for good: hold, and retreat target_lost_retreat_s after the last
    image."""
    cfg = MissionConfig()
    flight = _in_mode(Mode.CONTACT, cfg)
    t_lost = flight.t_s       # the last image was taken PERFECT.age_s before the last tick
    flight.run_to(Mode.TARGET_LOST, target=None, timeout_s=5.0)
    assert flight.t_s - t_lost == pytest.approx(cfg.contact.target_lost_hold_s - PERFECT.age_s,
                                                abs=2 * DT_S)
    flight.run_to(Mode.RETREAT, target=None, timeout_s=5.0)
    assert flight.t_s - t_lost == pytest.approx(cfg.contact.target_lost_retreat_s - PERFECT.age_s,
                                                abs=2 * DT_S)
    assert flight.mission.status['failsafe_reason'] == 'target_lost'


def test_target_reacquired_resumes_approach():
    flight = _in_mode(Mode.APPROACH)
    flight.run_to(Mode.TARGET_LOST, target=None, timeout_s=60.0)
    flight.step()
    assert flight.mission.mode == Mode.APPROACH
    flight.run_to(Mode.CONTACT, timeout_s=30.0)


def test_contact_keeps_the_target_once_the_tool_hides_it():
    cfg = MissionConfig()
    flight = _in_mode(Mode.CONTACT, cfg)
    # still far from the surface: a lost target is lost
    flight.run_to(Mode.TARGET_LOST, target=None, timeout_s=5.0)
    flight.step()
    assert flight.mission.mode == Mode.CONTACT
    flight.run_until(lambda f: f.mission.behaviours[Mode.CONTACT].tool_hides_poi(), 30.0)
    gap_m = (flight.p - P_POI) @ NORMAL - VEHICLE.tool_tip_x_m
    assert gap_m == pytest.approx(cfg.contact.tool_occlusion_range_m, abs=0.01)
    # within the occlusion range the camera cannot see the POI: the push goes on
    seen = len(flight.modes)
    flight.run_to(Mode.HOLD, target=None, timeout_s=30.0)
    assert flight.modes[seen - 1:] == [Mode.CONTACT, Mode.HOLD]


def test_contact_lost_during_hold_counted_and_not_success():
    cfg = MissionConfig()
    flight = _in_mode(Mode.HOLD, cfg)
    flight.run_for(1.0)
    flight.run_for(cfg.contact.lost_s + 0.05, force_n=0.0)
    assert flight.mission.status['contact_lost'] == 1
    assert flight.mission.mode == Mode.HOLD
    flight.run_to(Mode.IDLE, timeout_s=60.0)
    assert flight.mission.status['contact_lost'] == 1
    assert not flight.mission.status['success']
    assert not flight.mission.status['inspection_completed']


def test_short_force_dropout_is_not_contact_lost():
    cfg = MissionConfig()
    flight = _in_mode(Mode.HOLD, cfg)
    flight.run_for(cfg.contact.lost_s - 0.03, force_n=0.0)
    flight.run_to(Mode.IDLE, timeout_s=60.0)
    assert flight.mission.status['contact_lost'] == 0 and flight.mission.status['success']


def test_no_contact_retreats():
    flight = _in_mode(Mode.CONTACT)
    flight.run_to(Mode.RETREAT, timeout_s=30.0, force_n=0.0)
    assert flight.mission.status['failsafe_reason'] == 'no_contact'


def test_a_candidate_is_confirmed_by_agreeing_measurements_and_one_elsewhere_restarts():
    cfg = MissionConfig()
    flight = Flight(cfg)
    assert flight.mission.inspect()[0]
    flight.run_to(Mode.SEARCH, target=None, timeout_s=30.0)
    elsewhere = PERFECT._replace(p_poi_map=P_POI + [0.0, 2.0 * cfg.search.confirm_radius_m, 0.0])
    # each tick a new measurement (a newer stamp); the one elsewhere breaks the run
    for k in range(cfg.search.confirm_n - 1):
        flight.step(target=PERFECT)
    flight.step(target=elsewhere)
    flight.step(target=PERFECT)
    for k in range(cfg.search.confirm_n - 2):
        flight.step(target=PERFECT)
        assert flight.mission.mode == Mode.SEARCH, k
    flight.step(target=PERFECT)
    assert flight.mission.mode == Mode.APPROACH


def test_search_timeout_lands():
    cfg = from_dict(MissionConfig, {'search.timeout_s': 2.0, 'search.yaw_rate_rad_s': 0.2})
    flight = _in_mode(Mode.SEARCH, cfg)
    flight.run_to(Mode.LAND, target=None, timeout_s=3.0)
    assert flight.mission.status['failsafe_reason'] == 'target_not_found'
    search_yaws = [sp.yaw_rad for _, mode, sp, _ in flight.log if mode == Mode.SEARCH]
    assert search_yaws[-1] - search_yaws[0] == pytest.approx(
        cfg.search.yaw_rate_rad_s * cfg.search.timeout_s, abs=0.01)


def test_search_backs_off_what_the_tool_touches_then_turns_on():
    cfg = MissionConfig()
    flight = _in_mode(Mode.SEARCH, cfg)
    flight.run_for(2.0, target=None)
    # below the threshold (a brush), however long, the turn goes on
    flight.run_for(1.0, target=None, f_map=np.array([0.0, -0.9, 0.0]) * cfg.bump.threshold_n)
    assert flight.mission.phase == 'sweep'
    flight.run_for(0.3, target=None)        # the brush forgotten (10 tau)
    push = np.array([0.0, -1.2, 0.5])       # the vehicle pushed away from something in +y
    p0 = flight.touch(push, target=None)
    assert flight.mission.phase == 'clear'
    start = len(flight.log)
    flight.run_until(lambda f: f.mission.phase == 'sweep', 10.0, target=None)
    # backed off along the push, the turn standing still meanwhile
    np.testing.assert_allclose(flight.p - p0, push / np.linalg.norm(push)
                               * cfg.bump.clearance_m, atol=cfg.flight.arrive_tol_m)
    assert len({sp.yaw_rad for _, _, sp, _ in flight.log[start:-1]}) == 1
    yaw = flight.log[-1][2].yaw_rad
    flight.run_for(1.0, target=None)
    assert flight.log[-1][2].yaw_rad - yaw == pytest.approx(cfg.search.yaw_rate_rad_s, rel=0.05)


def test_a_climb_that_meets_a_wall_turns_where_it_backed_off():
    cfg = from_dict(MissionConfig, {'search.yaw_rate_rad_s': 1.0, 'flight.yaw_rate_rad_s': 1.0})
    flight = _in_mode(Mode.SEARCH, cfg)
    flight.run_until(lambda f: f.mission.phase == 'climb', 10.0, target=None)
    flight.run_for(0.5, target=None)
    flight.touch(np.array([-1.5, 0.0, -1.5]), target=None)   # a wall leaning over
    flight.run_until(lambda f: f.mission.phase == 'sweep', 10.0, target=None)
    resumed_s, z = flight.t_s, flight.p[2]
    assert z < cfg.flight.takeoff_altitude_m + cfg.search.climb_m - cfg.bump.clearance_m / 2
    # the second level's whole turn, there, before the search goes lower
    flight.run_until(lambda f: f.mission.phase == 'descend', 10.0, target=None)
    assert flight.t_s - resumed_s == pytest.approx(2 * np.pi / cfg.search.yaw_rate_rad_s,
                                                   abs=0.1)


def _climb_time_s(cfg):
    """The take-off's own climb from the ground, MinJerk at climb_speed_m_s."""
    return MinJerk(0.0, np.array([0.0, 0.0, GEAR_Z_M]),
                   np.array([0.0, 0.0, cfg.flight.takeoff_altitude_m]),
                   cfg.flight.climb_speed_m_s).T


def test_a_takeoff_that_meets_a_wall_backs_off_horizontally_and_climbs_on():
    cfg = MissionConfig()
    flight = Flight(cfg)
    assert flight.mission.inspect()[0]
    flight.run_until(lambda f: f.p[2] > 0.8, 10.0, target=None)
    # below the threshold the climb goes on
    flight.run_for(0.3, target=None, f_map=np.array([-0.9, 0.0, 0.0]) * cfg.bump.threshold_n)
    assert flight.mission.phase == ''
    flight.run_for(0.3, target=None)
    # the tool under a wall leaning over the start: pushed away from it and down
    push = np.array([-1.4, 0.6, -0.7])
    p0 = flight.touch(push, target=None)
    assert (flight.mission.mode, flight.mission.phase) == (Mode.TAKEOFF, 'clear')
    flight.run_until(lambda f: f.mission.phase == '', 10.0, target=None)
    away = push * [1.0, 1.0, 0.0]
    moved = flight.p - p0
    # backed off along the push's horizontal part only: the ground is below
    np.testing.assert_allclose(moved[:2], away[:2] / np.linalg.norm(away)
                               * cfg.bump.clearance_m, atol=cfg.flight.arrive_tol_m)
    assert abs(moved[2]) < cfg.flight.arrive_tol_m
    # then up to the take-off altitude from there, and on with the mission
    flight.run_to(Mode.HOVER, target=None, timeout_s=20.0)
    np.testing.assert_allclose(flight.p, [*(p0[:2] + moved[:2]), cfg.flight.takeoff_altitude_m],
                               atol=cfg.flight.arrive_tol_m)
    flight.run_to(Mode.SEARCH, target=None, timeout_s=5.0)


def test_a_takeoff_pushed_down_from_above_lands():
    cfg = MissionConfig()
    flight = Flight(cfg)
    assert flight.mission.inspect()[0]
    flight.run_until(lambda f: f.p[2] > 0.8, 10.0, target=None)
    # a ceiling: the push has less horizontal part than a wall 70 degrees from vertical
    flight.touch(np.array([0.3, 0.0, -1.5]), target=None)
    assert flight.mission.mode == Mode.LAND
    flight.run_to(Mode.IDLE, target=None, timeout_s=20.0)
    status = flight.mission.status
    assert status['failsafe_reason'] == 'takeoff_blocked' and not status['success']
    assert [r.reason for r in flight.mission.records] == ['not_run']


def test_a_takeoff_that_never_reaches_its_altitude_lands():
    cfg = from_dict(MissionConfig, {
        'flight.takeoff_timeout_s': float(np.random.default_rng().uniform(5.0, 15.0))})
    flight = Flight(cfg)
    assert flight.mission.inspect()[0]
    t0 = flight.t_s
    # something keeps meeting the tool as it climbs past 1 m
    while flight.mission.mode == Mode.TAKEOFF:
        assert flight.t_s < t0 + _climb_time_s(cfg) + cfg.flight.takeoff_timeout_s + 1.0
        bumped = flight.p[2] > 1.0 and flight.mission.phase == ''
        flight.step(target=None, f_map=np.array([-1.5, 0.0, 0.0]) if bumped else None)
    assert flight.mission.mode == Mode.LAND
    assert flight.t_s - t0 == pytest.approx(_climb_time_s(cfg) + cfg.flight.takeoff_timeout_s,
                                            abs=2 * DT_S)
    flight.run_to(Mode.IDLE, target=None, timeout_s=20.0)
    assert flight.mission.status['failsafe_reason'] == 'takeoff_timeout'
    assert flight.p[2] == pytest.approx(GEAR_Z_M)


def test_a_landing_that_meets_a_wall_backs_off_horizontally_and_descends_on():
    cfg = MissionConfig()
    flight = _hovering(cfg)
    assert flight.mission.land()[0]
    flight.run_until(lambda f: f.p[2] < 1.0, 10.0, target=None)
    # a push from below, the ground under the tool, is no obstacle: the descent goes on
    flight.run_for(0.2, target=None, f_map=np.array([0.2, 0.0, 1.5]))
    assert (flight.mission.mode, flight.mission.phase) == (Mode.LAND, '')
    flight.run_for(0.2, target=None)
    # a wall leaning away from the vehicle, met on the way down: pushed away and up
    push = np.array([0.3, -1.3, 0.6])
    p0 = flight.touch(push, target=None)
    assert flight.mission.phase == 'clear'
    flight.run_until(lambda f: f.mission.phase == '', 10.0, target=None)
    moved = flight.p - p0
    np.testing.assert_allclose(moved[:2], push[:2] / np.linalg.norm(push[:2])
                               * cfg.bump.clearance_m, atol=cfg.flight.arrive_tol_m)
    assert abs(moved[2]) < cfg.flight.arrive_tol_m
    flight.run_to(Mode.IDLE, target=None, timeout_s=20.0)
    np.testing.assert_allclose(flight.p, [*(p0[:2] + moved[:2]), GEAR_Z_M],
                               atol=cfg.flight.arrive_tol_m)


def _landing_on_a_roof():
    """Hovering, then landing where the ground stands a fresh 0.35-3 m above ground_z_m
    (a roof, a box; or ground_z_m set too low): the tracker stops the body there."""
    roof_m = float(np.random.default_rng().uniform(0.35, 3.0))
    cfg = from_dict(MissionConfig, {'land.ground_z_m': -roof_m})
    flight = _hovering(cfg)
    assert flight.mission.land()[0]
    return flight, roof_m


def _setpoint_z(flight):
    sp = flight.log[-1][2]
    return (sp.origin_map + sp.R_map_t @ sp.lambda_d_t)[2]


def _resting_thrust_n(cfg):
    """What the flight core asks of a vehicle stopped on a roof below its setpoint, once it
    has pulled down long enough: less than any vehicle in the air would need (a fresh
    share of land_detect_thrust_ratio of the weight)."""
    return float(np.random.default_rng().uniform(0.0, 0.99)) * (
        cfg.land.detect_thrust_ratio * WEIGHT_N)


def test_a_landing_stopped_above_ground_z_lands_where_it_stopped():
    flight, roof_m = _landing_on_a_roof()
    cfg = flight.config
    # stopped once its setpoint passes land_detect_height_m below it and pulling down,
    # landed land_detect_s on
    flight.run_until(lambda f: _setpoint_z(f) < GEAR_Z_M - cfg.land.detect_height_m, 30.0,
                     target=None)
    flight.thrust_up_n = _resting_thrust_n(cfg)
    t_held = flight.t_s
    flight.run_to(Mode.IDLE, timeout_s=cfg.land.detect_s + 0.1, target=None)
    assert flight.t_s - t_held == pytest.approx(cfg.land.detect_s, abs=2 * DT_S)
    event = flight.mission.events[-1]
    assert event['reason'] == f'landed {GEAR_Z_M + roof_m:.2f} m above ground_z_m'
    assert flight.mission.status['failsafe_reason'] == ''


def test_a_landing_held_by_its_tool_is_not_landed():
    flight, roof_m = _landing_on_a_roof()
    cfg = flight.config
    # the tool rests on a ledge: the ledge pushes it up, the vehicle hangs from it
    hanging = dict(target=None, f_map=np.array([0.0, 0.0, 2.0 * cfg.bump.threshold_n]))
    flight.run_until(lambda f: _setpoint_z(f) < GEAR_Z_M - cfg.land.detect_height_m, 30.0,
                     **hanging)
    flight.thrust_up_n = _resting_thrust_n(cfg)
    flight.run_for(2.0 * cfg.land.detect_s, **hanging)
    assert flight.mission.mode == Mode.LAND
    # off the ledge onto its gear: landed
    flight.run_to(Mode.IDLE, timeout_s=cfg.land.detect_s + 0.1, target=None)


def test_a_vehicle_hovering_above_its_descent_is_not_landed():
    """A vehicle lighter than the controller's model (the scenarios go down to half of it)
    hovers above its descending setpoint until the hover-thrust estimate has learnt its
    weight: still, above the setpoint, but making its own weight, it is in the air. Only
    once the thrust asked for falls below land_detect_thrust_ratio of the weight does it
    stand on something."""
    flight, roof_m = _landing_on_a_roof()
    cfg = flight.config
    rng = np.random.default_rng()
    flight.thrust_up_n = float(rng.uniform(0.5, 1.0)) * WEIGHT_N
    flight.run_until(lambda f: _setpoint_z(f) < GEAR_Z_M - cfg.land.detect_height_m, 30.0,
                     target=None)
    flight.run_for(4.0 * cfg.land.detect_s, target=None)
    assert flight.mission.mode == Mode.LAND
    flight.thrust_up_n = None         # unknown thrust: no such landing either
    flight.run_for(2.0 * cfg.land.detect_s, target=None)
    assert flight.mission.mode == Mode.LAND
    flight.thrust_up_n = _resting_thrust_n(cfg)
    flight.run_to(Mode.IDLE, timeout_s=cfg.land.detect_s + 0.1, target=None)
    assert flight.mission.events[-1]['reason'] == (
        f'landed {GEAR_Z_M + roof_m:.2f} m above ground_z_m')


def _tilted(flight, tilt_rad):
    """From now on the vehicle stays where it is, tilted by ``tilt_rad`` about a fresh
    horizontal axis."""
    axis = np.random.default_rng().normal(size=3) * [1.0, 1.0, 0.0]
    q = Rotation.from_rotvec(axis / np.linalg.norm(axis) * tilt_rad).as_quat()
    flight.q = q
    flight._track = lambda sp: setattr(flight, 'q', q)


def test_an_upset_stops_the_rotors():
    cfg = MissionConfig()
    flight = _in_mode(Mode.APPROACH, cfg)
    rng = np.random.default_rng()
    # tilted past the limit for less than upset_s, then upright again: flying on
    _tilted(flight, cfg.failsafe.upset_tilt_rad + rng.uniform(0.02, 2.0))
    flight.run_for(cfg.failsafe.upset_s - 3 * DT_S)
    del flight._track
    flight.run_for(0.5)
    assert flight.mission.mode == Mode.APPROACH
    # just under the limit for long: flying on
    _tilted(flight, cfg.failsafe.upset_tilt_rad - 0.02)
    flight.run_for(5.0 * cfg.failsafe.upset_s)
    assert flight.mission.mode == Mode.APPROACH
    # past it for upset_s: the rotors stop, the plan ends
    _tilted(flight, cfg.failsafe.upset_tilt_rad + rng.uniform(0.02, 2.0))
    t0 = flight.t_s
    flight.run_until(lambda f: f.mission.mode != Mode.APPROACH, cfg.failsafe.upset_s + 0.1)
    assert flight.t_s - t0 == pytest.approx(cfg.failsafe.upset_s, abs=2 * DT_S)
    assert flight.mission.mode == Mode.IDLE
    status = flight.mission.status
    assert status['failsafe_reason'] == 'upset' and not status['success']
    assert [r.reason for r in flight.mission.records] == ['upset']


def test_hover_backs_off_what_the_tool_touches_and_holds_there():
    cfg = MissionConfig()
    flight = _hovering(cfg)
    push = np.array([0.5, -1.5, 0.3])
    p0 = flight.touch(push, target=None)
    assert flight.mission.phase == 'clear'
    ok, why = flight.mission.set_hover_setpoint([0.0, 0.0, 2.0], 0.0)
    assert not ok and '(clear)' in why
    assert flight.mission.status['refused_setpoints'] == 1
    flight.run_until(lambda f: f.mission.phase == '', 10.0, target=None)
    flight.run_for(2.0, target=None)
    assert flight.mission.mode == Mode.HOVER
    np.testing.assert_allclose(flight.p - p0, push / np.linalg.norm(push)
                               * cfg.bump.clearance_m, atol=cfg.flight.arrive_tol_m)
    assert flight.mission.set_hover_setpoint([0.0, 0.0, 2.0], 0.0)[0]


def _held(flight):
    """Something holds the vehicle where it is (the ground, a wall it rests on): it follows
    no setpoint until ``del flight._track``."""
    flight.v = np.zeros(3)
    flight._track = lambda sp: None


def _deadline_s(flight):
    segment = flight.mission.reference.segment
    return segment.t0_s + segment.T + flight.config.flight.arrive_timeout_s


def _in_mode_held(mode, cfg):
    """A flight in ``mode`` (RETREAT: an abort in HOLD, once the push is let go), held
    half a second in."""
    flight = _in_mode(Mode.HOLD if mode == Mode.RETREAT else mode, cfg)
    if mode == Mode.RETREAT:
        assert flight.mission.abort()[0]
        assert flight.mission.phase == 'release'
        flight.run_until(lambda f: f.mission.phase == '', 2.0 * cfg.contact.press_time_s)
    flight.run_for(0.5)
    assert flight.mission.mode == mode
    _held(flight)
    return flight


@pytest.mark.parametrize('mode', [Mode.APPROACH, Mode.RETREAT])
def test_a_segment_the_vehicle_cannot_reach_lands(mode):
    cfg = from_dict(MissionConfig, {
        'flight.arrive_timeout_s': float(np.random.default_rng().uniform(2.0, 20.0))})
    flight = _in_mode_held(mode, cfg)
    deadline_s = _deadline_s(flight)
    flight.run_until(lambda f: f.mission.mode != mode, deadline_s - flight.t_s + 1.0)
    assert flight.mission.mode == Mode.LAND
    assert flight.t_s == pytest.approx(deadline_s, abs=2 * DT_S)
    del flight._track
    flight.run_to(Mode.IDLE, timeout_s=30.0)
    status = flight.mission.status
    assert status['failsafe_reason'] == 'unreachable' and not status['success']


@pytest.mark.parametrize('mode', [Mode.APPROACH, Mode.RETREAT])
def test_an_arrival_late_but_within_the_timeout_goes_on(mode):
    cfg = from_dict(MissionConfig, {
        'flight.arrive_timeout_s': float(np.random.default_rng().uniform(2.0, 20.0))})
    flight = _in_mode_held(mode, cfg)
    flight.run_until(lambda f: f.t_s > _deadline_s(f) - 0.1, 60.0)
    del flight._track
    flight.run_to(Mode.CONTACT if mode == Mode.APPROACH else Mode.HOVER, timeout_s=0.1)
    assert flight.mission.status['failsafe_reason'] == ''


def test_a_back_off_that_is_held_goes_on_from_where_it_got_to():
    cfg = from_dict(MissionConfig, {
        'flight.arrive_timeout_s': float(np.random.default_rng().uniform(2.0, 20.0))})
    flight = _hovering(cfg)
    flight.touch(np.array([0.0, -1.5, 0.0]), target=None)
    assert flight.mission.phase == 'clear'
    _held(flight)
    deadline_s = _deadline_s(flight)
    flight.run_until(lambda f: f.mission.phase == '', deadline_s - flight.t_s + 1.0,
                     target=None)
    assert flight.t_s == pytest.approx(deadline_s, abs=2 * DT_S)
    assert flight.mission.mode == Mode.HOVER
    assert flight.mission.status['failsafe_reason'] == ''


@pytest.mark.parametrize('takeoff_m, low_m', [(1.5, 0.9), (0.8, 0.6)])
def test_search_turns_at_the_takeoff_altitude_higher_and_lower_then_lands(takeoff_m, low_m):
    cfg = from_dict(MissionConfig, {'search.yaw_rate_rad_s': 1.0, 'flight.yaw_rate_rad_s': 1.0,
                                    'flight.takeoff_altitude_m': takeoff_m})
    flight = _in_mode(Mode.SEARCH, cfg)
    start = len(flight.log)
    flight.run_to(Mode.LAND, target=None, timeout_s=60.0)
    assert flight.mission.status['failsafe_reason'] == 'target_not_found'
    # a whole turn at each altitude: takeoff, search_climb_m higher, search_descend_m lower
    # but no lower than twice land_detect_height_m (0.6 m)
    turns = {}
    for (_, mode, sp, p), phase in zip(flight.log[start:], flight.phases[start:]):
        if mode == Mode.SEARCH and phase == 'sweep':
            turns.setdefault(round(p[2], 2), []).append(sp.yaw_rad)
    assert list(turns) == pytest.approx([takeoff_m, takeoff_m + cfg.search.climb_m, low_m])
    for yaws in turns.values():
        assert np.ptp(np.unwrap(yaws)) == pytest.approx(2 * np.pi, abs=0.05)


def test_after_its_turns_the_search_faces_the_wall_it_saw_from_both_ends_then_lands():
    cfg = from_dict(MissionConfig, {'search.yaw_rate_rad_s': 1.0, 'flight.yaw_rate_rad_s': 1.0})
    flight = _in_mode(Mode.SEARCH, cfg)
    # a wall 4 m north leaning 20 degrees back, seen from x = -3 to 1 m during the first
    # turn; and the ground, which is no wall
    lean = np.radians(20.0)
    n = np.array([0.0, -np.cos(lean), np.sin(lean)])
    wall_at_1_5_m = np.array([0.0, 4.0, 1.5])

    def seen(f):
        if f.mission.phase == 'sweep':
            x = -3.0 + 4.0 * (f.t_s % 2.0) / 2.0
            f.mission.observe_plane(wall_at_1_5_m + [x, 0.0, 0.0], n, 0.3)
            f.mission.observe_plane([x, 2.0, 0.0], [0.0, 0.0, 1.0], 0.4)
        return f.mission.phase == 'climb'
    flight.run_until(seen, 20.0, target=None)
    start = len(flight.log)
    flight.run_to(Mode.LAND, target=None, timeout_s=120.0)
    assert flight.mission.status['failsafe_reason'] == 'target_not_found'
    phases = flight.phases[start:]
    assert 'face' in phases and phases.index('descend') < phases.index('face')
    # after the three turns: a sweep across the wall from in front of each end of what was
    # seen, search_face_m out from it horizontally at the takeoff altitude, looking at it
    sweeps = {}
    first = phases.index('face')
    for (_, mode, sp, p), phase in zip(flight.log[start + first:], phases[first:]):
        if mode == Mode.SEARCH and phase == 'sweep':
            sweeps.setdefault((round(p[0], 1), round(p[1], 1), round(p[2], 1)), []).append(
                sp.yaw_rad)
    assert [k[1] for k in sweeps] == pytest.approx([4.0 - cfg.search.face_m] * 2, abs=0.1)
    assert sorted(k[0] for k in sweeps) == pytest.approx([-3.0, 1.0], abs=0.1)
    for (x, y, z), yaws in sweeps.items():
        assert z == pytest.approx(cfg.flight.takeoff_altitude_m, abs=0.05)
        yaws = np.unwrap(yaws)
        assert np.ptp(yaws) == pytest.approx(cfg.search.face_turn_rad, abs=0.05)
        # across the wall: centred on the heading that looks into it (north)
        assert np.mean([yaws.min(), yaws.max()]) == pytest.approx(np.pi / 2, abs=0.05)


@pytest.mark.parametrize('room', ['some', 'none'])
def test_under_a_wall_leaning_over_the_start_the_search_climbs_as_far_as_the_tool_clears_it(
        room):
    # A wall north of the start leaning 10-30 degrees over it, seen in the first turn; at
    # the takeoff altitude it leaves the tool's reach (tool_tip_x_m plus
    # search_wall_clearance_m) less room than search_climb_m needs, or none.
    rng = np.random.default_rng()
    cfg = from_dict(MissionConfig, {'search.yaw_rate_rad_s': 1.0, 'flight.yaw_rate_rad_s': 1.0})
    flight = _in_mode(Mode.SEARCH, cfg)
    lean = np.radians(rng.uniform(10.0, 30.0))
    n = np.array([0.0, -np.cos(lean), -np.sin(lean)])
    reach_m = VEHICLE.tool_tip_x_m + cfg.search.wall_clearance_m
    climb_room_m = rng.uniform(0.2, 0.8) * cfg.search.climb_m if room == 'some' else 0.0
    p0 = flight.p.copy()
    # horizontally this far from the start's vertical at the takeoff altitude
    wall_m = reach_m + climb_room_m * np.tan(lean) - (0.0 if room == 'some' else 0.05)
    on_wall = p0 + [0.0, wall_m, 0.0]

    def seen(f):
        if f.mission.phase == 'sweep':
            f.mission.observe_plane(on_wall + [rng.uniform(-2.0, 2.0), 0.0, 0.0], n, 0.3)
        return f.mission.phase != 'sweep'
    flight.run_until(seen, 20.0, target=None)
    if room == 'none':
        # no room to climb: the next turn is the lower one
        assert flight.mission.phase == 'descend'
        return
    assert flight.mission.phase == 'climb'
    flight.run_until(lambda f: f.mission.phase == 'sweep', 20.0, target=None)
    climbed_m = flight.p[2] - p0[2]
    assert climbed_m == pytest.approx(climb_room_m, abs=cfg.flight.arrive_tol_m)
    # the tool's reach, turning there, keeps the clearance from the wall (horizontally)
    clear_m = ((flight.p - on_wall) @ n) / np.cos(lean) - VEHICLE.tool_tip_x_m
    assert clear_m == pytest.approx(cfg.search.wall_clearance_m,
                                    abs=cfg.flight.arrive_tol_m * np.tan(lean) + 1e-6)
    flight.run_until(lambda f: f.mission.phase == 'descend', 20.0, target=None)


def test_without_a_wall_seen_the_search_lands_after_its_turns():
    cfg = from_dict(MissionConfig, {'search.yaw_rate_rad_s': 1.0, 'flight.yaw_rate_rad_s': 1.0})
    flight = _in_mode(Mode.SEARCH, cfg)
    flight.run_to(Mode.LAND, target=None, timeout_s=60.0)
    assert 'face' not in flight.phases


def test_the_search_turns_no_faster_than_the_yaw_reference():
    # asked to sweep at twice yaw_rate_rad_s, a counted turn is still a whole turn
    cfg = from_dict(MissionConfig, {'search.yaw_rate_rad_s': 1.0, 'flight.yaw_rate_rad_s': 0.5})
    flight = _in_mode(Mode.SEARCH, cfg)
    start = len(flight.log)
    flight.run_until(lambda f: f.mission.phase == 'climb', 20.0, target=None)
    yaws = [sp.yaw_rad for _, _, sp, _ in flight.log[start:]]
    assert np.ptp(np.unwrap(yaws)) == pytest.approx(2 * np.pi, abs=0.02)


def test_abort_in_contact_retreats_then_hovers():
    flight = _in_mode(Mode.CONTACT)
    ok, _ = flight.mission.abort()
    assert ok and flight.mission.mode == Mode.RETREAT
    flight.run_to(Mode.HOVER, timeout_s=30.0)
    assert flight.mission.status['failsafe_reason'] == ''
    flight.run_for(2.0)
    assert flight.mission.mode == Mode.HOVER


def _out_from_wall(flight):
    """The vehicle's distance out of the target's wall (along its normal)."""
    return float((flight.p - PERFECT.p_poi_map) @ PERFECT.normal_map)


@pytest.mark.parametrize('call, then', [('abort', Mode.HOVER), ('land', Mode.LAND)])
def test_abort_or_land_on_the_way_to_the_wall_stops_short_of_it(call, then):
    # an approach still far out has nothing to retreat from: RETREAT would fly on to the
    # standoff, towards the wall
    flight = _in_mode(Mode.APPROACH)
    flight.run_for(float(np.random.default_rng().uniform(0.5, 2.0)))
    out_m = _out_from_wall(flight)
    assert out_m > flight.config.contact.standoff_m + VEHICLE.tool_tip_x_m + 0.2
    ok, _ = getattr(flight.mission, call)()
    assert ok and flight.mission.mode == then
    nearest_m = out_m
    for _ in range(int(10.0 / DT_S)):
        flight.step()
        nearest_m = min(nearest_m, _out_from_wall(flight))
    # it stops within its braking distance: at 0.3 m/s and 1 m/s^2, under 5 cm
    assert nearest_m > out_m - 0.05, (out_m, nearest_m)
    assert flight.mission.mode == (Mode.HOVER if call == 'abort' else Mode.IDLE)


def test_abort_just_after_take_off_lands_rather_than_hover_on_the_ground():
    flight = Flight()
    assert flight.mission.takeoff()[0]
    flight.run_for(0.3)
    assert flight.mission.abort() == (True, 'landing: too low to hover')
    flight.run_to(Mode.IDLE, timeout_s=20.0)
    # high enough, abort hovers there
    assert flight.mission.takeoff()[0]
    flight.run_until(lambda f: f.p[2] > f.config.lowest_hover_m() + 0.1, 20.0)
    assert flight.mission.abort() == (True, 'hovering')


def test_abort_in_search_hovers_and_land_lands():
    flight = _in_mode(Mode.SEARCH)
    assert flight.mission.abort() == (True, 'hovering')
    assert flight.mission.mode == Mode.HOVER
    assert flight.mission.land()[0]
    flight.run_to(Mode.IDLE, timeout_s=30.0)
    assert not flight.mission.status['success']


@pytest.mark.parametrize('mode', [Mode.TAKEOFF, Mode.APPROACH, Mode.HOLD])
def test_inspect_while_the_plan_runs_says_so_and_changes_nothing(mode):
    flight = _in_mode(mode)
    records = flight.mission.status['task_outcomes']
    ok, why = flight.mission.inspect()
    assert not ok and 'already under way' in why and mode.value in why, why
    assert ('taking off' if mode == Mode.TAKEOFF else 'task 1 of 1') in why, why
    assert flight.mission.mode == mode and flight.mission.status['task_outcomes'] == records
    flight.run_to(Mode.IDLE, timeout_s=150.0)
    assert flight.mission.status['success']


def test_services_refused_in_wrong_modes():
    mission = Mission(VEHICLE)
    ok, why = mission.takeoff()
    assert not ok and 'odometry' in why          # no state yet
    flight = Flight()
    for call in (flight.mission.abort, flight.mission.land):
        ok, why = call()
        assert not ok and 'IDLE' in why
    ok, why = flight.mission.set_hover_setpoint([0.0, 0.0, 1.0], 0.0)
    assert not ok and 'HOVER' in why
    # a good setpoint at the wrong time: refused, not rejected; a bad one is rejected
    assert flight.mission.status['rejected_setpoints'] == 0
    assert flight.mission.status['refused_setpoints'] == 1
    ok, why = flight.mission.set_hover_setpoint([0.0, 0.0, -1.0], 0.0)
    assert not ok and 'lowest hover' in why
    assert flight.mission.status['rejected_setpoints'] == 1
    assert flight.mission.status['refused_setpoints'] == 1
    flight.mission.update(flight.t_s, flight.state(), None, 0.0, 0.5)
    assert not flight.mission.takeoff()[0]       # stale odometry on the ground
    flight.step()
    assert flight.mission.takeoff()[0]
    ok, why = flight.mission.takeoff()
    assert not ok and 'TAKEOFF' in why
    ok, why = flight.mission.inspect()
    assert not ok and 'TAKEOFF' in why
    assert flight.mission.mode == Mode.TAKEOFF


def test_min_jerk_boundary_conditions():
    p0, p1, v0 = np.array([0.0, 1.0, 2.0]), np.array([3.0, -1.0, 2.0]), np.array([0.2, 0, 0])
    seg = MinJerk(1.0, p0, p1, 0.5, v0)
    p, v, a = seg.sample(1.0)
    np.testing.assert_allclose([p, v, a], [p0, v0, np.zeros(3)], atol=1e-12)
    p, v, a = seg.sample(1.0 + seg.T - 1e-9)
    np.testing.assert_allclose([p, v, a], [p1, np.zeros(3), np.zeros(3)], atol=1e-6)
    still = MinJerk(0.0, p0, p1, 0.5)
    peak = max(np.linalg.norm(still.sample(t)[1]) for t in np.linspace(0, still.T, 1001))
    assert peak == pytest.approx(0.5, rel=1e-4)


def test_inconsistent_timeouts_rejected():
    with pytest.raises(ConfigError, match='target_lost_retreat_s'):
        Mission(VEHICLE, from_dict(MissionConfig, {'contact.target_lost_hold_s': 2.0,
                                                   'contact.target_lost_retreat_s': 1.0}))


def _touching_with_offset(cfg, offset_map, clearance_m=np.inf):
    """A flight in CONTACT's creep, once the tool tip's reference is ``clearance_m`` or less
    from the wall, whose tracker leaves the body ``offset_map`` off its reference from then
    on (a gust)."""
    flight = _in_mode(Mode.CONTACT, cfg)
    flight.run_until(lambda f: f.mission.phase == 'touch'
                     and _creep_depth(f) - VEHICLE.tool_tip_x_m <= clearance_m, 30.0)
    track = flight._track

    def off_track(sp):
        track(sp)
        flight.p = flight.p + offset_map
    flight._track = off_track
    return flight


def _creep_depth(flight):
    """The creep reference's coordinate along the wall's normal (z_t)."""
    return flight.log[-1][2].lambda_d_t[2]


@pytest.mark.parametrize('offset_m, pauses', [(0.01, True), (0.002, False)])
def test_the_touch_waits_for_the_tool_over_the_target(offset_m, pauses):
    cfg = MissionConfig()
    # the wall is x = 3 (normal -x): z in map lies in its plane
    flight = _touching_with_offset(cfg, np.array([0.0, 0.0, offset_m]))
    flight.run_for(0.5)
    z0 = _creep_depth(flight)
    flight.run_for(1.0)
    crept_m = z0 - _creep_depth(flight)
    if pauses:
        # off by more than touch_align_m: the creep stands still, and says so
        assert flight.mission.phase == 'align' and crept_m == pytest.approx(0.0, abs=1e-9)
        assert not np.any(flight.log[-1][2].dlambda_d_t)
    else:
        assert flight.mission.phase == 'touch'
        assert crept_m == pytest.approx(cfg.contact.touch_speed_m_s * 1.0, rel=0.02)
    # the gust over, the creep goes on to the wall and the push
    flight._track = Flight._track.__get__(flight)
    flight.run_to(Mode.HOLD, timeout_s=30.0)


def test_a_gust_near_the_wall_backs_the_tool_out_while_the_touch_waits():
    cfg = MissionConfig()
    # 2 mm from the wall, a gust puts the tool 1 cm off the target in the wall's plane
    flight = _touching_with_offset(cfg, np.array([0.0, 0.0, 0.01]), clearance_m=0.002)
    start = len(flight.log)
    flight.run_for(1.5)
    assert flight.mission.phase == 'align'
    # the creep ran back out, at its own speed, to the clearance, and waits there untouched
    clearance = [entry[2].lambda_d_t[2] - VEHICLE.tool_tip_x_m for entry in flight.log[start:]]
    assert np.max(np.diff(clearance)) <= cfg.contact.touch_speed_m_s * DT_S + 1e-12
    assert clearance[-1] == pytest.approx(cfg.contact.touch_align_clearance_m,
                                          abs=cfg.contact.touch_speed_m_s * DT_S)
    gaps = [(entry[3] - P_POI) @ NORMAL - VEHICLE.tool_tip_x_m for entry in flight.log[start:]]
    assert min(gaps) > 0.0
    # the gust over, the creep goes on to the wall and the push
    flight._track = Flight._track.__get__(flight)
    flight.run_to(Mode.HOLD, timeout_s=30.0)


def test_a_wall_felt_while_the_tool_is_off_the_target_is_not_pressed_on():
    # a soft wall takes seconds of light contact to pass the touch threshold; a gust that
    # swings the tip off the target then must not be pinned there by the press's friction
    cfg = MissionConfig()
    rng = np.random.default_rng()
    off_m, angle = rng.uniform(1.5, 5.0) * cfg.contact.touch_align_m, rng.uniform(0.0, 2 * np.pi)
    flight = _touching_with_offset(cfg, off_m * np.array([0.0, np.cos(angle), np.sin(angle)]),
                                   clearance_m=0.0)
    flight.run_until(lambda f: f.mission.phase == 'align', 2.0)
    felt_n = flight.mission.behaviours[Mode.CONTACT].touch_threshold_n() + 0.5
    for _ in range(3 * cfg.contact.detect_ticks):
        flight.step(force_n=felt_n)
    assert flight.mission.phase == 'align'
    # the gust over, the tool is over the target: the same push now starts the press
    flight._track = Flight._track.__get__(flight)
    flight.run_until(lambda f: f.mission.phase == 'touch', 2.0)
    for _ in range(cfg.contact.detect_ticks):
        flight.step(force_n=felt_n)
    assert flight.mission.phase == 'press'


def _touch_s(cfg, offset_m):
    """Seconds from the creep's start to the press, the body held ``offset_m`` above its
    reference (in the wall's plane)."""
    flight = _touching_with_offset(cfg, np.array([0.0, 0.0, offset_m]))
    start_s = flight.t_s
    flight.run_until(lambda f: f.mission.phase == 'press', 30.0)
    return flight.t_s - start_s


def test_the_touch_waits_no_longer_than_allowed():
    cfg = from_dict(MissionConfig, {'contact.touch_align_wait_s': 1.5})
    # an offset that stays does not stall the touch: it costs the wait allowed, no more
    assert _touch_s(cfg, 0.02) - _touch_s(cfg, 0.0) == pytest.approx(1.5, abs=2 * DT_S)


def test_the_touch_alignment_can_be_turned_off():
    flight = _touching_with_offset(from_dict(MissionConfig, {'contact.touch_align_m': 0.0}),
                                   np.array([0.0, 0.0, 0.02]))
    flight.run_until(lambda f: f.mission.phase == 'press', 30.0)
    assert 'align' not in flight.phases


def test_the_body_pitches_to_the_wall_at_the_pitch_rate_not_in_a_step():
    # a fresh lean within the pitch limit and a fresh rate: the tool tip, 0.45 m ahead,
    # swings with the reference, so the reference turns no faster than pitch_rate_rad_s
    rng = np.random.default_rng()
    lean, rate = rng.uniform(0.1, 0.45), rng.uniform(0.2, 1.0)
    cfg = from_dict(MissionConfig, {'flight.pitch_rate_rad_s': rate})
    normal = np.array([-np.cos(lean), 0.0, np.sin(lean)])
    flight = Flight(cfg, TargetEstimate(P_POI, normal, 0.02, True))
    assert flight.mission.inspect()[0]
    flight.run_to(Mode.HOLD, timeout_s=120.0)
    pitch = np.array([sp.pitch_rad for _, _, sp, _ in flight.log])
    assert np.abs(np.diff(pitch)).max() <= rate * DT_S * (1 + 1e-9), (lean, rate)
    # and the tool points along the normal before the approach ends
    approach_end = max(i for i, (_, mode, _, _) in enumerate(flight.log)
                       if mode == Mode.APPROACH)
    assert pitch[approach_end] == pytest.approx(lean, abs=cfg.flight.arrive_yaw_tol_rad)


def test_the_tool_tip_meets_a_target_beyond_the_pitch_limit():
    # a wall leaning back further than the body may pitch, touched off square as the margin
    # allows: the tool stays 0.2 rad off the normal, so the body stands off the normal
    # (9 cm here) for the tool tip to meet the POI
    cfg = from_dict(MissionConfig, {'contact.max_pitch_rad': 0.3,
                                    'contact.reach_margin_rad': 0.25})
    normal = np.array([-np.cos(0.5), 0.0, np.sin(0.5)])
    flight = Flight(cfg, TargetEstimate(P_POI, normal, 0.02, True))
    assert flight.mission.inspect()[0]
    flight.run_to(Mode.HOLD, timeout_s=120.0)
    _, _, sp, p = flight.log[-1]
    assert sp.pitch_rad == pytest.approx(cfg.contact.max_pitch_rad)
    tip = p + VEHICLE.tool_tip_x_m * Rotation.from_euler(
        'ZY', [sp.yaw_rad, sp.pitch_rad]).apply([1.0, 0.0, 0.0])
    off = tip - P_POI
    assert np.linalg.norm(off - (off @ normal) * normal) < 1e-3
    # over the target all along: the touch never waited for the tip
    assert 'align' not in flight.phases
    flight.run_until(lambda f: f.mission.mode == Mode.IDLE, 60.0)
    assert flight.mission.status['success']


def test_a_target_beyond_the_pitch_limit_and_its_margin_is_not_touched():
    """The same wall at the default margin: the task fails 'unreachable_normal' at the
    standoff, the vehicle never closing in, and it lands."""
    cfg = from_dict(MissionConfig, {'contact.max_pitch_rad': 0.3})
    assert 0.5 > cfg.contact.max_pitch_rad + cfg.contact.reach_margin_rad
    normal = np.array([-np.cos(0.5), 0.0, np.sin(0.5)])
    flight = Flight(cfg, TargetEstimate(P_POI, normal, 0.02, True))
    assert flight.mission.inspect()[0]
    flight.run_until(lambda f: f.mission.mode == Mode.IDLE and f.t_s > 1.0, 120.0)
    assert flight.mission.records[0].reason == 'unreachable_normal'
    assert Mode.CONTACT not in flight.modes and not flight.mission.status['success']


def test_the_retreat_lets_go_of_the_push_before_it_leaves_the_wall():
    flight = _in_mode(Mode.HOLD)
    cfg, tip = flight.config, VEHICLE.tool_tip_x_m
    flight.run_to(Mode.RETREAT, timeout_s=2.0 * cfg.contact.hold_time_s)
    assert flight.mission.phase == 'release'
    start = len(flight.log)
    flight.run_until(lambda f: f.mission.phase == '', 2.0 * cfg.contact.press_time_s)
    release = [sp for _, _, sp, _ in flight.log[start - 1:]]
    pushes = np.array([sp.push_n for sp in release])
    # from the hold's push down to none, never up, over the press's time
    assert pushes[0] == pytest.approx(flight.mission.contact_force_n, rel=1e-3)
    assert np.all(np.diff(pushes) <= 1e-12) and pushes[-1] == 0.0
    assert (len(release) - 1) * DT_S == pytest.approx(cfg.contact.press_time_s, abs=2 * DT_S)
    # meanwhile the reference stays on the surface, compliant while it pushes
    assert all(abs(sp.lambda_d_t[2] - tip) < 1e-3 for sp in release)
    assert all(sp.contact_gains for sp in release if sp.push_n > 0.0)
    flight.run_to(Mode.LAND, timeout_s=30.0)
    assert flight.mission.records[0].success


def test_a_failsafe_at_the_wall_lets_go_of_the_push_as_it_descends():
    flight = _in_mode(Mode.HOLD)
    cfg = flight.config
    flight.run_for(1.0)
    flight.step(odom_age_s=10.0 * cfg.failsafe.odom_stale_s)
    assert flight.mission.mode == Mode.FAILSAFE_LAND
    pushes = [flight.step(odom_age_s=10.0 * cfg.failsafe.odom_stale_s).push_n
              for _ in range(int(round(cfg.contact.press_time_s / DT_S)) + 2)]
    assert pushes[0] > 0.5 * flight.mission.contact_force_n
    assert np.all(np.diff(pushes) <= 1e-12) and pushes[-1] == 0.0


class GlimpseFlight(Flight):
    """Vision sees the target on two frames of the search, then never: too few measurements
    to confirm it, so the search moves closer to look again."""

    def __init__(self, config, target, obstacles):
        self._glimpses = 2
        super().__init__(config, target, obstacles=obstacles,
                         wall=(target.p_poi_map, target.normal_map, 10.0))

    def seen(self):
        if self.mission.mode == Mode.SEARCH and self._glimpses:
            self._glimpses -= 1
            return self.target
        return None


def test_the_move_closer_to_a_far_candidate_goes_round_obstacles():
    """A far candidate glimpsed twice, a pillar between it and the vehicle: the search moves
    closer to look again round the pillar, the body never nearer it than the vehicle's
    reach and the clearance, and drops the candidate when it is not seen again."""
    far = TargetEstimate(np.array([7.0, 0.0, 1.5]), NORMAL, 0.02, True)
    pillar = ObstacleBox((3.0, 0.0, 1.5), (0.4, 0.4, 3.0), 0.0)
    flight = GlimpseFlight(MissionConfig(), far, [pillar])
    assert flight.mission.inspect()[0]
    flight.run_until(lambda f: f.mission.phase == 'closer', 60.0)
    flight.run_until(lambda f: f.mission.phase != 'closer', 60.0)
    closer = [p for (_, _, _, p), phase in zip(flight.log, flight.phases) if phase == 'closer']
    keep_off_m = flight.mission._ctx.keep_off_m
    # it came within confirm_range_m of the candidate, past the pillar
    cfg = flight.config
    assert np.linalg.norm((far.p_poi_map - closer[-1])[:2]) <= (
        cfg.search.confirm_range_m + cfg.flight.arrive_tol_m)
    assert min(pillar.distance_xy(p[:2]) for p in closer) >= keep_off_m * 0.99
    flight.run_until(lambda f: f.mission.phase not in ('closer', 'confirm'), 60.0)
    assert flight.mission.mode == Mode.SEARCH
