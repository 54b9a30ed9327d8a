"""Structures of a scenario (DESIGN section 5): walls, boxes, cylinders and meshes, their
surfaces, and where an object placed on one sits (pure geometry; no PyBullet).

Every placed object has a surface frame S: z_S the outward surface normal at its centre,
y_S the map's up as seen in the tangent plane (the structure's axis where the normal is
vertical), x_S = y_S x z_S, right as seen from outside. On a wall it is the wall frame W.
"""
import dataclasses
import functools
import math

import numpy as np
from numpy.typing import NDArray

from uav_tilt_common.config import ConfigError, param
from uav_tilt_common.geometry import (cross3, cylinder_rotation, euler_zyx_to_matrix,
                                      wall_rotation)
from uav_tilt_sim.structure_mesh import MeshShape, load_mesh

WALL, BOX, CYLINDER, MESH = 'wall', 'box', 'cylinder', 'mesh'
KINDS = (WALL, BOX, CYLINDER, MESH)
BOX_FACES = ('+x', '-x', '+y', '-y', '+z')
WALL_THICKNESS_M = 0.2
UP = np.array([0.0, 0.0, 1.0])
Array = NDArray[np.float64]


@dataclasses.dataclass
class StructureConfig:
    """One structure: a wall (a rectangle 0.2 m thick), a box (a pillar, a beam), a
    cylinder (a pipe, a tank) or a mesh read from an OBJ or STL file; static, with the
    contact of its surface (and of the objects on it)."""

    id: str = param('', doc='its name, which objects give as their `on` (a letter, then '
                            'letters, digits or _; unique)')
    kind: str = param(WALL, choices=KINDS, doc='what it is')
    position_m: list = param([2.0, 0.0, 0.0], lo=-50.0, hi=50.0, length=3,
                             doc="map point: a wall's middle of the face's ground line; a "
                                 "box's middle of its base; a cylinder's middle of its axis; "
                                 "a mesh's file origin")
    yaw_deg: float = param(0.0, lo=-180.0, hi=180.0,
                           doc="a wall's heading into its face (as wall.yaw_deg); a box's or "
                               "a mesh's turn about map z; a cylinder's axis heading")
    inclination_deg: float = param(0.0, lo=-30.0, hi=30.0,
                                   doc="wall: top leaning away from the face's side")
    elevation_deg: float = param(0.0, lo=-90.0, hi=90.0,
                                 doc='cylinder: its axis above horizontal (90: upright, a '
                                     'tank or a round pillar)')
    width_m: float = param(5.0, lo=0.5, hi=50.0, doc='wall: along the ground line')
    height_m: float = param(3.5, lo=0.5, hi=20.0, doc='wall: up the face')
    size_m: list = param([0.6, 0.6, 3.0], lo=0.05, hi=50.0, length=3,
                         doc="box: its sides along its own x, y (yaw_deg turns them) and z")
    radius_m: float = param(0.3, lo=0.05, hi=3.0, doc='cylinder: its radius')
    length_m: float = param(3.0, lo=0.1, hi=50.0, doc='cylinder: along its axis')
    file: str = param('', doc='mesh: an OBJ or STL file (relative: to the scenario file); '
                              'closed (watertight)')
    scale: float = param(1.0, lo=1e-3, hi=1e3, doc='mesh: metres per unit of its file')
    stiffness_n_per_m: float = param(4000.0, lo=100.0, hi=1e6,
                                     doc='contact stiffness of it and its objects')
    damping_n_s_per_m: float = param(60.0, lo=0.0, hi=1e4,
                                     doc='contact damping of it and its objects')
    friction: float = param(0.4, lo=0.0, hi=2.0,
                            doc='Coulomb friction coefficient of it and its objects')


def surface_frame(normal: Array, fallback_up: Array) -> Array:
    """R_map_surface whose z is ``normal``, y the map's up in the tangent plane (else
    ``fallback_up`` there)."""
    z = normal / np.linalg.norm(normal)
    y = UP - (UP @ z) * z
    if np.linalg.norm(y) < 1e-6:
        y = fallback_up - (fallback_up @ z) * z
    y = y / np.linalg.norm(y)
    return np.column_stack([cross3(y, z), y, z])


@dataclasses.dataclass
class Placement:
    """Where an object's face sits: its centre and surface frame (map); ``curve_axis`` and
    ``curve_centre`` for an object wrapped around a cylinder (else None)."""

    centre_map: Array
    R_map_surface: Array
    curve_axis: Array | None = None
    curve_centre: Array | None = None
    curve_radius_m: float = 0.0


