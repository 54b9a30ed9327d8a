"""Worlds of structures (DESIGN section 5): walls, boxes, cylinders and meshes built in
PyBullet and drawn by both renderers, objects on their surfaces, the ground truth of every
target, and the files that cannot be flown refused with one line."""
import math

import numpy as np
import pytest
import trimesh
import yaml
from matplotlib.path import Path
from scipy.spatial.transform import Rotation

from structure_worlds import i_beam
from uav_tilt_common.config import ConfigError, from_dict
from uav_tilt_sim.bullet import pybullet as p
from uav_tilt_sim.camera.gl import GlRenderer
from uav_tilt_sim.camera.renderer import render_with
from uav_tilt_sim.camera.tiny import TinyRenderer
from uav_tilt_sim.camera.types import CameraConfig
from uav_tilt_sim.scenario import Scenario, check_scenario, load_scenario
from uav_tilt_sim.structure_visuals import box_arrays, cylinder_arrays, mesh_arrays, patch_arrays
from uav_tilt_sim.visuals import Scene
from uav_tilt_sim.world import PANEL_THICKNESS_M, build_world
from uav_tilt_sim.world_json import describe_world
from uav_tilt_tools.graph.foxglove_bridge import structure_shapes

# Both renderers draw the same triangles; they differ in rasterisation and depth precision.
DEPTH_AGREE_M = 0.01


@pytest.fixture
def client():
    c = p.connect(p.DIRECT)
    yield c
    p.disconnect(c)


def draw_world(rng, tmp_path):
    """A fresh world with one structure of each kind around the start, each carrying a
    target on the side that faces the start."""
    def u(lo, hi):
        return float(rng.uniform(lo, hi))
    tank_r = u(1.0, 3.0)
    i_beam(tmp_path / 'beam.obj')
    d = [u(2.0, 4.0) for _ in range(5)]
    structures = [
        dict(id='pipe', kind='cylinder', position_m=[d[0], 0.0, u(1.2, 2.0)],
             yaw_deg=90.0 + u(-20, 20), radius_m=u(0.15, 0.5), length_m=4.0),
        dict(id='tank', kind='cylinder', position_m=[0.0, d[1] + tank_r, 2.5],
             elevation_deg=90.0, radius_m=tank_r, length_m=5.0),
        dict(id='pillar', kind='box', position_m=[-d[2], 0.0, 0.0], yaw_deg=u(-30, 30),
             size_m=[0.6, 0.6, 3.0]),
        dict(id='beam', kind='mesh', position_m=[0.0, -d[3], 0.0], file='beam.obj'),
        dict(id='wall', kind='wall', position_m=[d[4] * 2, d[4] * 2, 0.0], yaw_deg=45.0),
    ]
    # angle 0 of the pipe (its axis near +y) and 180 of the tank face the start
    objects = [
        dict(on='pipe', angle_deg=u(-30, 30), axial_m=u(-1, 1), target=True, id='a'),
        dict(on='tank', angle_deg=float(rng.choice([-1, 1])) * u(120, 180), axial_m=-1.0,
             target=True, id='b'),
        dict(on='pillar', face='+x', u_m=0.0, v_m=u(1.0, 2.0), target=True, id='c'),
        dict(on='beam', point_m=[0.0, 0.3, u(1.0, 2.0)], target=True, id='d'),
        dict(on='wall', u_m=0.0, v_m=1.5, target=True, id='e'),
        dict(on='pillar', face='+x', u_m=0.0, v_m=0.5, cls='gauge'),
    ]
    path = tmp_path / 'world.yaml'
    path.write_text(yaml.safe_dump(dict(start_xyz_m=[0.0, 0.0, 0.0],
                                        seed=int(rng.integers(1e6)),
                                        structures=structures, objects=objects)))
    return path


