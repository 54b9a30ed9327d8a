"""Scenario files (DESIGN section 5): the world, disturbances, noise, model mismatch, seed."""
import dataclasses
import os
import re

import numpy as np

from uav_tilt_common import resources
from uav_tilt_common.config import ConfigError, close_match, load_yaml, nested, param
from uav_tilt_common.geometry import wall_rotation
from uav_tilt_common.targets import OBJECT_CLASSES
from uav_tilt_sim.structures import (BOX_FACES, MESH, WALL, Placement, Structure,
                                     StructureConfig, structure_of)
from uav_tilt_sim.textures import OBJECT_SIZE_M

# The scenario of an empty ``scenario_file``, relative to the package's files.
DEFAULT_SCENARIO = 'config/scenarios/default.yaml'


@dataclasses.dataclass
class WallConfig:
    """A flat wall whose ground line passes through ``position_m``. yaw: the heading (map, CCW
    from +x) into the wall's face, along its inward normal (the face looks back along yaw +
    180): the heading from the start to the wall only for a start on the normal through
    ``position_m``; a start anywhere on the face's side is flown, whatever its bearing and
    its own ``start_yaw_deg``. inclination: top leaning away from the face's side (positive)
    about the wall's horizontal axis."""

    position_m: list = param([2.0, 0.0], lo=-50.0, hi=50.0, length=2,
                             doc="map (x, y) of the middle of the face's ground line")
    yaw_deg: float = param(0.0, lo=-180.0, hi=180.0,
                           doc="heading into the face, along its inward normal (the face "
                               "looks back along yaw + 180); the start stands on the face's "
                               "side, at any bearing")
    inclination_deg: float = param(0.0, lo=-30.0, hi=30.0,
                                   doc="top leaning away from the face's side (positive) or "
                                       "over it (negative)")
    width_m: float = param(5.0, lo=0.5, hi=50.0, doc='along the ground line, centred on '
                                                     'position_m')
    height_m: float = param(3.5, lo=0.5, hi=20.0, doc='up the face from the ground line')
    stiffness_n_per_m: float = param(4000.0, lo=100.0, hi=1e6,
                                     doc='contact stiffness of the wall and its objects')
    damping_n_s_per_m: float = param(60.0, lo=0.0, hi=1e4,
                                     doc='contact damping of the wall and its objects')
    friction: float = param(0.4, lo=0.0, hi=2.0,
                            doc='Coulomb friction coefficient of the wall and its objects')


# A target's id names its ground-truth topic (ground_truth/targets/<id>): a ROS name token.
TARGET_ID = re.compile(r'[A-Za-z][A-Za-z0-9_]*')
# Points of interest are defined for bolt plates only (uav_tilt_sim.textures.POI_UV).
TARGET_CLASS = 'bolt_plate'


@dataclasses.dataclass
class ObjectConfig:
    """An inspection object on a structure (the wall), at the surface coordinates of its
    kind: (u right, v up) on a wall or a box's face, (axial, angle) on a cylinder, a point
    snapped onto a mesh; a target (a bolt plate) may have an id, which a plan names it by."""

    cls: str = param('bolt_plate', choices=OBJECT_CLASSES,
                     doc=f'what it is: a {OBJECT_SIZE_M:g} m square panel; two panels may '
                         f'not overlap')
    on: str = param('', doc="the id of the structure it is on ('': the first; the wall "
                            "of a scenario without structures)")
    u_m: float = param(0.0, lo=-25.0, hi=25.0,
                       doc="wall or box face: centre, right of position_m along the face "
                           "(seen from its side); |u_m| <= wall.width_m / 2")
    v_m: float = param(1.5, lo=0.0, hi=20.0,
                       doc="wall or box face: centre, up the face from its foot; at most "
                           "wall.height_m")
    face: str = param('-x', choices=BOX_FACES,
                      doc="box: which face, by its outward normal in the box's own axes")
    axial_m: float = param(0.0, lo=-25.0, hi=25.0,
                           doc="cylinder: centre, along the axis from its middle")
    angle_deg: float = param(0.0, lo=-180.0, hi=180.0,
                             doc="cylinder: centre, about the axis from its side at heading "
                                 "yaw_deg + 90 (0) towards the top (90)")
    point_m: list = param([0.0, 0.0, 0.0], lo=-50.0, hi=50.0, length=3,
                          doc="mesh: centre, in the mesh's metres and axes; snapped onto "
                              "its surface")
    target: bool = param(False, doc='the target of the inspection (a bolt_plate; its point '
                                    'of interest is the bolt); an inspection needs one')
    id: str = param('', doc='name a plan and ground_truth/targets/<id> use (a letter, then '
                            'letters, digits or _; unique); needed when several are targets')


