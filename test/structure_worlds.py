"""A mesh the tests write themselves: an I-beam as an OBJ file."""
import numpy as np
import trimesh


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
