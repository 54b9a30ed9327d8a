"""The campaign's world covers what a user will build, and the mission succeeds in it: a
ground-truth campaign of 20 draws made fresh for this run succeeds in >= 95% (goal 98%),
and one of 10 draws at the ends of every range (--corners) in at least 8. A run succeeds
when it meets the inspection bar by the truth, not only when the controller completed it."""
import numpy as np
import pytest

from uav_tilt_common.targets import HINT_ERROR_M
from uav_tilt_sim import randomise as rd
from uav_tilt_sim.randomise import random_draw
from uav_tilt_tools.campaign.run import campaign
from uav_tilt_tools.campaign.summary import summarize, wilson_interval
from uav_tilt_tools.metrics.tasks import failure_of
from uav_tilt_tools.metrics.tasks import POI_BAR_M, task_results

pytestmark = pytest.mark.slow     # minutes of missions or graphs: handed out first


def test_random_draws_cover_the_stated_ranges():
    draws = [random_draw(seed) for seed in range(300)]
    scenarios = [s for s, _ in draws]
    distance = np.array([np.hypot(*s.wall.position_m) for s in scenarios])
    assert distance.min() >= rd.WALL_DISTANCE_M[0] and distance.max() <= rd.WALL_DISTANCE_M[1]
    # the wall's normal off the line of sight, and the start heading off the wall
    off_normal, start_off = [], []
    for s in scenarios:
        bearing = np.degrees(np.arctan2(s.wall.position_m[1], s.wall.position_m[0]))
        off_normal.append(rd._wrap_deg(s.wall.yaw_deg - bearing))
        start_off.append(rd._wrap_deg(s.start_yaw_deg - bearing))
    assert np.max(np.abs(off_normal)) <= rd.WALL_YAW_DEG + 1e-9
    assert np.ptp(off_normal) > rd.WALL_YAW_DEG and np.ptp(start_off) > 300.0
    inclination = np.array([s.wall.inclination_deg for s in scenarios])
    assert np.all(np.abs(inclination) <= rd.WALL_INCLINATION_DEG)
    stiffness = np.array([s.wall.stiffness_n_per_m for s in scenarios])
    assert stiffness.min() >= 500.0 and stiffness.max() <= 50000.0
    # log-uniform: as many draws below the geometric mean as above it
    assert abs(np.mean(stiffness < np.sqrt(500.0 * 50000.0)) - 0.5) < 0.1
    mass = np.array([s.mismatch.mass_scale for s in scenarios])
    assert np.all(np.abs(mass - 1.0) <= rd.MASS_MISMATCH)
    for s, hint in draws:
        target = [o for o in s.objects if o.target]
        assert len(target) == 1 and rd.TARGET_HEIGHT_M[0] <= target[0].v_m \
            <= rd.TARGET_HEIGHT_M[1]
        assert np.linalg.norm(s.wind.mean_m_s) <= rd.MEAN_WIND_M_S + 1e-9
        assert 3.0 * s.wind.gust_std_m_s <= rd.GUST_PEAK_M_S + 1e-9
        plates = [o for o in s.objects if o.cls == 'bolt_plate']
        # a look-alike comes with a hint within 0.3 m of the target
        assert (hint is not None) == (len(plates) > 1)
        if hint is not None:
            assert max(abs(hint[0] - target[0].u_m), abs(hint[1] - target[0].v_m)) <= 0.3
        # every object lies on the wall
        assert all(abs(o.u_m) < s.wall.width_m / 2 and 0.0 < o.v_m < s.wall.height_m
                   for o in s.objects)
    assert 0.15 < np.mean([h is not None for _, h in draws]) < 0.45
    assert random_draw(7) == random_draw(7)


def test_corner_draws_put_every_range_at_one_of_its_ends():
    draws = [random_draw(seed, corners=True) for seed in range(80)]

    def at_ends(values, ends):
        values = np.asarray(values, dtype=float)
        low, high = (np.isclose(values, end, rtol=1e-9, atol=1e-9) for end in ends)
        # every value at an end, both ends drawn
        assert np.all(low | high) and low.any() and high.any(), (ends, values)

    scenarios = [s for s, _ in draws]
    bearing = [np.degrees(np.arctan2(s.wall.position_m[1], s.wall.position_m[0]))
               for s in scenarios]
    at_ends([np.hypot(*s.wall.position_m) for s in scenarios], rd.WALL_DISTANCE_M)
    at_ends([rd._wrap_deg(s.wall.yaw_deg - b) for s, b in zip(scenarios, bearing)],
            (-rd.WALL_YAW_DEG, rd.WALL_YAW_DEG))
    # the start heading off the wall's direction: +-180 degrees are one heading, away
    assert all(abs(abs(rd._wrap_deg(s.start_yaw_deg - b)) - 180.0) < 1e-6
               for s, b in zip(scenarios, bearing))
    at_ends([s.wall.inclination_deg for s in scenarios],
            (-rd.WALL_INCLINATION_DEG, rd.WALL_INCLINATION_DEG))
    at_ends([s.wall.stiffness_n_per_m for s in scenarios], rd.STIFFNESS_N_PER_M)
    assert {s.wall.stiffness_n_per_m for s in scenarios} == set(rd.STIFFNESS_N_PER_M)
    at_ends([s.wall.friction for s in scenarios], rd.FRICTION)
    at_ends([np.linalg.norm(s.wind.mean_m_s) for s in scenarios], (0.0, rd.MEAN_WIND_M_S))
    at_ends([3.0 * s.wind.gust_std_m_s for s in scenarios], (0.0, rd.GUST_PEAK_M_S))
    at_ends([s.mismatch.mass_scale for s in scenarios],
            (1.0 - rd.MASS_MISMATCH, 1.0 + rd.MASS_MISMATCH))
    targets = [next(o for o in s.objects if o.target) for s in scenarios]
    at_ends([t.u_m for t in targets], (-rd.TARGET_U_M, rd.TARGET_U_M))
    at_ends([t.v_m for t in targets], rd.TARGET_HEIGHT_M)
    hinted = [(hint, t) for (_, hint), t in zip(draws, targets) if hint is not None]
    assert hinted
    for hint, t in hinted:
        np.testing.assert_allclose(np.abs([hint[0] - t.u_m, hint[1] - t.v_m]),
                                   HINT_ERROR_M)
    assert all(abs(o.u_m) < s.wall.width_m / 2 and 0.0 < o.v_m < s.wall.height_m
               for s in scenarios for o in s.objects)
    # the uniform draw is another world
    assert random_draw(7, corners=True) != random_draw(7)


