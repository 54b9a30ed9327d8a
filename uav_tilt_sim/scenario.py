"""Scenario files (DESIGN section 5): the world, disturbances, noise, model mismatch, seed."""
import dataclasses
import os
import re

from uav_tilt_common import resources
from uav_tilt_common.config import ConfigError, load_yaml, nested, param
from uav_tilt_common.geometry import wall_rotation
from uav_tilt_common.targets import OBJECT_CLASSES

# The scenario of an empty ``scenario_file``, relative to the package's files.
DEFAULT_SCENARIO = 'config/scenarios/default.yaml'


@dataclasses.dataclass
class WallConfig:
    """A flat wall. yaw: heading (map, CCW from +x) of the direction from the start to the wall;
    inclination: top leaning away from the vehicle (positive) about the wall's horizontal axis."""

    position_m: list = param([2.0, 0.0], lo=-50.0, hi=50.0, length=2)  # surface, ground line
    yaw_deg: float = param(0.0, lo=-180.0, hi=180.0)
    inclination_deg: float = param(0.0, lo=-30.0, hi=30.0)
    width_m: float = param(5.0, lo=0.5, hi=50.0)
    height_m: float = param(3.5, lo=0.5, hi=20.0)
    stiffness_n_per_m: float = param(4000.0, lo=100.0, hi=1e6)
    damping_n_s_per_m: float = param(60.0, lo=0.0, hi=1e4)
    friction: float = param(0.4, lo=0.0, hi=2.0)


# A target's id names its ground-truth topic (ground_truth/targets/<id>): a ROS name token.
TARGET_ID = re.compile(r'[A-Za-z][A-Za-z0-9_]*')
# Points of interest are defined for bolt plates only (uav_tilt_sim.textures.POI_UV).
TARGET_CLASS = 'bolt_plate'


@dataclasses.dataclass
class ObjectConfig:
    """An inspection object on the wall at (u right, v up) in the wall surface frame, metres;
    a target (a bolt plate) may have an id, which a plan names it by."""

    cls: str = param('bolt_plate', choices=OBJECT_CLASSES)
    u_m: float = param(0.0, lo=-25.0, hi=25.0)
    v_m: float = param(1.5, lo=0.0, hi=20.0)
    target: bool = param(False)
    id: str = param('')


@dataclasses.dataclass
class WindConfig:
    """Mean wind (map, m/s) and gusts: Ornstein-Uhlenbeck per axis with std and time constant."""

    mean_m_s: list = param([0.0, 0.0, 0.0], lo=-20.0, hi=20.0, length=3)
    gust_std_m_s: float = param(0.0, lo=0.0, hi=10.0)
    gust_tau_s: float = param(1.5, lo=0.05, hi=60.0)
    drag_n_s2_per_m2: float = param(0.04, lo=0.0, hi=5.0)  # quadratic drag 0.5 rho Cd A


@dataclasses.dataclass
class NoiseConfig:
    """Sensor noise standard deviations (0 = perfect)."""

    imu_gyro_rad_s: float = param(0.0, lo=0.0, hi=1.0)
    imu_accel_m_s2: float = param(0.0, lo=0.0, hi=10.0)
    odom_pos_m: float = param(0.0, lo=0.0, hi=0.5)
    odom_att_rad: float = param(0.0, lo=0.0, hi=0.2)
    odom_vel_m_s: float = param(0.0, lo=0.0, hi=1.0)
    ft_force_n: float = param(0.0, lo=0.0, hi=5.0)
    ft_torque_nm: float = param(0.0, lo=0.0, hi=1.0)
    depth_m: float = param(0.0, lo=0.0, hi=0.1)


@dataclasses.dataclass
class MismatchConfig:
    """How the simulated vehicle differs from the nominal model the controller uses."""

    mass_scale: float = param(1.0, lo=0.5, hi=2.0)
    inertia_scale: float = param(1.0, lo=0.5, hi=2.0)


@dataclasses.dataclass
class Scenario:
    """One world: wall, objects, wind, noise, mismatch, start pose, seed."""

    seed: int = param(0, lo=0, hi=2**31 - 1)
    start_xyz_m: list = param([0.0, 0.0, 0.0], lo=-50.0, hi=50.0, length=3)
    start_yaw_deg: float = param(0.0, lo=-180.0, hi=180.0)
    wall: WallConfig = nested(WallConfig)
    objects: list = param([], items=ObjectConfig)
    wind: WindConfig = nested(WindConfig)
    noise: NoiseConfig = nested(NoiseConfig)
    mismatch: MismatchConfig = nested(MismatchConfig)
    texture_seed: int = param(-1, lo=-1, hi=2**31 - 1)  # -1: same as seed


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
    unique ROS name tokens. Returns the scenario."""
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
    return scenario


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
                          f"{wall.yaw_deg}: the heading from the start to the wall)")
    for i, o in enumerate(scenario.objects):
        if abs(o.u_m) > wall.width_m / 2:
            raise ConfigError(f"parameter 'objects[{i}].u_m' = {o.u_m} is off the wall "
                              f"(|u_m| <= wall.width_m / 2 = {wall.width_m / 2})")
        if o.v_m > wall.height_m:
            raise ConfigError(f"parameter 'objects[{i}].v_m' = {o.v_m} is above the wall "
                              f"(wall.height_m = {wall.height_m})")


def target_ids(scenario):
    """The ids of the scenario's targets, in order."""
    return [o.id for o in scenario.objects if o.target and o.id]
