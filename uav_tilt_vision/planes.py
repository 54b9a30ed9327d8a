"""The large planes of a depth image (walls, the ground), camera optical frame. No rclpy.

RANSAC on a sparse grid of the image's depth samples, one plane after another: the one
with the most samples within the depth noise is refined by least squares, taken out, and
the search goes on in what is left. The noise of a stereo-like depth grows with the range
squared, and so does the band a sample must lie in.
"""
import dataclasses
from typing import Any

import numpy as np
from numpy.typing import NDArray

from uav_tilt_common.config import param
from uav_tilt_common.planes import Plane
from uav_tilt_vision.target_pose import CameraIntrinsics, deproject, sampled_plane_residuals

_TRIALS = 64
_REFINE_ROUNDS = 2


@dataclasses.dataclass
class PlaneConfig:
    """Parameters of :func:`find_planes`."""

    every: int = param(5, lo=0, hi=1000, doc='look for planes every N frames (0 = off)')
    stride_px: int = param(8, lo=1, hi=64, doc='depth grid step of the plane search')
    max_range_m: float = param(8.0, lo=0.5, hi=100.0, unit='m',
                               doc='depth samples beyond this are left out')
    max_planes: int = param(2, lo=1, hi=8, doc='planes sought per frame')
    min_share: float = param(0.1, lo=0.0, hi=1.0,
                             doc="a plane needs this share of the frame's samples")
    band_m: float = param(0.03, lo=0.001, hi=1.0, unit='m',
                          doc='a sample lies on a plane within band_m + band_per_m2 z^2')
    band_per_m2: float = param(0.012, lo=0.0, hi=1.0, unit='1/m',
                               doc='growth of the band with range squared')


def find_planes(depth_m: NDArray[np.floating[Any]], K: CameraIntrinsics,
                config: PlaneConfig | None = None) -> list[Plane]:
    """The planes of a depth image (metres; inf or NaN = nothing seen), largest first."""
    cfg = config or PlaneConfig()
    s = cfg.stride_px
    vv, uu = np.mgrid[s // 2:depth_m.shape[0]:s, s // 2:depth_m.shape[1]:s]
    z = depth_m[vv, uu].astype(float)
    with np.errstate(invalid='ignore'):
        valid = np.isfinite(z) & (z > 0) & (z <= cfg.max_range_m)
    pts = deproject(uu[valid], vv[valid], z[valid], K)
    band = cfg.band_m + cfg.band_per_m2 * pts[:, 2] ** 2
    need = max(cfg.min_share * z.size, 3)
    rng = np.random.default_rng(0)      # fixed: the same image gives the same planes
    planes: list[Plane] = []
    while len(planes) < cfg.max_planes and len(pts) >= need:
        on = _ransac(pts, band, rng)
        if on.sum() < need:
            break
        n, c, on = _refine(pts, band, on)
        if on.sum() < need:
            break
        planes.append(Plane(c, n, float(on.sum() / z.size)))
        pts, band = pts[~on], band[~on]
    return planes


def _ransac(pts: NDArray[np.float64], band: NDArray[np.float64],
            rng: np.random.Generator) -> NDArray[np.bool_]:
    """Samples on the plane through three sampled points that has the most of them."""
    on = sampled_plane_residuals(pts, rng, _TRIALS) <= band
    if not len(on):
        return np.zeros(len(pts), bool)
    return on[int(np.argmax(on.sum(axis=1)))]


def _refine(pts: NDArray[np.float64], band: NDArray[np.float64], on: NDArray[np.bool_]
            ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
    """Least-squares plane of the samples ``on`` (normal towards the camera, centroid) and
    the samples within its band, a few rounds."""
    for _ in range(_REFINE_ROUNDS):
        q = pts[on]
        c = q.mean(axis=0)
        n = np.linalg.svd(q - c, full_matrices=False)[2][2]
        on = np.abs((pts - c) @ n) <= band
        if on.sum() < 3:
            break
    c = pts[on].mean(axis=0) if on.any() else c
    return (-n if n @ c > 0 else n), c, on