def test_every_target_lies_on_its_surface_facing_out(client, tmp_path):
    """The ground truth of each target is where PyBullet's bodies are: a ray cast along
    its normal from outside meets its object at its point of interest, and the normal is
    the surface's (radial on a cylinder, the face's on a box, a mesh and a wall)."""
    for seed in np.random.SeedSequence().generate_state(3):
        rng = np.random.default_rng(seed)
        scenario = load_scenario(draw_world(rng, tmp_path))
        world = build_world(client, scenario)
        truth = world.truth_targets()
        assert sorted(truth) == ['', 'a', 'b', 'c', 'd', 'e']
        by_id = {o.id: o for o in world.objects if o.id}
        cfg = {s.id: s for s in scenario.structures}
        for target_id, (poi, R) in truth.items():
            if not target_id:
                continue
            n = R[:, 2]
            assert np.allclose(R.T @ R, np.eye(3), atol=1e-9)
            hit = p.rayTest((poi + 0.5 * n).tolist(), (poi - 0.05 * n).tolist(),
                            physicsClientId=client)[0]
            assert hit[0] == by_id[target_id].body, target_id
            assert np.linalg.norm(np.asarray(hit[3]) - poi) < 1e-4, target_id
        for target_id in ('a', 'b'):
            c = cfg['pipe' if target_id == 'a' else 'tank']
            poi, R = truth[target_id]
            from_axis = poi - np.asarray(c.position_m)
            axis = world.structures[[s.id for s in world.structures].index(c.id)] \
                .geometry.R[:, 2]
            radial = from_axis - (from_axis @ axis) * axis
            assert np.linalg.norm(radial) == pytest.approx(c.radius_m + PANEL_THICKNESS_M,
                                                           abs=1e-9)
            assert np.allclose(R[:, 2], radial / np.linalg.norm(radial), atol=1e-9)
        yaw = math.radians(cfg['pillar'].yaw_deg)
        assert np.allclose(truth['c'][1][:, 2], [math.cos(yaw), math.sin(yaw), 0.0])
        assert np.allclose(truth['d'][1][:, 2], [0.0, 1.0, 0.0], atol=1e-9)
        p.resetSimulation(physicsClientId=client)


def test_the_old_wall_and_a_wall_structure_are_one_world(client):
    """A scenario's `wall:` is read as before: the same world as the same wall listed as a
    structure, to the bit (bodies, textures drawn in the same order, ground truth)."""
    rng = np.random.default_rng(np.random.SeedSequence().entropy)
    wall = dict(position_m=[float(rng.uniform(1.5, 4)), float(rng.uniform(-1, 1))],
                yaw_deg=float(rng.uniform(-30, 30)), inclination_deg=float(rng.uniform(-10, 10)),
                stiffness_n_per_m=float(rng.uniform(1000, 8000)))
    objects = [dict(u_m=float(rng.uniform(-1, 1)), v_m=1.5, target=True, id='t'),
               dict(u_m=1.8, v_m=0.6, cls='gauge')]
    old = check_scenario(from_dict(Scenario, dict(wall=wall, objects=objects, seed=7)))
    as_structure = dict(wall, id='w', kind='wall', position_m=[*wall['position_m'], 0.0])
    new = check_scenario(from_dict(Scenario, dict(structures=[as_structure], seed=7,
                                                  objects=[dict(o, on='w') for o in objects])))
    worlds = []
    for scenario in (old, new):
        scene = Scene(client)
        worlds.append((build_world(client, scenario, scene=scene), scene))
        p.resetSimulation(physicsClientId=client)
    (a, scene_a), (b, scene_b) = worlds
    for key in ('', 't'):
        assert np.array_equal(a.truth_targets()[key][0], b.truth_targets()[key][0])
        assert np.array_equal(a.truth_targets()[key][1], b.truth_targets()[key][1])
    assert np.array_equal(a.R_map_wall, b.R_map_wall)
    textures_a = [v.texture for body in scene_a.bodies.values() for v in body.links[-1]]
    textures_b = [v.texture for body in scene_b.bodies.values() for v in body.links[-1]]
    assert all(np.array_equal(x, y) for x, y in zip(textures_a, textures_b, strict=True))


