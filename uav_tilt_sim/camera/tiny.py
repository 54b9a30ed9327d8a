"""PyBullet's TinyRenderer (about 25 ms a frame on a CPU): ``renderer: tiny``, and the
fallback when the GL renderer cannot start.

Draws the physics client's own visual shapes with the pinhole projection of the camera's K.
"""
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from uav_tilt_sim.bullet import pybullet as p
from uav_tilt_sim.camera.types import CameraConfig, Frame, Lighting

if TYPE_CHECKING:
    from uav_tilt_sim.visuals import Scene


# TinyRenderer's image rows come out one pixel above the pinhole model's (measured by
# test_camera), while columns match; the projection compensates.
ROW_OFFSET_PX = 1.0


def projection_matrix(cam: CameraConfig) -> list[float]:
    """OpenGL projection (column-major, 16 floats) reproducing the pinhole model K."""
    w, h, n, f = cam.width, cam.height, cam.near_m, cam.far_m
    cy = cam.cy + ROW_OFFSET_PX
    m = np.array([
        [2 * cam.fx / w, 0.0, 1.0 - 2 * cam.cx / w, 0.0],
        [0.0, 2 * cam.fy / h, 2 * cy / h - 1.0, 0.0],
        [0.0, 0.0, -(f + n) / (f - n), -2 * f * n / (f - n)],
        [0.0, 0.0, -1.0, 0.0],
    ])
    return m.T.reshape(-1).tolist()


def view_matrix(p_cam_map: ArrayLike, R_map_cam: NDArray[np.float64]) -> list[float]:
    """OpenGL view matrix for an optical frame (z forward, x right, y down) in map."""
    eye = np.asarray(p_cam_map, dtype=float)
    forward, down = R_map_cam[:, 2], R_map_cam[:, 1]
    return p.computeViewMatrix(eye.tolist(), (eye + forward).tolist(), (-down).tolist())


def render(client: int, cam: CameraConfig, p_cam_map: ArrayLike,
           R_map_cam: NDArray[np.float64], lighting: Lighting | None = None,
           segmentation: bool = False) -> Frame:
    """Render (rgb uint8 HxWx3, depth float32 HxW metres along the optical axis, seg or None).

    Depth is the optical-frame z of the surface; pixels that see nothing read ``inf``.
    Segmentation, when asked, holds the PyBullet body id per pixel (-1 for background).
    """
    light = lighting or Lighting()
    flags = 0 if segmentation else p.ER_NO_SEGMENTATION_MASK
    _, _, rgba, zbuf, seg = p.getCameraImage(
        cam.width, cam.height, view_matrix(p_cam_map, R_map_cam), projection_matrix(cam),
        lightDirection=list(light.direction), lightColor=list(light.color),
        lightAmbientCoeff=light.ambient, lightDiffuseCoeff=light.diffuse,
        lightSpecularCoeff=light.specular, shadow=0, renderer=p.ER_TINY_RENDERER,
        flags=flags, physicsClientId=client)
    rgb = np.asarray(rgba, dtype=np.uint8).reshape(cam.height, cam.width, 4)[:, :, :3]
    zbuf = np.asarray(zbuf, dtype=np.float64).reshape(cam.height, cam.width)
    n, f = cam.near_m, cam.far_m
    depth = (f * n / (f - (f - n) * zbuf)).astype(np.float32)
    depth[zbuf >= 1.0] = np.inf
    seg_img = np.asarray(seg, dtype=np.int64).reshape(cam.height, cam.width) \
        if segmentation else None
    return np.ascontiguousarray(rgb), depth, seg_img


class TinyRenderer:
    """PyBullet's TinyRenderer behind the renderer interface (draws the client's own
    visual shapes; the scene is not needed)."""

    name = 'tiny'

    def __init__(self, cam: CameraConfig) -> None:
        self.cam = cam

    def render(self, scene: 'Scene', p_cam_map: ArrayLike, R_map_cam: NDArray[np.float64],
               lighting: Lighting | None = None, segmentation: bool = False) -> Frame:
        """As :func:`render`, of the scene's physics client."""
        return render(scene.client, self.cam, p_cam_map, R_map_cam, lighting, segmentation)

    def close(self) -> None:
        """Nothing to release."""
