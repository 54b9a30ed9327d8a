"""Tests for uav_tilt_control.walls: the walls a search saw, and where it faces them from."""
import math

import numpy as np
import pytest

from uav_tilt_control import frames
from uav_tilt_control.walls import WallMemory

FRESH = np.random.SeedSequence().entropy


def _wall(rng):
    """A wall 2-5 m from the origin, yawed anywhere, leaning up to 30 degrees either way:
    (a point on it at 1.5 m, its unit normal towards the origin, its horizontal along)."""
    yaw, lean = rng.uniform(-np.pi, np.pi), np.radians(rng.uniform(-30, 30))
    n = np.array([np.cos(yaw) * np.cos(lean), np.sin(yaw) * np.cos(lean), np.sin(lean)])
    R, _ = frames.target_frame_from_normal(np.zeros(3), n)
    point = -n * rng.uniform(2.0, 5.0)
    point = point + R[:, 1] * (1.5 - point[2]) / R[:, 1][2]
    return point, n, R[:, 0]


@pytest.mark.parametrize('draw', range(4))
def test_the_parts_of_one_wall_make_one_wall_and_the_ground_none(draw):
    rng = np.random.default_rng([FRESH, draw])
    point, n, along = _wall(rng)
    R, _ = frames.target_frame_from_normal(point, n)
    up = R[:, 1]
    memory = WallMemory()
    assert not memory.observe([1.0, 2.0, 0.0], [0.0, 0.0, 1.0], 0.3)       # the ground
    assert not memory.observe([1.0, 2.0, 3.0], [0.1, 0.0, -0.99], 0.3)     # a ceiling
    seen = rng.uniform(-3.0, 3.0, 12)
    shares = rng.uniform(0.1, 0.8, seen.size)
    for s, share in zip(seen, shares):
        # the centroid of what a frame saw of it, 1 degree of normal noise
        tilt = frames.unit(n + rng.normal(0.0, math.radians(1.0), 3))
        assert memory.observe(point + along * s + up * rng.uniform(-0.5, 0.5), tilt, share)
    assert len(memory.walls) == 1
    wall = memory.best()
    # the share-weighted mean of the normals: 1 degree per axis across the normal, shrunk
    # by the weights; its angle off the normal is Rayleigh, over 5 sigma once in 270,000
    sigma_deg = 1.0 * np.sqrt(np.sum(shares ** 2)) / np.sum(shares)
    assert math.degrees(math.acos(min(wall.normal_map @ n, 1.0))) < 5.0 * sigma_deg
    assert abs((wall.point_map - point) @ n) < 0.02
    # the extent reaches both ends of what was seen, along the wall
    lo, hi = wall.along_m
    ends = [(wall.point_map + along * e - point) @ along for e in (lo, hi)]
    assert ends == pytest.approx([seen.min(), seen.max()], abs=0.1)


def test_two_walls_stay_apart_and_the_one_seen_most_is_best():
    memory = WallMemory()
    n1, n2 = np.array([-1.0, 0.0, 0.0]), np.array([0.0, -1.0, 0.0])
    for _ in range(3):
        memory.observe([3.0, 0.0, 1.5], n1, 0.2)
        memory.observe([0.0, 4.0, 1.5], n2, 0.3)
    # parallel to the first but a metre behind it: another wall
    memory.observe([4.0, 0.0, 1.5], n1, 0.1)
    assert len(memory.walls) == 3
    np.testing.assert_allclose(memory.best().normal_map, n2)


@pytest.mark.parametrize('draw', range(4))
def test_the_face_points_stand_off_the_wall_at_the_altitude_and_face_it(draw):
    rng = np.random.default_rng([FRESH, 100 + draw])
    point, n, along = _wall(rng)
    memory = WallMemory()
    for s in (-2.0, 0.0, 2.0):
        memory.observe(point + along * s, n, 0.3)
    wall = memory.best()
    standoff, altitude = rng.uniform(1.5, 3.5), rng.uniform(0.8, 2.5)
    points, yaw = wall.face_points(standoff, altitude, spacing_m=2.0)
    n_h = frames.unit([n[0], n[1], 0.0])
    assert len(points) == 2
    for p in points:
        assert p[2] == pytest.approx(altitude)
        # standoff_m out from the wall's line at that altitude, horizontally
        assert (p - point) @ n == pytest.approx(standoff * (n_h @ n), abs=1e-6)
    assert abs(((points[1] - points[0]) @ along)) == pytest.approx(4.0, abs=1e-6)
    # the heading looks into the wall
    assert np.array([math.cos(yaw), math.sin(yaw)]) @ n_h[:2] == pytest.approx(-1.0)
    # ends nearer together than the spacing: one point, in front of their middle
    single, _ = wall.face_points(standoff, altitude, spacing_m=5.0)
    assert len(single) == 1
    np.testing.assert_allclose(single[0], 0.5 * (points[0] + points[1]), atol=1e-9)


def _reach_clearance_m(point, n, p, z, reach_m):
    """How far the nearest point of the horizontal circle of radius ``reach_m`` around
    (p_x, p_y, z) is in front of the plane (point, n): sampled, not solved."""
    angles = np.linspace(0.0, 2 * np.pi, 3601)
    circle = np.stack([p[0] + reach_m * np.cos(angles), p[1] + reach_m * np.sin(angles),
                       np.full(angles.size, z)], axis=1)
    return float(((circle - point) @ n).min())


@pytest.mark.parametrize('draw', range(4))
def test_the_altitudes_clear_of_a_leaning_wall_keep_the_reach_in_front_of_it(draw):
    rng = np.random.default_rng([FRESH, draw])
    point, n, _ = _wall(rng)
    memory = WallMemory()
    assert memory.observe(point, n, 0.5)
    p, reach_m = np.array([0.0, 0.0, 1.5]), rng.uniform(0.3, 1.0)
    lo, hi = memory.altitudes_clear_of(p, reach_m)
    # one end is open: a wall leaning over limits the climb, one leaning away the descent
    assert (lo == -math.inf) == (n[2] <= 0.0) and (hi == math.inf) == (n[2] >= 0.0)
    edge = hi if n[2] < 0.0 else lo
    step = math.copysign(0.01, n[2])
    # at the limit the reach just meets the plane, a centimetre inside it is clear of it
    assert _reach_clearance_m(point, n, p, edge, reach_m) == pytest.approx(0.0, abs=1e-4)
    assert _reach_clearance_m(point, n, p, edge + step, reach_m) > 0.0
    assert _reach_clearance_m(point, n, p, edge - step, reach_m) < 0.0


def test_the_altitudes_clear_of_all_walls_are_those_clear_of_each():
    memory = WallMemory()
    assert memory.altitudes_clear_of([0.0, 0.0, 1.5], 0.5) == (-math.inf, math.inf)
    lean = math.radians(20.0)
    over = np.array([math.cos(lean), 0.0, -math.sin(lean)])     # leaning over, 2 m west
    away = np.array([0.0, math.cos(lean), math.sin(lean)])      # leaning away, 3 m south
    memory.observe([-2.0, 0.0, 1.5], over, 0.5)
    memory.observe([0.0, -3.0, 1.5], away, 0.5)
    lo, hi = memory.altitudes_clear_of([0.0, 0.0, 1.5], 0.5)
    assert (lo, hi) == (memory.walls[1].altitudes_clear_of([0.0, 0.0, 1.5], 0.5)[0],
                        memory.walls[0].altitudes_clear_of([0.0, 0.0, 1.5], 0.5)[1])
    assert lo < 1.5 < hi
