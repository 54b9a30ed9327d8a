"""Reference segments: the sliding profile is at rest at each vertex, cruises at the task's
speed, keeps within the acceleration bound, and its p, v, a are consistent."""
import numpy as np
import pytest

from uav_tilt_control.trajectory import (BRAKE_ACCEL_M_S2, BRAKE_REACH, MIN_SEGMENT_S,
                                         Cruise, MinJerk, PolylineCruise)

DT_S = 0.002


def _samples(segment, t0_s):
    t = np.arange(t0_s - 0.5, t0_s + segment.T + 0.5, DT_S)
    p, v, a = (np.array(x) for x in zip(*(segment.sample(tk) for tk in t)))
    return t, p, v, a


@pytest.mark.parametrize('length_m, speed, accel', [(1.0, 0.1, 0.1), (1.0, 0.2, 0.1),
                                                    (0.05, 0.2, 0.1), (2.0, 0.5, 2.0)])
def test_cruise_is_at_rest_at_both_ends_and_keeps_its_bounds(length_m, speed, accel):
    p0 = np.array([0.3, -1.0, 2.0])
    direction = np.array([1.0, 2.0, -2.0]) / 3.0
    seg = Cruise(4.0, p0, p0 + length_m * direction, speed, accel)
    t, p, v, a = _samples(seg, 4.0)
    np.testing.assert_allclose(p[0], p0, atol=1e-12)
    np.testing.assert_allclose(p[-1], seg.p1, atol=1e-12)
    assert np.abs(v[[0, -1]]).max() == 0.0
    speed_along = v @ direction
    # cruises at the speed when the leg is long enough, else at the most it can reach
    reachable = min(speed, np.sqrt(length_m * accel / 1.875))
    assert speed_along.max() == pytest.approx(reachable, rel=1e-6)
    assert np.linalg.norm(a, axis=1).max() <= accel * (1 + 1e-6)
    # p integrates v and v integrates a (trapezoidal rule, smooth profile)
    np.testing.assert_allclose(np.diff(p, axis=0), 0.5 * (v[1:] + v[:-1]) * DT_S, atol=1e-7)
    np.testing.assert_allclose(np.diff(v, axis=0), 0.5 * (a[1:] + a[:-1]) * DT_S, atol=1e-6)
    # the reference stays on the line
    off = (p - p0) - np.outer((p - p0) @ direction, direction)
    assert np.abs(off).max() < 1e-12
    if speed_along.max() == pytest.approx(speed):
        assert seg.T == pytest.approx(length_m / speed + 1.875 * speed / accel)


def test_a_polyline_stops_at_each_vertex_and_reports_its_progress():
    points = np.array([[0.0, 0.0, 0.0], [0.0, 0.6, 0.0], [0.4, 0.6, 0.0]])
    line = PolylineCruise(1.0, points, 0.1, 0.1)
    assert line.length == pytest.approx(1.0)
    first = line.legs[0]
    p, v, _ = line.sample(first.t0_s + first.T)
    np.testing.assert_allclose(p, points[1], atol=1e-12)
    assert np.linalg.norm(v) < 1e-12
    t, p, _, _ = _samples(line, 1.0)
    progress = np.array([line.progress(tk) for tk in t])
    assert progress[0] == 0.0 and progress[-1] == 1.0
    assert np.all(np.diff(progress) >= -1e-12)
    # progress is the covered length: along the first leg it is the distance from the start
    inside = (t > 1.0) & (t < first.t0_s + first.T)
    np.testing.assert_allclose(progress[inside], np.linalg.norm(p[inside], axis=1), atol=1e-9)
    assert line.done(1.0 + line.T) and not line.done(1.0 + line.T - 1e-6)


def _distance_to_segment(p, a, b):
    d = b - a
    u = np.clip((p - a) @ d / max(d @ d, 1e-12), 0.0, 1.0)
    return np.linalg.norm(p - a - np.outer(u, d), axis=1)


# Peak of the brake quintic's share of a start acceleration, h_a(tau) = tau^2 (1 - tau)^3 / 2,
# per a0 T_b^2 (at tau = 2/5).
ACCEL_REACH = 0.5 * 0.4 ** 2 * 0.6 ** 3


def _parts_of_start_velocity(p0, p1, v0, T):
    """What the spec keeps of v0 (along p1 - p0, at most MIN_JERK_PEAK |p1 - p0| / T) and
    what it brakes."""
    d = p1 - p0
    along = d / np.linalg.norm(d)
    v_keep = along * np.clip(v0 @ along, 0.0, 1.875 * np.linalg.norm(d) / T)
    return v_keep, v0 - v_keep