def test_wilson_interval():
    low, high = wilson_interval(19, 20)
    # the textbook value for 19 of 20 at 95%: [0.764, 0.991]
    assert low == pytest.approx(0.764, abs=1e-3) and high == pytest.approx(0.991, abs=1e-3)
    # all successes (or none): the rate lies inside its own interval, without rounding
    for n in (1, 7, 20, 40, 333):
        low, high = wilson_interval(n, n)
        assert low <= 1.0 == high
        low, high = wilson_interval(0, n)
        assert low == 0.0 <= high


def _completed_touch(offset_m, push_n, force_n=5.0):
    """A one-touch run the controller completed, its task measured (task_results) from a
    5 s hold with the true tool tip ``offset_m`` from the point of interest along the wall
    and the wall pushing back with ``push_n``."""
    t_s = np.arange(0.0, 10.0, 0.01)
    poi_map = np.array([3.0, -1.0, 1.5])
    R_map_target = np.array([[0.0, 0.0, -1.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    normal = R_map_target[:, 2]
    tips = np.tile(poi_map + R_map_target[:, 0] * offset_m, (len(t_s), 1))
    forces = np.tile(normal * push_n, (len(t_s), 1))
    task = dict(index=0, kind='touch', target='', force_n=force_n, success=True, reason='',
                contact_lost=0, t_contact_s=[2.0, 7.0])
    tasks = task_results([task], t_s, tips, forces, {'': (poi_map, R_map_target)})
    return dict(success=True, tasks=tasks)


def test_a_completed_run_off_the_bar_by_the_truth_is_a_failure():
    rng = np.random.default_rng()
    within = _completed_touch(rng.uniform(0.0, 0.95) * POI_BAR_M, 5.0 + rng.uniform(-0.05, 0.05))
    assert failure_of(within) is None
    # a look-alike pressed instead of the target: the controller completed it
    elsewhere = _completed_touch(rng.uniform(1.05, 100.0) * POI_BAR_M, 5.0)
    assert failure_of(elsewhere) == dict(reason='off_target', mode='HOLD', phase='')
    pushed = _completed_touch(0.0, 5.0 + rng.choice([-1.0, 1.0]) * rng.uniform(0.15, 1.0))
    assert failure_of(pushed)['reason'] == 'force_off_setpoint'
    runs = [dict(within, failure=failure_of(within)),
            dict(elsewhere, failure=failure_of(elsewhere))]
    result = summarize(2, 0, 'vision', runs)
    assert result['successes'] == 1 and result['failures'] == {'off_target in HOLD': 1}


def test_campaign_of_twenty_fresh_draws_succeeds_in_at_least_95_percent():
    seed = int(np.random.default_rng().integers(0, 2**31 - 1))
    result = campaign(20, seed=seed, progress=False)
    assert result['n'] == 20 and len(result['runs']) == 20
    failed = [r for r in result['runs'] if r['failure']]
    assert all(r['failure']['reason'] and r['failure']['mode'] for r in failed)
    low, high = result['success_rate_ci95']
    assert low <= result['success_rate'] <= high
    assert result['success_rate'] >= 0.95, (seed, [(r['seed'], r['failure']) for r in failed])


def test_corner_campaign_succeeds_at_the_ends_of_every_range():
    # Half of these walls are 50,000 N/m, half 500; every one inclined 25 degrees, every
    # target at a corner of its area; mean wind 2 m/s or none, gusts 1 m/s or none. Measured
    # 40 of 40 (seed 20261211): at least 8 of 10 fails about once in a thousand runs at a
    # true rate of 98%, and certainly when a kind of corner (a stiff wall, say) fails.
    seed = int(np.random.default_rng().integers(0, 2**31 - 1))
    result = campaign(10, seed=seed, progress=False, corners=True)
    assert result['corners'] is True and result['n'] == 10
    failed = [r for r in result['runs'] if r['failure']]
    assert result['successes'] >= 8, (seed, [(r['seed'], r['failure']) for r in failed])
