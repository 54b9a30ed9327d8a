"""Structure worlds drawn fresh for the tests: an I-beam mesh written as an OBJ file, and
one world per structure kind with its target where the mission can reach it."""
import math

import dataclasses

import numpy as np
import trimesh
import yaml

from uav_tilt_sim.randomise import random_draw


def i_beam(path, flange_m=0.4, web_m=0.08, depth_m=0.5, thick_m=0.06, height_m=3.0):
    """An I-beam standing on the ground, its flanges across x at y = +-depth/2, written as
    an OBJ file: its section triangulated by hand (each flange a fan, so that the web's
    corners are vertices of both), extruded up."""
    f, w, d, t = flange_m / 2, web_m / 2, depth_m / 2, thick_m
    section = np.array([(-f, -d), (f, -d), (f, -d + t), (w, -d + t), (-w, -d + t), (-f, -d + t),
                        (f, d), (-f, d), (-f, d - t), (-w, d - t), (w, d - t), (f, d - t)])
    fan = [(0, 1, 2), (0, 2, 3), (0, 3, 4), (0, 4, 5)]
    faces = fan + [(a + 6, b + 6, c + 6) for a, b, c in fan] + [(4, 3, 10), (4, 10, 9)]
    beam = trimesh.creation.extrude_triangulation(section, np.array(faces), height_m)
    assert beam.is_watertight
    beam.export(path)
    return beam


def _u(rng, lo, hi):
    return float(rng.uniform(lo, hi))


def kind_world(kind, rng, folder):
    """(structures, objects) of a world of one ``kind`` (pipe, tank, corner, pillar, mesh)
    around a start at the origin facing +x, its target (id 't') on the side the mission
    reaches: a horizontal pipe of radius 0.15-0.5 m, the target within 30 deg of its side;
    an upright tank of radius 1-3 m; a corner of two walls at 90 deg, the target within
    0.4 m of the edge; a square pillar; an I-beam read from an OBJ file."""
    height = _u(rng, 1.3, 2.0)
    target = dict(target=True, id='t')
    if kind == 'pipe':
        radius, d = _u(rng, 0.15, 0.5), _u(rng, 2.5, 4.0)
        yaw = 90.0 + _u(rng, -20, 20)       # its side at angle 0 looks back at the start
        return ([dict(id='pipe', kind='cylinder', position_m=[d + radius, 0.0, height],
                      yaw_deg=yaw, radius_m=radius, length_m=4.0)],
                [dict(on='pipe', angle_deg=_u(rng, -30, 30), axial_m=_u(rng, -0.8, 0.8),
                      **target)])
    if kind == 'tank':
        radius, d = _u(rng, 1.0, 3.0), _u(rng, 2.5, 4.0)
        bearing = _u(rng, -30, 30)
        b = math.radians(bearing)
        centre = [(d + radius) * math.cos(b), (d + radius) * math.sin(b), 2.5]
        # angle theta about an upright axis is the radial (-sin theta, cos theta, 0)
        facing = bearing + 90.0 + _u(rng, -20, 20)
        facing = (facing + 180.0) % 360.0 - 180.0
        return ([dict(id='tank', kind='cylinder', position_m=centre, elevation_deg=90.0,
                      radius_m=radius, length_m=5.0)],
                [dict(on='tank', angle_deg=facing, axial_m=height - 2.5, **target)])
    if kind == 'corner':
        d, edge_y, e = _u(rng, 2.5, 4.0), _u(rng, -1.5, -0.5), _u(rng, 0.25, 0.4)
        # wall A faces the start (its face at x = d, u right = -y); wall B meets it at
        # y = edge_y, its face looking +y, reaching back towards the start
        return ([dict(id='a', kind='wall', position_m=[d, 0.0, 0.0], width_m=5.0),
                 dict(id='b', kind='wall', position_m=[d - 1.5, edge_y, 0.0], yaw_deg=-90.0,
                      width_m=3.0)],
                [dict(on='a', u_m=-(edge_y + e), v_m=height, **target)])
    if kind == 'pillar':
        side, d = _u(rng, 0.4, 0.8), _u(rng, 2.5, 4.0)
        return ([dict(id='pillar', kind='box', position_m=[d + side / 2, 0.0, 0.0],
                      yaw_deg=_u(rng, -20, 20), size_m=[side, side, 3.0])],
                [dict(on='pillar', face='-x', u_m=_u(rng, -0.1, 0.1) * side, v_m=height,
                      **target)])
    assert kind == 'mesh'
    i_beam(folder / 'beam.obj')
    d = _u(rng, 2.5, 4.0)
    # the beam turned so that its flange (normal +y in its file) faces the start
    return ([dict(id='beam', kind='mesh', position_m=[d + 0.25, 0.0, 0.0], yaw_deg=90.0,
                  file='beam.obj')],
            [dict(on='beam', point_m=[_u(rng, -0.08, 0.08), 0.3, height], **target)])


def write_world(folder, structures, objects, seed=0):
    """The scenario file of a world, in ``folder``, with the wind, sensor noise, model
    mismatch and surface stiffness and friction a campaign's draw of ``seed`` has; its
    path."""
    drawn, _ = random_draw(seed)
    contact = dict(stiffness_n_per_m=drawn.wall.stiffness_n_per_m,
                   friction=drawn.wall.friction)
    path = folder / 'world.yaml'
    path.write_text(yaml.safe_dump(dict(
        start_xyz_m=[0.0, 0.0, 0.0], seed=seed, objects=objects,
        structures=[dict(s, **contact) for s in structures],
        wind=dataclasses.asdict(drawn.wind), noise=dataclasses.asdict(drawn.noise),
        mismatch=dataclasses.asdict(drawn.mismatch))))
    return path
