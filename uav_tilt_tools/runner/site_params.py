"""The controller's site from a scenario, as a survey would give it: the wall, its target ids,
its cylinders (by id) and every structure as an obstacle box
(uav_tilt_control.site.SiteConfig). A world of structures gives its first wall standing on
the ground, or none.

``python -m uav_tilt_tools.runner.site_params [SCENARIO [MISSION]]`` prints them as ROS
arguments, one word a line (``-p``, ``site.wall_yaw_deg:=0.0``, ...), for scripts/launch.sh;
an empty SCENARIO is the default scenario. A bad scenario, or with MISSION ``inspect`` one
that designates no target or one the tool cannot sit square on (at the default
``mission.contact.max_pitch_rad``), prints one line on stderr and exits 2.
"""
import sys
from typing import Any, Iterable, Sequence

from uav_tilt_common.config import ConfigError
from uav_tilt_control.mission import MissionConfig
from uav_tilt_control.reach import check_reachable
from uav_tilt_sim.scenario import (Scenario, check_target, load_scenario, structures_of,
                                   target_ids, world_geometry)
from uav_tilt_sim.structures import CYLINDER, WALL


def site_overrides(scenario: Scenario, hint_uv_m: Sequence[float] | None = None
                   ) -> dict[str, Any]:
    """Controller parameters that give it the scenario's wall, target ids, cylinders and
    structures as a survey would, and the hint (u, v on that wall) when there is one."""
    out: dict[str, Any] = {'site.target_ids': target_ids(scenario),
                           **obstacle_overrides(scenario)}
    # the site's wall stands on the ground (its ground line's x, y)
    wall = next((c for c in structures_of(scenario)
                 if c.kind == WALL and c.position_m[2] == 0.0), None)
    if wall is not None:
        out.update({'site.wall_position_m': [float(v) for v in wall.position_m[:2]],
                    'site.wall_yaw_deg': float(wall.yaw_deg),
                    'site.wall_inclination_deg': float(wall.inclination_deg),
                    'site.wall_width_m': float(wall.width_m),
                    'site.wall_height_m': float(wall.height_m)})
    cylinders = [c for c in structures_of(scenario) if c.kind == CYLINDER and c.id]
    if cylinders:
        out.update({'site.cylinder_ids': [c.id for c in cylinders],
                    'site.cylinders': [float(v) for c in cylinders
                                       for v in (*c.position_m, c.yaw_deg, c.elevation_deg,
                                                 c.radius_m, c.length_m)]})
    if hint_uv_m is not None:
        out['site.target_hint_uv_m'] = [float(v) for v in hint_uv_m]
    return out


def obstacle_overrides(scenario: Scenario) -> dict[str, Any]:
    """``site.obstacle_boxes``: every structure of ``scenario`` as an upright box that holds
    it (:meth:`uav_tilt_sim.structures.Structure.plan_box`), as a survey would list them."""
    geometry, _ = world_geometry(scenario)
    return {'site.obstacle_boxes': [float(v) for g in geometry for box in [g.plan_box()]
                                    for v in (*box[0], *box[1], box[2])]}


def check_reach(scenario: Scenario, touched: Iterable[str], max_pitch_rad: float) -> None:
    """ConfigError unless the tool can sit square on each target ``touched`` (its id; ''
    the first target), pitched within ``max_pitch_rad`` (:mod:`uav_tilt_control.reach`)."""
    _, placed = world_geometry(scenario)
    targets = [(o.id, p.R_map_surface) for o, (_, p) in zip(scenario.objects, placed)
               if o.target]
    frames = dict(targets)
    if targets:
        frames[''] = targets[0][1]      # the first target, as ground_truth/target
    for target_id in touched:
        if target_id in frames:
            check_reachable(f"target {target_id!r}" if target_id else 'the target',
                            frames[target_id][:, 2], max_pitch_rad)


def ros_arguments(overrides: dict[str, Any]) -> list[str]:
    """``-p name:=value`` words of parameter overrides (strings quoted, so that an id such
    as ``y`` stays a string; an empty list, which has no type, left out)."""
    words = []
    for name, value in overrides.items():
        if isinstance(value, list) and not value:
            continue
        text = repr(value) if isinstance(value, (list, str)) else str(value)
        words += ['-p', f'{name}:={text}']
    return words


def main(argv: list[str] | None = None) -> int:
    """Print the site parameters of the scenario file in ``argv`` (see the docstring)."""
    argv = sys.argv[1:] if argv is None else argv
    try:
        scenario = load_scenario(argv[0] if argv and argv[0] else None)
        if argv[1:2] == ['inspect']:    # the one-touch inspection needs its target
            check_target(scenario)
            check_reach(scenario, [''], MissionConfig().contact.max_pitch_rad)
    except (OSError, ConfigError) as err:
        print(f'site_params: {err}', file=sys.stderr)
        return 2
    print('\n'.join(ros_arguments(site_overrides(scenario))))
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
