"""3D point of interest and surface normal from a depth image (camera optical frame), no rclpy.

Covariance model of :func:`estimate_target_pose` (6x6, order x, y, z, rot x, rot y,
rot z; metres and rad^2, axes of the camera optical frame), by first-order propagation
of independent errors:

- plane normal: sigma^2 * sum_k e_k e_k^T / lambda_k over the two in-plane eigen-pairs of
  the inlier scatter matrix (sigma^2 = residual variance, floored at the sensor noise);
- plane offset at the inlier centroid: sigma^2 / N;
- pixel position of the POI: ``pixel_sigma_px`` in u and v.

The point is the ray through (u, v) cut by the plane, so its error lies along the ray
(offset, normal tilt times the lever arm from the centroid) plus the in-plane shift of
the pixel ray. The orientation error is the normal's tilt, n x dn; rotation about the
normal is a convention, not a measurement, and gets ``UNOBSERVED_VAR_RAD2``. Where the
surface is curved (:func:`_curved_surface`) the point and normal are the curved fit's and
the covariance is the plane's: on a window centred on the POI the slope there is as
uncertain under either model.
"""
import dataclasses

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation
from scipy.special import fdtri

UNOBSERVED_VAR_RAD2 = 1.0e3
_MIN_POINTS = 12
_LMEDS_TRIALS = 64
# The curved fit replaces the plane when an F-test rejects the plane at this level: a plane
# seen through noise takes it once in a thousand windows (and is then fitted as well, only
# a little noisier), a pipe of 0.1 m radius within a few metres every time.
CURVATURE_ALPHA = 1.0e-3


@dataclasses.dataclass(frozen=True)
class CameraIntrinsics:
    """Pinhole intrinsics (pixels) of a width x height image."""

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int


def deproject(u_px: ArrayLike, v_px: ArrayLike, depth_m: ArrayLike,
              K: CameraIntrinsics) -> NDArray[np.float64]:
    """Camera-frame points (..., 3) of pixels (u, v) at depth z (arrays broadcast)."""
    u, v, z = np.broadcast_arrays(np.asarray(u_px, float), np.asarray(v_px, float),
                                  np.asarray(depth_m, float))
    return np.stack([(u - K.cx) / K.fx * z, (v - K.cy) / K.fy * z, z], axis=-1)


def estimate_target_pose(u_px: float, v_px: float, depth_m: np.ndarray, K: CameraIntrinsics,
                         window_px: int = 10, pixel_sigma_px: float = 0.5,
                         depth_sigma_floor_m: float = 1.0e-3, reject_rounds: int = 2
                         ) -> tuple[NDArray[np.float64], NDArray[np.float64],
                                    NDArray[np.float64]] | None:
    """Point ``p_cam_m``, unit normal ``n_cam`` (toward the camera) and 6x6 covariance.

    A plane is fitted (in inverse depth) to the valid depth pixels (finite, > 0) in a
    (2 window_px + 1)^2 window around (u, v), with ``reject_rounds`` rounds of
    residual-based outlier rejection; the point is the ray through (u, v) cut by
    that plane, so a hole at the POI itself does not matter. None without a fit.
    """
    h, w = depth_m.shape
    uc, vc = int(round(u_px)), int(round(v_px))
    x0, x1 = max(uc - window_px, 0), min(uc + window_px + 1, w)
    y0, y1 = max(vc - window_px, 0), min(vc + window_px + 1, h)
    if x0 >= x1 or y0 >= y1:
        return None
    z = depth_m[y0:y1, x0:x1].astype(float)
    vv, uu = np.mgrid[y0:y1, x0:x1]
    valid = np.isfinite(z) & (z > 0)
    pts = deproject(uu[valid], vv[valid], z[valid], K)
    fit = _robust_plane(pts, depth_sigma_floor_m, reject_rounds)
    if fit is None:
        return None
    n, c, inliers, sigma2 = fit
    d = np.array([(u_px - K.cx) / K.fx, (v_px - K.cy) / K.fy, 1.0])
    nd = float(n @ d)
    if nd > -1e-3:
        return None  # ray (almost) parallel to the plane, or the plane behind the camera
    p = d * float(n @ c) / nd
    curved = _curved_surface(inliers, d)
    if curved is not None:
        p, n = curved
    return p, n, _covariance(p, n, c, d, inliers, sigma2, K, pixel_sigma_px)


