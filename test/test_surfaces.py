"""Surfaces a plan works on (uav_tilt_control.surfaces): a cylinder's unrolled coordinates
agree with where its objects sit in the simulator; a path on it keeps to the surface; a
slide's reference rides along it with the surface's normal; the site and the plan name
cylinders by id and refuse what is off them or out of the tool's reach with one line."""
import math
import pathlib

import numpy as np
import pytest

from uav_tilt_common.config import ConfigError, from_dict, read_yaml
from uav_tilt_common.targets import HINT_ERROR_M
from uav_tilt_control.mission import MissionConfig
from uav_tilt_control.plan import Slide, nearest_on_path, parse_plan
from uav_tilt_control.site import CYLINDER_FIELDS, SiteConfig
from uav_tilt_control.surfaces import PATH_STEP_M, CylinderSurface, path_on
from uav_tilt_control.trajectory import SurfaceCruise
from uav_tilt_sim.scenario import load_scenario
from uav_tilt_tools.runner.site_params import site_overrides
from uav_tilt_sim.structures import StructureConfig, structure_of
from uav_tilt_tools.metrics.tasks import slide_normals

FORCES = (MissionConfig().contact.threshold_n, MissionConfig().failsafe.force_limit_n,
          'mission.contact.threshold_n, mission.failsafe.force_limit_n')
REPO = pathlib.Path(__file__).resolve().parent.parent
MAX_PITCH_RAD = MissionConfig().contact.max_pitch_rad
LOWEST_M = MissionConfig().lowest_hover_m()


def _random_cylinders(n):
    """``n`` fresh cylinders (x, y, z, yaw, elevation, radius, length) of any pose and the
    scenario's range of radii."""
    rng = np.random.default_rng()
    return [tuple(float(v) for v in (rng.uniform(-10, 10), rng.uniform(-10, 10),
                                     rng.uniform(0.5, 5), rng.uniform(-180, 180),
                                     rng.uniform(-90, 90), rng.uniform(0.05, 3.0),
                                     rng.uniform(0.5, 10)))
            for _ in range(n)]


@pytest.mark.parametrize('cyl', _random_cylinders(30))
def test_a_cylinder_s_coordinates_are_where_the_simulator_puts_its_objects(cyl):
    """(u, v) = (radius x angle, axial) on the site's cylinder is the point and the normal
    at which the scenario's (axial_m, angle_deg) places an object."""
    x, y, z, yaw, elevation, radius, length = cyl
    rng = np.random.default_rng()
    angle_deg, share = rng.uniform(-180, 180), rng.uniform(-0.5, 0.5)
    surface = CylinderSurface((x, y, z), yaw, elevation, radius, length)
    geometry = structure_of(StructureConfig(
        id='pipe', kind='cylinder', position_m=[x, y, z], yaw_deg=yaw,
        elevation_deg=elevation, radius_m=radius, length_m=length), 'structures[0]')
    axial = share * length
    placed = geometry.place('', 0.0, 0.0, axial, angle_deg, [0.0, 0.0, 0.0], 0.1, 'objects[0]')
    uv = [radius * math.radians(angle_deg), axial]
    np.testing.assert_allclose(surface.point_map(uv), placed.centre_map, atol=1e-9)
    np.testing.assert_allclose(surface.normal_map(uv), placed.R_map_surface[:, 2], atol=1e-9)
    assert surface.on(uv) and not surface.on([uv[0], length / 2 + 1e-6])


@pytest.mark.parametrize('cyl', _random_cylinders(20))
def test_a_path_on_a_cylinder_keeps_to_its_surface_as_long_as_it_is_in_u_v(cyl):
    """Unrolling keeps lengths: the sampled path is as long as the polyline in (u, v) (less
    the chords' sag), no two points farther apart than PATH_STEP_M, every point at the
    radius from the axis with its normal radial there."""
    x, y, z, yaw, elevation, radius, length = cyl
    rng = np.random.default_rng()
    uv = np.column_stack([rng.uniform(-2, 2, 4), rng.uniform(-0.5, 0.5, 4) * length])
    surface = CylinderSurface((x, y, z), yaw, elevation, radius, length)
    path = path_on(surface, uv)
    legs = np.linalg.norm(np.diff(path.points_map, axis=0), axis=1)
    assert legs.max() <= PATH_STEP_M + 1e-9
    unrolled = float(np.sum(np.linalg.norm(np.diff(uv, axis=0), axis=1)))
    # a chord of length c on a circle of radius r is shorter than its arc by ~c^3 / (24 r^2)
    assert unrolled - 1e-9 <= path.length_m / (1.0 - PATH_STEP_M ** 2 / (24 * radius ** 2)) \
        and path.length_m <= unrolled + 1e-9
    axis = surface.point_map([0.0, 1.0]) - surface.point_map([0.0, 0.0])
    centre = np.asarray([x, y, z])
    rel = path.points_map - centre
    radial = rel - np.outer(rel @ axis, axis)
    np.testing.assert_allclose(np.linalg.norm(radial, axis=1), radius, rtol=1e-9)
    np.testing.assert_allclose(path.normals_map, radial / radius, atol=1e-9)
    np.testing.assert_allclose(path.points_map[path.vertices],
                               [surface.point_map(p) for p in uv], atol=1e-9)


