"""Textured triangle meshes of structures (visuals.MESH arrays in the body frame): split into
tiles of about ``tile_m`` (TinyRenderer drops a whole triangle that projects far outside
the image), the texture repeated every ``texture_m``."""
import numpy as np
import trimesh

from uav_tilt_sim.visuals import Mesh, box_faces, concat, quad_grid

ROUND_SEGMENTS_MIN = 24
PATCH_SEGMENTS = 8


def box_arrays(size_m: np.ndarray, tile_m: float, texture_m: float) -> Mesh:
    """A box of sides ``size_m`` whose frame is the middle of its base."""
    half = np.asarray(size_m, dtype=float) / 2
    v, n, uv, tri = box_faces(half, tile_m, texture_m)
    return v + [0.0, 0.0, half[2]], n, uv, tri


def cylinder_arrays(radius_m: float, length_m: float, tile_m: float, texture_m: float
                    ) -> Mesh:
    """A closed cylinder about z, its frame the middle of its axis."""
    n_round = max(ROUND_SEGMENTS_MIN, int(np.ceil(2 * np.pi * radius_m / tile_m)))
    n_long = max(1, int(np.ceil(length_m / tile_m)))
    a = 2 * np.pi * np.arange(n_round + 1) / n_round
    z = np.linspace(-length_m / 2, length_m / 2, n_long + 1)
    aa, zz = np.meshgrid(a, z)
    ring = np.column_stack([np.cos(aa.ravel()), np.sin(aa.ravel()), np.zeros(aa.size)])
    side_v = ring * radius_m + np.column_stack([np.zeros((aa.size, 2)), zz.ravel()])
    k = (np.arange(n_long)[:, None] * (n_round + 1) + np.arange(n_round)[None, :]).ravel()
    side_tri = np.column_stack([k, k + 1, k + n_round + 2,
                                k, k + n_round + 2, k + n_round + 1]).reshape(-1, 3)
    side_uv = np.column_stack([aa.ravel() * radius_m, zz.ravel()]) / texture_m
    parts = [(side_v, ring, side_uv, side_tri)]
    n_rings = max(1, int(np.ceil(radius_m / tile_m)))
    for sign in (1.0, -1.0):
        # a polar grid, so that no cap triangle is much larger than a tile
        r = np.linspace(0.0, radius_m, n_rings + 1)
        rr, ca = np.meshgrid(r, a)
        v = np.column_stack([rr.ravel() * np.cos(ca.ravel()), rr.ravel() * np.sin(ca.ravel()),
                             np.full(rr.size, sign * length_m / 2)])
        k = (np.arange(n_round)[:, None] * (n_rings + 1) + np.arange(n_rings)[None, :]).ravel()
        quads = np.column_stack([k, k + n_rings + 1, k + n_rings + 2, k + 1])
        # counter-clockwise seen from outside (+z for the top)
        order = [0, 2, 1, 0, 3, 2] if sign > 0 else [0, 1, 2, 0, 2, 3]
        tri = quads[:, order].reshape(-1, 3)
        parts.append((v, np.tile([0.0, 0.0, sign], (len(v), 1)), v[:, :2] / texture_m, tri))
    return concat(parts)


def patch_arrays(half_m: float, radius_m: float, out_m: float, axis_s: np.ndarray) -> Mesh:
    """A square panel of side 2 ``half_m`` (its frame S: +z out of its centre) wrapped round
    a cylinder of ``radius_m`` whose axis, along ``axis_s`` (in S, in its xy plane), lies
    ``radius_m`` behind the centre; the panel ``out_m`` proud of it, its texture once over
    it, as a quad's (visuals.QUAD)."""
    v, uv, tri = quad_grid(half_m, half_m, 2 * half_m / PATCH_SEGMENTS)
    a = np.array([axis_s[0], axis_s[1], 0.0]) / np.hypot(axis_s[0], axis_s[1])
    e = np.array([-a[1], a[0], 0.0])            # round the curve, in the panel's plane
    z = np.array([0.0, 0.0, 1.0])
    phi = (v @ e) / radius_m                    # arc length round the curve
    r = radius_m + out_m
    vertices = (np.outer(v @ a, a) + np.outer(r * np.sin(phi), e)
                + np.outer(r * np.cos(phi) - radius_m, z))
    normals = np.outer(np.sin(phi), e) + np.outer(np.cos(phi), z)
    return vertices, normals, uv, tri


def mesh_arrays(vertices: np.ndarray, faces: np.ndarray, tile_m: float, texture_m: float
                ) -> Mesh:
    """A closed mesh, each triangle flat shaded, textured by projecting along its normal's
    largest axis."""
    v, f = trimesh.remesh.subdivide_to_size(vertices, faces, max_edge=tile_m)
    tri_v = v[f]                                              # T x 3 x 3
    normals = np.cross(tri_v[:, 1] - tri_v[:, 0], tri_v[:, 2] - tri_v[:, 0])
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
    drop = np.abs(normals).argmax(axis=1)
    keep = np.array([[1, 2], [0, 2], [0, 1]])[drop]           # T x 2
    uv = np.take_along_axis(tri_v, keep[:, None, :].repeat(3, axis=1), axis=2) / texture_m
    n = len(f)
    return (tri_v.reshape(-1, 3), np.repeat(normals, 3, axis=0), uv.reshape(-1, 2),
            np.arange(3 * n).reshape(n, 3))
