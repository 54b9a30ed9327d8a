"""The renderer interface: what the plant and the data set generator ask of a renderer."""
from typing import TYPE_CHECKING, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from uav_tilt_sim.camera.types import Frame, Lighting

if TYPE_CHECKING:
    from uav_tilt_sim.visuals import Scene


class Renderer(Protocol):
    """Draws the scene of a physics client at one camera config."""

    name: str   # 'gl' or 'tiny': which one the plant reports it draws with

    def render(self, scene: 'Scene', p_cam_map: ArrayLike, R_map_cam: NDArray[np.float64],
               lighting: Lighting, segmentation: bool = False) -> Frame:
        """(rgb uint8 HxWx3, depth float32 HxW [m] along the optical axis, seg or None) of
        the optical frame (z forward, x right, y down) at ``p_cam_map``, ``R_map_cam``.

        Depth is ``inf`` and seg (the PyBullet body id per pixel) -1 where nothing is seen.
        """
        ...

    def close(self) -> None:
        """Release what the renderer holds (a GL context)."""
        ...


def render_with(renderer: Renderer, scene: 'Scene', p_cam_map: ArrayLike,
                R_map_cam: NDArray[np.float64], lighting: Lighting | None = None,
                segmentation: bool = False) -> Frame:
    """``renderer.render`` with the default lighting when none is given."""
    return renderer.render(scene, p_cam_map, R_map_cam, lighting or Lighting(), segmentation)
