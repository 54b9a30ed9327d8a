"""Which surfaces the tool can sit square on: it pushes along the body's forward axis,
which the mission pitches by at most ``contact.max_pitch_rad`` (DESIGN section 5), so a
surface whose normal leans further from horizontal (the top or the underside of a pipe, a
ceiling) cannot be touched square."""
import math

from numpy.typing import ArrayLike

from uav_tilt_common.config import ConfigError
from uav_tilt_control import frames


def normal_elevation_rad(normal_map: ArrayLike) -> float:
    """How far the outward normal leans above horizontal (negative: below)."""
    return frames.pitch_facing(normal_map)


def check_reachable(name: str, normal_map: ArrayLike, max_pitch_rad: float) -> None:
    """ConfigError (one line, naming ``name``, the target) unless the tool, pitched within
    ``max_pitch_rad``, can push along -``normal_map``."""
    elevation = normal_elevation_rad(normal_map)
    # a hair of slack: a wall inclined by exactly the limit is reachable
    if abs(elevation) > max_pitch_rad + 1e-9:
        side = 'up' if elevation > 0 else 'down'
        limit = math.degrees(max_pitch_rad)
        raise ConfigError(
            f"{name}'s surface faces {abs(math.degrees(elevation)):.1f} deg {side}: the tool "
            f"pushes along the body's forward axis, pitched at most {limit:.1f} deg "
            f"(mission.contact.max_pitch_rad {max_pitch_rad:g}), so it reaches surfaces "
            f"whose normal lies within {limit:.1f} deg of horizontal")