@pytest.mark.parametrize('draw', range(20))
def test_a_min_jerk_that_starts_moving_brakes_within_its_bound_and_keeps_near_its_line(draw):
    """A fresh draw: a start velocity in any direction up to 1 m/s and acceleration up to
    2 m/s^2, a segment up to 8 m long. What of the start velocity does not carry on along
    the line is brought to rest at BRAKE_ACCEL_M_S2 where the segment is long enough, so
    the reference strays from the line between the ends by at most
    BRAKE_REACH |v_brake| T_b + ACCEL_REACH |a0| T_b^2, however long the segment."""
    rng = np.random.default_rng()
    p0 = rng.uniform(-3.0, 3.0, 3)
    p1 = p0 + rng.normal(size=3) * rng.uniform(0.01, 8.0) / np.sqrt(3.0)
    v0 = rng.normal(size=3)
    v0 *= rng.uniform(0.0, 1.0) / np.linalg.norm(v0)
    a0 = rng.normal(size=3)
    a0 *= rng.uniform(0.0, 2.0) / np.linalg.norm(a0)
    seg = MinJerk(2.0, p0, p1, rng.uniform(0.1, 1.0), v0, a0)
    t = np.arange(2.0, 2.0 + seg.T + 0.5, DT_S)
    p, v, a = (np.array(x) for x in zip(*(seg.sample(tk) for tk in t)))
    np.testing.assert_allclose([p[0], v[0], a[0]], [p0, v0, a0], atol=1e-12)
    np.testing.assert_allclose([p[-1], v[-1], a[-1]], [p1, np.zeros(3), np.zeros(3)],
                               atol=1e-12)
    np.testing.assert_allclose(np.diff(p, axis=0), 0.5 * (v[1:] + v[:-1]) * DT_S, atol=1e-6)
    np.testing.assert_allclose(np.diff(v, axis=0), 0.5 * (a[1:] + a[:-1]) * DT_S, atol=1e-4)
    v_keep, v_brake = _parts_of_start_velocity(p0, p1, v0, seg.T)
    speed = np.linalg.norm(v_brake)
    assert seg.T_brake <= seg.T
    assert seg.T_brake <= max(MIN_SEGMENT_S, 3.95 * speed / BRAKE_ACCEL_M_S2)
    reach = _distance_to_segment(p, p0, p1).max()
    assert reach <= (BRAKE_REACH * speed * seg.T_brake
                     + ACCEL_REACH * np.linalg.norm(a0) * seg.T_brake ** 2 + 1e-9)
    rest_to_rest = 5.7735 * np.linalg.norm(p1 - p0) / seg.T ** 2
    carried = 3.9403 * np.linalg.norm(v_keep) / seg.T
    brake = 3.9403 * speed / seg.T_brake
    bound = rest_to_rest + carried + brake + np.linalg.norm(a0)
    assert np.linalg.norm(a, axis=1).max() <= bound + 1e-6
    if seg.T >= max(MIN_SEGMENT_S, 3.95 * speed / BRAKE_ACCEL_M_S2):
        # long enough to brake at the bound: it does
        assert brake <= BRAKE_ACCEL_M_S2 * (1 + 1e-4)


@pytest.mark.parametrize('draw', range(10))
def test_a_min_jerk_carries_a_start_velocity_along_its_line_without_overshoot(draw):
    """Moving towards the goal at up to the speed the segment carries on (v_max, or less
    where the segment lasts longer than its length needs: MIN_SEGMENT_S), the segment goes
    on at that speed, never faster, never back, never past the goal, and on the line."""
    rng = np.random.default_rng()
    p0 = rng.uniform(-3.0, 3.0, 3)
    direction = rng.normal(size=3)
    direction /= np.linalg.norm(direction)
    length_m = rng.uniform(0.01, 5.0)
    p1 = p0 + direction * length_m
    v_max = rng.uniform(0.1, 1.0)
    T = max(1.875 * length_m / v_max, MIN_SEGMENT_S)
    v0 = direction * rng.uniform(0.0, 1.875 * length_m / T)
    seg = MinJerk(0.0, p0, p1, v_max, v0)
    assert seg.T == pytest.approx(T)
    t, p, v, _ = _samples(seg, 0.0)
    progress = (p - p0) @ direction
    assert np.all(np.diff(progress) >= -1e-12)
    assert progress.max() <= length_m + 1e-12
    assert np.linalg.norm(v, axis=1).max() <= v_max * (1 + 1e-9)
    assert _distance_to_segment(p, p0, p1).max() < 1e-9
    # from v0 the speed rises at most to the rest-to-rest peak, then only falls
    speed = v[t >= 0.0] @ direction
    assert speed.max() <= max(np.linalg.norm(v0), 1.875 * length_m / T) * (1 + 1e-9)
    assert np.all(np.diff(speed[speed.argmax():]) <= 1e-12)


@pytest.mark.parametrize('draw', range(10))
def test_a_stream_of_goals_is_followed_at_its_speed(draw):
    """A goal moving at a steady speed, sent as a new segment from the current reference at
    10-50 Hz (a stream of setpoints): the reference moves at the stream's speed and lags
    it by 0.6 u MIN_SEGMENT_S (the receding minimum-jerk law's ramp error, 60 L / T^3 =
    36 u / T^2) plus what the goal moved since it was sent, whatever the rate."""
    rng = np.random.default_rng()
    v_max = rng.uniform(0.2, 1.0)
    u = rng.uniform(0.05, 0.7) * v_max
    rate_hz = rng.uniform(10.0, 50.0)
    direction = rng.normal(size=3)
    direction /= np.linalg.norm(direction)
    p0 = rng.uniform(-3.0, 3.0, 3)
    seg = MinJerk(0.0, p0, p0, v_max)
    lags, speeds, t_next = [], [], 0.0
    for t in np.arange(0.0, 8.0, DT_S):
        if t >= t_next:
            p, v, a = seg.sample(t)
            seg = MinJerk(t, p, p0 + direction * u * t, v_max, v, a)
            t_next += 1.0 / rate_hz
        p, v, _ = seg.sample(t)
        assert np.linalg.norm(v) <= v_max * (1 + 1e-9)
        if t > 4.0:     # settled: the law's poles lie at 2.7-3.6 s^-1 for T = 1 s
            lags.append(u * t - (p - p0) @ direction)
            speeds.append(v @ direction)
            assert np.linalg.norm(p - p0 - ((p - p0) @ direction) * direction) < 1e-9
    lag_m = 0.6 * u * MIN_SEGMENT_S
    assert lag_m * 0.97 <= min(lags) and max(lags) <= (lag_m + u / rate_hz) * 1.03
    assert np.mean(speeds) == pytest.approx(u, rel=0.02)
