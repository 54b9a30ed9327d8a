"""The surfaces a plan works on, in their own coordinates (u, v) in metres, and paths on
them (DESIGN section 5). No rclpy.

A wall's (u, v) are the scenario's: u right as seen from in front, v up from the ground.
A cylinder's are its surface unrolled: u = radius x angle (the angle about the axis of its
objects' ``angle_deg``, in radians), v = the axial position (its objects' ``axial_m``).
Seen from outside with the axis pointing up, u runs right and v up, as on a wall; a
straight line in (u, v) is the shortest way on the surface between its ends (a line at
constant v is an arc round it, at constant u a line along it).
"""
import dataclasses
import math
from collections.abc import Sequence
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from uav_tilt_common.geometry import cylinder_rotation, wall_point, wall_rotation

Array = NDArray[np.float64]
# the spacing of the points that stand for a path on a surface: the chord of an arc of
# radius r sags (PATH_STEP_M)^2 / (8 r) off it, 0.3 mm on the thinnest pipe (0.15 m)
PATH_STEP_M = 0.02


class Surface(Protocol):
    """One surface of the site, in its own coordinates."""

    def point_map(self, uv_m: Sequence[float]) -> Array:
        """The map point at (u, v)."""

    def normal_map(self, uv_m: Sequence[float]) -> Array:
        """The outward unit normal at (u, v), in map."""

    def on(self, uv_m: Sequence[float], margin_m: float = 0.0) -> bool:
        """Whether (u, v) lies on the surface (edges included), or within ``margin_m``."""

    def extent(self) -> str:
        """What :meth:`on` allows, in words."""


@dataclasses.dataclass(frozen=True)
class WallSurface:
    """A wall: its ground line through ``position_m`` (x, y), faced along heading
    ``yaw_deg``, its top leaning away by ``inclination_deg``; ``width_m`` across u = 0,
    ``height_m`` up from the ground."""

    position_m: tuple[float, float]
    yaw_deg: float
    inclination_deg: float
    width_m: float
    height_m: float

    def point_map(self, uv_m: Sequence[float]) -> Array:
        return wall_point(self.position_m, self.yaw_deg, self.inclination_deg, *uv_m)

    def normal_map(self, uv_m: Sequence[float]) -> Array:
        return wall_rotation(self.yaw_deg, self.inclination_deg)[:, 2]

    def on(self, uv_m: Sequence[float], margin_m: float = 0.0) -> bool:
        u, v = uv_m
        return (abs(u) <= self.width_m / 2.0 + margin_m
                and -margin_m <= v <= self.height_m + margin_m)

    def extent(self) -> str:
        return f'u in [{-self.width_m / 2}, {self.width_m / 2}], v in [0, {self.height_m}] m'


@dataclasses.dataclass(frozen=True)
class CylinderSurface:
    """A cylinder (a pipe, a tank): the middle of its axis at ``centre_m`` (map), the axis
    at heading ``yaw_deg`` and ``elevation_deg`` above horizontal (as a scenario's), its
    ``radius_m`` and ``length_m``."""

    centre_m: tuple[float, float, float]
    yaw_deg: float
    elevation_deg: float
    radius_m: float
    length_m: float

    def _radial(self, u_m: float) -> tuple[Array, Array]:
        R = cylinder_rotation(self.yaw_deg, self.elevation_deg)
        theta = u_m / self.radius_m
        return math.cos(theta) * R[:, 0] + math.sin(theta) * R[:, 1], R[:, 2]

    def point_map(self, uv_m: Sequence[float]) -> Array:
        radial, axis = self._radial(uv_m[0])
        return np.asarray(self.centre_m, dtype=float) + axis * uv_m[1] + radial * self.radius_m

    def normal_map(self, uv_m: Sequence[float]) -> Array:
        return self._radial(uv_m[0])[0]

    def on(self, uv_m: Sequence[float], margin_m: float = 0.0) -> bool:
        return abs(uv_m[1]) <= self.length_m / 2.0 + margin_m

    def extent(self) -> str:
        return (f'v (along the axis) in [{-self.length_m / 2}, {self.length_m / 2}] m, u '
                f'(round it) any: radius {self.radius_m} m x the angle in radians')


@dataclasses.dataclass
class SurfacePath:
    """A path on a surface as points no more than PATH_STEP_M apart (map), with the
    outward normal at each; ``vertices``: the index of each of the path's own vertices."""

    points_map: Array
    normals_map: Array
    vertices: list[int]

    @property
    def length_m(self) -> float:
        return float(np.sum(np.linalg.norm(np.diff(self.points_map, axis=0), axis=1)))


def path_on(surface: Surface, points_uv: Sequence[Sequence[float]],
            step_m: float = PATH_STEP_M) -> SurfacePath:
    """The polyline through ``points_uv`` (straight in the surface's coordinates) on
    ``surface``, sampled at most ``step_m`` apart along the surface."""
    uv = np.asarray(points_uv, dtype=float)
    samples, vertices = [uv[0]], [0]
    for a, b in zip(uv[:-1], uv[1:]):
        # on a wall and a cylinder alike, a step in (u, v) is as long on the surface
        n = max(int(math.ceil(float(np.linalg.norm(b - a)) / step_m)), 1)
        samples += [a + (b - a) * k / n for k in range(1, n + 1)]
        vertices.append(len(samples) - 1)
    return SurfacePath(np.array([surface.point_map(p) for p in samples]),
                       np.array([surface.normal_map(p) for p in samples]), vertices)
