"""The mission as a plan executor, flown by test_mission's Flight (a synthetic perfect
tracker): the vehicle is where the setpoint puts it, except that a flat wall stops the tool
tip, and pushed against it with contact gains it measures the impedance spring K_z times the
depth. Each touch's target is seen by vision (or never, where a test says so)."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from uav_tilt_common.config import from_dict
from uav_tilt_control.mission import Mission, MissionConfig, Mode
from uav_tilt_control.mission.base import ModeBehaviour
from uav_tilt_control.obstacles import ObstacleBox
from uav_tilt_control.plan import Slide, Touch
from uav_tilt_control.surfaces import SurfacePath
from uav_tilt_control.target_estimator import TargetEstimate
from test_mission import DT_S, VEHICLE, Flight, touch_ticks

TIP = VEHICLE.tool_tip_x_m
WALL_X_M = 3.0
NORMAL = np.array([-1.0, 0.0, 0.0])                 # out of the wall, towards the start
TARGETS = {'a': np.array([WALL_X_M, 0.5, 1.4]), 'b': np.array([WALL_X_M, -0.6, 1.8]),
           # far apart on the wall, a pillar between them (test_the_transit_goes_round...)
           'c': np.array([WALL_X_M, 1.6, 1.5]), 'd': np.array([WALL_X_M, -1.6, 1.5])}
LINE = np.array([[WALL_X_M, -1.3, 1.0], [WALL_X_M, -1.3, 2.0]])   # 1 m up the wall


def _slide(line):
    """A slide along ``line`` on the flat wall (its vertices the path's)."""
    return Slide(SurfacePath(line.copy(), np.tile(NORMAL, (len(line), 1)),
                             list(range(len(line)))), 0.1, 5.0)


def _plan(slide_first=False):
    touches = [Touch('a', TARGETS['a'] + [0.0, 0.1, 0.1], NORMAL, 5.0, 2.0),
               Touch('b', TARGETS['b'] + [0.0, -0.2, 0.1], NORMAL, 8.0, 1.0)]
    slide = _slide(LINE)
    return [slide, *touches] if slide_first else [*touches, slide]


class PlanFlight(Flight):
    """test_mission's Flight flying a plan, against a flat wall that reaches everywhere;
    ``unseen``: targets vision never finds; ``yaw_error_rad``: added to the odometry's yaw
    while sliding (a tool swung aside)."""

    def __init__(self, plan, config=None, unseen=(), yaw_error_rad=0.0, stuck=False,
                 obstacles=()):
        self.unseen, self.yaw_error_rad, self.stuck = set(unseen), yaw_error_rad, stuck
        self._stuck_p_map = None
        super().__init__(config or from_dict(MissionConfig, {'search.timeout_s': 4.0}),
                         target=None, plan=plan,
                         wall=(TARGETS['a'], NORMAL, np.inf), obstacles=obstacles)

    def seen(self):
        task = self.mission.task
        if task is None or task.kind != 'touch' or task.target in self.unseen:
            return None
        return TargetEstimate(TARGETS[task.target], NORMAL, 0.02, True)

    def state(self):
        state = super().state()
        if self.mission.mode == Mode.SLIDE and self.yaw_error_rad:
            state.q_map_base = (Rotation.from_euler('z', self.yaw_error_rad)
                                * Rotation.from_quat(state.q_map_base)).as_quat()
        if self.mission.mode == Mode.SLIDE and self.stuck:
            # odometry sees the vehicle stay where the slide began
            if self._stuck_p_map is None:
                self._stuck_p_map = state.p_map.copy()
            state.p_map = self._stuck_p_map.copy()
        return state

    def fly(self):
        assert self.mission.inspect()[0]
        self.run_until(lambda f: f.mission.mode == Mode.IDLE and f.t_s > 1.0)
        return self


def test_a_plan_runs_two_touches_and_a_slide_in_order():
    flight = PlanFlight(_plan()).fly()
    mission = flight.mission
    status = mission.status
    assert status['success'] and status['inspection_completed'], mission.records
    assert status['task_outcomes'] == 'ok,ok,ok' and status['task_count'] == 3
    touch = [Mode.SEARCH, Mode.APPROACH, Mode.CONTACT, Mode.HOLD, Mode.RETREAT]
    assert flight.modes == [Mode.IDLE, Mode.TAKEOFF, Mode.HOVER, *touch, Mode.HOVER, *touch,
                            Mode.APPROACH, Mode.CONTACT, Mode.SLIDE, Mode.RETREAT, Mode.LAND,
                            Mode.IDLE]
    records = mission.records
    assert [r.success for r in records] == [True, True, True]
    plan = mission.plan
    for task, record in zip(plan[:2], records[:2]):
        start, end = record.t_contact_s
        assert end - start == pytest.approx(task.hold_s, abs=2 * DT_S)
        held = [f for (t, *_), f in zip(flight.log, flight.forces) if start <= t < end]
        # the push of each task is its own: K_z times the depth from its force
        assert np.mean(held[10:]) == pytest.approx(task.force_n, rel=1e-3)
    # before each touch it flew (HOVER 'transit') to look at where the plan says the target
    # is, from look_distance_m in front of the wall, facing it: SEARCH starts there
    starts = [k for k in range(1, len(flight.log))
              if flight.log[k][1] == Mode.SEARCH and flight.log[k - 1][1] != Mode.SEARCH]
    assert len(starts) == 2
    for k, task in zip(starts, plan[:2]):
        assert flight.phases[k - 1] == 'transit'
        look = task.hint_map + NORMAL * flight.config.flight.look_distance_m
        np.testing.assert_allclose(flight.log[k][3], look, atol=flight.config.flight.arrive_tol_m)
        x_tool = Rotation.from_quat(flight.attitudes[k]).apply([1.0, 0.0, 0.0])
        assert x_tool @ -NORMAL > np.cos(flight.config.flight.arrive_yaw_tol_rad)


@pytest.mark.parametrize('inclination_deg, hint_z_m',
                         [(-25.0, 0.7), (25.0, 0.7), (-25.0, 2.5), (0.0, 0.4)])
def test_the_camera_looks_at_the_hint_when_the_search_starts(inclination_deg, hint_z_m):
    # A wall leaning over the start (negative inclination) puts the look point along its
    # normal under a low hint's height, so the ground limit raises it: the camera must then
    # look down at the hint, not up along the normal and over it.
    tilt = np.radians(inclination_deg)
    normal = np.array([-np.cos(tilt), 0.0, np.sin(tilt)])
    hint = np.array([WALL_X_M, 0.3, hint_z_m])
    flight = PlanFlight([Touch('a', hint, normal, 5.0, 1.0)], unseen={'a'})
    assert flight.mission.inspect()[0]
    flight.run_until(lambda f: f.mission.mode == Mode.SEARCH)
    p_map, q = flight.log[-1][3], flight.attitudes[-1]
    config = flight.config
    assert p_map[2] >= config.land.ground_z_m + 2.0 * config.land.detect_height_m - 1e-9
    cam = VEHICLE.camera_in_base()
    R_map_base = Rotation.from_quat(q).as_matrix()
    ray_cam = (R_map_base @ cam.R).T @ (hint - (p_map + R_map_base @ cam.p))
    # the hint is within a few degrees of the optical axis (the half field of view of the
    # 320x240 camera is 30 x 23 degrees; a target +-0.3 m off the hint must stay in it)
    off_axis_deg = np.degrees(np.arctan2(np.hypot(ray_cam[0], ray_cam[1]), ray_cam[2]))
    assert off_axis_deg < 5.0


def test_the_slide_follows_its_line_with_the_push_and_the_friction_feedforward():
    flight = PlanFlight(_plan()).fly()
    slide = flight.mission.plan[2]
    record = flight.mission.records[2]
    start, end = record.t_contact_s
    ticks = [(*entry, f, q) for entry, f, q in zip(flight.log, flight.forces, flight.attitudes)
             if start <= entry[0] < end]
    assert all(mode == Mode.SLIDE for _, mode, *_ in ticks)
    # tool tip of the vehicle (where the setpoint put it) against the line
    tips = np.array([p + Rotation.from_quat(q).apply([TIP, 0.0, 0.0])
                     for _, _, _, p, _, q in ticks])
    assert np.abs(tips[:, 1] - LINE[0, 1]).max() < 1e-6
    assert np.abs((tips - LINE[0]) @ NORMAL).max() < 1e-9         # on the surface
    assert tips[0, 2] == pytest.approx(LINE[0, 2], abs=1e-6)
    assert tips[-1, 2] == pytest.approx(LINE[1, 2], abs=1e-3)
    speeds = np.array([np.linalg.norm(sp.R_map_t @ sp.dlambda_d_t) for _, _, sp, *_ in ticks])
    assert speeds.max() == pytest.approx(slide.speed_m_s, rel=1e-6)
    assert np.array([f for *_, f, _ in ticks])[5:] == pytest.approx(slide.force_n, rel=1e-3)
    # compliant along the normal, friction fed forward exactly while sliding
    assert all(sp.contact_gains and sp.tangential_feedforward for _, _, sp, *_ in ticks)
    assert not any(sp.tangential_feedforward for _, mode, sp, _ in flight.log
                   if mode != Mode.SLIDE)
    # 1 m at 0.1 m/s, plus the speed-up and slow-down (each half as long at the cruise speed)
    assert end - start == pytest.approx(1.0 / 0.1 + 1.875 * 0.1 / flight.config.slide.accel_m_s2,
                                        abs=2 * DT_S)


def test_a_target_never_seen_fails_its_task_and_the_plan_goes_on():
    flight = PlanFlight(_plan(), unseen={'a'}).fly()
    records = flight.mission.records
    assert (records[0].success, records[0].reason) == (False, 'target_not_found')
    assert [r.success for r in records[1:]] == [True, True]
    status = flight.mission.status
    assert status['task_outcomes'] == 'target_not_found,ok,ok'
    assert not status['success'] and status['failsafe_reason'] == 'target_not_found'
    modes = flight.modes
    assert modes[:5] == [Mode.IDLE, Mode.TAKEOFF, Mode.HOVER, Mode.SEARCH, Mode.HOVER]
    assert Mode.SLIDE in modes and modes[-2:] == [Mode.LAND, Mode.IDLE]


def test_a_tool_swung_off_the_line_fails_the_slide_which_lifts_off():
    flight = PlanFlight(_plan(slide_first=True), yaw_error_rad=0.15).fly()
    records = flight.mission.records
    assert (records[0].success, records[0].reason) == (False, 'off_line')
    assert [r.success for r in records[1:]] == [True, True]
    after = flight.modes
    assert after[after.index(Mode.SLIDE) + 1] == Mode.RETREAT


@pytest.mark.parametrize('line', [
    LINE,
    # up half a metre and back: its end is its start, where the tool tip stays
    np.array([LINE[0], LINE[0] + [0.0, 0.0, 0.5], LINE[0]]),
])
def test_a_tool_tip_that_does_not_follow_the_line_fails_the_slide(line):
    """Friction, or something on the line, may hold the tool tip where it touched while the
    reference slides on: the slide fails once the reference is slide_path_tolerance_m ahead
    along the line, not when the line's time is up (the vehicle pitches against what holds
    the tool meanwhile: a real one tipped over)."""
    slide = _slide(line)
    plan = [slide, *_plan()[:1]]
    flight = PlanFlight(plan, stuck=True).fly()
    records = flight.mission.records
    assert (records[0].success, records[0].reason) == (False, 'short_of_line'), records
    sliding_s = [t for t, mode, _, _ in flight.log if mode == Mode.SLIDE]
    # the reference's speed-up alone covers the tolerance (5 cm) within speed / accel + the
    # tolerance / speed (1.5 s); the line takes over 10 s
    cfg = flight.config
    ahead_s = slide.speed_m_s / cfg.slide.accel_m_s2 + cfg.slide.path_tolerance_m / (
        slide.speed_m_s)
    assert sliding_s[-1] - sliding_s[0] <= ahead_s < slide.contact_s / 5
    assert records[1].success
    modes = flight.modes
    assert modes[modes.index(Mode.SLIDE) + 1] == Mode.RETREAT


def test_the_force_limit_ends_the_plan():
    flight = PlanFlight(_plan())
    assert flight.mission.inspect()[0]
    flight.run_until(lambda f: f.mission.mode == Mode.HOLD)
    flight.step(force_n=flight.config.failsafe.force_limit_n + 1.0)
    flight.run_until(lambda f: f.mission.mode == Mode.IDLE)
    records = flight.mission.records
    assert [(r.success, r.reason) for r in records] == [
        (False, 'force_limit'), (False, 'not_run'), (False, 'not_run')]
    assert flight.modes[-4:] == [Mode.HOLD, Mode.RETREAT, Mode.LAND, Mode.IDLE]


def test_abort_stops_the_plan_and_hovers():
    flight = PlanFlight(_plan())
    assert flight.mission.inspect()[0]
    flight.run_until(lambda f: f.mission.phase == 'transit' and f.mission.task.target == 'b')
    assert flight.mission.abort() == (True, 'hovering')
    flight.run_until(lambda f: np.linalg.norm(f.v) < 1e-6, 30.0)
    assert flight.mission.mode == Mode.HOVER and flight.mission.phase == ''
    assert [r.reason for r in flight.mission.records] == ['', 'aborted', 'not_run']


def test_a_transit_that_meets_a_wall_backs_off_and_searches_from_there():
    flight = PlanFlight(_plan(), MissionConfig())
    cfg = flight.config
    assert flight.mission.inspect()[0]
    flight.run_until(lambda f: f.mission.phase == 'transit' and f.mission.task.target == 'b'
                     and np.linalg.norm(f.v) > 0.2)
    push = np.array([-0.4, 1.5, 0.0])
    for _ in range(touch_ticks(cfg, push, DT_S)):
        p0 = flight.p.copy()
        flight.step(f_map=push)
        if flight.mission.phase == 'clear':
            break
    assert flight.mission.phase == 'clear'
    flight.run_until(lambda f: f.mission.mode == Mode.SEARCH, 20.0)
    # searched from where it backed off, not from the look point
    np.testing.assert_allclose(flight.p - p0, push / np.linalg.norm(push)
                               * cfg.bump.clearance_m, atol=cfg.flight.arrive_tol_m)
    flight.run_until(lambda f: f.mission.mode == Mode.IDLE)
    assert flight.mission.status['task_outcomes'] == 'ok,ok,ok'


def test_a_transit_held_on_its_way_lands_and_ends_the_plan():
    cfg = from_dict(MissionConfig, {
        'flight.arrive_timeout_s': float(np.random.default_rng().uniform(2.0, 20.0))})
    flight = PlanFlight(_plan(), cfg)
    assert flight.mission.inspect()[0]
    flight.run_until(lambda f: f.mission.phase == 'transit' and f.mission.task.target == 'b')
    flight._track = lambda sp: None       # something holds the vehicle where it is
    segment = flight.mission.reference.segment
    flight.run_until(lambda f: f.mission.mode != Mode.HOVER,
                     segment.T + cfg.flight.arrive_timeout_s)
    assert flight.mission.mode == Mode.LAND
    assert flight.t_s == pytest.approx(segment.t0_s + segment.T + cfg.flight.arrive_timeout_s,
                                       abs=2 * DT_S)
    del flight._track
    flight.run_until(lambda f: f.mission.mode == Mode.IDLE, 30.0)
    assert [r.reason for r in flight.mission.records] == ['', 'unreachable', 'not_run']


def test_every_mode_is_a_behaviour_of_its_own_with_its_own_tick():
    behaviours = Mission(VEHICLE).behaviours
    assert set(behaviours) == set(Mode)
    assert all(b.mode == mode for mode, b in behaviours.items())
    assert len({id(b) for b in behaviours.values()}) == len(Mode)
    assert all(type(b).tick is not ModeBehaviour.tick for b in behaviours.values())


def test_one_noisy_force_reading_is_not_the_wall():
    """Closing in, a single F/T reading over the touch threshold (noise) starts no press."""
    flight = PlanFlight(_plan())
    assert flight.mission.inspect()[0]
    flight.run_until(lambda f: f.mission.phase == 'close')
    flight.step(force_n=flight.config.contact.touch_threshold_n + 0.5)
    flight.run_until(lambda f: f.mission.phase != 'close')
    assert flight.mission.phase == 'touch'


def test_the_transit_between_two_touches_goes_round_a_pillar_in_its_way():
    """Two touches either side of a pillar standing out from the wall: from the first
    touch's standoff to where the second is looked at, the straight way crosses the
    pillar; the transit goes round it (the wall too is an obstacle of the site), the body
    never nearer it than the vehicle's reach and the clearance, and both touches are made."""
    pillar = ObstacleBox((1.75, 0.0, 1.5), (0.3, 0.3, 3.0), 0.0)
    wall = ObstacleBox((WALL_X_M + 0.1, 0.0, 1.75), (0.2, 8.0, 3.5), 0.0)
    plan = [Touch('c', TARGETS['c'] + [0.0, -0.1, 0.1], NORMAL, 5.0, 1.0),
            Touch('d', TARGETS['d'] + [0.0, 0.1, -0.1], NORMAL, 5.0, 1.0)]
    flight = PlanFlight(plan, obstacles=[pillar, wall]).fly()
    assert [r.success for r in flight.mission.records] == [True, True]
    keep_off_m = flight.mission._ctx.keep_off_m
    held_s = next(t for t, mode, _, _ in flight.log if mode == Mode.HOLD)
    # from the first touch to the second (the flight to the first starts at take-off)
    transit = [p for (t, mode, _, p), phase in zip(flight.log, flight.phases)
               if mode == Mode.HOVER and phase == 'transit' and t > held_s]
    assert transit
    # the straight way would have crossed it
    a, b = transit[0][:2], transit[-1][:2]
    assert min(pillar.distance_xy(a + (b - a) * k) for k in np.linspace(0, 1, 101)) == 0.0
    assert min(pillar.distance_xy(p[:2]) for p in transit) >= keep_off_m * 0.99
