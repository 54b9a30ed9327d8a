"""RGB-D-segmentation camera on OpenGL (moderngl, headless EGL; Mesa's llvmpipe on a CPU).

Draws the :class:`~uav_tilt_sim.visuals.Scene` of a physics client with the poses PyBullet
has for its bodies, in one pass into three attachments: colour, metric depth (optical-frame
z, float32) and the body id. The shading is TinyRenderer's, so that both renderers make the
same images of the same world (every surface is closed, or seen from its front only: the
faces turned away are not drawn): texel colour times (ambient + diffuse (n . l) + specular
(r_z)^2) with the light colour on the last two, nearest-texel sampling, no shadows. The
lighting is computed per vertex: exact on the flat faces this world is made of.
"""
import os
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from uav_tilt_common.geometry import quat_to_matrix
from uav_tilt_sim.bullet import pybullet as p
from uav_tilt_sim.camera.types import CameraConfig, Frame, Lighting

if TYPE_CHECKING:
    from uav_tilt_sim.visuals import Scene, Visual

_VERTEX = """
#version 330
uniform mat4 mvp;
uniform mat3 normal_to_map;
uniform vec3 light_dir;
uniform vec3 light_color;
uniform vec3 coeffs;   // ambient, diffuse, specular
in vec3 in_position;
in vec3 in_normal;
in vec2 in_uv;
out vec3 v_intensity;
out vec2 v_uv;
out float v_depth;
void main() {
    gl_Position = mvp * vec4(in_position, 1.0);
    // TinyRenderer's Phong terms; the specular one uses map z, not the view direction
    vec3 n = normalize(normal_to_map * in_normal);
    vec3 r = normalize(2.0 * dot(n, light_dir) * n - light_dir);
    float specular = pow(max(r.z, 0.0), 2.0);
    float diffuse = max(dot(n, light_dir), 0.0);
    v_intensity = coeffs.x + (coeffs.y * diffuse + coeffs.z * specular) * light_color;
    v_uv = in_uv;
    v_depth = gl_Position.w;    // the optical-frame z of the point
}
"""

_FRAGMENT = """
#version 330
uniform sampler2D texture0;
uniform bool textured;
uniform vec4 rgba;
uniform int body_id;
in vec3 v_intensity;
in vec2 v_uv;
in float v_depth;
layout(location = 0) out vec4 out_color;
layout(location = 1) out float out_depth;
layout(location = 2) out int out_body;
void main() {
    vec3 texel = textured ? texture(texture0, vec2(v_uv.x, 1.0 - v_uv.y)).rgb : vec3(1.0);
    vec3 c = floor(texel * 255.0 + 0.5) * rgba.rgb * v_intensity;
    out_color = vec4(min(floor(c), 255.0) / 255.0, 1.0);
    out_depth = v_depth;        // 0 where nothing is drawn (the near plane is nearer)
    out_body = body_id + 1;     // 0 where nothing is drawn
}
"""


_ALL = ((True,) * 4,) * 3
_COLOR_ONLY = ((True,) * 4, (False,) * 4, (False,) * 4)
_DATA_ONLY = ((False,) * 4, (True,) * 4, (True,) * 4)