class Structure:
    """A structure's geometry in map: where a surface point lies, whether a point is inside."""

    def __init__(self, cfg: StructureConfig, mesh: MeshShape | None = None) -> None:
        self.cfg = cfg
        self.position = np.asarray(cfg.position_m, dtype=float)
        self.mesh = mesh
        if cfg.kind == WALL:
            self.R = wall_rotation(cfg.yaw_deg, cfg.inclination_deg)
        elif cfg.kind == CYLINDER:
            self.R = cylinder_rotation(cfg.yaw_deg, cfg.elevation_deg)
        else:
            self.R = euler_zyx_to_matrix(math.radians(cfg.yaw_deg), 0.0, 0.0)

    def local(self, points_map: Array) -> Array:
        """Points (N x 3) in the structure's frame (origin ``position_m``)."""
        return (np.atleast_2d(points_map) - self.position) @ self.R

    def contains(self, points_map: Array, margin_m: float = 0.0) -> NDArray[np.bool_]:
        """Whether each point lies inside (grown by ``margin_m``)."""
        q, c, m = self.local(points_map), self.cfg, margin_m
        if c.kind == WALL:
            return ((np.abs(q[:, 0]) <= c.width_m / 2 + m) & (q[:, 1] >= -m)
                    & (q[:, 1] <= c.height_m + m) & (q[:, 2] <= m)
                    & (q[:, 2] >= -WALL_THICKNESS_M - m))
        if c.kind == BOX:
            half = np.asarray(c.size_m) / 2
            return ((np.abs(q[:, 0]) <= half[0] + m) & (np.abs(q[:, 1]) <= half[1] + m)
                    & (q[:, 2] >= -m) & (q[:, 2] <= c.size_m[2] + m))
        if c.kind == CYLINDER:
            return ((np.abs(q[:, 2]) <= c.length_m / 2 + m)
                    & (np.hypot(q[:, 0], q[:, 1]) <= c.radius_m + m))
        assert self.mesh is not None
        return self.mesh.contains(q, m)

    def centre_map(self) -> Array:
        """The middle of its volume (a mesh's: of its bounding box)."""
        c = self.cfg
        if c.kind == WALL:
            middle = np.array([0.0, c.height_m / 2, -WALL_THICKNESS_M / 2])
        elif c.kind == BOX:
            middle = np.array([0.0, 0.0, c.size_m[2] / 2])
        elif c.kind == CYLINDER:
            middle = np.zeros(3)
        else:
            assert self.mesh is not None
            middle = (self.mesh.vertices.min(axis=0) + self.mesh.vertices.max(axis=0)) / 2
        return self.position + self.R @ middle

    def hull_points_map(self) -> Array:
        """Points (N x 3, map) whose convex hull holds the structure: a box's or a wall's
        corners, a cylinder's two rims (a 64-gon drawn round each rim), a mesh's vertices."""
        c = self.cfg
        if c.kind in (WALL, BOX):
            if c.kind == WALL:
                lo = np.array([-c.width_m / 2, 0.0, -WALL_THICKNESS_M])
                hi = np.array([c.width_m / 2, c.height_m, 0.0])
            else:
                lo = np.array([-c.size_m[0] / 2, -c.size_m[1] / 2, 0.0])
                hi = np.array([c.size_m[0] / 2, c.size_m[1] / 2, c.size_m[2]])
            local = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                              for z in (lo[2], hi[2])])
        elif c.kind == CYLINDER:
            a = np.linspace(0.0, 2.0 * math.pi, 64, endpoint=False)
            # the polygon's sides lie inside the circle: reach it with their middles
            r = c.radius_m / math.cos(math.pi / 64)
            rim = np.column_stack([r * np.cos(a), r * np.sin(a)])
            local = np.vstack([np.column_stack([rim, np.full(64, z)])
                               for z in (-c.length_m / 2, c.length_m / 2)])
        else:
            assert self.mesh is not None
            local = self.mesh.vertices
        return self.position + local @ self.R.T

    def plan_box(self) -> tuple[Array, Array, float]:
        """(centre, sizes, yaw_deg) of an upright box turned by the structure's yaw that
        holds it: an obstacle as a site lists it (uav_tilt_control.obstacles)."""
        points = self.hull_points_map()
        yaw = math.radians(self.cfg.yaw_deg)
        R = euler_zyx_to_matrix(yaw, 0.0, 0.0)
        local = points @ R
        lo, hi = local.min(axis=0), local.max(axis=0)
        return R @ ((lo + hi) / 2.0), hi - lo, float(self.cfg.yaw_deg)

    def place(self, face: str, u_m: float, v_m: float, axial_m: float, angle_deg: float,
              point_m: list[float], size_m: float, name: str) -> Placement:
        """Where an object ``size_m`` square sits on this structure, from the surface
        coordinates of its kind: (u, v) on a wall or on a box's ``face``, (axial, angle)
        on a cylinder, a point snapped to a mesh; ConfigError (naming ``name``) when its
        centre is off the surface."""
        c, pos, R = self.cfg, self.position, self.R
        where = f"{c.kind} {c.id!r}" if c.id else c.kind
        if c.kind == WALL:
            if abs(u_m) > c.width_m / 2:
                raise ConfigError(f"parameter '{name}.u_m' = {u_m} is off the {where} "
                                  f"(|u_m| <= width_m / 2 = {c.width_m / 2})")
            if v_m > c.height_m:
                raise ConfigError(f"parameter '{name}.v_m' = {v_m} is above the {where} "
                                  f"(height_m = {c.height_m})")
            return Placement(pos + R[:, 0] * u_m + R[:, 1] * v_m, R.copy())
        if c.kind == BOX:
            return self._place_on_box(face, u_m, v_m, name, where)
        if c.kind == CYLINDER:
            if abs(axial_m) > c.length_m / 2:
                raise ConfigError(f"parameter '{name}.axial_m' = {axial_m} is off the {where} "
                                  f"(|axial_m| <= length_m / 2 = {c.length_m / 2})")
            # a panel wrapped more than half way round would face itself
            if c.radius_m < size_m / math.pi:
                raise ConfigError(f"parameter '{name}.on' = {c.id!r}: a {size_m:g} m panel "
                                  f"wraps more than half way round a radius of {c.radius_m} "
                                  f"m (at least {size_m / math.pi:.3f} m)")
            theta = math.radians(angle_deg)
            radial = math.cos(theta) * R[:, 0] + math.sin(theta) * R[:, 1]
            axis = R[:, 2]
            return Placement(pos + axis * axial_m + radial * c.radius_m,
                             surface_frame(radial, axis), curve_axis=axis.copy(),
                             curve_centre=pos + axis * axial_m, curve_radius_m=c.radius_m)
        assert self.mesh is not None
        points, normals, distances = self.mesh.closest(np.asarray(point_m, dtype=float))
        if distances[0] > size_m / 2:
            raise ConfigError(f"parameter '{name}.point_m' = {list(point_m)} is "
                              f"{distances[0]:.3f} m off the surface of {where} (at most "
                              f"{size_m / 2:g} m: it is snapped onto it)")
        normal = R @ normals[0]
        return Placement(pos + R @ points[0], surface_frame(normal, R[:, 0]))

    def _place_on_box(self, face: str, u_m: float, v_m: float, name: str,
                      where: str) -> Placement:
        c, pos, R = self.cfg, self.position, self.R
        half = np.asarray(c.size_m) / 2
        if face == '+z':
            S = surface_frame(UP, R[:, 0])
            if abs(u_m) > half[1] or abs(v_m) > half[0]:
                raise ConfigError(f"parameter '{name}' (u_m {u_m}, v_m {v_m}) is off the "
                                  f"top of the {where} (|u_m| <= {half[1]}, |v_m| <= "
                                  f"{half[0]})")
            return Placement(pos + UP * c.size_m[2] + S[:, 0] * u_m + S[:, 1] * v_m, S)
        axis = 0 if face[1] == 'x' else 1
        normal = R[:, axis] * (1.0 if face[0] == '+' else -1.0)
        S = surface_frame(normal, R[:, 0])
        across = half[1 - axis]
        if abs(u_m) > across:
            raise ConfigError(f"parameter '{name}.u_m' = {u_m} is off the {face} face of the "
                              f"{where} (|u_m| <= {across})")
        if v_m > c.size_m[2]:
            raise ConfigError(f"parameter '{name}.v_m' = {v_m} is above the {where} "
                              f"(size_m[2] = {c.size_m[2]})")
        return Placement(pos + normal * half[axis] + S[:, 0] * u_m + UP * v_m, S)


@functools.lru_cache(maxsize=32)
def _mesh_of(path: str, scale: float, parameter: str) -> MeshShape:
    return load_mesh(path, scale, parameter)


def structure_of(cfg: StructureConfig, name: str) -> Structure:
    """The geometry of ``cfg`` (its mesh read, once per file and scale)."""
    mesh = _mesh_of(cfg.file, cfg.scale, f'{name}.file') if cfg.kind == MESH else None
    return Structure(cfg, mesh)
