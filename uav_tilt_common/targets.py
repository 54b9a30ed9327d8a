"""Vision's targets on the wire (DESIGN section 3), defined once for producer and consumers.

- ``target/pose`` (PoseWithCovarianceStamped): the target vision tracks; covariance[0] = -1
  means "no target in this frame" (the sensor_msgs/Imu convention).
- ``target/candidates`` (PointCloud2, one point per detection of the target class with a
  point of interest, the tracked one first): what the controller chooses its target from,
  so that a plan's or a hint's target can be picked among look-alikes.
"""
import dataclasses
from typing import Iterable

import numpy as np
from numpy.typing import ArrayLike, NDArray

# A target hint (where a survey or a plan says the target is on its wall) is good to this
# along each of the wall's axes (DESIGN section 5), so up to sqrt(2) times it away on the
# diagonal: the controller takes hints to be this good, and random worlds make them so.
HINT_ERROR_M = 0.3
# The inspection objects a scenario places and the detector is trained on (class index =
# position here); points of interest are defined for bolt plates.
OBJECT_CLASSES = ('bolt_plate', 'gauge', 'hazard_sign')
NO_TARGET_COV0 = -1.0
# PointCloud2 fields of target/candidates, all float32: the POI (camera optical frame, m),
# the unit surface normal towards the camera, the POI's position covariance (m^2, upper
# triangle), the detector's score and the class index.
CANDIDATE_FIELDS = ('x', 'y', 'z', 'nx', 'ny', 'nz', 'cxx', 'cxy', 'cxz', 'cyy', 'cyz', 'czz',
                    'score', 'class_id')
_UPPER = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))


def no_target_covariance() -> NDArray[np.float64]:
    """The 36-element covariance of a "no target" target/pose."""
    cov = np.zeros(36)
    cov[0] = NO_TARGET_COV0
    return cov


def is_no_target(covariance: ArrayLike) -> bool:
    """True for the covariance of a "no target" target/pose."""
    cov = np.asarray(covariance, dtype=float).ravel()
    return bool(cov.size) and cov[0] == NO_TARGET_COV0


@dataclasses.dataclass
class TargetCandidate:
    """One detected target in the camera optical frame."""

    p_cam: np.ndarray           # point of interest, m
    n_cam: np.ndarray           # unit surface normal, towards the camera
    cov_cam: np.ndarray         # 3x3 position covariance, m^2
    score: float = 1.0
    class_id: int = 0


def candidates_to_array(candidates: Iterable[TargetCandidate]) -> NDArray[np.float32]:
    """(N, len(CANDIDATE_FIELDS)) float32 rows of ``candidates``."""
    rows = [np.concatenate([c.p_cam, c.n_cam, [c.cov_cam[i, j] for i, j in _UPPER],
                            [c.score, c.class_id]]) for c in candidates]
    return np.asarray(rows, dtype=np.float32).reshape(-1, len(CANDIDATE_FIELDS))


def candidates_from_array(rows: ArrayLike) -> list[TargetCandidate]:
    """The candidates of :func:`candidates_to_array` rows; ValueError on a non-finite one
    or one whose normal is not a unit vector (vision/planes' rule)."""
    out = []
    for row in np.asarray(rows, dtype=float).reshape(-1, len(CANDIDATE_FIELDS)):
        if not np.all(np.isfinite(row)):
            raise ValueError('non-finite candidate')
        if abs(np.linalg.norm(row[3:6]) - 1.0) > 1e-3:
            raise ValueError(f'candidate normal {row[3:6]} is not a unit vector')
        cov = np.zeros((3, 3))
        for (i, j), value in zip(_UPPER, row[6:12]):
            cov[i, j] = cov[j, i] = value
        out.append(TargetCandidate(row[0:3].copy(), row[3:6].copy(), cov, float(row[12]),
                                   int(round(row[13]))))
    return out