class GlRenderer:
    """Renders :class:`~uav_tilt_sim.visuals.Scene` s of PyBullet clients at one camera config.

    Raises RuntimeError (with the reason) when no OpenGL 3.3 context can be made.
    """

    def __init__(self, cam: CameraConfig) -> None:
        # llvmpipe rasterises in the calling thread: on two cores its worker threads only
        # add hand-overs (measured: 2.5 ms a frame with none, 4 ms with its default two)
        os.environ.setdefault('LP_NUM_THREADS', '0')
        try:
            import moderngl
            self.ctx = moderngl.create_standalone_context(backend='egl')
        except Exception as exc:  # noqa: BLE001 - any failure means: no GL here
            raise RuntimeError(f'no headless OpenGL context ({exc})') from exc
        self._gl = moderngl
        self.cam = cam
        ctx = self.ctx
        self.program = ctx.program(vertex_shader=_VERTEX, fragment_shader=_FRAGMENT)
        w, h = cam.width, cam.height
        self._color = ctx.renderbuffer((w, h), 4)
        self._depth = ctx.renderbuffer((w, h), 1, dtype='f4')
        self._body = ctx.renderbuffer((w, h), 1, dtype='i4')
        self.fbo = ctx.framebuffer([self._color, self._depth, self._body],
                                   ctx.depth_renderbuffer((w, h)))
        self._projection = _projection(cam)
        # id(visual) -> (visual, vao, texture or None)
        self._meshes: dict[int, tuple[Visual, Any, Any]] = {}
        # body -> [(link, pose)] of static bodies
        self._static: dict[int, list[tuple[int, NDArray[np.float64]]]] = {}
        # (version, client) of the scene the caches are for
        self._drawn: tuple[int, int] | None = None
        self._uniforms = {name: self.program[name] for name in (
            'light_dir', 'light_color', 'coeffs', 'normal_to_map', 'mvp', 'body_id', 'rgba',
            'textured')}
        self.name = 'gl'

    def close(self) -> None:
        """Release the GL context."""
        if self.ctx is not None:
            self.ctx.release()
            self.ctx = None

    def _mesh(self, visual: 'Visual') -> tuple['Visual', Any, Any]:
        entry = self._meshes.get(id(visual))
        if entry is not None and entry[0] is visual:
            return entry
        vertices, normals, uvs, triangles = visual.mesh()
        data = np.hstack([vertices, normals, uvs]).astype('f4')
        vbo = self.ctx.buffer(data.tobytes())
        ibo = self.ctx.buffer(triangles.astype('i4').tobytes())
        vao = self.ctx.vertex_array(self.program, [(vbo, '3f 3f 2f', 'in_position',
                                                    'in_normal', 'in_uv')], ibo)
        texture = None
        if visual.texture is not None:
            img = np.ascontiguousarray(visual.texture, dtype=np.uint8)
            texture = self.ctx.texture((img.shape[1], img.shape[0]), 3, img.tobytes())
            texture.filter = (self._gl.NEAREST, self._gl.NEAREST)
            texture.repeat_x = texture.repeat_y = True
        entry = (visual, vao, texture)
        self._meshes[id(visual)] = entry
        return entry

    def _release_unused(self, scene: 'Scene') -> None:
        alive = {id(v) for body in scene.bodies.values() for vs in body.links.values()
                 for v in vs}
        for key in [k for k in self._meshes if k not in alive]:
            _, vao, texture = self._meshes.pop(key)
            vao.release()
            if texture is not None:
                texture.release()

    def _poses(self, scene: 'Scene') -> list[tuple[int, int, NDArray[np.float64]]]:
        """[(body, link, 4x4 pose in map)] of every drawn link; static ones are cached."""
        client = scene.client
        out: list[tuple[int, int, NDArray[np.float64]]] = []
        for body, entry in scene.bodies.items():
            cached = self._static.get(body) if entry.static else None
            if cached is None:
                cached = [(link, _link_matrix(client, body, link)) for link in entry.links]
                if entry.static:
                    self._static[body] = cached
            out.extend((body, link, pose) for link, pose in cached)
        return out

    def render(self, scene: 'Scene', p_cam_map: ArrayLike, R_map_cam: ArrayLike,
               lighting: Lighting, segmentation: bool = False) -> Frame:
        """(rgb uint8 HxWx3, depth float32 HxW [m] along the optical axis, seg or None).

        Depth is ``inf`` and seg -1 where nothing is seen.
        """
        if (scene.version, scene.client) != self._drawn:
            self._release_unused(scene)
            self._static.clear()
            self._drawn = (scene.version, scene.client)
        view_projection = self._projection @ _view_matrix(p_cam_map, R_map_cam)
        light = np.asarray(lighting.direction, dtype=float)
        self.fbo.use()
        # Faces turned away from the camera are hidden behind the others of their closed
        # surface, so they are not drawn (half the rasterising; the images are the same).
        # The projection flips y, so the turned-away faces wind as GL's 'front' ones.
        self.ctx.cull_face = 'front'
        self.ctx.enable(self._gl.DEPTH_TEST | self._gl.CULL_FACE)
        # white where nothing is drawn, as TinyRenderer; depth and body 0 there
        self.fbo.color_mask = _COLOR_ONLY
        self.fbo.clear(1.0, 1.0, 1.0, 1.0, depth=1.0)
        self.fbo.color_mask = _DATA_ONLY
        self.fbo.clear(0.0, 0.0, 0.0, 0.0)
        self.fbo.color_mask = _ALL
        prog = self._uniforms
        prog['light_dir'].value = tuple(light / np.linalg.norm(light))
        prog['light_color'].value = tuple(float(c) for c in lighting.color)
        prog['coeffs'].value = (lighting.ambient, lighting.diffuse, lighting.specular)
        for body, link, pose in self._poses(scene):
            prog['normal_to_map'].write(pose[:3, :3].T.astype('f4').tobytes())
            prog['mvp'].write((view_projection @ pose).T.astype('f4').tobytes())
            prog['body_id'].value = body
            for visual in scene.bodies[body].links[link]:
                _, vao, texture = self._mesh(visual)
                prog['rgba'].value = visual.rgba
                prog['textured'].value = texture is not None
                if texture is not None:
                    texture.use(0)
                vao.render()
        return self._read(segmentation)

    def _read(self, segmentation: bool) -> Frame:
        w, h = self.cam.width, self.cam.height
        # the projection draws row 0 at the top, so the buffers read out in image order
        rgb = np.frombuffer(self.fbo.read(components=3, attachment=0), np.uint8)
        depth = np.frombuffer(self.fbo.read(components=1, attachment=1, dtype='f4'),
                              np.float32).reshape(h, w).copy()
        depth[depth == 0.0] = np.inf
        seg = None
        if segmentation:
            seg = np.frombuffer(self.fbo.read(components=1, attachment=2, dtype='i4'),
                                np.int32).reshape(h, w) - np.int64(1)
        return rgb.reshape(h, w, 3).copy(), depth, seg


