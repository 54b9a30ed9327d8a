"""The world of a scenario in PyBullet: ground, a (yawed, inclined) wall, textured objects."""
import dataclasses
import os
import tempfile

import cv2
import numpy as np
import pybullet as p
from scipy.spatial.transform import Rotation

from uav_tilt_sim import textures

WALL_THICKNESS_M = 0.2
PANEL_THICKNESS_M = 0.01
TILE_M = 0.5     # wall tiles (see _quad_visual)


@dataclasses.dataclass
class ObjectInstance:
    """An inspection object placed on the wall."""

    cls: str
    body: int
    centre_map: np.ndarray      # centre of its front face
    target: bool


@dataclasses.dataclass
class WorldInfo:
    """Where things are. The wall frame W: z_W = outward surface normal, y_W = up the wall,
    x_W = right as seen from in front; its origin is the surface point at ground level."""

    R_map_wall: np.ndarray
    wall_origin_map: np.ndarray
    wall_body: int
    ground_body: int
    objects: list
    target_poi_map: np.ndarray = None      # point of interest on the target's front face
    R_map_target: np.ndarray = None        # z = surface normal out of the wall

    def body_classes(self):
        """PyBullet body id -> object class (for segmentation labels)."""
        return {o.body: o.cls for o in self.objects}


def wall_rotation(yaw_deg, inclination_deg):
    """R_map_wall for a wall faced along heading ``yaw`` with its top leaning away."""
    yaw, inc = np.radians(yaw_deg), np.radians(inclination_deg)
    facing = np.array([np.cos(yaw), np.sin(yaw), 0.0])          # from the vehicle to the wall
    normal = -np.cos(inc) * facing + np.array([0.0, 0.0, np.sin(inc)])
    up = np.sin(inc) * facing + np.array([0.0, 0.0, np.cos(inc)])
    right = np.cross(up, normal)
    return np.column_stack([right, up, normal])


def _quad_visual(client, half_w, half_h, texture_rgb, tmpdir, name, tile_m=None,
                 offset_z=0.0):
    """A textured rectangle facing +z of its frame, ``offset_z`` along it: texture row 0 at
    +y, column 0 at -x.

    Large rectangles are split into tiles of about ``tile_m``: TinyRenderer drops a whole
    triangle when its vertices project far outside the image, which made big walls vanish
    in halves at some camera poses.
    """
    path = os.path.join(tmpdir, name + '.png')
    cv2.imwrite(path, cv2.cvtColor(texture_rgb, cv2.COLOR_RGB2BGR))
    nx = max(1, int(np.ceil(2 * half_w / tile_m))) if tile_m else 1
    ny = max(1, int(np.ceil(2 * half_h / tile_m))) if tile_m else 1
    u, v = np.meshgrid(np.linspace(0.0, 1.0, nx + 1), np.linspace(0.0, 1.0, ny + 1))
    vertices = np.column_stack([(2 * u.ravel() - 1) * half_w, (2 * v.ravel() - 1) * half_h,
                                np.zeros(u.size)])
    corner = (np.arange(ny)[:, None] * (nx + 1) + np.arange(nx)[None, :]).ravel()
    # Two counter-clockwise triangles (seen from +z) per tile.
    indices = np.column_stack([corner, corner + 1, corner + nx + 2,
                               corner, corner + nx + 2, corner + nx + 1]).ravel()
    visual = p.createVisualShape(
        p.GEOM_MESH, vertices=vertices.tolist(), indices=indices.tolist(),
        uvs=np.column_stack([u.ravel(), v.ravel()]).tolist(),
        normals=[[0, 0, 1]] * len(vertices), visualFramePosition=[0, 0, offset_z],
        physicsClientId=client)
    return visual, p.loadTexture(path, physicsClientId=client)


def build_world(client, scenario, texture_rng=None):
    """Create ground, wall and objects of ``scenario``; returns :class:`WorldInfo`."""
    rng = texture_rng or np.random.default_rng(
        scenario.texture_seed if scenario.texture_seed >= 0 else scenario.seed)
    wall = scenario.wall
    R = wall_rotation(wall.yaw_deg, wall.inclination_deg)
    origin = np.array([wall.position_m[0], wall.position_m[1], 0.0])
    quat = Rotation.from_matrix(R).as_quat().tolist()
    with tempfile.TemporaryDirectory() as tmpdir:
        ground = _build_ground(client)
        centre = origin + R[:, 1] * wall.height_m / 2 - R[:, 2] * WALL_THICKNESS_M / 2
        col = p.createCollisionShape(
            p.GEOM_BOX, halfExtents=[wall.width_m / 2, wall.height_m / 2, WALL_THICKNESS_M / 2],
            physicsClientId=client)
        # The textured face is the box's only visual: a body without one would be drawn from
        # its collision box, whose front face z-fights with the texture.
        vis, tex = _quad_visual(client, wall.width_m / 2, wall.height_m / 2,
                                textures.wall_texture(rng), tmpdir, 'wall', TILE_M,
                                offset_z=WALL_THICKNESS_M / 2)
        wall_body = p.createMultiBody(0.0, col, vis, centre.tolist(), quat,
                                      physicsClientId=client)
        p.changeVisualShape(wall_body, -1, textureUniqueId=tex, physicsClientId=client)
        _set_contact(client, wall_body, wall)
        objects = [_build_object(client, o, origin, R, quat, rng, tmpdir, i, wall)
                   for i, o in enumerate(scenario.objects)]
    info = WorldInfo(R, origin, wall_body, ground, objects)
    for obj, cfg in zip(objects, scenario.objects):
        if cfg.target:
            du, dv = (np.asarray(textures.POI_UV[cfg.cls]) - 0.5) * textures.OBJECT_SIZE_M
            info.target_poi_map = obj.centre_map + R[:, 0] * du - R[:, 1] * dv
            info.R_map_target = R.copy()
    return info


def _set_contact(client, body, wall):
    p.changeDynamics(body, -1, contactStiffness=wall.stiffness_n_per_m,
                     contactDamping=wall.damping_n_s_per_m, lateralFriction=wall.friction,
                     physicsClientId=client)


def _build_ground(client):
    # Collision only: TinyRenderer does not clip triangles at the near plane, so a ground
    # mesh passing under the camera was drawn across the image.
    ground = p.createMultiBody(0.0, p.createCollisionShape(p.GEOM_PLANE, physicsClientId=client),
                               -1, [0, 0, 0], physicsClientId=client)
    p.changeDynamics(ground, -1, lateralFriction=0.8, physicsClientId=client)
    return ground


def _build_object(client, cfg, origin, R, quat, rng, tmpdir, index, wall):
    half = textures.OBJECT_SIZE_M / 2
    front = origin + R[:, 0] * cfg.u_m + R[:, 1] * cfg.v_m + R[:, 2] * PANEL_THICKNESS_M
    col = p.createCollisionShape(
        p.GEOM_BOX, halfExtents=[half, half, PANEL_THICKNESS_M / 2],
        collisionFramePosition=[0, 0, -PANEL_THICKNESS_M / 2], physicsClientId=client)
    vis, tex = _quad_visual(client, half, half, textures.object_texture(cfg.cls, rng),
                            tmpdir, f'object{index}')
    body = p.createMultiBody(0.0, col, vis, front.tolist(), quat, physicsClientId=client)
    p.changeVisualShape(body, -1, textureUniqueId=tex, physicsClientId=client)
    _set_contact(client, body, wall)
    return ObjectInstance(cfg.cls, body, front, cfg.target)
