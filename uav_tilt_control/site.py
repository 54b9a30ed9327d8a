"""What the controller knows of the site before it flies: the wall and its targets, as a
drawing or a prior survey gives them (wall coordinates u right, v up, as in a scenario)."""
import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from uav_tilt_common.config import ConfigError, param
from uav_tilt_common.geometry import wall_point, wall_rotation
from uav_tilt_common.targets import HINT_ERROR_M
from uav_tilt_control.obstacles import BOX_FIELDS, ObstacleBox, boxes_from_flat


@dataclasses.dataclass
class SiteConfig:
    """The wall (the scenario's convention: its ground line through ``wall_position_m``,
    ``wall_yaw_deg`` the heading towards it, ``wall_inclination_deg`` its top leaning away,
    ``wall_width_m`` across u = 0, ``wall_height_m`` from the ground; 0 = not surveyed),
    the ids of the targets a plan may name, optionally roughly where the target of a
    one-touch inspection is on the wall (u, v metres; within HINT_ERROR_M along each), and
    the structures the approach keeps clear of, as upright boxes."""

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
        return self

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
        return wall_point(self.wall_position_m, self.wall_yaw_deg, self.wall_inclination_deg,
                          *uv_m)

    def rotation(self) -> NDArray[np.float64]:
        """R_map_wall: x along the wall (u), y up it (v), z its outward normal."""
        return wall_rotation(self.wall_yaw_deg, self.wall_inclination_deg)

    def normal_map(self) -> NDArray[np.float64]:
        """The wall's outward surface normal in map."""
        return self.rotation()[:, 2]

    def on_wall(self, uv_m: Sequence[float], margin_m: float = 0.0) -> bool:
        """True when (u, v) lies on the surveyed wall (edges included), or within
        ``margin_m`` of it."""
        u, v = uv_m
        return (abs(u) <= self.wall_width_m / 2.0 + margin_m
                and -margin_m <= v <= self.wall_height_m + margin_m)

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
