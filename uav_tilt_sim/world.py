"""The world of a scenario in PyBullet: ground, its structures (a yawed, inclined wall;
boxes, cylinders, meshes), textured objects on them."""
import dataclasses

import numpy as np
from scipy.spatial.transform import Rotation

from uav_tilt_sim import textures
from uav_tilt_sim.bullet import pybullet as p
from uav_tilt_sim.scenario import ObjectConfig, Scenario, world_geometry
from uav_tilt_sim.structure_visuals import (box_arrays, cylinder_arrays, mesh_arrays,
                                            patch_arrays)
from uav_tilt_sim.structures import (BOX, CYLINDER, WALL, WALL_THICKNESS_M, Placement,
                                     Structure, StructureConfig)
from uav_tilt_sim.visuals import MESH, QUAD, Scene, Visual, create_static_body

PANEL_THICKNESS_M = 0.01
# A panel's collision box reaches this far behind its face, into the wall. A box that ends
# 1 cm behind its face, as the panel does, pushes a tool sunk past its middle (a tip 1.2 cm
# in radius, 5 N on a wall under 300 N/m) out of its back: the wall then holds the tool in.
PANEL_COLLISION_DEPTH_M = PANEL_THICKNESS_M + WALL_THICKNESS_M / 2
TILE_M = 0.5     # wall tiles (see visuals.Visual)
# a structure other than a wall repeats its texture every this many metres (a wall's spans
# its face once)
TEXTURE_M = 2.0
# Bullet grows a convex hull by this margin: a hull built this much inside its face
# collides at the face
HULL_MARGIN_M = 0.001
GROUND_HALF_M = 20.0
GROUND_TILE_M = 2.0
GROUND_TEXTURE_M = 2.0   # the ground texture repeats every 2 m


@dataclasses.dataclass
class StructureInstance:
    """A structure built: its body, geometry and drawn surface."""

    id: str
    kind: str
    body: int
    geometry: Structure
    visual: Visual
    body_position_map: np.ndarray     # its body's origin (its orientation is geometry.R)


@dataclasses.dataclass
class ObjectInstance:
    """An inspection object placed on a structure."""

    cls: str
    body: int
    centre_map: np.ndarray      # centre of its front face
    target: bool
    id: str = ''
    poi_map: np.ndarray | None = None   # a target's point of interest on its face
    # its surface frame (structures.Placement): z the outward normal at its centre
    R_map_surface: np.ndarray = dataclasses.field(default_factory=lambda: np.eye(3))
    on: str = ''                # the id of its structure