def _view_matrix(p_cam_map: ArrayLike, R_map_cam: ArrayLike) -> NDArray[np.float64]:
    """map -> GL eye (x right, y up, z backwards) for an optical frame (x right, y down)."""
    R_eye_map = np.diag([1.0, -1.0, -1.0]) @ np.asarray(R_map_cam).T
    view = np.eye(4)
    view[:3, :3] = R_eye_map
    view[:3, 3] = -R_eye_map @ np.asarray(p_cam_map, dtype=float)
    return view


def _projection(cam: CameraConfig) -> NDArray[np.float64]:
    """GL projection of the pinhole K with pixel centres at integer pixel coordinates."""
    w, h, n, f = cam.width, cam.height, cam.near_m, cam.far_m
    # window x = u + 1/2 for u = fx X/Z + cx, and window y = v + 1/2 for v = fy Y/Z + cy:
    # GL's window rows count up from the first row in memory, so memory holds the image
    # top row first (the eye frame's y is up, hence the sign of the second row)
    return np.array([
        [2 * cam.fx / w, 0.0, 1.0 - 2 * (cam.cx + 0.5) / w, 0.0],
        [0.0, -2 * cam.fy / h, 1.0 - 2 * (cam.cy + 0.5) / h, 0.0],
        [0.0, 0.0, -(f + n) / (f - n), -2 * f * n / (f - n)],
        [0.0, 0.0, -1.0, 0.0],
    ])


def _link_matrix(client: int, body: int, link: int) -> NDArray[np.float64]:
    """4x4 pose in map of a body's base frame (link -1) or of one of its link frames."""
    if link < 0:
        pos, quat = p.getBasePositionAndOrientation(body, physicsClientId=client)
        # PyBullet's base pose is its centre of mass; visuals sit in the base link frame
        info = p.getDynamicsInfo(body, -1, physicsClientId=client)
        pos, quat = p.multiplyTransforms(pos, quat, *p.invertTransform(info[3], info[4]))
    else:
        state = p.getLinkState(body, link, computeForwardKinematics=True,
                               physicsClientId=client)
        pos, quat = state[4], state[5]
    m = np.eye(4)
    m[:3, :3] = quat_to_matrix(quat)
    m[:3, 3] = pos
    return m
