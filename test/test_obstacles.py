"""The way round the site's obstacles (uav_tilt_control.obstacles), on boxes drawn fresh:
clear of every box by the clearance, as short as going round allows, straight when
nothing is in the way, None when boxed in; and the boxes a scenario's structures give."""
import math

import numpy as np
import pytest

from uav_tilt_control.obstacles import BOX_FIELDS, ObstacleBox, boxes_from_flat, face_views, route
from uav_tilt_sim.randomise_structures import STRUCTURE_KINDS, structure_draw
from uav_tilt_sim.scenario import world_geometry


def _gap_along(path, box, steps=400):
    """The least plan distance from the box to the polyline ``path``."""
    points = np.concatenate([np.linspace(a, b, steps)[:, :2] for a, b in zip(path, path[1:])])
    return min(box.distance_xy(p) for p in points)


def _random_boxes(rng, n):
    return [ObstacleBox((*rng.uniform(-4, 4, 2), 1.5), (*rng.uniform(0.3, 1.5, 2), 3.0),
                        float(rng.uniform(-180, 180))) for _ in range(n)]


def test_the_way_keeps_the_clearance_off_every_box():
    rng = np.random.default_rng()
    clearance, checked = 0.7, 0
    for _ in range(60):
        boxes = _random_boxes(rng, int(rng.integers(1, 5)))
        start, goal = (np.array([*rng.uniform(-6, 6, 2), rng.uniform(0.5, 2.5)])
                       for _ in range(2))
        if min(b.distance_xy(q[:2]) for b in boxes for q in (start, goal)) <= clearance:
            continue        # within a box's clearance: it is grown less there (next test)
        path = route(start, goal, boxes, clearance)
        if path is None:
            continue
        full = [start, *path]
        np.testing.assert_allclose(path[-1], goal)
        for box in boxes:
            # the corners are 1 cm out; the sampled polyline may cut 1e-3 m of a corner
            assert _gap_along(full, box) >= clearance - 1e-3
        straight = float(np.linalg.norm(goal[:2] - start[:2]))
        length = sum(float(np.linalg.norm(b[:2] - a[:2])) for a, b in zip(full, full[1:]))
        # never shorter than straight; going round a box adds at most its grown perimeter
        bound = straight + sum(2 * (b.size_m[0] + b.size_m[1]) + 8 * clearance for b in boxes)
        assert straight - 1e-9 <= length <= bound
        # the altitude changes evenly along the way
        z = [q[2] for q in full]
        assert all(min(start[2], goal[2]) - 1e-9 <= v <= max(start[2], goal[2]) + 1e-9
                   for v in z)
        checked += 1
    assert checked >= 20


def test_a_clear_line_is_flown_straight_and_a_box_out_of_height_is_left_out():
    rng = np.random.default_rng()
    start, goal = np.array([0.0, 0.0, 1.5]), np.array([6.0, rng.uniform(-1, 1), 1.5])
    assert len(route(start, goal, [], 0.7)) == 1
    in_way = ObstacleBox((3.0, goal[1] / 2, 1.5), (0.5, 0.5, 3.0), float(rng.uniform(-45, 45)))
    assert len(route(start, goal, [in_way], 0.7)) > 1
    above = ObstacleBox((3.0, goal[1] / 2, 4.0), (0.5, 5.0, 1.0), 0.0)   # a pipe overhead
    assert len(route(start, goal, [above], 0.7)) == 1
    aside = ObstacleBox((3.0, goal[1] / 2 + 2.0, 1.5), (0.5, 0.5, 3.0), 0.0)
    assert len(route(start, goal, [aside], 0.7)) == 1


def test_a_start_near_a_box_is_let_go_and_a_boxed_in_goal_is_none():
    # hovering 0.3 m from the surface it inspects, within the clearance: it may leave
    wall = ObstacleBox((0.0, 0.0, 1.5), (0.2, 6.0, 3.0), 0.0)
    start, goal = np.array([0.4, 0.0, 1.5]), np.array([3.0, 0.5, 1.5])
    assert len(route(start, goal, [wall], 0.7)) == 1
    ring = [ObstacleBox((x, y, 1.5), (sx, sy, 3.0), 0.0)
            for x, y, sx, sy in ((5, 0, 0.4, 10.4), (-5, 0, 0.4, 10.4),
                                 (0, 5, 10.4, 0.4), (0, -5, 10.4, 0.4))]
    # the goal inside a closed ring of walls
    assert route(np.array([8.0, 0.0, 1.5]), np.array([0.0, 0.0, 1.5]), ring, 0.7) is None


