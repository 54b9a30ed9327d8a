"""Eye-in-hand RGB-D camera: pinhole intrinsics, two headless renderers, metric depth.

``renderer: gl`` (the default) draws the scene with OpenGL on EGL
(:mod:`uav_tilt_sim.gl_renderer`, about 1-2 ms a frame on a CPU); ``tiny`` is PyBullet's
TinyRenderer (about 25 ms), which is also taken, with one warning, when GL cannot start.
Both give the same pinhole projection, depth and shading.
"""
import dataclasses
import sys
from typing import TYPE_CHECKING, Callable, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from uav_tilt_common.config import param
from uav_tilt_sim.bullet import pybullet as p

if TYPE_CHECKING:
    from uav_tilt_sim.gl_renderer import GlRenderer
    from uav_tilt_sim.visuals import Scene

# what a renderer returns: rgb uint8 (H, W, 3), depth float32 (H, W) metres, seg or None
Frame = tuple[NDArray[np.uint8], NDArray[np.float32], NDArray[np.int64] | None]


@dataclasses.dataclass
class CameraConfig:
    """Pinhole intrinsics in pixels; near/far clip planes in metres."""

    width: int = param(320, lo=16, hi=1920)
    height: int = param(240, lo=16, hi=1080)
    fx: float = param(277.0, lo=10.0, hi=5000.0)
    fy: float = param(277.0, lo=10.0, hi=5000.0)
    cx: float = param(160.0, lo=0.0, hi=1920.0)
    cy: float = param(120.0, lo=0.0, hi=1080.0)
    near_m: float = param(0.03, lo=0.001, hi=1.0)
    far_m: float = param(12.0, lo=1.0, hi=100.0)
    rate_hz: float = param(30.0, lo=1.0, hi=120.0)
    renderer: str = param('gl', choices=('gl', 'tiny'))

    def k_matrix(self) -> NDArray[np.float64]:
        """3x3 intrinsic matrix K."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])


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


@dataclasses.dataclass
class Lighting:
    """TinyRenderer light: direction (map), colour and Phong coefficients."""

    direction: Sequence[float] = (1.0, -0.5, 2.0)
    color: Sequence[float] = (1.0, 1.0, 1.0)
    ambient: float = 0.55
    diffuse: float = 0.45
    specular: float = 0.05


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


def make_renderer(cam: CameraConfig, warn: Callable[[str], object] | None = None
                  ) -> 'GlRenderer | TinyRenderer':
    """The renderer ``cam.renderer`` asks for; TinyRenderer, with one line to ``warn``
    (default: stderr), when the GL renderer cannot start."""
    if cam.renderer == 'gl':
        from uav_tilt_sim.gl_renderer import GlRenderer
        try:
            return GlRenderer(cam)
        except RuntimeError as err:
            line = f'GL renderer unavailable: {err}; rendering with TinyRenderer (~25 ms a frame)'
            if warn is None:
                print(f'[camera] {line}', file=sys.stderr, flush=True)
            else:
                warn(line)
    return TinyRenderer(cam)


def render_with(renderer: 'GlRenderer | TinyRenderer', scene: 'Scene', p_cam_map: ArrayLike,
                R_map_cam: NDArray[np.float64], lighting: Lighting | None = None,
                segmentation: bool = False) -> Frame:
    """``renderer.render`` with the default lighting when none is given."""
    return renderer.render(scene, p_cam_map, R_map_cam, lighting or Lighting(), segmentation)
