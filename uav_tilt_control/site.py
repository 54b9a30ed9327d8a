"""What the controller knows of the site before it flies: the wall, the cylinders (pipes,
tanks) a plan may work on, the targets and the obstacles, as a drawing or a prior survey
gives them (surface coordinates: uav_tilt_control.surfaces)."""
import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from uav_tilt_common.config import ConfigError, param
from uav_tilt_common.geometry import wall_rotation
from uav_tilt_common.targets import HINT_ERROR_M
from uav_tilt_control.obstacles import BOX_FIELDS, ObstacleBox, boxes_from_flat
from uav_tilt_control.surfaces import CylinderSurface, Surface, WallSurface

# a cylinder of site.cylinders: the middle of its axis (x, y, z, m), the axis' heading and
# elevation (deg), its radius and length (m), as a scenario's cylinder gives them
CYLINDER_FIELDS = ('x', 'y', 'z', 'yaw_deg', 'elevation_deg', 'radius_m', 'length_m')


@dataclasses.dataclass
class SiteConfig:
    """The wall (the scenario's convention: its ground line through ``wall_position_m``,
    ``wall_yaw_deg`` the heading towards it, ``wall_inclination_deg`` its top leaning away,
    ``wall_width_m`` across u = 0, ``wall_height_m`` from the ground; 0 = not surveyed),
    the ids of the targets a plan may name, optionally roughly where the target of a
    one-touch inspection is on the wall (u, v metres; within HINT_ERROR_M along each), and
    the structures the approach keeps clear of, as upright boxes; and the cylinders a plan
    may name (``on``), by id."""

    wall_position_m: list = param([], lo=-1000.0, hi=1000.0, items=float)
    wall_yaw_deg: float = param(0.0, lo=-180.0, hi=180.0)
    wall_inclination_deg: float = param(0.0, lo=-30.0, hi=30.0)
    wall_width_m: float = param(0.0, lo=0.0, hi=1000.0)
    wall_height_m: float = param(0.0, lo=0.0, hi=1000.0)
    target_hint_uv_m: list = param([], lo=-1000.0, hi=1000.0, items=float)
    target_ids: list = param([], items=str)
    obstacle_boxes: list = param(
        [], lo=-1000.0, hi=1000.0, items=float,
        doc=f'the structures to keep clear of, as upright boxes in map of '
            f'{len(BOX_FIELDS)} numbers each: centre x, y, z and sizes along the box\'s own '
            f'x, y, z (m), then its yaw (deg); the approach to a target goes round them')
    cylinder_ids: list = param([], items=str,
                               doc='the ids of the cylinders of site.cylinders, in order: a '
                                   'plan\'s task names one as its `on`')
    cylinders: list = param(
        [], lo=-1000.0, hi=1000.0, items=float,
        doc=f'the cylinders (pipes, tanks) a plan may work on, {len(CYLINDER_FIELDS)} numbers '
            f'each: the middle of the axis x, y, z (m), the axis\' heading and elevation '
            f'(deg), the radius and the length (m)')

    def check(self) -> 'SiteConfig':
        """Cross-field checks (ConfigError); returns the site."""
        for name in ('wall_position_m', 'target_hint_uv_m'):
            value = getattr(self, name)
            if value and len(value) != 2:
                raise ConfigError(f"parameter 'site.{name}' = {value!r} must have 2 elements")
        if self.target_hint_uv_m and not self.wall_position_m:
            raise ConfigError("parameter 'site.target_hint_uv_m' needs 'site.wall_position_m' "
                              "(the wall the hint is on)")
        if self.target_hint_uv_m and self.wall_size_known and not self.on_wall(
                self.target_hint_uv_m, margin_m=HINT_ERROR_M):
            raise ConfigError(f"parameter 'site.target_hint_uv_m' = {self.target_hint_uv_m!r} "
                              f"is more than {HINT_ERROR_M} m off the wall (site.wall_width_m "
                              f"{self.wall_width_m}, site.wall_height_m {self.wall_height_m})")
        if len(set(self.target_ids)) != len(self.target_ids):
            raise ConfigError(f"parameter 'site.target_ids' = {self.target_ids!r} repeats an id")
        self.obstacles()
        n = len(CYLINDER_FIELDS)
        if len(self.cylinders) != n * len(self.cylinder_ids):
            raise ConfigError(f"parameter 'site.cylinders' has {len(self.cylinders)} numbers: "
                              f"{n} for each of site.cylinder_ids {list(self.cylinder_ids)!r} "
                              f"({', '.join(CYLINDER_FIELDS)})")
        if len(set(self.cylinder_ids)) != len(self.cylinder_ids) or '' in self.cylinder_ids:
            raise ConfigError(f"parameter 'site.cylinder_ids' = {self.cylinder_ids!r} repeats "
                              f"an id or has an empty one")
        for k in range(len(self.cylinder_ids)):
            radius, length = self.cylinders[n * k + 5:n * k + 7]
            if not (radius > 0.0 and length > 0.0):
                raise ConfigError(f"parameter 'site.cylinders': cylinder "
                                  f"{self.cylinder_ids[k]!r} needs a radius and a length "
                                  f"more than 0, not {radius}, {length}")
        return self

    def surface(self, on: str = '') -> Surface:
        """The surface a task's ``on`` names: '' the wall, else a cylinder's id (ValueError
        for an unknown one)."""
        if not on:
            return self.wall()
        k, n = list(self.cylinder_ids).index(on), len(CYLINDER_FIELDS)
        x, y, z, yaw, elevation, radius, length = self.cylinders[n * k:n * (k + 1)]
        return CylinderSurface((x, y, z), yaw, elevation, radius, length)

    def wall(self) -> WallSurface:
        """The surveyed wall as a surface."""
        x, y = self.wall_position_m
        return WallSurface((x, y), self.wall_yaw_deg, self.wall_inclination_deg,
                           self.wall_width_m, self.wall_height_m)

    def obstacles(self) -> list[ObstacleBox]:
        """The boxes of ``obstacle_boxes`` (ConfigError for a bad list)."""
        try:
            return boxes_from_flat(self.obstacle_boxes)
        except ValueError as err:
            raise ConfigError(f"parameter 'site.obstacle_boxes': {err}") from None

    @property
    def wall_known(self) -> bool:
        """True when the wall's pose is surveyed."""
        return bool(self.wall_position_m)

    @property
    def wall_size_known(self) -> bool:
        """True when the wall's pose and its extent are surveyed."""
        return self.wall_known and self.wall_width_m > 0.0 and self.wall_height_m > 0.0

    def point_map(self, uv_m: Sequence[float]) -> NDArray[np.float64]:
        """Map point of wall coordinates (u, v) on the wall's surface."""
        return self.wall().point_map(uv_m)

    def rotation(self) -> NDArray[np.float64]:
        """R_map_wall: x along the wall (u), y up it (v), z its outward normal."""
        return wall_rotation(self.wall_yaw_deg, self.wall_inclination_deg)

    def normal_map(self) -> NDArray[np.float64]:
        """The wall's outward surface normal in map."""
        return self.rotation()[:, 2]

    def on_wall(self, uv_m: Sequence[float], margin_m: float = 0.0) -> bool:
        """True when (u, v) lies on the surveyed wall (edges included), or within
        ``margin_m`` of it."""
        return self.wall().on(uv_m, margin_m)

    def target_hint_map(self) -> NDArray[np.float64] | None:
        """The one-touch hint as a map point, or None without one."""
        self.check()
        return self.point_map(self.target_hint_uv_m) if self.target_hint_uv_m else None

    def wall_frame(self) -> dict[str, list[Any]] | None:
        """{'origin_map', 'R_map_wall'} of the surveyed wall (lists), or None."""
        if not self.wall_known:
            return None
        origin = np.array([self.wall_position_m[0], self.wall_position_m[1], 0.0])
        return {'origin_map': origin.tolist(), 'R_map_wall': self.rotation().tolist()}
