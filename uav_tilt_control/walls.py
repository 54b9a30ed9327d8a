"""Walls seen while searching, from vision's planes in map, and where to face them from.
No rclpy.

A plane whose normal is within ``MAX_TILT_RAD`` of horizontal is a wall (the ground and
ceilings are not). Planes whose normals agree within ``SAME_ANGLE_RAD`` and whose offsets
within ``SAME_OFFSET_M`` are one wall; each keeps its weight (the shares it was seen
with, summed), its normal and centroid (weighted means) and how far along it the
centroids reached: a turn in front of a wall sees its parts one after another.
"""
import dataclasses
import math

import numpy as np

from uav_tilt_control import frames

MAX_TILT_RAD = math.radians(50.0)
SAME_ANGLE_RAD = math.radians(20.0)
SAME_OFFSET_M = 0.5


@dataclasses.dataclass
class Wall:
    """A wall in map: weighted centroid and unit normal (towards where it was seen from),
    the weight, and the extent of the centroids along it (m, from ``point_map`` along the
    horizontal ``x`` of :func:`frames.target_frame_from_normal`)."""

    point_map: np.ndarray
    normal_map: np.ndarray
    weight: float
    along_m: tuple[float, float] = (0.0, 0.0)

    def face_points(self, standoff_m, altitude_m, spacing_m):
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

    def __init__(self):
        self.walls = []

    def observe(self, point_map, normal_map, share):
        """One plane of a frame (map): added to the wall it lies on, or a new wall; planes
        far from vertical are left out. Returns whether it was a wall."""
        n = frames.unit(normal_map)
        p = np.asarray(point_map, dtype=float)
        if abs(n[2]) > math.sin(MAX_TILT_RAD) or not (share > 0.0 and np.all(np.isfinite(p))):
            return False
        for wall in self.walls:
            if n @ wall.normal_map >= math.cos(SAME_ANGLE_RAD) and \
                    abs((p - wall.point_map) @ wall.normal_map) <= SAME_OFFSET_M:
                self._merge(wall, p, n, share)
                return True
        self.walls.append(Wall(p, n, float(share)))
        return True

    def best(self):
        """The wall seen most, or None."""
        return max(self.walls, key=lambda w: w.weight, default=None)

    @staticmethod
    def _merge(wall, p, n, share):
        total = wall.weight + share
        R, _ = frames.target_frame_from_normal(wall.point_map, wall.normal_map)
        along = (p - wall.point_map) @ R[:, 0]
        lo, hi = min(wall.along_m[0], along), max(wall.along_m[1], along)
        point = (wall.point_map * wall.weight + p * share) / total
        normal = frames.unit(wall.normal_map * wall.weight + n * share)
        # the extent is kept about the new centroid, along the new horizontal
        R_new, _ = frames.target_frame_from_normal(point, normal)
        shift = (point - wall.point_map) @ R_new[:, 0]
        wall.point_map, wall.normal_map, wall.weight = point, normal, total
        wall.along_m = (lo - shift, hi - shift)
