"""A structure read from a mesh file (OBJ or STL, with trimesh): checked closed, scaled to
metres, and asked where its surface is and what lies inside it."""
import os

import numpy as np
import trimesh
from numpy.typing import NDArray

from uav_tilt_common.config import ConfigError

Array = NDArray[np.float64]
FORMATS = ('.obj', '.stl')


class MeshShape:
    """A closed triangle mesh in its own frame, metres."""

    def __init__(self, mesh: trimesh.Trimesh) -> None:
        self.trimesh = mesh
        self.vertices = np.asarray(mesh.vertices, dtype=float)
        self.faces = np.asarray(mesh.faces, dtype=np.int64)
        self.face_normals = np.asarray(mesh.face_normals, dtype=float)

    def closest(self, q: Array) -> tuple[Array, Array, Array]:
        """(points, outward normals, distances) of the surface nearest to points ``q``."""
        points, distances, triangles = trimesh.proximity.closest_point_naive(
            self.trimesh, np.atleast_2d(q))
        return (np.asarray(points, dtype=float), self.face_normals[triangles],
                np.asarray(distances, dtype=float))

    def contains(self, q: Array, margin_m: float = 0.0) -> NDArray[np.bool_]:
        """Whether each point lies inside, or within ``margin_m`` of the surface: the
        generalised winding number (exact for a closed mesh, no ray casting)."""
        q = np.atleast_2d(q)
        tri = self.vertices[self.faces]                     # T x 3 x 3
        a, b, c = (tri[None, :, k, :] - q[:, None, :] for k in range(3))
        la, lb, lc = (np.linalg.norm(x, axis=2) for x in (a, b, c))
        det = np.einsum('ntk,ntk->nt', a, np.cross(b, c))
        den = (la * lb * lc + np.einsum('ntk,ntk->nt', a, b) * lc
               + np.einsum('ntk,ntk->nt', b, c) * la + np.einsum('ntk,ntk->nt', c, a) * lb)
        winding = np.arctan2(det, den).sum(axis=1) / (2.0 * np.pi)
        inside = winding > 0.5
        if margin_m > 0.0:
            inside |= self.closest(q)[2] <= margin_m
        return inside


def load_mesh(path: str, scale: float, parameter: str) -> MeshShape:
    """The closed mesh in file ``path`` times ``scale``; ConfigError (naming ``parameter``)
    when it is missing, unreadable, empty or not closed."""
    if os.path.splitext(path)[1].lower() not in FORMATS:
        raise ConfigError(f"parameter '{parameter}' = {path!r}: a mesh is an OBJ or STL file")
    if not os.path.isfile(path):
        raise ConfigError(f"parameter '{parameter}' = {path!r}: no such file")
    try:
        mesh = trimesh.load(path, force='mesh', process=True)
    except Exception as err:    # trimesh raises what its parsers raise
        raise ConfigError(f"parameter '{parameter}' = {path!r} cannot be read: "
                          f"{' '.join(str(err).split())}") from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise ConfigError(f"parameter '{parameter}' = {path!r} holds no triangles")
    if not mesh.is_watertight:
        raise ConfigError(f"parameter '{parameter}' = {path!r} is not a closed surface "
                          f"(open or non-manifold edges): a structure needs an inside")
    if mesh.volume < 0.0:
        mesh.invert()           # faces wound inwards: their normals out of the solid
    mesh.apply_scale(scale)
    return MeshShape(mesh)
