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


def _quad_visual(client, half_w, half_h, texture_rgb, tmpdir, name):
    """A textured rectangle facing +z of its frame: texture row 0 at +y, column 0 at -x."""
    path = os.path.join(tmpdir, name + '.png')
    cv2.imwrite(path, cv2.cvtColor(texture_rgb, cv2.COLOR_RGB2BGR))
    vertices = [[-half_w, half_h, 0], [half_w, half_h, 0], [half_w, -half_h, 0],
                [-half_w, -half_h, 0]]
    visual = p.createVisualShape(
        p.GEOM_MESH, vertices=vertices, indices=[0, 2, 1, 0, 3, 2],
        uvs=[[0, 1], [1, 1], [1, 0], [0, 0]], normals=[[0, 0, 1]] * 4,
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
        ground = _build_ground(client, rng, tmpdir)
        centre = origin + R[:, 1] * wall.height_m / 2 - R[:, 2] * WALL_THICKNESS_M / 2
        col = p.createCollisionShape(
            p.GEOM_BOX, halfExtents=[wall.width_m / 2, wall.height_m / 2, WALL_THICKNESS_M / 2],
            physicsClientId=client)
        vis, tex = _quad_visual(client, wall.width_m / 2, wall.height_m / 2,
                                textures.wall_texture(rng), tmpdir, 'wall')
        # The visual quad is offset to the front face by its own body frame: a second body.
        wall_body = p.createMultiBody(0.0, col, -1, centre.tolist(), quat,
                                      physicsClientId=client)
        face = p.createMultiBody(0.0, -1, vis, (centre + R[:, 2] * WALL_THICKNESS_M / 2)
                                 .tolist(), quat, physicsClientId=client)
        p.changeVisualShape(face, -1, textureUniqueId=tex, physicsClientId=client)
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


def _build_ground(client, rng, tmpdir):
    half = 25.0
    col = p.createCollisionShape(p.GEOM_PLANE, physicsClientId=client)
    vis, tex = _quad_visual(client, half, half, textures.ground_texture(rng), tmpdir, 'ground')
    ground = p.createMultiBody(0.0, col, vis, [0, 0, 0], physicsClientId=client)
    p.changeVisualShape(ground, -1, textureUniqueId=tex, physicsClientId=client)
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