@dataclasses.dataclass
class WorldInfo:
    """Where things are. The wall frame W (of the first wall; in a world without one, the
    first target's surface frame): z_W = outward surface normal, y_W = up the wall, x_W =
    right as seen from in front; its origin is the surface point at ground level (the
    surface point under the target's centre)."""

    R_map_wall: np.ndarray
    wall_origin_map: np.ndarray
    wall_body: int                                # the first structure's
    ground_body: int
    objects: list[ObjectInstance]
    wall_visual: Visual                           # the first structure's textured surface
    target_poi_map: np.ndarray | None = None      # point of interest on the target's face
    R_map_target: np.ndarray | None = None        # z = surface normal out of the wall
    # id -> (poi_map, R_map_target) of every target
    targets: dict[str, tuple[np.ndarray, np.ndarray]] = dataclasses.field(default_factory=dict)
    structures: list[StructureInstance] = dataclasses.field(default_factory=list)

    def truth_targets(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """What each ground-truth target topic carries (names.ground_truth_target): target
        id ('' the first target) -> (poi_map, R_map_target); empty without a target."""
        if self.target_poi_map is None or self.R_map_target is None:
            return {}
        return {'': (self.target_poi_map, self.R_map_target), **self.targets}

    def body_classes(self) -> dict[int, str]:
        """PyBullet body id -> object class (for segmentation labels)."""
        return {o.body: o.cls for o in self.objects}

    def reaches_into(self, point_map: np.ndarray) -> bool:
        """Whether ``point_map`` lies in a structure, or behind a wall's face within its
        outline (through it: the wall's thickness is no limit)."""
        for s in self.structures:
            if s.kind == WALL:
                c = s.geometry.cfg
                u, v, out = s.geometry.local(point_map)[0]
                if out < 0.0 and abs(u) <= c.width_m / 2 and 0.0 <= v <= c.height_m:
                    return True
            elif s.geometry.contains(point_map)[0]:
                return True
        return False


def build_world(client: int, scenario: Scenario, texture_rng: np.random.Generator | None = None,
                scene: Scene | None = None) -> WorldInfo:
    """Create ground, structures and objects of ``scenario`` (their visuals in ``scene``
    when given); returns :class:`WorldInfo`."""
    rng = texture_rng or np.random.default_rng(
        scenario.texture_seed if scenario.texture_seed >= 0 else scenario.seed)
    geometry, placed = world_geometry(scenario)
    structures = [_build_structure(client, scene, g, rng) for g in geometry]
    objects = [_build_object(client, scene, cfg, placement, geometry[k].cfg, rng)
               for cfg, (k, placement) in zip(scenario.objects, placed)]
    # drawn last, so that the wall and object textures of a seed stay what they were
    ground = _build_ground(client, scene, rng)
    for obj, cfg in zip(objects, scenario.objects):
        if cfg.target:
            du, dv = (np.asarray(textures.POI_UV[cfg.cls]) - 0.5) * textures.OBJECT_SIZE_M
            R = obj.R_map_surface
            obj.poi_map = obj.centre_map + R[:, 0] * du - R[:, 1] * dv
    first = structures[0]
    R_wall, origin = _wall_frame(structures, objects)
    info = WorldInfo(R_wall, origin, first.body, ground, objects, wall_visual=first.visual,
                     structures=structures)
    for obj in objects:
        if obj.target and obj.poi_map is not None:
            if info.target_poi_map is None:
                info.target_poi_map, info.R_map_target = obj.poi_map, obj.R_map_surface.copy()
            if obj.id:
                info.targets[obj.id] = (obj.poi_map, obj.R_map_surface.copy())
    return info


def _wall_frame(structures: list[StructureInstance], objects: list[ObjectInstance]
                ) -> tuple[np.ndarray, np.ndarray]:
    wall = next((s for s in structures if s.kind == WALL), None)
    if wall is not None:
        return wall.geometry.R, wall.geometry.position
    target = next((o for o in objects if o.target), objects[0] if objects else None)
    if target is not None:      # the surface under it (its face is a panel proud of it)
        R = target.R_map_surface
        return R.copy(), target.centre_map - R[:, 2] * PANEL_THICKNESS_M
    return structures[0].geometry.R, structures[0].geometry.position


def _set_contact(client: int, body: int, cfg: StructureConfig) -> None:
    p.changeDynamics(body, -1, contactStiffness=cfg.stiffness_n_per_m,
                     contactDamping=cfg.damping_n_s_per_m, lateralFriction=cfg.friction,
                     physicsClientId=client)


def _quat(R: np.ndarray) -> list[float]:
    return [float(q) for q in Rotation.from_matrix(R).as_quat()]


def _build_structure(client: int, scene: Scene | None, g: Structure,
                     rng: np.random.Generator) -> StructureInstance:
    c = g.cfg
    texture = textures.wall_texture(rng)
    if c.kind == WALL:
        R, origin = g.R, g.position
        centre = origin + R[:, 1] * c.height_m / 2 - R[:, 2] * WALL_THICKNESS_M / 2
        col = p.createCollisionShape(
            p.GEOM_BOX, halfExtents=[c.width_m / 2, c.height_m / 2, WALL_THICKNESS_M / 2],
            physicsClientId=client)
        # The textured face is the box's only visual: a body without one would be drawn
        # from its collision box, whose front face z-fights with the texture.
        visual = Visual(QUAD, (c.width_m / 2, c.height_m / 2), texture=texture,
                        position=(0.0, 0.0, WALL_THICKNESS_M / 2), tile_m=TILE_M)
        position = centre
    else:
        if c.kind == BOX:
            half = [s / 2 for s in c.size_m]
            col = p.createCollisionShape(p.GEOM_BOX, halfExtents=half,
                                         collisionFramePosition=[0.0, 0.0, half[2]],
                                         physicsClientId=client)
            arrays = box_arrays(np.asarray(c.size_m), TILE_M, TEXTURE_M)
        elif c.kind == CYLINDER:
            col = p.createCollisionShape(p.GEOM_CYLINDER, radius=c.radius_m,
                                         height=c.length_m, physicsClientId=client)
            arrays = cylinder_arrays(c.radius_m, c.length_m, TILE_M, TEXTURE_M)
        else:
            assert g.mesh is not None
            col = p.createCollisionShape(p.GEOM_MESH, vertices=g.mesh.vertices.tolist(),
                                         indices=g.mesh.faces.ravel().tolist(),
                                         flags=p.GEOM_FORCE_CONCAVE_TRIMESH,
                                         physicsClientId=client)
            arrays = mesh_arrays(g.mesh.vertices, g.mesh.faces, TILE_M, TEXTURE_M)
        visual = Visual(MESH, (), texture=texture, arrays=arrays)
        position = g.position
    body = create_static_body(client, scene, visual, position, _quat(g.R), col)
    _set_contact(client, body, c)
    return StructureInstance(c.id, c.kind, body, g, visual, np.asarray(position, dtype=float))


def _build_ground(client: int, scene: Scene | None, rng: np.random.Generator) -> int:
    # Tiled, for the same TinyRenderer reason as the wall; without a visual of its own the
    # plane would be drawn from its collision shape with PyBullet's checker texture.
    face = Visual(QUAD, (GROUND_HALF_M, GROUND_HALF_M), texture=textures.ground_texture(rng),
                  tile_m=GROUND_TILE_M, texture_m=GROUND_TEXTURE_M)
    ground = create_static_body(client, scene, face, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0),
                                p.createCollisionShape(p.GEOM_PLANE, physicsClientId=client))
    p.changeDynamics(ground, -1, lateralFriction=0.8, physicsClientId=client)
    return ground


