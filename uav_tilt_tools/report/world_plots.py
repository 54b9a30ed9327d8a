"""trajectory.png: the world that was flown and the flight in it (see
:mod:`uav_tilt_tools.report.plots`).

Three views, the wall and its objects as the plant built them (plant/scenario,
:mod:`uav_tilt_sim.world_json`: the wall's true extent, yaw and inclination; every object,
each target by its id), the vehicle's and the tool tip's true paths, and the plan's tasks:

- top view (map x, y);
- the wall's face (its coordinates u right, v up, as the scenario and a plan give them):
  the objects, each touch's mean tool tip over its hold, each slide's requested line and
  the tool tip's path on the wall while it slid;
- a section across the wall (horizontal distance from the wall's ground line along its
  outward normal, height): the wall's inclination, the approach.

A recording without plant/scenario (made before it was published) gets the targets of its
ground truth and no wall; a world of structures without a wall gets the top view only,
each structure's outline in it. The artists a test reads carry a ``gid``: ``wall``,
``structure:<id>``, ``target:<id>`` (a target's marker; '' for an unnamed first target),
``object:<i>``.
"""
from typing import Any

import matplotlib
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from uav_tilt_tools.bag import reader
from uav_tilt_tools.bag.reader import Recording
from uav_tilt_tools.metrics.tasks import pushing
from uav_tilt_tools.report.task_plots import ReportTask, task_colour

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402  (after the headless backend is chosen)

# Tool-tip samples this close to the wall's plane are drawn on its face (the approach and
# the work at the wall, not the flight to it).
NEAR_WALL_M = 0.3


class WallView:
    """The wall of a recorded world: map <-> wall coordinates and the section's axes."""

    def __init__(self, wall: dict[str, Any]) -> None:
        self.origin = np.asarray(wall['origin_map'], dtype=float)
        self.R = np.asarray(wall['R_map_wall'], dtype=float)
        self.width_m = float(wall['width_m'])
        self.height_m = float(wall['height_m'])
        self.corners = np.asarray(wall['corners_map'], dtype=float)
        normal = self.R[:, 2]
        horizontal = np.array([normal[0], normal[1], 0.0])
        self.out = horizontal / max(float(np.linalg.norm(horizontal)), 1e-9)

    def uv(self, points: np.ndarray) -> np.ndarray:
        """(u, v, depth off the surface) of map points (N, 3)."""
        return (np.asarray(points, dtype=float).reshape(-1, 3) - self.origin) @ self.R

    def section(self, points: np.ndarray) -> np.ndarray:
        """(horizontal distance out of the wall's ground line, height) of map points."""
        p = np.asarray(points, dtype=float).reshape(-1, 3) - self.origin
        return np.column_stack([p @ self.out, p[:, 2]])


def plot_trajectory(rec: Recording, tool_tip_x_m: float, tasks: list[ReportTask]
                    ) -> Figure | None:
    """The three views; None when the recording has neither the flight nor the world."""
    poses = reader.vehicle_poses(rec)
    world = reader.world(rec)
    if not poses and world is None:
        return None
    body = np.array([p for p, _ in poses.values()]).reshape(-1, 3)
    t_tip, tips = reader.tool_tips(rec, tool_tip_x_m)
    view = WallView(world['wall']) if world is not None and world['wall'] else None
    targets = _targets(rec, world)
    fig, (ax_top, ax_face, ax_side) = plt.subplots(1, 3, figsize=(16, 5.2))
    _top_view(ax_top, view, world, targets, body, tips, tasks)
    if view is not None and world is not None:
        _face_view(ax_face, view, world, t_tip, tips, tasks)
        _section_view(ax_side, view, targets, body, tips)
    else:
        for ax in (ax_face, ax_side):
            why = ('the world was not recorded (no plant/scenario)' if world is None
                   else 'a world without a wall: the top view shows it')
            ax.text(0.5, 0.5, why, ha='center', va='center', transform=ax.transAxes)
            ax.set_axis_off()
    fig.tight_layout()
    return fig


def _targets(rec: Recording, world: dict[str, Any] | None) -> dict[str, np.ndarray]:
    """Target id -> its point of interest (map): the world's targets, else the ground
    truth's ('' for the scenario's first target when it has no id)."""
    if world is not None:
        return {o['id']: np.asarray(o['poi_map'], dtype=float) for o in world['objects']
                if o['target'] and o['poi_map'] is not None}
    return {i: poi for i, (poi, _) in reader.target_poses(rec).items()}


def _once(ax: Axes, label: str) -> str | None:
    """``label`` for the first artist of its kind in ``ax``, None (no legend entry) after."""
    return None if label in ax.get_legend_handles_labels()[1] else label


def _label_target(ax: Axes, target_id: str, xy: np.ndarray) -> None:
    ax.plot(xy[0], xy[1], 'r*', ms=12, gid=f'target:{target_id}',
            label=_once(ax, 'target (by id)'))
    ax.annotate(target_id or 'target', (float(xy[0]), float(xy[1])), xytext=(6, 6),
                textcoords='offset points', color='tab:red', fontsize=9, weight='bold')