def test_a_slide_s_reference_rides_round_a_tank_on_its_surface():
    """Round an upright tank at constant height, at 0.1 m/s: the reference's point stays on
    the surface with the radial as its normal, its velocity is tangent to the surface at
    the cruise speed, and it is pulled towards the axis at v^2 / r; a point out along the
    normal goes round with it."""
    rng = np.random.default_rng()
    radius = float(rng.uniform(1.0, 3.0))
    surface = CylinderSurface((rng.uniform(-5, 5), rng.uniform(-5, 5), 2.5),
                              float(rng.uniform(-180, 180)), 90.0, radius, 5.0)
    height = float(rng.uniform(-1.0, 1.0))
    cruise = SurfaceCruise(0.0, path_on(surface, [[-0.5, height], [0.5, height]]), 0.1, 0.1)
    assert cruise.length == pytest.approx(1.0, rel=1e-4)
    centre = np.asarray(surface.centre_m) + [0.0, 0.0, height]
    middle = cruise.T / 2.0          # cruising
    for t in np.linspace(0.0, cruise.T, 41):
        point, normal, v, a = cruise.sample(float(t))
        radial = point - centre
        assert np.linalg.norm(radial) == pytest.approx(radius, abs=1e-4)
        np.testing.assert_allclose(normal, radial / np.linalg.norm(radial), atol=1e-3)
        # along a chord, which turns from the surface by at most half its own angle
        assert abs(v @ normal) <= np.linalg.norm(v) * PATH_STEP_M / (2 * radius) + 1e-12
        assert v[2] == pytest.approx(0.0, abs=1e-12)
    _, normal, v, a = cruise.sample(middle)
    # the speed is taken across the two legs round the point: a chord of two steps is
    # shorter than its arc by (2 step / r)^2 / 24
    assert np.linalg.norm(v) == pytest.approx(
        0.1, rel=(2 * PATH_STEP_M / radius) ** 2 / 24 + 1e-9)
    assert -a @ normal == pytest.approx(0.1 ** 2 / radius, rel=0.05)
    # the body's reference, the tool's length out along the normal, goes round on a circle
    # of r + d at (r + d) / r the speed
    d = 0.45
    _, _, v_out, a_out = cruise.sample(middle, d)
    speed = 0.1 * (radius + d) / radius
    assert np.linalg.norm(v_out) == pytest.approx(speed, rel=(2 * PATH_STEP_M / radius) ** 2)
    assert -a_out @ normal == pytest.approx(speed ** 2 / (radius + d), rel=0.05)


def test_a_tip_off_the_path_is_off_by_its_distance_along_the_surface():
    """A tip pressed into the surface (or lifted off it) along the normal is on the path;
    one moved across it is off by that much; the normal where either is, is the
    surface's there (between the path's points as at them)."""
    rng = np.random.default_rng()
    radius = float(rng.uniform(0.15, 0.5))
    surface = CylinderSurface((0.0, 0.0, 2.0), float(rng.uniform(-180, 180)), 0.0, radius, 4.0)
    path = path_on(surface, [[-0.1, 0.0], [0.1, 0.0]])     # round the side, across the axis
    uv = [float(rng.uniform(-0.1, 0.1)), 0.0]
    p, n = surface.point_map(uv), surface.normal_map(uv)
    axis = surface.point_map([0.0, 1.0]) - surface.point_map([0.0, 0.0])
    depth, across = rng.uniform(-0.02, 0.02), rng.uniform(0.001, 0.05)
    tips = [p + n * depth, p + axis * across]
    (pressed, moved), normals = nearest_on_path(tips, path.points_map, path.normals_map)
    # each leg's plane turns from the normal along it by at most half its angle, and the
    # surface sags off the chord by step^2 / 8 r
    sag_m = PATH_STEP_M ** 2 / (8 * radius)
    assert pressed <= (abs(depth) + sag_m) * PATH_STEP_M / (2 * radius) + 1e-9
    assert moved == pytest.approx(across, abs=1e-9)
    for normal in normals:
        assert np.degrees(np.arccos(min(normal @ n, 1.0))) <= np.degrees(
            (PATH_STEP_M / radius) ** 2)


def _cylinder_site(**cylinder):
    values = dict(x=3.0, y=0.0, z=1.6, yaw_deg=90.0, elevation_deg=0.0, radius_m=0.3,
                  length_m=4.0)
    values.update(cylinder)
    return from_dict(SiteConfig, dict(cylinder_ids=['pipe_1'],
                                      cylinders=[values[f] for f in CYLINDER_FIELDS]))


def _plan(site, *tasks, max_pitch_rad=MAX_PITCH_RAD):
    return parse_plan({'tasks': list(tasks)}, site, FORCES, LOWEST_M, 0.05, max_pitch_rad)


