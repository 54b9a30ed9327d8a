"""The world of a scenario in PyBullet: ground, a (yawed, inclined) wall, textured objects."""
import dataclasses

import numpy as np
from scipy.spatial.transform import Rotation

from uav_tilt_common.geometry import wall_rotation
from uav_tilt_sim import textures
from uav_tilt_sim.bullet import pybullet as p
from uav_tilt_sim.scenario import ObjectConfig, Scenario, WallConfig
from uav_tilt_sim.visuals import QUAD, Scene, Visual, create_static_body

WALL_THICKNESS_M = 0.2
PANEL_THICKNESS_M = 0.01
# A panel's collision box reaches this far behind its face, into the wall. A box that ends
# 1 cm behind its face, as the panel does, pushes a tool sunk past its middle (a tip 1.2 cm
# in radius, 5 N on a wall under 300 N/m) out of its back: the wall then holds the tool in.
PANEL_COLLISION_DEPTH_M = PANEL_THICKNESS_M + WALL_THICKNESS_M / 2
TILE_M = 0.5     # wall tiles (see visuals.Visual)
GROUND_HALF_M = 20.0
GROUND_TILE_M = 2.0
GROUND_TEXTURE_M = 2.0   # the ground texture repeats every 2 m


@dataclasses.dataclass
class ObjectInstance:
    """An inspection object placed on the wall."""

    cls: str
    body: int
    centre_map: np.ndarray      # centre of its front face
    target: bool
    id: str = ''
    poi_map: np.ndarray | None = None   # a target's point of interest on its face


@dataclasses.dataclass
class WorldInfo:
    """Where things are. The wall frame W: z_W = outward surface normal, y_W = up the wall,
    x_W = right as seen from in front; its origin is the surface point at ground level."""

    R_map_wall: np.ndarray
    wall_origin_map: np.ndarray
    wall_body: int
    ground_body: int
    objects: list[ObjectInstance]
    wall_visual: Visual                           # the wall's textured face
    target_poi_map: np.ndarray | None = None      # point of interest on the target's face
    R_map_target: np.ndarray | None = None        # z = surface normal out of the wall
    # id -> (poi_map, R_map_target) of every target
    targets: dict[str, tuple[np.ndarray, np.ndarray]] = dataclasses.field(default_factory=dict)

    def truth_targets(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """What each ground-truth target topic carries (names.ground_truth_target): target
        id ('' the first target) -> (poi_map, R_map_target); empty without a target."""
        if self.target_poi_map is None or self.R_map_target is None:
            return {}
        return {'': (self.target_poi_map, self.R_map_target), **self.targets}

    def body_classes(self) -> dict[int, str]:
        """PyBullet body id -> object class (for segmentation labels)."""
        return {o.body: o.cls for o in self.objects}


def build_world(client: int, scenario: Scenario, texture_rng: np.random.Generator | None = None,
                scene: Scene | None = None) -> WorldInfo:
    """Create ground, wall and objects of ``scenario`` (their visuals in ``scene`` when
    given); returns :class:`WorldInfo`."""
    rng = texture_rng or np.random.default_rng(
        scenario.texture_seed if scenario.texture_seed >= 0 else scenario.seed)
    wall = scenario.wall
    R = wall_rotation(wall.yaw_deg, wall.inclination_deg)
    origin = np.array([wall.position_m[0], wall.position_m[1], 0.0])
    quat = Rotation.from_matrix(R).as_quat().tolist()
    centre = origin + R[:, 1] * wall.height_m / 2 - R[:, 2] * WALL_THICKNESS_M / 2
    col = p.createCollisionShape(
        p.GEOM_BOX, halfExtents=[wall.width_m / 2, wall.height_m / 2, WALL_THICKNESS_M / 2],
        physicsClientId=client)
    # The textured face is the box's only visual: a body without one would be drawn from
    # its collision box, whose front face z-fights with the texture.
    face = Visual(QUAD, (wall.width_m / 2, wall.height_m / 2),
                  texture=textures.wall_texture(rng), position=(0.0, 0.0, WALL_THICKNESS_M / 2),
                  tile_m=TILE_M)
    wall_body = create_static_body(client, scene, face, centre, quat, col)
    _set_contact(client, wall_body, wall)
    objects = [_build_object(client, scene, o, origin, R, quat, rng, wall)
               for o in scenario.objects]
    # drawn last, so that the wall and object textures of a seed stay what they were
    ground = _build_ground(client, scene, rng)
    info = WorldInfo(R, origin, wall_body, ground, objects, wall_visual=face)
    for obj, cfg in zip(objects, scenario.objects):
        if cfg.target:
            du, dv = (np.asarray(textures.POI_UV[cfg.cls]) - 0.5) * textures.OBJECT_SIZE_M
            poi = obj.centre_map + R[:, 0] * du - R[:, 1] * dv
            obj.poi_map = poi
            if info.target_poi_map is None:
                info.target_poi_map, info.R_map_target = poi, R.copy()
            if cfg.id:
                info.targets[cfg.id] = (poi, R.copy())
    return info


def _set_contact(client: int, body: int, wall: WallConfig) -> None:
    p.changeDynamics(body, -1, contactStiffness=wall.stiffness_n_per_m,
                     contactDamping=wall.damping_n_s_per_m, lateralFriction=wall.friction,
                     physicsClientId=client)


def _build_ground(client: int, scene: Scene | None, rng: np.random.Generator) -> int:
    # Tiled, for the same TinyRenderer reason as the wall; without a visual of its own the
    # plane would be drawn from its collision shape with PyBullet's checker texture.
    face = Visual(QUAD, (GROUND_HALF_M, GROUND_HALF_M), texture=textures.ground_texture(rng),
                  tile_m=GROUND_TILE_M, texture_m=GROUND_TEXTURE_M)
    ground = create_static_body(client, scene, face, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0),
                                p.createCollisionShape(p.GEOM_PLANE, physicsClientId=client))
    p.changeDynamics(ground, -1, lateralFriction=0.8, physicsClientId=client)
    return ground


def _build_object(client: int, scene: Scene | None, cfg: ObjectConfig, origin: np.ndarray,
                  R: np.ndarray, quat: list[float], rng: np.random.Generator,
                  wall: WallConfig) -> ObjectInstance:
    half = textures.OBJECT_SIZE_M / 2
    front = origin + R[:, 0] * cfg.u_m + R[:, 1] * cfg.v_m + R[:, 2] * PANEL_THICKNESS_M
    col = p.createCollisionShape(
        p.GEOM_BOX, halfExtents=[half, half, PANEL_COLLISION_DEPTH_M / 2],
        collisionFramePosition=[0, 0, -PANEL_COLLISION_DEPTH_M / 2], physicsClientId=client)
    face = Visual(QUAD, (half, half), texture=textures.object_texture(cfg.cls, rng))
    body = create_static_body(client, scene, face, front, quat, col)
    _set_contact(client, body, wall)
    return ObjectInstance(cfg.cls, body, front, cfg.target, cfg.id)
