"""The world a plant flies, as `plant/scenario` carries it (DESIGN section 3): the scenario
file's values and the geometry built from them, in map, so that a report draws the wall and
the objects where they were without building the world again.

JSON object (std_msgs/String, latched):

- ``scenario``: the scenario's values (:class:`uav_tilt_sim.scenario.Scenario`, every key);
- ``wall``: the first wall structure (null in a world without one): ``origin_map`` (the
  surface point at ground level, (x, y, 0)), ``R_map_wall``
  (rows of the 3x3 rotation: columns x_W right as seen from in front, y_W up the wall, z_W
  the outward normal), ``width_m``, ``height_m``, ``yaw_deg``, ``inclination_deg`` and
  ``corners_map`` (the surface's four corners: bottom left, bottom right, top right, top
  left as seen from in front);
- ``structures``: one per structure, in order (a scenario without structures: its wall, id
  ``wall``): ``id``, ``kind``, ``position_m``, ``R_map`` (rows of its frame's rotation),
  ``footprint_map`` (the (x, y) corners of the convex outline of what it covers, seen
  from above) and ``height_range_m`` (its lowest and highest point);
- ``objects``: one per scenario object, in its order: ``cls``, ``id``, ``target``, ``on``
  (its structure's id), ``u_m``, ``v_m`` (wall coordinates of its centre), ``size_m`` (side
  of its square face), ``centre_map`` (the centre of its face), ``normal_map`` (the outward
  surface normal there) and ``poi_map`` (a target's point of interest, else null).
"""
import dataclasses
import json
from typing import Any

import numpy as np
from scipy.spatial import ConvexHull

from uav_tilt_sim.scenario import Scenario
from uav_tilt_sim.structures import WALL
from uav_tilt_sim.textures import OBJECT_SIZE_M
from uav_tilt_sim.world import StructureInstance, WorldInfo


def _listed(x: Any) -> Any:
    return None if x is None else np.asarray(x, dtype=float).tolist()


def describe_structure(s: StructureInstance) -> dict[str, Any]:
    """A structure's entry in ``structures``."""
    g = s.geometry
    points = s.visual.mesh()[0].astype(float) @ g.R.T + s.body_position_map
    xy = points[:, :2]
    # joggled: a wall's face seen from above is a line, which qhull refuses as it is
    hull = xy[ConvexHull(xy, qhull_options='QJ').vertices]
    return dict(id=s.id, kind=s.kind, position_m=_listed(g.position), R_map=_listed(g.R),
                footprint_map=_listed(hull),
                height_range_m=[float(points[:, 2].min()), float(points[:, 2].max())])


def describe_world(scenario: Scenario, world: WorldInfo) -> dict[str, Any]:
    """The `plant/scenario` object of ``scenario`` as ``world`` was built from it."""
    wall = next((s for s in world.structures if s.kind == WALL), None)
    wall_entry = None
    if wall is not None:
        c, R, origin = wall.geometry.cfg, wall.geometry.R, wall.geometry.position
        half = c.width_m / 2
        corners = [origin + R[:, 0] * u + R[:, 1] * v
                   for u, v in ((-half, 0.0), (half, 0.0), (half, c.height_m),
                                (-half, c.height_m))]
        wall_entry = dict(origin_map=_listed(origin), R_map_wall=_listed(R),
                          width_m=c.width_m, height_m=c.height_m, yaw_deg=c.yaw_deg,
                          inclination_deg=c.inclination_deg, corners_map=_listed(corners))
    objects = [dict(cls=o.cls, id=cfg.id, target=bool(cfg.target), on=o.on, u_m=cfg.u_m,
                    v_m=cfg.v_m, size_m=OBJECT_SIZE_M, centre_map=_listed(o.centre_map),
                    normal_map=_listed(o.R_map_surface[:, 2]), poi_map=_listed(o.poi_map))
               for o, cfg in zip(world.objects, scenario.objects)]
    return dict(scenario=dataclasses.asdict(scenario), wall=wall_entry,
                structures=[describe_structure(s) for s in world.structures],
                objects=objects)


def world_json(scenario: Scenario, world: WorldInfo) -> str:
    """:func:`describe_world` as the JSON text `plant/scenario` carries."""
    return json.dumps(describe_world(scenario, world))