def test_both_renderers_draw_the_structures_at_their_depth(client, tmp_path):
    """Looking along each target's normal from a distance d, the depth at the image centre
    is d (the target's face), in the GL renderer and in TinyRenderer alike, and the two
    depth images agree."""
    rng = np.random.default_rng(np.random.SeedSequence().entropy)
    scenario = load_scenario(draw_world(rng, tmp_path))
    scene = Scene(client)
    world = build_world(client, scenario, scene=scene)
    cam = CameraConfig(width=161, height=121, cx=80.0, cy=60.0)
    renderers = [GlRenderer(cam), TinyRenderer(cam)]
    try:
        for target_id, (poi, R) in world.truth_targets().items():
            d = rng.uniform(0.6, 1.5)
            eye = poi + d * R[:, 2]
            R_map_cam = np.column_stack([R[:, 0], -R[:, 1], -R[:, 2]])    # x right, y down
            depths = [render_with(r, scene, eye, R_map_cam)[1] for r in renderers]
            for depth in depths:
                assert depth[60, 80] == pytest.approx(d, abs=2e-3), target_id
            seen = np.isfinite(depths[0]) & np.isfinite(depths[1])
            assert seen.sum() > 100
            assert np.median(np.abs(depths[0][seen] - depths[1][seen])) < DEPTH_AGREE_M
    finally:
        for r in renderers:
            r.close()


def test_the_recorded_world_outlines_every_structure(client, tmp_path):
    """plant/scenario carries each structure's outline from above: it holds the structure's
    targets and its heights span theirs."""
    rng = np.random.default_rng(np.random.SeedSequence().entropy)
    scenario = load_scenario(draw_world(rng, tmp_path))
    described = describe_world(scenario, build_world(client, scenario))
    by_id = {s['id']: s for s in described['structures']}
    assert sorted(by_id) == ['beam', 'pillar', 'pipe', 'tank', 'wall']
    for obj in described['objects']:
        s = by_id[obj['on']]
        centre = np.asarray(obj['centre_map'])
        inward = centre - 0.05 * np.asarray(obj['normal_map'])
        if s['kind'] != 'wall':
            assert Path(np.asarray(s['footprint_map'])).contains_point(inward[:2]), obj
        low, high = s['height_range_m']
        assert low - 1e-6 <= centre[2] <= high + 1e-6


def write_scenario(tmp_path, structures, objects, start=(0.0, 0.0, 0.0)):
    path = tmp_path / 'world.yaml'
    path.write_text(yaml.safe_dump(dict(start_xyz_m=list(start), structures=structures,
                                        objects=objects)))
    return path


PIPE = dict(id='pipe', kind='cylinder', position_m=[3.0, 0.0, 1.5], yaw_deg=90.0,
            radius_m=0.3, length_m=4.0)
PILLAR = dict(id='pillar', kind='box', position_m=[-3.0, 0.0, 0.0], size_m=[0.6, 0.6, 3.0])


@pytest.mark.parametrize('structures, objects, start, words', [
    ([PIPE], [dict(on='pipe', axial_m=2.5)], None, "'objects[0].axial_m' = 2.5 is off"),
    ([PIPE], [dict(on='pipr')], None, "'objects[0].on' = 'pipr' names no structure (did "
                                      "you mean 'pipe'?)"),
    ([PILLAR], [dict(on='pillar', face='+y', u_m=0.5)], None,
     "'objects[0].u_m' = 0.5 is off the +y face"),
    ([PILLAR], [dict(on='pillar', v_m=3.5)], None, "'objects[0].v_m' = 3.5 is above"),
    ([PIPE, dict(PILLAR, position_m=[3.0, 1.0, 0.0])], [], None,
     "'structures[1]' (box 'pillar') lies inside 'structures[0]' (cylinder 'pipe')"),
    ([PILLAR], [], (-3.1, 0.1, 0.0), "'start_xyz_m' = [-3.1, 0.1, 0.0] is inside"),
    ([PIPE, dict(PIPE, position_m=[3.0, 0.0, 3.0])], [], None,
     "'structures[1].id' = 'pipe' is not unique"),
    ([dict(PIPE, radius_m=0.06)], [dict(on='pipe')], None, "wraps more than half way"),
    ([PIPE], [dict(on='pipe', angle_deg=180.0), dict(on='pipe', angle_deg=170.0)], None,
     "'objects[1]' overlaps 'objects[0]'"),
    ([dict(id='m', kind='mesh', file='none.obj')], [], None, "no such file"),
    ([dict(id='m', kind='mesh', file='open.obj')], [], None, "is not a closed surface"),
    ([dict(id='m', kind='mesh', file='empty.obj')], [], None, "holds no triangles"),
    ([dict(id='m', kind='mesh', file='beam.obj')], [dict(on='m', point_m=[0.0, 2.0, 1.0])],
     None, "'objects[0].point_m' = [0.0, 2.0, 1.0] is 1.750 m off the surface of mesh 'm'"),
])
def test_a_world_that_cannot_be_built_is_refused_in_one_line(tmp_path, structures, objects,
                                                             start, words):
    i_beam(tmp_path / 'beam.obj')
    box = trimesh.creation.box((1.0, 1.0, 1.0))
    open_box = trimesh.Trimesh(box.vertices, box.faces[:-2])
    open_box.export(tmp_path / 'open.obj')
    (tmp_path / 'empty.obj').write_text('# nothing\n')
    path = write_scenario(tmp_path, structures, objects, start or (0.0, 0.0, 0.0))
    with pytest.raises(ConfigError) as err:
        load_scenario(path)
    assert words in str(err.value) and '\n' not in str(err.value)


