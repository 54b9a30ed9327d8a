"""A rigid pose: where frame b is in frame a (DESIGN section 2's R_a_b, p_a_b)."""
from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import ArrayLike, NDArray

from uav_tilt_common.geometry import quat_to_matrix


@dataclasses.dataclass(frozen=True)
class Pose:
    """Rotation ``R`` (3x3, maps b vectors to a) and position ``p`` (b's origin in a).

    ``pose_a_b @ pose_b_c`` is pose_a_c; ``pose_a_b.apply(x_b)`` is the point in a.
    """

    R: NDArray[np.float64]
    p: NDArray[np.float64]

    def __post_init__(self) -> None:
        object.__setattr__(self, 'R', np.asarray(self.R, dtype=float).reshape(3, 3))
        object.__setattr__(self, 'p', np.asarray(self.p, dtype=float).reshape(3))

    @classmethod
    def identity(cls) -> Pose:
        return cls(np.eye(3), np.zeros(3))

    @classmethod
    def from_quat(cls, q_xyzw: ArrayLike, p: ArrayLike) -> Pose:
        """From a unit quaternion (x, y, z, w) and a position."""
        return cls(quat_to_matrix(np.asarray(q_xyzw, dtype=float)), np.asarray(p, dtype=float))

    def __matmul__(self, other: Pose) -> Pose:
        return Pose(self.R @ other.R, self.p + self.R @ other.p)

    def inverse(self) -> Pose:
        return Pose(self.R.T, -(self.R.T @ self.p))

    def apply(self, x_b: ArrayLike) -> NDArray[np.float64]:
        """A point of frame b expressed in a."""
        return self.p + self.R @ np.asarray(x_b, dtype=float)

    def rotate(self, v_b: ArrayLike) -> NDArray[np.float64]:
        """A direction of frame b expressed in a."""
        return self.R @ np.asarray(v_b, dtype=float)
