"""What the camera sees: visual shapes described once, drawn by either renderer.

A :class:`Visual` (a textured rectangle, a box, a cylinder, a sphere or a textured triangle
mesh in a link frame) makes
both the PyBullet visual shape that TinyRenderer draws and the triangle mesh that the GL
renderer (:mod:`uav_tilt_sim.camera.gl`) draws. A :class:`Scene` lists the visuals of
every body of one physics client by (body, link); the builders of the world, the vehicle
and the data set fill it as they create bodies.
"""
import dataclasses
import os
import tempfile
from typing import Any, Iterable, Sequence

import cv2
import numpy as np

from uav_tilt_common.geometry import Vector
from uav_tilt_sim.bullet import pybullet as p

QUAD, BOX, CYLINDER, SPHERE, MESH = 'quad', 'box', 'cylinder', 'sphere', 'mesh'
# Tessellation of round shapes for the GL renderer (TinyRenderer tessellates its own).
ROUND_SEGMENTS = 24

# (vertices, normals, uvs, triangles) of a shape
Mesh = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]


@dataclasses.dataclass(eq=False)
class Visual:
    """One visual shape in its link frame.

    ``size``: quad (half width along x, half height along y; it faces +z), box (half
    extents), cylinder (radius, length along z), sphere (radius,), mesh (unused: its
    triangles are ``arrays``, textured by their uvs). A quad's texture row 0
    lies at +y and column 0 at -x. ``tile_m`` splits a large quad into tiles of about that
    side (TinyRenderer drops a whole triangle whose vertices project far outside the image);
    ``texture_m`` repeats the texture every that many metres (default: once over the quad).
    """

    kind: str
    size: Sequence[float]
    rgba: Sequence[float] = (1.0, 1.0, 1.0, 1.0)
    texture: np.ndarray | None = None          # HxWx3 uint8 RGB
    position: Sequence[float] = (0.0, 0.0, 0.0)   # of the shape in the link frame
    quaternion: Sequence[float] = (0.0, 0.0, 0.0, 1.0)
    tile_m: float | None = None
    texture_m: float | None = None
    arrays: Mesh | None = None

    def mesh(self) -> Mesh:
        """(vertices, normals, uvs, triangles) in the link frame, float32 / int32 arrays."""
        if self.kind == MESH:
            assert self.arrays is not None
            v, n, uv, tri = self.arrays
        else:
            builder = {QUAD: _quad_mesh, BOX: _box_mesh, CYLINDER: _cylinder_mesh,
                       SPHERE: _sphere_mesh}[self.kind]
            v, n, uv, tri = builder(self)
        R = np.array(p.getMatrixFromQuaternion(self.quaternion)).reshape(3, 3)
        return ((v @ R.T + np.asarray(self.position)).astype(np.float32),
                (n @ R.T).astype(np.float32), uv.astype(np.float32), tri.astype(np.int32))