@dataclasses.dataclass
class WindConfig:
    """Mean wind (map, m/s) and gusts: Ornstein-Uhlenbeck per axis with std and time constant."""

    mean_m_s: list = param([0.0, 0.0, 0.0], lo=-20.0, hi=20.0, length=3,
                           doc='mean wind velocity (map x, y, z)')
    gust_std_m_s: float = param(0.0, lo=0.0, hi=10.0,
                                doc='standard deviation of the gusts, per axis')
    gust_tau_s: float = param(1.5, lo=0.05, hi=60.0, doc='time constant of the gusts')
    drag_n_s2_per_m2: float = param(0.04, lo=0.0, hi=5.0,
                                    doc='quadratic drag 0.5 rho Cd A on the air speed')


@dataclasses.dataclass
class NoiseConfig:
    """Sensor noise standard deviations (0 = perfect)."""

    imu_gyro_rad_s: float = param(0.0, lo=0.0, hi=1.0, doc='IMU angular rate, per axis')
    imu_accel_m_s2: float = param(0.0, lo=0.0, hi=10.0, doc='IMU specific force, per axis')
    odom_pos_m: float = param(0.0, lo=0.0, hi=0.5, doc='odometry position, per axis')
    odom_att_rad: float = param(0.0, lo=0.0, hi=0.2, doc='odometry attitude, per axis')
    odom_vel_m_s: float = param(0.0, lo=0.0, hi=1.0, doc='odometry velocity, per axis')
    ft_force_n: float = param(0.0, lo=0.0, hi=5.0, doc='F/T sensor force, per axis')
    ft_torque_nm: float = param(0.0, lo=0.0, hi=1.0, doc='F/T sensor torque, per axis')
    depth_m: float = param(0.0, lo=0.0, hi=0.1, doc='depth camera, per pixel')


@dataclasses.dataclass
class MismatchConfig:
    """How the simulated vehicle differs from the nominal model the controller uses."""

    mass_scale: float = param(1.0, lo=0.5, hi=2.0,
                              doc="the simulated masses over the model's (vehicle.mass_kg, "
                                  "its arms and tool)")
    inertia_scale: float = param(1.0, lo=0.5, hi=2.0,
                                 doc="the simulated inertia over the model's")


@dataclasses.dataclass
class Scenario:
    """One world: the wall or the structures, the inspection objects on them, the wind, the
    sensors' noise, how
    the simulated vehicle differs from the controller's model of it, where the vehicle
    starts, and the seed of its random streams."""

    seed: int = param(0, lo=0, hi=2**31 - 1,
                      doc='random streams of the gusts and every sensor\'s noise (and the '
                          'textures, see texture_seed)')
    start_xyz_m: list = param([0.0, 0.0, 0.0], lo=-50.0, hi=50.0, length=3,
                              doc="map position of the vehicle at take-off (z at or below "
                                  "the ground: standing on its skid); in front of the wall's "
                                  "face, the vehicle and its tool clear of it")
    start_yaw_deg: float = param(0.0, lo=-180.0, hi=180.0,
                                 doc='heading of the vehicle at take-off (map, CCW from +x)')
    wall: WallConfig = nested(WallConfig)
    structures: list = param([], items=StructureConfig,
                             doc='the world\'s structures (walls, boxes, cylinders, meshes; '
                                 'the structures[] table); none: the wall alone')
    objects: list = param([], items=ObjectConfig,
                          doc='inspection objects on the structures (the objects[] table)')
    wind: WindConfig = nested(WindConfig)
    noise: NoiseConfig = nested(NoiseConfig)
    mismatch: MismatchConfig = nested(MismatchConfig)
    texture_seed: int = param(-1, lo=-1, hi=2**31 - 1,
                              doc='the look of the wall, objects and ground; -1: seed')


def load_scenario(path: str | os.PathLike[str] | None = None,
                  parameter: str = 'scenario_file') -> Scenario:
    """Load and validate a scenario YAML (empty path: the default scenario); a relative path
    as :func:`resources.resolve` finds it. ConfigError names ``parameter`` when the file is
    missing or unreadable."""
    resolved = resources.resolve(path or DEFAULT_SCENARIO, parameter)
    scenario = load_yaml(Scenario, resolved, parameter)
    folder = os.path.dirname(os.path.abspath(resolved))
    scenario.structures = [
        dataclasses.replace(c, file=os.path.join(folder, c.file)) if c.file else c
        for c in scenario.structures]
    return check_scenario(scenario)


