"""The planes vision sees in the depth image (``vision/planes``, DESIGN section 3), defined
once for producer and consumers: walls that the search can fly to face.

One point per plane of a frame, the largest first, in the camera optical frame: a point
on it (the centroid of its pixels), its unit normal towards the camera and the share of
the frame's depth samples on it.
"""
import dataclasses
from typing import Iterable

import numpy as np
from numpy.typing import ArrayLike, NDArray

PLANE_FIELDS = ('x', 'y', 'z', 'nx', 'ny', 'nz', 'share')


@dataclasses.dataclass
class Plane:
    """A plane of one depth image, camera optical frame."""

    point_cam: np.ndarray       # centroid of its pixels, m
    normal_cam: np.ndarray      # unit normal, towards the camera
    share: float                # of the frame's depth samples (0-1)


def planes_to_array(planes: Iterable[Plane]) -> NDArray[np.float32]:
    """(N, len(PLANE_FIELDS)) float32 rows of ``planes``."""
    rows = [np.concatenate([p.point_cam, p.normal_cam, [p.share]]) for p in planes]
    return np.asarray(rows, dtype=np.float32).reshape(-1, len(PLANE_FIELDS))


def planes_from_array(rows: ArrayLike) -> list[Plane]:
    """The planes of :func:`planes_to_array` rows; ValueError on a non-finite row, a normal
    that is not a unit vector or a share outside 0-1."""
    out = []
    for row in np.asarray(rows, dtype=float).reshape(-1, len(PLANE_FIELDS)):
        if not np.all(np.isfinite(row)):
            raise ValueError('non-finite plane')
        if abs(np.linalg.norm(row[3:6]) - 1.0) > 1e-3 or not 0.0 <= row[6] <= 1.0:
            raise ValueError(f'bad plane normal {row[3:6]} or share {row[6]}')
        out.append(Plane(row[0:3].copy(), row[3:6] / np.linalg.norm(row[3:6]),
                         float(row[6])))
    return out