def quad_grid(half_w: float, half_h: float, tile_m: float | None
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(vertices, uvs, triangles) of a quad in the xy plane split into tiles of about
    ``tile_m`` (one without), its triangles counter-clockwise seen from +z."""
    nx = max(1, int(np.ceil(2 * half_w / tile_m))) if tile_m else 1
    ny = max(1, int(np.ceil(2 * half_h / tile_m))) if tile_m else 1
    u, v = np.meshgrid(np.linspace(0.0, 1.0, nx + 1), np.linspace(0.0, 1.0, ny + 1))
    vertices = np.column_stack([(2 * u.ravel() - 1) * half_w, (2 * v.ravel() - 1) * half_h,
                                np.zeros(u.size)])
    corner = (np.arange(ny)[:, None] * (nx + 1) + np.arange(nx)[None, :]).ravel()
    # Two counter-clockwise triangles (seen from +z) per tile.
    triangles = np.column_stack([corner, corner + 1, corner + nx + 2,
                                 corner, corner + nx + 2, corner + nx + 1]).reshape(-1, 3)
    return vertices, np.column_stack([u.ravel(), v.ravel()]), triangles


def _quad_mesh(visual: Visual) -> Mesh:
    half_w, half_h = visual.size
    vertices, uvs, triangles = quad_grid(half_w, half_h, visual.tile_m)
    if visual.texture_m:
        uvs = uvs * 2 * np.asarray(visual.size) / visual.texture_m
    # PyBullet's texture coordinate v runs from texture row 0 at v = 1 (it flips images).
    return vertices, np.tile([0.0, 0.0, 1.0], (len(vertices), 1)), uvs, triangles


def _box_mesh(visual: Visual) -> Mesh:
    return box_faces(np.asarray(visual.size, dtype=float))


def box_faces(half: np.ndarray, tile_m: float | None = None,
              texture_m: float | None = None) -> Mesh:
    """A box of half extents ``half`` about its centre, each face a quad (split into tiles
    of about ``tile_m``) turned so that its +z is the face's outward normal, its texture
    once over it or repeated every ``texture_m``."""
    parts = []
    for axis in range(3):
        for sign in (1.0, -1.0):
            normal = np.zeros(3)
            normal[axis] = sign
            a, b = (axis + 1) % 3, (axis + 2) % 3
            x_dir, y_dir = np.eye(3)[a], np.eye(3)[b] * sign
            R = np.column_stack([x_dir, y_dir, np.cross(x_dir, y_dir)])
            v, uv, tri = quad_grid(half[a], half[b], tile_m)
            if texture_m:
                uv = uv * 2 * np.array([half[a], half[b]]) / texture_m
            parts.append((v @ R.T + normal * half, np.tile(normal, (len(v), 1)), uv, tri))
    return concat(parts)


def _cylinder_mesh(visual: Visual) -> Mesh:
    radius, length = visual.size
    a = 2 * np.pi * np.arange(ROUND_SEGMENTS + 1) / ROUND_SEGMENTS
    ring = np.column_stack([np.cos(a), np.sin(a), np.zeros_like(a)])
    n = len(a)
    side_v = np.vstack([ring * radius + [0, 0, -length / 2], ring * radius + [0, 0, length / 2]])
    k = np.arange(n - 1)
    side_tri = np.column_stack([k, k + 1, k + n + 1, k, k + n + 1, k + n]).reshape(-1, 3)
    parts = [(side_v, np.vstack([ring, ring]), np.zeros((2 * n, 2)), side_tri)]
    for sign in (1.0, -1.0):
        cap_v = np.vstack([[0, 0, sign * length / 2], ring[:-1] * radius
                           + [0, 0, sign * length / 2]])
        j = np.arange(1, n)
        nxt = np.where(j == n - 1, 1, j + 1)
        cap_tri = np.column_stack([np.zeros_like(j), j, nxt] if sign > 0
                                  else [np.zeros_like(j), nxt, j])
        parts.append((cap_v, np.tile([0, 0, sign], (n, 1)), np.zeros((n, 2)), cap_tri))
    return concat(parts)


def _sphere_mesh(visual: Visual) -> Mesh:
    radius = visual.size[0]
    rows, cols = ROUND_SEGMENTS // 2, ROUND_SEGMENTS
    theta = np.linspace(0, np.pi, rows + 1)[:, None]
    phi = np.linspace(0, 2 * np.pi, cols + 1)[None, :]
    normals = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi),
                        np.cos(theta) * np.ones_like(phi)], axis=-1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(rows), np.arange(cols), indexing='ij')
    c = (i * (cols + 1) + j).ravel()
    tri = np.column_stack([c, c + cols + 1, c + cols + 2, c, c + cols + 2, c + 1]).reshape(-1, 3)
    return normals * radius, normals, np.zeros((len(normals), 2)), tri


def concat(parts: Iterable[Mesh]) -> Mesh:
    """One mesh of several (vertices, normals, uvs, triangles)."""
    out: list[list[np.ndarray]] = [[], [], [], []]
    offset = 0
    for v, n, uv, tri in parts:
        for lst, arr in zip(out, (v, n, uv, tri + offset)):
            lst.append(np.asarray(arr, dtype=float))
        offset += len(v)
    vertices, normals, uvs, triangles = (np.vstack(lst) for lst in out)
    return vertices, normals, uvs, triangles


def pybullet_shape(client: int, visuals: Sequence[Visual]) -> int:
    """PyBullet visual shape (for TinyRenderer) of one or more visuals of a link."""
    shapes: list[dict[str, Any]] = []
    for v in visuals:
        if v.kind in (QUAD, MESH):
            vertices, normals, uvs, tri = v.mesh()
            shapes.append(dict(shapeType=p.GEOM_MESH, vertices=vertices.tolist(),
                               indices=tri.ravel().tolist(), uvs=uvs.tolist(),
                               normals=normals.tolist()))
            continue
        if v.kind == BOX:
            kwargs = dict(shapeType=p.GEOM_BOX, halfExtents=list(v.size))
        elif v.kind == CYLINDER:
            kwargs = dict(shapeType=p.GEOM_CYLINDER, radius=v.size[0], length=v.size[1])
        else:
            kwargs = dict(shapeType=p.GEOM_SPHERE, radius=v.size[0])
        shapes.append(dict(visualFramePosition=list(v.position),
                           visualFrameOrientation=list(v.quaternion), **kwargs))
    if len(visuals) == 1:
        return p.createVisualShape(rgbaColor=list(visuals[0].rgba), physicsClientId=client,
                                   **shapes[0])
    return p.createVisualShapeArray(
        shapeTypes=[s['shapeType'] for s in shapes],
        halfExtents=[s.get('halfExtents', [0, 0, 0]) for s in shapes],
        radii=[s.get('radius', 0.0) for s in shapes],
        lengths=[s.get('length', 0.0) for s in shapes],
        rgbaColors=[list(v.rgba) for v in visuals],
        visualFramePositions=[s['visualFramePosition'] for s in shapes],
        visualFrameOrientations=[s['visualFrameOrientation'] for s in shapes],
        physicsClientId=client)


def apply_texture(client: int, body: int, visual: Visual, link: int = -1) -> None:
    """Give the PyBullet shape of ``body``/``link`` the texture of ``visual``."""
    if visual.texture is None:
        raise ValueError('the visual has no texture')
    with tempfile.TemporaryDirectory() as tmpdir:
        path = os.path.join(tmpdir, 'texture.png')
        cv2.imwrite(path, cv2.cvtColor(visual.texture, cv2.COLOR_RGB2BGR))
        texture = p.loadTexture(path, physicsClientId=client)
    p.changeVisualShape(body, link, textureUniqueId=texture, physicsClientId=client)


@dataclasses.dataclass
class SceneBody:
    """The visuals of one body, by link (-1: the base); ``static`` bodies never move."""

    links: dict[int, list[Visual]]
    static: bool


class Scene:
    """The visuals of the bodies of physics client ``client``, for the GL renderer."""

    def __init__(self, client: int) -> None:
        self.client = client
        self.bodies: dict[int, SceneBody] = {}
        self.version = 0        # changes with every change of the scene

    def add(self, body: int, link: int, visuals: Iterable[Visual], static: bool) -> None:
        """Register the visuals of ``body``'s ``link`` (a list of :class:`Visual`)."""
        entry = self.bodies.setdefault(body, SceneBody({}, static))
        entry.links[link] = list(visuals)
        entry.static = entry.static and static
        self.version += 1

    def remove(self, body: int) -> None:
        """Forget a removed body."""
        self.bodies.pop(body, None)
        self.version += 1

    def clear(self) -> None:
        """Forget every body (after ``resetSimulation``)."""
        self.bodies.clear()
        self.version += 1


def create_static_body(client: int, scene: Scene | None, visual: Visual,
                       position: Vector, quaternion: Vector,
                       collision: int = -1) -> int:
    """A static (mass 0) body drawn as ``visual``; registered in ``scene`` when given."""
    body = p.createMultiBody(0.0, collision, pybullet_shape(client, [visual]), list(position),
                             list(quaternion), physicsClientId=client)
    if visual.texture is not None:
        apply_texture(client, body, visual)
    if scene is not None:
        scene.add(body, -1, [visual], static=True)
    return body
