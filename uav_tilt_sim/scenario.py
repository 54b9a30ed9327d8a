"""Scenario files (DESIGN section 5): the world, disturbances, noise, model mismatch, seed."""
import dataclasses
import os
import re

from uav_tilt_common import resources
from uav_tilt_common.config import ConfigError, load_yaml, nested, param
from uav_tilt_common.geometry import wall_rotation
from uav_tilt_common.targets import OBJECT_CLASSES
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
    """An inspection object on the wall at (u right, v up) in the wall surface frame, metres;
    a target (a bolt plate) may have an id, which a plan names it by."""

    cls: str = param('bolt_plate', choices=OBJECT_CLASSES,
                     doc=f'what it is: a {OBJECT_SIZE_M:g} m square panel; two panels may '
                         f'not overlap')
    u_m: float = param(0.0, lo=-25.0, hi=25.0,
                       doc="centre, right of position_m along the face (seen from its side); "
                           "|u_m| <= wall.width_m / 2")
    v_m: float = param(1.5, lo=0.0, hi=20.0,
                       doc='centre, up the face from the ground line; at most wall.height_m')
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
    """One world: the wall, the inspection objects on it, the wind, the sensors' noise, how
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
    objects: list = param([], items=ObjectConfig,
                          doc='inspection objects on the wall (the objects[] table)')
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
    return check_scenario(load_yaml(Scenario, resources.resolve(path or DEFAULT_SCENARIO,
                                                                parameter), parameter))


def check_scenario(scenario: Scenario) -> Scenario:
    """Checks across fields: the start stands in front of the wall's face and every object's
    centre lies on the wall; targets are bolt plates; several targets need ids, and ids are
    unique ROS name tokens; no two objects overlap. Returns the scenario. (Whether it has a
    target is the mission's question: :func:`check_target`.)"""
    _check_on_the_wall(scenario)
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


def target_ids(scenario: Scenario) -> list[str]:
    """The ids of the scenario's targets, in order."""
    return [o.id for o in scenario.objects if o.target and o.id]
