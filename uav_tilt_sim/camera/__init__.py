"""Eye-in-hand RGB-D camera: pinhole intrinsics, two headless renderers, metric depth.

``renderer: gl`` (the default) draws the scene with OpenGL on EGL
(:mod:`uav_tilt_sim.camera.gl`, about 1-2 ms a frame on a CPU); ``tiny`` is PyBullet's
TinyRenderer (:mod:`uav_tilt_sim.camera.tiny`, about 25 ms), which is also taken, with one
warning, when GL cannot start. Both give the same pinhole projection, depth and shading,
behind one interface (:class:`Renderer`).
"""
from uav_tilt_sim.camera.factory import make_renderer
from uav_tilt_sim.camera.renderer import Renderer, render_with
from uav_tilt_sim.camera.tiny import TinyRenderer
from uav_tilt_sim.camera.types import CameraConfig, Frame, Lighting

__all__ = ['CameraConfig', 'Frame', 'Lighting', 'Renderer', 'TinyRenderer', 'make_renderer',
           'render_with']