def test_a_plan_slides_on_a_cylinder_it_names_and_the_metrics_judge_it_there():
    """``on: pipe_1`` puts the line on the site's cylinder; its normals go round with it
    (0.3 m from -20 to 20 deg: the normal pitches through 40 deg), and the task metrics
    judge the push and the path along those normals."""
    site = _cylinder_site()
    u = 0.3 * math.radians(20.0)
    (slide,) = _plan(site, {'slide': {'on': 'pipe_1', 'from_uv_m': [-u, 0.5],
                                      'to_uv_m': [u, 0.5]}})
    assert isinstance(slide, Slide) and slide.on == 'pipe_1'
    assert slide.length_m == pytest.approx(2 * u, rel=1e-3)
    pitch = np.degrees(np.arcsin(slide.normals_map[:, 2]))
    assert pitch[0] == pytest.approx(-20.0) and pitch[-1] == pytest.approx(20.0)
    described = slide.describe()
    np.testing.assert_allclose(slide_normals(described, [1.0, 0.0, 0.0]), slide.normals_map)
    # on the wall the true wall's normal judges it, as before
    assert slide_normals(dict(described, on=''), [1.0, 0.0, 0.0]).shape == (3,)


@pytest.mark.parametrize('task, words', [
    ({'slide': {'on': 'pipe1', 'from_uv_m': [0.0, 0.0], 'to_uv_m': [0.0, 1.0]}},
     ["'on' = 'pipe1' is not one of site.cylinder_ids", "did you mean 'pipe_1'"]),
    ({'slide': {'on': 'pipe_1', 'from_uv_m': [0.0, 1.5], 'to_uv_m': [0.0, 2.5]}},
     ["'to_uv_m' = [0.0, 2.5] is off the cylinder 'pipe_1'", 'v (along the axis) in']),
    ({'slide': {'from_uv_m': [0.0, 0.5], 'to_uv_m': [0.0, 1.5]}},
     ["the site's wall is needed", "or 'on' naming one of site.cylinder_ids"]),
    # over the top of the pipe: the normal turns up past what the tool pitches to
    ({'slide': {'on': 'pipe_1', 'from_uv_m': [0.0, 0.0], 'to_uv_m': [0.3 * 1.4, 0.0]}},
     ["tasks[0] (slide): the line", 'faces', 'deg up', 'within 30.9 deg of horizontal']),
    # round the underside: below the lowest the mission works at
    ({'slide': {'on': 'pipe_1', 'from_uv_m': [0.0, 0.0], 'to_uv_m': [-0.3 * 4.0, 0.0]}},
     ['dips to z =', "round the cylinder 'pipe_1'", 'below the lowest']),
])
def test_a_slide_off_its_cylinder_or_out_of_reach_is_refused_with_one_line(task, words):
    with pytest.raises(ConfigError) as err:
        _plan(_cylinder_site(z=float(LOWEST_M + 0.2)), task)
    message = str(err.value)
    assert '\n' not in message and all(w in message for w in words), message


def test_a_site_s_cylinders_must_match_their_ids():
    with pytest.raises(ConfigError, match="7 for each of site.cylinder_ids"):
        from_dict(SiteConfig, dict(cylinder_ids=['a', 'b'], cylinders=[0.0] * 7)).check()
    with pytest.raises(ConfigError, match="needs a radius and a length more than 0"):
        from_dict(SiteConfig, dict(cylinder_ids=['a'],
                                   cylinders=[0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0])).check()


def test_the_shipped_pipe_plan_resolves_on_its_scenario_s_pipe():
    """config/plans/pipe.yaml on config/scenarios/structures.yaml, its site as `fly` gives
    it: the touch's hint within the hint's error of the plate, its normal the plate's; the
    slide round the pipe's side on its surface, beside the plate."""
    scenario = load_scenario(REPO / 'config' / 'scenarios' / 'structures.yaml')
    values = {k.split('.', 1)[1]: v for k, v in site_overrides(scenario).items()}
    site = from_dict(SiteConfig, values)
    plan = read_yaml(REPO / 'config' / 'plans' / 'pipe.yaml')     # `on:` a key, not True
    touch, slide = parse_plan(plan, site, FORCES, LOWEST_M, 0.05, MAX_PITCH_RAD)
    (plate,) = [o for o in scenario.objects if o.id == touch.target]
    pipe = next(s for s in scenario.structures if s.id == plate.on)
    uv = [pipe.radius_m * math.radians(plate.angle_deg), plate.axial_m]
    assert np.abs(np.subtract(touch.near_uv_m, uv)).max() <= HINT_ERROR_M
    surface = site.surface(plate.on)
    np.testing.assert_allclose(touch.normal_map, surface.normal_map(touch.near_uv_m))
    assert isinstance(slide, Slide) and slide.on == plate.on
    rel = slide.points_map - np.asarray(pipe.position_m)
    axis = surface.point_map([0.0, 1.0]) - surface.point_map([0.0, 0.0])
    np.testing.assert_allclose(np.linalg.norm(rel - np.outer(rel @ axis, axis), axis=1),
                               pipe.radius_m, rtol=1e-9)
    # beside the plate (a bolt plate is 0.15 m square), not over it
    assert np.all(np.abs(rel @ axis - plate.axial_m) > 0.15)