def _build_object(client: int, scene: Scene | None, cfg: ObjectConfig, placement: Placement,
                  structure: StructureConfig, rng: np.random.Generator) -> ObjectInstance:
    half = textures.OBJECT_SIZE_M / 2
    R = placement.R_map_surface
    texture = textures.object_texture(cfg.cls, rng)
    if placement.curve_axis is None:
        front = placement.centre_map + R[:, 2] * PANEL_THICKNESS_M
        col = p.createCollisionShape(
            p.GEOM_BOX, halfExtents=[half, half, PANEL_COLLISION_DEPTH_M / 2],
            collisionFramePosition=[0, 0, -PANEL_COLLISION_DEPTH_M / 2], physicsClientId=client)
        face = Visual(QUAD, (half, half), texture=texture)
        body = create_static_body(client, scene, face, front, _quat(R), col)
    else:
        # wrapped round the cylinder; its collision is the hull of its face and of the same
        # face as deep inside the cylinder as a flat panel's box reaches
        axis_s = R.T @ placement.curve_axis
        radius = placement.curve_radius_m
        arrays = patch_arrays(half, radius, PANEL_THICKNESS_M, axis_s)
        hull = [patch_arrays(half, radius, out, axis_s)[0]
                for out in (PANEL_THICKNESS_M - HULL_MARGIN_M,
                            PANEL_THICKNESS_M - PANEL_COLLISION_DEPTH_M)]
        col = p.createCollisionShape(p.GEOM_MESH, vertices=np.vstack(hull).tolist(),
                                     physicsClientId=client)
        face = Visual(MESH, (), texture=texture, arrays=arrays)
        body = create_static_body(client, scene, face, placement.centre_map, _quat(R), col)
        front = placement.centre_map + R[:, 2] * PANEL_THICKNESS_M
    _set_contact(client, body, structure)
    return ObjectInstance(cfg.cls, body, front, cfg.target, cfg.id, R_map_surface=R.copy(),
                          on=structure.id)