def _top_view(ax: Axes, view: WallView | None, world: dict[str, Any] | None,
              targets: dict[str, np.ndarray], body: np.ndarray, tips: np.ndarray,
              tasks: list[ReportTask]) -> None:
    walls = [s for s in (world or {}).get('structures', []) if s['kind'] == 'wall']
    for s in (world or {}).get('structures', []):
        if walls and s is walls[0]:
            continue            # the wall below, with its size and pose
        outline = np.asarray(s['footprint_map'], dtype=float)
        outline = np.vstack([outline, outline[:1]])
        low, high = s['height_range_m']
        ax.fill(outline[:, 0], outline[:, 1], color='0.75', ec='k', lw=1.5,
                gid=f"structure:{s['id']}",
                label=f"{s['kind']} {s['id']} ({low:.1f}-{high:.1f} m high)")
    if world is not None:
        for i, obj in enumerate(world['objects']):
            if not obj['target']:
                ax.plot(*np.asarray(obj['centre_map'])[:2], 's', color='0.5', ms=6,
                        gid=f'object:{i}', label=_once(ax, 'other object'))
    if view is not None and world is not None:
        outline = np.vstack([view.corners, view.corners[:1]])
        ax.plot(outline[:, 0], outline[:, 1], 'k-', lw=2.5, gid='wall',
                label=f"wall ({view.width_m:g} x {view.height_m:g} m, yaw "
                      f"{world['wall']['yaw_deg']:g} deg, inclined "
                      f"{world['wall']['inclination_deg']:g} deg)")
    if len(body):
        ax.plot(body[:, 0], body[:, 1], lw=1, label='vehicle')
        ax.plot(body[0, 0], body[0, 1], 'go', ms=6, label='start')
    if len(tips):
        ax.plot(tips[:, 0], tips[:, 1], lw=0.8, label='tool tip')
    for task in tasks:
        if task.kind == 'slide' and task.points_map is not None:
            ax.plot(task.points_map[:, 0], task.points_map[:, 1], '--', lw=2,
                    color=task_colour(task.index), label=f'task {task.index}: slide line')
    for target_id, poi in targets.items():
        _label_target(ax, target_id, poi[:2])
    ax.set_xlabel('x [m]')
    ax.set_ylabel('y [m]')
    ax.set_title('top view (map)')
    ax.axis('equal')
    ax.grid(True)
    ax.legend(fontsize=7, loc='best')


def _face_view(ax: Axes, view: WallView, world: dict[str, Any], t_tip: np.ndarray,
               tips: np.ndarray, tasks: list[ReportTask]) -> None:
    half = view.width_m / 2
    ax.plot([-half, half, half, -half, -half], [0.0, 0.0, view.height_m, view.height_m, 0.0],
            'k-', lw=2.5, gid='wall', label='wall')
    for i, obj in enumerate(world['objects']):
        u, v, s = obj['u_m'], obj['v_m'], obj['size_m'] / 2
        ax.plot([u - s, u + s, u + s, u - s, u - s], [v - s, v - s, v + s, v + s, v - s],
                '-', color='tab:red' if obj['target'] else '0.5', lw=1, gid=f'object:{i}')
        if obj['target'] and obj['poi_map'] is not None:
            _label_target(ax, obj['id'], view.uv(np.asarray(obj['poi_map']))[0, :2])
        else:
            ax.annotate(obj['cls'], (u, v - s), xytext=(0, -10), textcoords='offset points',
                        ha='center', fontsize=7, color='0.4')
    if len(tips):
        uvd = view.uv(tips)
        near = np.abs(uvd[:, 2]) < NEAR_WALL_M
        ax.plot(np.where(near, uvd[:, 0], np.nan), np.where(near, uvd[:, 1], np.nan),
                lw=0.6, color='tab:orange', label=f'tool tip within {NEAR_WALL_M:g} m')
        for task in tasks:
            mask = pushing(task.record, t_tip)
            if not mask.any():
                continue
            colour = task_colour(task.index)
            if task.kind == 'touch':
                u, v = uvd[mask, :2].mean(axis=0)
                ax.plot(u, v, 'x', color=colour, ms=9, mew=2,
                        label=f'task {task.index}: touch {task.target or ""} (mean tip)')
            else:
                ax.plot(uvd[mask, 0], uvd[mask, 1], '-', color=colour, lw=1.5,
                        label=f'task {task.index}: slide (tip)')
    for task in tasks:
        if task.kind == 'slide' and task.points_map is not None:
            line = view.uv(task.points_map)
            ax.plot(line[:, 0], line[:, 1], '--', color=task_colour(task.index), lw=1,
                    label=f'task {task.index}: slide line')
    ax.set_xlabel('u (right along the wall) [m]')
    ax.set_ylabel('v (up the wall) [m]')
    ax.set_title('the wall, seen from in front')
    ax.axis('equal')
    ax.grid(True)
    ax.legend(fontsize=7, loc='best')


def _section_view(ax: Axes, view: WallView, targets: dict[str, np.ndarray],
                  body: np.ndarray, tips: np.ndarray) -> None:
    bottom_top = view.section(view.corners[[0, 3]])
    ax.plot(bottom_top[:, 0], bottom_top[:, 1], 'k-', lw=2.5, gid='wall', label='wall')
    ax.axhline(0.0, color='0.6', lw=1)
    if len(body):
        ax.plot(*view.section(body).T, lw=1, label='vehicle')
    if len(tips):
        ax.plot(*view.section(tips).T, lw=0.8, label='tool tip')
    for target_id, poi in targets.items():
        _label_target(ax, target_id, view.section(poi)[0])
    ax.set_xlabel("out of the wall's ground line (horizontal) [m]")
    ax.set_ylabel('height [m]')
    ax.set_title('section across the wall')
    ax.axis('equal')
    ax.grid(True)
    ax.legend(fontsize=7, loc='best')
