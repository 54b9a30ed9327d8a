"""The renderer a camera config asks for, and the fallback when it cannot start."""
import sys
from typing import Callable

from uav_tilt_sim.camera.gl import GlRenderer
from uav_tilt_sim.camera.renderer import Renderer
from uav_tilt_sim.camera.tiny import TinyRenderer
from uav_tilt_sim.camera.types import CameraConfig


def make_renderer(cam: CameraConfig, warn: Callable[[str], object] | None = None) -> Renderer:
    """The renderer ``cam.renderer`` asks for; TinyRenderer, with one line to ``warn``
    (default: stderr), when the GL renderer cannot start."""
    if cam.renderer == 'gl':
        try:
            return GlRenderer(cam)
        except RuntimeError as err:
            line = f'GL renderer unavailable: {err}; rendering with TinyRenderer (~25 ms a frame)'
            if warn is None:
                print(f'[camera] {line}', file=sys.stderr, flush=True)
            else:
                warn(line)
    return TinyRenderer(cam)
