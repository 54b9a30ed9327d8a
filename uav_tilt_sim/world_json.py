"""The world a plant flies, as `plant/scenario` carries it (DESIGN section 3): the scenario
file's values and the geometry built from them, in map, so that a report draws the wall and
the objects where they were without building the world again.

JSON object (std_msgs/String, latched):

- ``scenario``: the scenario's values (:class:`uav_tilt_sim.scenario.Scenario`, every key);
- ``wall``: ``origin_map`` (the surface point at ground level, (x, y, 0)), ``R_map_wall``
  (rows of the 3x3 rotation: columns x_W right as seen from in front, y_W up the wall, z_W
  the outward normal), ``width_m``, ``height_m``, ``yaw_deg``, ``inclination_deg`` and
  ``corners_map`` (the surface's four corners: bottom left, bottom right, top right, top
  left as seen from in front);
- ``objects``: one per scenario object, in its order: ``cls``, ``id``, ``target``, ``u_m``,
  ``v_m`` (wall coordinates of its centre), ``size_m`` (side of its square face),
  ``centre_map`` (the centre of its face) and ``poi_map`` (a target's point of interest,
  else null).
"""
import dataclasses
import json
from typing import Any

import numpy as np

from uav_tilt_sim.scenario import Scenario
from uav_tilt_sim.textures import OBJECT_SIZE_M
from uav_tilt_sim.world import WorldInfo


def _listed(x: Any) -> Any:
    return None if x is None else np.asarray(x, dtype=float).tolist()


def describe_world(scenario: Scenario, world: WorldInfo) -> dict[str, Any]:
    """The `plant/scenario` object of ``scenario`` as ``world`` was built from it."""
    wall = scenario.wall
    R, origin = world.R_map_wall, world.wall_origin_map
    half = wall.width_m / 2
    corners = [origin + R[:, 0] * u + R[:, 1] * v
               for u, v in ((-half, 0.0), (half, 0.0), (half, wall.height_m),
                            (-half, wall.height_m))]
    objects = [dict(cls=o.cls, id=cfg.id, target=bool(cfg.target), u_m=cfg.u_m, v_m=cfg.v_m,
                    size_m=OBJECT_SIZE_M, centre_map=_listed(o.centre_map),
                    poi_map=_listed(o.poi_map))
               for o, cfg in zip(world.objects, scenario.objects)]
    return dict(scenario=dataclasses.asdict(scenario),
                wall=dict(origin_map=_listed(origin), R_map_wall=_listed(R),
                          width_m=wall.width_m, height_m=wall.height_m,
                          yaw_deg=wall.yaw_deg, inclination_deg=wall.inclination_deg,
                          corners_map=_listed(corners)),
                objects=objects)


def world_json(scenario: Scenario, world: WorldInfo) -> str:
    """:func:`describe_world` as the JSON text `plant/scenario` carries."""
    return json.dumps(describe_world(scenario, world))
