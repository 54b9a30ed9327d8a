"""Walls seen while searching, from vision's planes in map, and where to face them from.
No rclpy.

A plane whose normal is within ``MAX_TILT_RAD`` of horizontal is a wall (the ground and
ceilings are not). Planes whose normals agree within ``SAME_ANGLE_RAD`` and whose offsets
within ``SAME_OFFSET_M`` are one wall; each keeps its weight (the shares it was seen
with, summed), its normal and centroid (weighted means) and how far along it the
centroids reach: a turn in front of a wall sees its parts one after another.
"""
import dataclasses
import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from uav_tilt_common.geometry import Vector
from uav_tilt_control import frames

MAX_TILT_RAD = math.radians(50.0)
SAME_ANGLE_RAD = math.radians(20.0)
SAME_OFFSET_M = 0.5


@dataclasses.dataclass
class Wall:
    """What a search saw of one wall in map: the centroids of its planes, their unit
    normals (towards where they were seen from) and the shares they were seen with."""

    centroids: list = dataclasses.field(default_factory=list)
    normals: list = dataclasses.field(default_factory=list)
    shares: list = dataclasses.field(default_factory=list)

    @property
    def weight(self) -> float:
        return float(sum(self.shares))

    @property
    def point_map(self) -> NDArray[np.float64]:
        """The centroids' mean, weighted by share."""
        return np.average(self.centroids, axis=0, weights=self.shares)

    @property
    def normal_map(self) -> NDArray[np.float64]:
        return frames.unit(np.average(self.normals, axis=0, weights=self.shares))

    @property
    def along_m(self) -> tuple[float, float]:
        """How far the centroids reach along the wall, (min, max) in m from ``point_map``
        along the horizontal ``x`` of :func:`frames.target_frame_from_normal`."""
        R, origin = frames.target_frame_from_normal(self.point_map, self.normal_map)
        along = (np.asarray(self.centroids) - origin) @ R[:, 0]
        return float(along.min()), float(along.max())

    def altitudes_clear_of(self, p_map: Vector, reach_m: float) -> tuple[float, float]:
        """The altitudes (lo, hi) at which the horizontal circle of radius ``reach_m``
        around ``p_map``'s vertical stays in front of this wall's plane: a wall leaning
        over ``p_map`` nears as one climbs, one leaning away as one descends."""
        n = self.normal_map
        n_h = math.hypot(n[0], n[1])
        # the plane's signed distance along n, less the reach's share of it, at p's altitude
        spare_m = float((np.asarray(p_map) - self.point_map) @ n) - n_h * reach_m
        if n[2] < 0.0:
            return -math.inf, float(p_map[2] + spare_m / -n[2])
        if n[2] > 0.0:
            return float(p_map[2] - spare_m / n[2]), math.inf
        return -math.inf, math.inf

    def face_points(self, standoff_m: float, altitude_m: float,
                    spacing_m: float) -> tuple[list[NDArray[np.float64]], float]:
        """Points at ``altitude_m``, ``standoff_m`` out from the wall horizontally, in
        front of the two ends of its extent (one, in front of the middle, when they are
        less than ``spacing_m`` apart); and the heading that faces the wall."""
        R, origin = frames.target_frame_from_normal(self.point_map, self.normal_map)
        x_t, y_t, n = R[:, 0], R[:, 1], R[:, 2]
        # the wall's horizontal line at that altitude, along its own up direction
        at_altitude = origin + y_t * (altitude_m - origin[2]) / y_t[2]
        n_h = frames.unit([n[0], n[1], 0.0])
        lo, hi = self.along_m
        ends = (lo, hi) if hi - lo >= spacing_m else (0.5 * (lo + hi),)
        points = [at_altitude + x_t * s + n_h * standoff_m for s in ends]
        return points, frames.yaw_facing(n)


class WallMemory:
    """The walls of one search."""

    def __init__(self) -> None:
        self.walls: list[Wall] = []

    def observe(self, point_map: ArrayLike, normal_map: ArrayLike, share: float) -> bool:
        """One plane of a frame (map): added to the wall it lies on, or a new wall; planes
        far from vertical are left out. Returns whether it was a wall."""
        n = frames.unit(normal_map)
        p = np.asarray(point_map, dtype=float)
        if abs(n[2]) > math.sin(MAX_TILT_RAD) or not (share > 0.0 and np.all(np.isfinite(p))):
            return False
        wall = next((w for w in self.walls if n @ w.normal_map >= math.cos(SAME_ANGLE_RAD)
                     and abs((p - w.point_map) @ w.normal_map) <= SAME_OFFSET_M), None)
        if wall is None:
            wall = Wall()
            self.walls.append(wall)
        wall.centroids.append(p)
        wall.normals.append(n)
        wall.shares.append(float(share))
        return True

    def altitudes_clear_of(self, p_map: Vector, reach_m: float) -> tuple[float, float]:
        """The altitudes (lo, hi) at which every wall is clear of ``reach_m`` around
        ``p_map``'s vertical (:meth:`Wall.altitudes_clear_of`); lo > hi when none is."""
        ranges = [w.altitudes_clear_of(p_map, reach_m) for w in self.walls]
        return (max((r[0] for r in ranges), default=-math.inf),
                min((r[1] for r in ranges), default=math.inf))

    def best(self) -> Wall | None:
        """The wall seen most, or None."""
        return max(self.walls, key=lambda w: w.weight, default=None)