def check_scenario(scenario: Scenario) -> Scenario:
    """Checks across fields: the start stands in front of the wall's face (with structures:
    in none of them) and every object's centre lies on its structure's surface; structures
    are not inside each other; targets are bolt plates; several targets need ids, and ids
    are unique ROS name tokens; no two objects overlap. Returns the scenario. (Whether it
    has a target is the mission's question: :func:`check_target`.)"""
    if scenario.structures:
        _check_structures(scenario)
    else:
        _check_on_the_wall(scenario)
        world_geometry(scenario)        # the objects' `on`
    targets = [(i, o) for i, o in enumerate(scenario.objects) if o.target]
    for i, o in targets:
        if o.cls != TARGET_CLASS:
            raise ConfigError(f"parameter 'objects[{i}].cls' = {o.cls!r}: targets are "
                              f"{TARGET_CLASS}s (their points of interest are defined)")
    if len(targets) > 1 and not all(o.id for _, o in targets):
        raise ConfigError(f"parameter 'objects' has {len(targets)} targets: several targets "
                          f"need an 'id' each")
    ids = [o.id for o in scenario.objects if o.id]
    for i, o in enumerate(scenario.objects):
        if o.id and not TARGET_ID.fullmatch(o.id):
            raise ConfigError(f"parameter 'objects[{i}].id' = {o.id!r} must be a letter "
                              f"followed by letters, digits or '_'")
        if o.id and ids.count(o.id) > 1:
            raise ConfigError(f"parameter 'objects[{i}].id' = {o.id!r} is not unique")
    if not scenario.structures:
        _check_apart(scenario.objects)
    return scenario


def check_target(scenario: Scenario) -> None:
    """ConfigError unless ``scenario`` designates a target (an object with ``target: true``):
    what an inspection flies to and pushes, and what its touch is scored against. A world
    without one is flown only where nothing is inspected (the plant alone, hovering)."""
    if not any(o.target for o in scenario.objects):
        classes = ', '.join(o.cls for o in scenario.objects) or 'none'
        raise ConfigError(f"parameter 'objects' designates no target (objects: {classes}): "
                          f"an inspection needs one {TARGET_CLASS} with 'target: true'")


def _check_apart(objects: list[ObjectConfig]) -> None:
    # Every class is an OBJECT_SIZE_M square panel on the face (world._build_object): two
    # closer than that along both of the wall's axes would be drawn and touched as one, such
    # as a gauge hiding the target's bolt.
    for j, b in enumerate(objects):
        for i, a in enumerate(objects[:j]):
            if abs(a.u_m - b.u_m) < OBJECT_SIZE_M and abs(a.v_m - b.v_m) < OBJECT_SIZE_M:
                raise ConfigError(
                    f"parameter 'objects[{j}]' ({b.cls} at u_m {b.u_m:g}, v_m {b.v_m:g}) "
                    f"overlaps 'objects[{i}]' ({a.cls} at u_m {a.u_m:g}, v_m {a.v_m:g}): "
                    f"objects are {OBJECT_SIZE_M:g} m squares, so their centres must lie "
                    f"at least {OBJECT_SIZE_M:g} m apart along u or v")


def _check_on_the_wall(scenario: Scenario) -> None:
    # Both are easy slips in a hand-written file (a swapped sign, a height above the wall's)
    # that would fly a world with nothing to inspect: the face turned away from the vehicle,
    # or a panel hanging in the air beside the wall.
    wall = scenario.wall
    R_map_wall = wall_rotation(wall.yaw_deg, wall.inclination_deg)
    in_front_m = sum((scenario.start_xyz_m[k] - wall.position_m[k]) * R_map_wall[k, 2]
                     for k in (0, 1))
    if in_front_m <= 0.0:
        raise ConfigError(f"parameter 'start_xyz_m' = {scenario.start_xyz_m} is behind the "
                          f"wall's face (wall.position_m {wall.position_m}, yaw_deg "
                          f"{wall.yaw_deg}: the heading into the face)")
    for i, o in enumerate(scenario.objects):
        if abs(o.u_m) > wall.width_m / 2:
            raise ConfigError(f"parameter 'objects[{i}].u_m' = {o.u_m} is off the wall "
                              f"(|u_m| <= wall.width_m / 2 = {wall.width_m / 2})")
        if o.v_m > wall.height_m:
            raise ConfigError(f"parameter 'objects[{i}].v_m' = {o.v_m} is above the wall "
                              f"(wall.height_m = {wall.height_m})")


