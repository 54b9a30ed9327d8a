"""Randomised worlds of structures: one scenario per seed, of one structure kind drawn from
STRUCTURE_KINDS, in any direction from the start, under the wind, sensor noise, model
mismatch, stiffness and friction of :func:`uav_tilt_sim.randomise.random_draw`'s draw of the
same seed (a ``wall`` is that draw itself). The target is on the side the vehicle reaches
flying straight to it: facing the start, within the tool's reach of horizontal; but a
``pillar``'s target is on a face turned away from the start, and in a ``pillar_between``
world a pillar stands in the straight flight's way, not in the camera's: the search and the
approach go round them.
"""
import dataclasses
import math
from typing import Any

import numpy as np

from uav_tilt_common import resources
from uav_tilt_common.config import from_dict
from uav_tilt_sim.randomise import START_YAW_DEG, random_draw
from uav_tilt_sim.scenario import Scenario, check_scenario

STRUCTURE_KINDS = ('wall', 'corner', 'pillar', 'pipe', 'vertical_pipe', 'tank', 'mesh',
                   'pillar_between')
MESH_FILE = 'config/meshes/i_beam.obj'       # an I-beam 3 m tall, its flange 0.4 m wide
DISTANCE_M = (2.5, 4.0)             # start to the surface in front of it
TARGET_HEIGHT_M = (1.3, 2.0)
PIPE_RADIUS_M = (0.15, 0.5)
TANK_RADIUS_M = (1.0, 3.0)
PIPE_SIDE_DEG = 30.0                # a horizontal pipe's target, off its side
OFF_FACING_DEG = 20.0               # a round target's normal, off the line to the start
CORNER_EDGE_M = (0.25, 0.4)         # a corner's target from the edge
# a pillar's target is on a face turned away from the start (its -x face looks at it): the
# search goes round the pillar to see it, the approach round it to reach it
PILLAR_FACES = ('+y', '-y', '+x')
BETWEEN_WALL_M = (4.0, 5.5)         # pillar_between: start to the wall
BETWEEN_AT = (0.4, 0.6)             # the pillar's share of the way there
# the pillar's near edge off the line of sight: the camera sees past it, and the vehicle
# flying straight would strike it (its arms reach 0.16 m to each side, their blades more)
BETWEEN_GAP_M = (0.05, 0.15)


def structure_draw(seed: int, kind: str | None = None
                   ) -> tuple[Scenario, str, list[float] | None]:
    """(scenario, kind, hint) of world ``seed``: ``kind`` (drawn from STRUCTURE_KINDS with
    the seed when None); the hint of a wall with a look-alike (random_draw's), else None."""
    rng = np.random.default_rng([seed, 51])      # a stream of its own beside the draw's
    kind = kind or str(rng.choice(STRUCTURE_KINDS))
    drawn, hint = random_draw(seed)
    if kind == 'wall':
        return drawn, kind, hint
    structures, objects = _local_world(kind, rng)
    bearing = float(rng.uniform(-180.0, 180.0))
    contact = dict(stiffness_n_per_m=drawn.wall.stiffness_n_per_m, friction=drawn.wall.friction)
    data: dict[str, Any] = dict(
        seed=seed, start_xyz_m=[0.0, 0.0, 0.0],
        start_yaw_deg=_wrap_deg(bearing + rng.uniform(-START_YAW_DEG, START_YAW_DEG)),
        structures=[dict(_turned(s, bearing), **contact) for s in structures],
        objects=objects, wind=dataclasses.asdict(drawn.wind),
        noise=dataclasses.asdict(drawn.noise), mismatch=dataclasses.asdict(drawn.mismatch))
    return check_scenario(from_dict(Scenario, data)), kind, None


