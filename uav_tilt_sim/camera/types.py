"""What both renderers share: the camera's intrinsics, the light, the frame they return."""
import dataclasses
from typing import Sequence

import numpy as np
from numpy.typing import NDArray

from uav_tilt_common.config import param

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


@dataclasses.dataclass
class Lighting:
    """TinyRenderer's light, which the GL renderer reproduces: direction (map), colour and
    Phong coefficients."""

    direction: Sequence[float] = (1.0, -0.5, 2.0)
    color: Sequence[float] = (1.0, 1.0, 1.0)
    ambient: float = 0.55
    diffuse: float = 0.45
    specular: float = 0.05
