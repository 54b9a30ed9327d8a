"""Frame helpers for the mission layer (DESIGN section 2): target frame t, yaw, pitch.

Rotations are 3x3 matrices R_a_b mapping vectors from frame b to frame a; positions p_a_b
are the origin of b expressed in a.
"""
import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from uav_tilt_common.geometry import Vector, cross3, quat_to_matrix

_E_Z = np.array([0.0, 0.0, 1.0])
# Below this horizontal norm a normal counts as vertical and the horizontal axis is
# taken from map x, so that the frame stays deterministic.
_VERTICAL_EPS = 1e-6


def unit(v: ArrayLike) -> NDArray[np.float64]:
    """``v`` normalised; raises ValueError for a zero or non-finite vector."""
    v = np.asarray(v, dtype=float)
    norm = math.sqrt(v @ v)
    if not math.isfinite(norm) or norm < 1e-12:
        raise ValueError(f'cannot normalise {v!r}')
    return v / norm


def target_frame_from_normal(p_poi_map: ArrayLike, normal_map: ArrayLike
                             ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Target frame t at the point of interest: returns (R_map_t, origin_map).

    z_t is the surface normal (out of the wall), x_t is horizontal along the wall and
    y_t = z_t x x_t points up along the wall. For a vertical normal x_t is x_map
    (projected on the surface).
    """
    z_t = unit(normal_map)
    x_t = cross3(_E_Z, z_t)
    if math.sqrt(x_t @ x_t) < _VERTICAL_EPS:
        x_t = np.array([1.0, 0.0, 0.0]) - z_t * z_t[0]
    x_t = unit(x_t)
    y_t = cross3(z_t, x_t)
    return np.column_stack([x_t, y_t, z_t]), np.asarray(p_poi_map, dtype=float).copy()


def yaw_facing(normal_map: Vector, default_rad: float = 0.0) -> float:
    """Heading (rad, ENU) that points x_FLU into the wall, i.e. along -normal projected
    on the horizontal plane; ``default_rad`` when the normal is vertical."""
    n0, n1 = float(normal_map[0]), float(normal_map[1])
    if math.hypot(n0, n1) < _VERTICAL_EPS:
        return float(default_rad)
    return math.atan2(-n1, -n0)


def pitch_facing(normal_map: ArrayLike) -> float:
    """Pitch (rad, positive nose down) that points x_FLU along -normal."""
    return math.asin(min(max(float(unit(normal_map)[2]), -1.0), 1.0))


def tool_direction(yaw_rad: float, pitch_rad: float) -> NDArray[np.float64]:
    """x_FLU in map (the tool's axis) at this heading and pitch (positive nose down)."""
    c = math.cos(pitch_rad)
    return np.array([c * math.cos(yaw_rad), c * math.sin(yaw_rad), -math.sin(pitch_rad)])


def quat_matrix(q: ArrayLike) -> NDArray[np.float64]:
    """Rotation matrix of a quaternion (x, y, z, w) of any norm, which scipy's from_quat
    accepts too; a non-finite or zero one gives NaNs instead of raising."""
    q = np.asarray(q, dtype=float)
    return quat_to_matrix(q / math.sqrt(q @ q))


def to_frame(R_map_t: NDArray[np.float64], origin_map: NDArray[np.float64],
             p_map: ArrayLike) -> NDArray[np.float64]:
    """Express a map point in frame t."""
    return R_map_t.T @ (np.asarray(p_map, dtype=float) - origin_map)


def wrap_angle(a_rad: float) -> float:
    """Angle wrapped to [-pi, pi)."""
    return float((a_rad + math.pi) % (2.0 * math.pi) - math.pi)