def _local_world(kind: str, rng: np.random.Generator
                 ) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """(structures, objects) of ``kind`` before the start, which faces +x at the origin."""
    def u(lo: float, hi: float) -> float:
        return float(rng.uniform(lo, hi))
    d, height = u(*DISTANCE_M), u(*TARGET_HEIGHT_M)
    target = dict(target=True, id='target')
    if kind in ('pipe', 'vertical_pipe', 'tank'):
        upright = kind != 'pipe'
        radius = u(*(TANK_RADIUS_M if kind == 'tank' else PIPE_RADIUS_M))
        off = u(-OFF_FACING_DEG, OFF_FACING_DEG)
        if upright:
            # about an upright axis at yaw 0 the radial at angle theta is (-sin, cos, 0):
            # theta = 90 deg looks back along -x, at the start
            cylinder = dict(position_m=[d + radius, 0.0, 2.5], elevation_deg=90.0,
                            length_m=5.0)
            where = dict(angle_deg=90.0 + off, axial_m=height - 2.5)
        else:
            # an axis across the line of sight (heading 90 deg, turned by off): its side at
            # angle 0 looks back at the start
            cylinder = dict(position_m=[d + radius, 0.0, height], yaw_deg=90.0 + off,
                            length_m=4.0)
            where = dict(angle_deg=u(-PIPE_SIDE_DEG, PIPE_SIDE_DEG), axial_m=u(-0.8, 0.8))
        return ([dict(id=kind, kind='cylinder', radius_m=radius, **cylinder)],
                [dict(on=kind, **where, **target)])
    if kind == 'corner':
        edge_y = u(-1.5, -0.5)
        # wall a faces the start (its face at x = d, u right = -y); wall b meets it at
        # y = edge_y, its face looking +y, reaching back towards the start
        return ([dict(id='a', kind='wall', position_m=[d, 0.0, 0.0], width_m=5.0),
                 dict(id='b', kind='wall', position_m=[d - 1.5, edge_y, 0.0], yaw_deg=-90.0,
                      width_m=3.0)],
                [dict(on='a', u_m=-(edge_y + u(*CORNER_EDGE_M)), v_m=height, **target)])
    if kind == 'pillar_between':
        d, u_t, side, at = u(*BETWEEN_WALL_M), u(-0.2, 0.2), u(0.4, 0.6), u(*BETWEEN_AT)
        # the wall faces the start (u right = -y); the line of sight passes y = -u_t at
        y = -u_t * at + float(rng.choice([-1.0, 1.0])) * (side / 2 + u(*BETWEEN_GAP_M))
        return ([dict(id='wall', kind='wall', position_m=[d, 0.0, 0.0], width_m=5.0),
                 dict(id='pillar', kind='box', position_m=[d * at, y, 0.0],
                      size_m=[side, side, 3.0])],
                [dict(on='wall', u_m=u_t, v_m=height, **target)])
    if kind == 'pillar':
        side = u(0.4, 0.8)
        return ([dict(id='pillar', kind='box', position_m=[d + side / 2, 0.0, 0.0],
                      yaw_deg=u(-OFF_FACING_DEG, OFF_FACING_DEG), size_m=[side, side, 3.0])],
                [dict(on='pillar', face=str(rng.choice(PILLAR_FACES)), u_m=u(-0.1, 0.1) * side,
                      v_m=height, **target)])
    assert kind == 'mesh', kind
    # the beam's flange (normal +y in its file, 0.25 m off its axis) turned to the start
    return ([dict(id='beam', kind='mesh', file=str(resources.resolve(MESH_FILE, 'file')),
                  position_m=[d + 0.25, 0.0, 0.0], yaw_deg=90.0)],
            [dict(on='beam', point_m=[u(-0.08, 0.08), 0.3, height], **target)])


def _turned(structure: dict[str, Any], bearing_deg: float) -> dict[str, Any]:
    """``structure`` turned by ``bearing_deg`` about the start (map z through the origin)."""
    b = math.radians(bearing_deg)
    x, y, z = structure['position_m']
    return dict(structure, position_m=[x * math.cos(b) - y * math.sin(b),
                                       x * math.sin(b) + y * math.cos(b), z],
                yaw_deg=_wrap_deg(structure.get('yaw_deg', 0.0) + bearing_deg))


def _wrap_deg(angle: float) -> float:
    return float((angle + 180.0) % 360.0 - 180.0)