def _curved_surface(q: NDArray[np.float64], d: NDArray[np.float64]
                    ) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
    """Point and normal (towards the camera) where the ray ``d`` = (a0, b0, 1) meets the
    surface through the points ``q``, when a curved surface explains them better than a
    plane.

    The fits are of inverse depth w over the normalised image coordinates (a, b) = (x/z,
    y/z), as the plane's: a plane is linear there, a pipe or a tank seen square nearly
    quadratic, and one seen aslant needs the cubic terms too (a quadratic leaves a bias in
    the slope there, 2 degrees on a 0.1 m pipe 1 m away). Stereo-like depth noise (growing
    with z^2) is the same everywhere in w. Each higher degree is taken only when an F-test
    against the degree kept so far rejects it at ``CURVATURE_ALPHA``: every term more adds
    variance to the slope. The surface X = (a, b, 1) / w(a, b) has the normal (w_a, w_b,
    w - a w_a - b w_b), the cross product of its two tangents, read at the POI's ray
    (where the fit is centred, so its first three coefficients are w, w_a, w_b there).
    None when the plane is kept or the fit is degenerate.
    """
    da, db = q[:, 0] / q[:, 2] - d[0], q[:, 1] / q[:, 2] - d[1]
    w = 1.0 / q[:, 2]
    A = np.column_stack([np.ones_like(w), da, db, da * da, da * db, db * db,
                         da ** 3, da * da * db, da * db * db, db ** 3])
    kept: tuple[int, float, NDArray[np.float64]] | None = None
    for cols in (3, 6, 10):
        dof = len(w) - cols
        if dof < cols:
            break
        coef, *_ = np.linalg.lstsq(A[:, :cols], w, rcond=None)
        r = A[:, :cols] @ coef - w
        rss = float(r @ r)
        if kept is not None:
            extra = cols - kept[0]
            if not rss > 0.0 or (kept[1] - rss) / extra / (rss / dof) < fdtri(
                    extra, dof, 1.0 - CURVATURE_ALPHA):
                break
        kept = (cols, rss, coef)
    if kept is None or kept[0] == 3:
        return None
    w0, w_a, w_b = kept[2][:3]
    if not w0 > 0.0:
        return None
    normal = np.array([w_a, w_b, w0 - d[0] * w_a - d[1] * w_b])
    return d / w0, -normal / np.linalg.norm(normal)


def _robust_plane(pts: NDArray[np.float64], sigma_floor_m: float, rounds: int
                  ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64],
                             float] | None:
    """(normal toward the camera, a point of the plane at the inliers' centroid, inlier
    points, residual variance) or None.

    A least-median-of-squares seed keeps gross outliers (flying pixels, foreground
    clutter) from tilting the first fit; least squares rounds then refine it. Those fit
    inverse depth, which on a plane m.X = D is linear in the normalised image coordinates
    (1/z = m.(x/z, y/z, 1) / D), because depth noise lies along the rays: a fit across the
    plane (SVD of the points) tilts towards the noise once it nears the window's extent
    (a 21 px window 3 m away, depth noise 0.007 z^2: 28 degrees median against 4).
    """
    if len(pts) < _MIN_POINTS:
        return None
    keep = _lmeds_inliers(pts, sigma_floor_m)
    rays = pts / pts[:, 2:3]                # (x/z, y/z, 1)
    inverse_depth = 1.0 / pts[:, 2]
    for k in range(rounds + 1):
        if keep.sum() < _MIN_POINTS:
            return None
        coef = np.linalg.lstsq(rays[keep], inverse_depth[keep], rcond=None)[0]
        m = coef / np.linalg.norm(coef)     # away from the camera: m.X = offset > 0
        offset = 1.0 / np.linalg.norm(coef)
        if k == rounds:
            break
        keep = _inliers(np.abs(pts @ m - offset), keep, sigma_floor_m)
    q = pts[keep]
    res = q @ m - offset
    c = q.mean(axis=0) - float(res.mean()) * m
    sigma2 = max(float(res @ res) / max(len(q) - 3, 1), sigma_floor_m ** 2)
    return -m, c, q, sigma2