def structures_of(scenario: Scenario) -> list[StructureConfig]:
    """The scenario's structures: its ``structures``, or without any its wall (id 'wall')."""
    if scenario.structures:
        return list(scenario.structures)
    w = scenario.wall
    return [StructureConfig(id=WALL, kind=WALL, position_m=[*w.position_m, 0.0],
                            yaw_deg=w.yaw_deg, inclination_deg=w.inclination_deg,
                            width_m=w.width_m, height_m=w.height_m,
                            stiffness_n_per_m=w.stiffness_n_per_m,
                            damping_n_s_per_m=w.damping_n_s_per_m, friction=w.friction)]


def world_geometry(scenario: Scenario) -> tuple[list[Structure], list[tuple[int, Placement]]]:
    """The geometry of the scenario's structures, and for each object the index of its
    structure and where it sits (ConfigError where one is off its surface)."""
    structures = [structure_of(c, f'structures[{i}]')
                  for i, c in enumerate(structures_of(scenario))]
    ids = [s.cfg.id for s in structures]
    placed = []
    for i, o in enumerate(scenario.objects):
        name = f'objects[{i}]'
        if o.on and o.on not in ids:
            close = close_match(o.on, ids)
            hint = f" (did you mean {close!r}?)" if close else f" (structures: {', '.join(ids)})"
            raise ConfigError(f"parameter '{name}.on' = {o.on!r} names no structure{hint}")
        k = ids.index(o.on) if o.on else 0
        placed.append((k, structures[k].place(o.face, o.u_m, o.v_m, o.axial_m, o.angle_deg,
                                              o.point_m, OBJECT_SIZE_M, name)))
    return structures, placed


def _check_structures(scenario: Scenario) -> None:
    # The wall group is the world of a scenario without structures: beside them it would
    # be ignored, and a user who set it expects it built.
    if scenario.wall != WallConfig():
        raise ConfigError("parameters 'wall' and 'structures' are both set: list the wall "
                          "among the structures (kind: wall)")
    for i, c in enumerate(scenario.structures):
        if not TARGET_ID.fullmatch(c.id):
            raise ConfigError(f"parameter 'structures[{i}].id' = {c.id!r} must be a letter "
                              f"followed by letters, digits or '_'")
        if c.id in [d.id for d in scenario.structures[:i]]:
            raise ConfigError(f"parameter 'structures[{i}].id' = {c.id!r} is not unique")
        if c.kind == MESH and not c.file:
            raise ConfigError(f"parameter 'structures[{i}].file' is empty: a mesh needs its "
                              f"OBJ or STL file")
    structures, placed = world_geometry(scenario)
    for j, b in enumerate(structures):
        for i, a in enumerate(structures):
            if i != j and a.contains(b.centre_map())[0]:
                raise ConfigError(f"parameter 'structures[{j}]' ({b.cfg.kind} "
                                  f"{b.cfg.id!r}) lies inside 'structures[{i}]' ({a.cfg.kind} "
                                  f"{a.cfg.id!r})")
    start = np.asarray(scenario.start_xyz_m, dtype=float)
    for i, a in enumerate(structures):
        if a.contains(start)[0]:
            raise ConfigError(f"parameter 'start_xyz_m' = {scenario.start_xyz_m} is inside "
                              f"'structures[{i}]' ({a.cfg.kind} {a.cfg.id!r})")
    for j, (kb, pb) in enumerate(placed):
        for i, (ka, pa) in enumerate(placed[:j]):
            d = pb.centre_map - pa.centre_map
            if (ka == kb and abs(d @ pa.R_map_surface[:, 0]) < OBJECT_SIZE_M
                    and abs(d @ pa.R_map_surface[:, 1]) < OBJECT_SIZE_M
                    and abs(d @ pa.R_map_surface[:, 2]) < OBJECT_SIZE_M):
                raise ConfigError(f"parameter 'objects[{j}]' overlaps 'objects[{i}]' on "
                                  f"{structures[ka].cfg.id!r}: objects are {OBJECT_SIZE_M:g} "
                                  f"m squares, their centres at least that far apart")


def target_ids(scenario: Scenario) -> list[str]:
    """The ids of the scenario's targets, in order."""
    return [o.id for o in scenario.objects if o.target and o.id]