def test_the_wall_beside_structures_is_refused(tmp_path):
    path = tmp_path / 'world.yaml'
    path.write_text(yaml.safe_dump(dict(wall=dict(yaw_deg=10.0), structures=[PIPE])))
    with pytest.raises(ConfigError, match="'wall' and 'structures' are both set"):
        load_scenario(path)


def test_the_live_view_draws_each_structure_as_built(tmp_path):
    """Foxglove's scene: one shape per structure, the primitive of its kind where the world
    builds it (a cylinder centred on its axis, a box's centre half its height up, a wall's
    face on its surface)."""
    rng = np.random.default_rng(np.random.SeedSequence().entropy)
    scenario = load_scenario(draw_world(rng, tmp_path))
    shapes = {s.entity_id: s for s in structure_shapes(scenario)}
    assert sorted(shapes) == sorted(f'structure:{s.id}' for s in scenario.structures)
    cfg = {s.id: s for s in scenario.structures}
    pipe = shapes['structure:pipe']
    assert pipe.primitive == 'cylinder'
    assert pipe.position == pytest.approx(cfg['pipe'].position_m)
    assert pipe.size == pytest.approx((2 * cfg['pipe'].radius_m,) * 2 + (cfg['pipe'].length_m,))
    axis = Rotation.from_quat(pipe.quaternion).as_matrix()[:, 2]
    yaw = math.radians(cfg['pipe'].yaw_deg)
    assert abs(axis @ [math.cos(yaw), math.sin(yaw), 0.0]) == pytest.approx(1.0)
    pillar = shapes['structure:pillar']
    assert pillar.primitive == 'cube' and pillar.position[2] == pytest.approx(1.5)
    beam = shapes['structure:beam']
    assert beam.primitive == 'triangles' and beam.indices.max() < len(beam.points)
    wall = shapes['structure:wall']
    face = wall.position + Rotation.from_quat(wall.quaternion).as_matrix()[:, 2] * 0.1
    assert face[:2] == pytest.approx(cfg['wall'].position_m[:2])
    assert face[2] == pytest.approx(cfg['wall'].height_m / 2)


def test_the_drawn_surfaces_face_outwards(tmp_path):
    """Each triangle of a structure's or a wrapped panel's mesh turns counter-clockwise
    seen from outside (as every visual does), its shading normals on the same side."""
    rng = np.random.default_rng(np.random.SeedSequence().entropy)
    beam = i_beam(tmp_path / 'beam.obj')
    meshes = [box_arrays(rng.uniform(0.1, 3.0, 3), 0.5, 2.0),
              cylinder_arrays(rng.uniform(0.05, 3.0), rng.uniform(0.1, 5.0), 0.5, 2.0),
              patch_arrays(0.1, rng.uniform(0.07, 3.0), 0.01,
                           np.array([math.cos(a := rng.uniform(0, math.pi)), math.sin(a)])),
              mesh_arrays(np.asarray(beam.vertices), np.asarray(beam.faces), 0.5, 2.0)]
    for vertices, normals, _, triangles in meshes:
        triangles = np.asarray(triangles, dtype=int)
        corners = vertices[triangles]
        winding = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        area = np.linalg.norm(winding, axis=1)
        shading = normals[triangles].mean(axis=1)
        kept = area > 1e-12                  # a polar grid's triangles at its centre vanish
        assert np.all(np.einsum('ij,ij->i', winding[kept], shading[kept]) > 0)