def _inliers(abs_res: NDArray[np.float64], keep: NDArray[np.bool_],
             sigma_floor_m: float) -> NDArray[np.bool_]:
    """Residuals within 3 robust sigmas (MAD over ``keep``, floored at the sensor noise)."""
    scale = max(1.4826 * np.median(abs_res[keep]), sigma_floor_m)
    return abs_res < 3.0 * scale


def _lmeds_inliers(pts: NDArray[np.float64], sigma_floor_m: float,
                   n_trials: int = _LMEDS_TRIALS) -> NDArray[np.bool_]:
    """Inliers of the plane through 3 sampled points with the least median residual."""
    rng = np.random.default_rng(0)  # fixed: the same image gives the same pose
    abs_res = sampled_plane_residuals(pts, rng, n_trials)
    if not len(abs_res):
        return np.zeros(len(pts), bool)
    best = int(np.argmin(np.median(abs_res, axis=1)))
    return _inliers(abs_res[best], np.ones(len(pts), bool), sigma_floor_m)


def sampled_plane_residuals(pts: NDArray[np.float64], rng: np.random.Generator,
                            n_trials: int) -> NDArray[np.float64]:
    """(T, N) distances of the N points to each of T <= ``n_trials`` planes through three
    of them drawn at random (degenerate triples left out)."""
    tri = pts[rng.integers(0, len(pts), (n_trials, 3))]
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    norms = np.linalg.norm(normals, axis=1)
    ok = norms > 1e-12
    normals = normals[ok] / norms[ok, None]
    return np.abs(np.einsum('tk,tnk->tn', normals, pts[None] - tri[ok, None, 0]))


def _covariance(p: NDArray[np.float64], n: NDArray[np.float64], c: NDArray[np.float64],
                d: NDArray[np.float64], q: NDArray[np.float64], sigma2: float,
                K: CameraIntrinsics, pixel_sigma_px: float) -> NDArray[np.float64]:
    dq = q - c
    scatter = dq.T @ dq
    evals, evecs = np.linalg.eigh(scatter)
    cov_n = sum(np.outer(evecs[:, i], evecs[:, i]) / max(evals[i], 1e-12) for i in (1, 2))
    cov_n *= sigma2
    nd = float(n @ d)
    # p = d t with t = n.c / n.d; perturbing the plane moves p along the ray.
    ray = d / nd
    j_p_n = -np.outer(ray, p - c)           # dp / dn
    j_p_off = ray[:, None]                  # dp / d(offset along n at c)
    proj = np.eye(3) - np.outer(d, n) / nd  # keeps the shifted ray on the plane
    t = float(n @ p) / nd
    j_p_uv = t * proj @ np.array([[1.0 / K.fx, 0.0], [0.0, 1.0 / K.fy], [0.0, 0.0]])
    j = np.zeros((6, 6))
    j[:3, :3], j[:3, 3:4], j[:3, 4:] = j_p_n, j_p_off, j_p_uv
    j[3:, :3] = np.cross(np.eye(3), n)     # d(theta) = n x dn
    noise = np.zeros((6, 6))
    noise[:3, :3] = cov_n
    noise[3, 3] = sigma2 / len(q)
    noise[4, 4] = noise[5, 5] = pixel_sigma_px ** 2
    cov = j @ noise @ j.T
    cov[3:, 3:] += UNOBSERVED_VAR_RAD2 * np.outer(n, n)
    return 0.5 * (cov + cov.T)


def pose_quaternion_from_normal(n_cam: ArrayLike) -> NDArray[np.float64]:
    """Quaternion (x, y, z, w) of the target frame: z = n_cam, x = camera x projected on the
    surface (camera y when nearly parallel), y = z cross x (up for a level camera)."""
    z = np.asarray(n_cam, float)
    z = z / np.linalg.norm(z)
    ref = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = ref - (ref @ z) * z
    x /= np.linalg.norm(x)
    return Rotation.from_matrix(np.column_stack([x, np.cross(z, x), z])).as_quat()