def test_boxes_from_a_flat_list_and_their_refusals():
    values = [1.0, 2.0, 1.5, 0.5, 0.6, 3.0, 30.0] * 2
    boxes = boxes_from_flat(values)
    assert len(boxes) == 2 and boxes[0].size_m == (0.5, 0.6, 3.0) and boxes[0].yaw_deg == 30.0
    with pytest.raises(ValueError, match=f'boxes of {len(BOX_FIELDS)}'):
        boxes_from_flat(values[:-1])
    with pytest.raises(ValueError, match='more than 0'):
        boxes_from_flat([1.0, 2.0, 1.5, 0.0, 0.6, 3.0, 30.0])


@pytest.mark.parametrize('kind', STRUCTURE_KINDS)
def test_a_structure_s_box_holds_it(kind):
    """Points drawn inside each structure of a fresh draw lie in its plan box."""
    rng = np.random.default_rng()
    scenario, _, _ = structure_draw(int(rng.integers(2**31)), kind)
    geometry, _ = world_geometry(scenario)
    for g in geometry:
        centre, size, yaw_deg = g.plan_box()
        box = ObstacleBox(tuple(centre), tuple(size), yaw_deg)
        hull = g.hull_points_map()
        lo, hi = hull.min(axis=0), hull.max(axis=0)
        samples = rng.uniform(lo, hi, (4000, 3))
        inside = samples[g.contains(samples)]
        assert len(inside) > 0
        assert all(box.distance_xy(p[:2]) < 1e-9 for p in inside)
        assert np.all(inside[:, 2] >= box.z_range_m[0] - 1e-9)
        assert np.all(inside[:, 2] <= box.z_range_m[1] + 1e-9)
        # and not much more: a pillar's or a wall's box is the structure's own
        if g.cfg.kind in ('box', 'wall') and g.cfg.inclination_deg == 0.0:
            assert math.prod(size) == pytest.approx(
                math.prod(g.cfg.size_m) if g.cfg.kind == 'box'
                else g.cfg.width_m * g.cfg.height_m * 0.2, rel=1e-6)


def test_the_faces_to_look_at_are_those_turned_away_and_clear_of_every_box():
    rng = np.random.default_rng()
    yaw = float(rng.uniform(-180, 180))
    pillar = ObstacleBox((4.0, 0.0, 1.5), (0.6, 0.6, 3.0), yaw)
    views = face_views([pillar], 2.5, 1.5, np.zeros(3), 0.7)
    # of the four faces, those whose normal is more than 45 degrees off the way from the
    # face's middle to the start: two to four, depending on the pillar's yaw (two faces
    # turned 45 degrees to the start are both a little more than that off it)
    away = 0
    for k in range(4):
        a = math.radians(yaw) + k * math.pi / 2
        n = np.array([math.cos(a), math.sin(a)])
        to_start = -(np.asarray(pillar.centre_m[:2]) + n * 0.3)
        away += n @ to_start <= math.cos(math.pi / 4) * np.linalg.norm(to_start)
    assert len(views) == away >= 2
    for point, heading in views:
        assert point[2] == 1.5
        assert pillar.distance_xy(point[:2]) == pytest.approx(2.5)
        # facing the pillar: its centre straight ahead
        to_centre = np.asarray(pillar.centre_m[:2]) - point[:2]
        assert math.atan2(to_centre[1], to_centre[0]) == pytest.approx(heading, abs=1e-9)
    # a wall right behind the pillar: the view from its back is inside the wall's clearance
    wall = ObstacleBox((7.2, 0.0, 1.5), (0.2, 8.0, 3.0), 0.0)
    assert all(wall.distance_xy(q[:2]) >= 0.7
               for q, _ in face_views([pillar, wall], 2.5, 1.5, np.zeros(3), 0.7))
