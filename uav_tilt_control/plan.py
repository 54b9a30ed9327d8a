"""Inspection plans: the tasks of one flight, read from YAML, validated against the site and
resolved into map coordinates for the mission.

A plan file holds ``tasks``, a list in which each entry is one kind of task::

    tasks:
      - {touch: {target: plate_a, near_uv_m: [-0.5, 1.4], force_n: 5.0, hold_s: 5.0}}
      - {slide: {from_uv_m: [1.2, 0.9], to_uv_m: [1.2, 1.9], speed_m_s: 0.1, force_n: 5.0}}
      - {slide: {on: tank, from_uv_m: [-0.5, 0.0], to_uv_m: [0.5, 0.0]}}

``touch`` flies to the named target (vision picks the detection nearest ``near_uv_m``) and
pushes with ``force_n`` for ``hold_s``; ``slide`` touches down at ``from_uv_m``, keeps the
push while the tool tip follows the polyline ``from_uv_m``, ``via_uv_m``..., ``to_uv_m`` at
``speed_m_s`` and lifts off at its end. The points are in the coordinates of the surface
``on`` names (:mod:`uav_tilt_control.surfaces`): the site's wall (u right, v up) when it
names none, else one of the site's cylinders, on which a line in (u, v) is a path round
it, along it, or both (the push follows the surface's normal along the path).
Every problem is one ConfigError line naming the task (index and kind) and the field.
"""
import dataclasses
import os
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from uav_tilt_common.config import ConfigError, close_match, from_dict, param, read_yaml
from uav_tilt_common.targets import HINT_ERROR_M
from uav_tilt_control.reach import check_reachable
from uav_tilt_control.site import SiteConfig
from uav_tilt_control.surfaces import Surface, SurfacePath, path_on

UV_RANGE_M = 1000.0
# (low, high, what sets them): the open range a push must lie in, see check_force
ForceRange = tuple[float, float, str]
ON_DOC = ("the surface the points are on: '' (the site's wall) or the id of one of "
          "site.cylinder_ids")
# the range of a task's force_n, from the mission's config (check_force)
FORCE_RANGE = ('more than mission.contact.threshold_n, less than '
               'mission.failsafe.force_limit_n and, without '
               'flight.impedance.contact_feedforward, less than the most the vehicle pushes: '
               'vehicle.mass_kg x flight.impedance.accel_limit_mps2')


@dataclasses.dataclass
class TouchTask:
    """Push a target: its id, roughly where it is on its surface, the push and how long."""

    target: str = param('', doc="the id of one of the scenario's targets (site.target_ids)")
    on: str = param('', doc=ON_DOC)
    near_uv_m: list = param([], lo=-UV_RANGE_M, hi=UV_RANGE_M, items=float,
                            doc=f'(u, v): roughly where the target is on its surface, good to '
                                f'{HINT_ERROR_M:g} m along each axis; the detection of its '
                                f'class nearest it is pushed')
    force_n: float = param(5.0, doc=f'the push along the surface\'s normal over the hold; '
                                    f'{FORCE_RANGE}')
    hold_s: float = param(5.0, hi=600.0,      # more than 0: see _resolve
                          doc='how long the push is held, and scored; more than 0')


@dataclasses.dataclass
class SlideTask:
    """Slide the tool tip along a polyline on a surface, pushing with ``force_n``."""

    on: str = param('', doc=ON_DOC)
    from_uv_m: list = param([], lo=-UV_RANGE_M, hi=UV_RANGE_M, items=float,
                            doc='(u, v): where the tool touches down and the line begins')
    via_uv_m: list = param([], lo=-UV_RANGE_M, hi=UV_RANGE_M, item_length=2,
                           doc='the points (u, v) the line passes through, in order')
    to_uv_m: list = param([], lo=-UV_RANGE_M, hi=UV_RANGE_M, items=float,
                          doc='(u, v): where the line ends and the tool lifts off')
    speed_m_s: float = param(0.1, lo=0.005, hi=0.5,
                             doc='along the line (minimum-jerk speed-up and slow-down at each '
                                 'vertex)')
    force_n: float = param(5.0, doc=f"the push along the surface's normal while sliding; "
                                    f"{FORCE_RANGE}")

    def points_uv(self) -> list[list[float]]:
        """The polyline's vertices, from first to last."""
        return [list(self.from_uv_m), *[list(p) for p in self.via_uv_m], list(self.to_uv_m)]


KINDS = {'touch': TouchTask, 'slide': SlideTask}
REQUIRED = {'touch': ('target', 'near_uv_m'), 'slide': ('from_uv_m', 'to_uv_m')}


@dataclasses.dataclass
class Touch:
    """A touch resolved for the mission. ``target`` '' is the one target of an inspection;
    ``hint_map``/``normal_map``: where it should be and the surface's normal there (None when
    the site does not say)."""

    target: str
    hint_map: np.ndarray | None
    normal_map: np.ndarray | None
    force_n: float
    hold_s: float
    near_uv_m: list | None = None
    kind = 'touch'

    @property
    def contact_s(self) -> float:
        """How long the task pushes: its hold."""
        return self.hold_s

    def describe(self) -> dict[str, Any]:
        """JSON-able description (controller/plan)."""
        return dict(kind=self.kind, target=self.target, force_n=self.force_n,
                    hold_s=self.hold_s, near_uv_m=self.near_uv_m,
                    hint_map=_listed(self.hint_map), normal_map=_listed(self.normal_map))


@dataclasses.dataclass
class Slide:
    """A slide resolved for the mission: its path on the surface (map), sampled densely
    enough to stand for a curved one, with the outward normal at each point."""

    path: SurfacePath
    speed_m_s: float
    force_n: float
    points_uv: list | None = None
    on: str = ''
    kind = 'slide'
    target = ''

    @property
    def points_map(self) -> np.ndarray:
        return self.path.points_map

    @property
    def normals_map(self) -> np.ndarray:
        return self.path.normals_map

    @property
    def normal_map(self) -> np.ndarray:
        """The outward normal where the slide begins."""
        return self.path.normals_map[0]

    @property
    def length_m(self) -> float:
        """Length of the polyline."""
        return self.path.length_m

    @property
    def contact_s(self) -> float:
        """How long the task pushes: the polyline at its speed."""
        return self.length_m / self.speed_m_s

    def describe(self) -> dict[str, Any]:
        """JSON-able description (controller/plan)."""
        return dict(kind=self.kind, target='', on=self.on, force_n=self.force_n,
                    speed_m_s=self.speed_m_s, points_uv=self.points_uv,
                    points_map=_listed(self.points_map), normal_map=_listed(self.normal_map),
                    normals_map=_listed(self.normals_map), length_m=self.length_m)


# a task of a plan, resolved for the mission
Task = Touch | Slide


class LineProgress:
    """How far along a polyline a point that follows it has come, measured along the line.

    A cursor that starts at the point of the line nearest the first position (the first
    such point where several are), then only moves forward, each :meth:`update` to the point
    nearest the new position within ``WINDOW_M`` ahead of it: a line that comes back on
    itself is followed leg by leg (the nearest point of the whole line would fold it back),
    and a point that stays where it started stays there. The vertices and positions are
    points of one space (2-D in the wall's plane, or 3-D: on a surface, a path's points).
    """

    # farther than the tool tip moves between two samples (at most 0.5 m/s: 1.7 mm a
    # control tick)
    WINDOW_M = 0.02

    def __init__(self, vertices: ArrayLike) -> None:
        self._points = np.asarray(vertices, dtype=float)
        legs = np.linalg.norm(np.diff(self._points, axis=0), axis=1)
        self._starts = np.concatenate(([0.0], np.cumsum(legs)))
        self.length_m = float(self._starts[-1])
        self.along_m: float | None = None     # before the first position

    def update(self, p: ArrayLike) -> float:
        """Move the cursor for position ``p``; returns how far along the line it is [m]."""
        p = np.asarray(p, dtype=float)
        if self.along_m is None:
            s0, s1 = 0.0, self.length_m
        else:
            s0, s1 = self.along_m, min(self.along_m + self.WINDOW_M, self.length_m)
        best_m, best_s = np.inf, s0
        for k in range(len(self._points) - 1):
            a_s, b_s = self._starts[k], self._starts[k + 1]
            if b_s < s0 or a_s > s1:
                continue
            a, d, leg = self._points[k], self._points[k + 1] - self._points[k], b_s - a_s
            u = min(max(float((p - a) @ d) / leg, s0 - a_s, 0.0), s1 - a_s, leg)
            distance = float(np.linalg.norm(p - a - d * (u / leg)))
            if distance < best_m:
                best_m, best_s = distance, float(a_s + u)
        self.along_m = best_s
        return best_s


def nearest_on_path(tips: ArrayLike, points: ArrayLike, normals: ArrayLike
                    ) -> tuple[np.ndarray, np.ndarray]:
    """(distance, outward normal there) of the path's point nearest each of ``tips`` (N, 3),
    the path through ``points`` (M, 3) on the surface whose outward normals there are
    ``normals`` (M, 3, or one for all). The distance is along the surface: each leg's in
    the plane across its mean normal, so that a tip pressed into a surface that gives way,
    or lifted off it, is not off the path for it. The normal is interpolated along the leg
    (N, 3)."""
    tips = np.asarray(tips, dtype=float).reshape(-1, 1, 3)
    points = np.asarray(points, dtype=float)
    normals = np.broadcast_to(np.asarray(normals, dtype=float), points.shape)
    a, d = points[:-1], np.diff(points, axis=0)
    n = normals[:-1] + normals[1:]
    n = n / np.linalg.norm(n, axis=1, keepdims=True)
    rel = tips - a                                       # (N, L, 3)
    rel = rel - np.sum(rel * n, axis=2, keepdims=True) * n
    d = d - np.sum(d * n, axis=1, keepdims=True) * n
    u = np.clip(np.sum(rel * d, axis=2) / np.sum(d * d, axis=1), 0.0, 1.0)
    distance = np.linalg.norm(rel - u[:, :, None] * d, axis=2)
    leg = np.argmin(distance, axis=1)
    w = u[np.arange(len(leg)), leg][:, None]
    normal = normals[leg] + w * (normals[leg + 1] - normals[leg])
    return (distance[np.arange(len(leg)), leg],
            normal / np.linalg.norm(normal, axis=1, keepdims=True))


def _listed(array: ArrayLike | None) -> list[Any] | None:
    return None if array is None else np.asarray(array, dtype=float).tolist()


def check_force(name: str, force_n: float, force_range_n: ForceRange) -> None:
    """A push asked for must lie in the open range ``force_range_n`` = (low, high, what
    sets them): felt as contact, under the force limit and within what the vehicle pushes
    (uav_tilt_control.controller_core.force_range_n)."""
    low, high, limits = force_range_n
    if not low < force_n < high:
        raise ConfigError(f"{name} = {force_n!r} must be in ({low:g}, {high:g}) ({limits})")


def one_touch_plan(site: SiteConfig, force_n: float, hold_s: float) -> list[Task]:
    """Today's inspection as a plan: one touch of the target, near the site's hint if any."""
    hint = site.target_hint_map()
    normal = site.normal_map() if hint is not None else None
    return [Touch('', hint, normal, float(force_n), float(hold_s),
                  list(site.target_hint_uv_m) or None)]


def load_plan(path: str | os.PathLike[str], site: SiteConfig, force_range_n: ForceRange,
              lowest_m: float | None = None, tolerance_m: float | None = None,
              max_pitch_rad: float | None = None) -> list[Task]:
    """Read, validate and resolve the plan file ``path`` (see the module docstring).

    ``site``: the SiteConfig the plan is checked against (target ids, surfaces);
    ``force_range_n``: (low, high, what sets them), the open range a task's push must lie in
    (:func:`check_force`); ``lowest_m``:
    the lowest altitude (map z) the mission works at (MissionConfig.lowest_hover_m), which
    a slide's line and a touch's target (its position within the hint's error) must reach;
    ``tolerance_m``: how far the mission lets the tool tip be off a slide's line and short
    of its end (MissionConfig.slide_path_tolerance_m), which a line must be longer than;
    ``max_pitch_rad``: how far the tool pitches (mission.contact.max_pitch_rad), which
    bounds the normals along a slide's path (:mod:`uav_tilt_control.reach`).
    """
    try:
        data = read_yaml(path)
    except ConfigError as err:
        raise ConfigError(f"plan_file '{path}': cannot be read: {err}") from None
    try:
        return parse_plan(data, site, force_range_n, lowest_m, tolerance_m, max_pitch_rad)
    except ConfigError as err:
        raise ConfigError(f"plan_file '{path}': {err}") from None


def parse_plan(data: Any, site: SiteConfig, force_range_n: ForceRange,
               lowest_m: float | None = None, tolerance_m: float | None = None,
               max_pitch_rad: float | None = None) -> list[Task]:
    """Validate and resolve plan ``data`` (as loaded from YAML); see :func:`load_plan`."""
    if not isinstance(data, dict) or set(data) != {'tasks'}:
        keys = sorted(map(str, data)) if isinstance(data, dict) else data
        raise ConfigError(f"a plan is a mapping with the one key 'tasks', not {keys!r}")
    entries = data['tasks']
    if not isinstance(entries, list):
        raise ConfigError(f"'tasks' = {entries!r} must be a list of tasks")
    if not entries:
        raise ConfigError("'tasks' is empty: a plan needs at least one task")
    site.check()
    limits = _Limits(force_range_n, lowest_m, tolerance_m, max_pitch_rad)
    return [_resolve(i, entry, site, limits) for i, entry in enumerate(entries)]


@dataclasses.dataclass
class _Limits:
    """What a task is checked against besides the site (see :func:`load_plan`)."""

    force_range_n: ForceRange
    lowest_m: float | None
    tolerance_m: float | None
    max_pitch_rad: float | None


def _resolve(i: int, entry: Any, site: SiteConfig, limits: _Limits) -> Task:
    where = f'tasks[{i}]'
    if not isinstance(entry, dict) or len(entry) != 1 or next(iter(entry)) not in KINDS:
        close = close_match(str(next(iter(entry))), KINDS) \
            if isinstance(entry, dict) and len(entry) == 1 else None
        raise ConfigError(f"{where} = {entry!r} must be one of "
                          f"{', '.join(f'{{{k}: {{...}}}}' for k in KINDS)}"
                          + (f" (did you mean '{close}'?)" if close else ''))
    kind, body = next(iter(entry.items()))
    task: TouchTask | SlideTask = from_dict(KINDS[kind], body, f'{where}.{kind}.')
    where = f'{where} ({kind})'
    for name in REQUIRED[kind]:
        if not getattr(task, name):
            raise ConfigError(f"{where}: '{name}' is required")
    for name in ('near_uv_m', 'from_uv_m', 'to_uv_m'):
        value = getattr(task, name, None)
        if value is not None and len(value) != 2:
            raise ConfigError(f"{where}: '{name}' = {value!r} must have 2 elements (u, v)")
    check_force(f"{where}: 'force_n'", task.force_n, limits.force_range_n)
    surface = _surface(where, task.on, site)
    off = [(name, uv) for name, uv in _points_named(task) if not surface.on(uv)]
    if off:
        name, uv = off[0]
        raise ConfigError(f"{where}: '{name}' = {uv!r} is off the "
                          f"{_surface_name(task.on)} ({surface.extent()})")
    if limits.lowest_m is not None:
        _check_low(where, task, surface, limits.lowest_m)
    if isinstance(task, TouchTask):
        return _touch(where, task, site, surface)
    points = task.points_uv()
    for k in range(1, len(points)):
        if np.allclose(points[k], points[k - 1]):
            raise ConfigError(f"{where}: point {k} of the line {points!r} repeats the one "
                              f"before it")
    slide = Slide(path_on(surface, points), task.speed_m_s, task.force_n, points, task.on)
    if limits.lowest_m is not None and slide.points_map[:, 2].min() < limits.lowest_m:
        k = int(np.argmin(slide.points_map[:, 2]))
        raise ConfigError(f"{where}: the line {points!r} dips to z = "
                          f"{slide.points_map[k, 2]:.2f} m round the {_surface_name(task.on)}, "
                          f"below the lowest the mission works at, {limits.lowest_m:g} m "
                          f"(mission.land.ground_z_m + 2 mission.land.detect_height_m)")
    if limits.max_pitch_rad is not None:
        # the normal that leans furthest from horizontal along the path
        k = int(np.argmax(np.abs(slide.normals_map[:, 2])))
        check_reachable(f"{where}: the line {points!r}", slide.normals_map[k],
                        limits.max_pitch_rad)
    if limits.tolerance_m is not None and slide.length_m <= limits.tolerance_m:
        # a tool tip that never moved would be within the tolerance of its end
        raise ConfigError(f"{where}: the line {points!r} is {slide.length_m:.3g} m long, no "
                          f"longer than the tolerance the slide is held to, "
                          f"{limits.tolerance_m:g} m (mission.slide.path_tolerance_m)")
    return slide


def _surface(where: str, on: str, site: SiteConfig) -> Surface:
    """The surface ``on`` names on ``site`` (ConfigError naming the task when none)."""
    if on and on not in site.cylinder_ids:
        close = close_match(on, site.cylinder_ids)
        raise ConfigError(f"{where}: 'on' = {on!r} is not one of site.cylinder_ids "
                          f"{list(site.cylinder_ids)!r}"
                          + (f" (did you mean '{close}'?)" if close else ''))
    if not on and not site.wall_size_known:
        raise ConfigError(f"{where}: the site's wall is needed (site.wall_position_m, "
                          f"site.wall_width_m, site.wall_height_m), or 'on' naming one of "
                          f"site.cylinder_ids")
    return site.surface(on)


def _surface_name(on: str) -> str:
    return f'cylinder {on!r}' if on else 'wall'


def _check_low(where: str, task: TouchTask | SlideTask, surface: Surface,
               lowest_m: float) -> None:
    # a touch's target may lie the hint's error above the point the plan gives
    slack_m = HINT_ERROR_M if isinstance(task, TouchTask) else 0.0
    low = [(name, uv) for name, uv in _points_named(task)
           if surface.point_map(uv)[2] + slack_m < lowest_m]
    if low:
        name, uv = low[0]
        z = surface.point_map(uv)[2]
        slack = f" less the hint's error, {slack_m:g} m" if slack_m else ''
        raise ConfigError(f"{where}: '{name}' = {uv!r} is at z = {z:.2f} m, below "
                          f"{lowest_m - slack_m:g} m: the lowest the mission works at, "
                          f"{lowest_m:g} m (mission.land.ground_z_m + 2 "
                          f"mission.land.detect_height_m){slack}")


def _touch(where: str, task: TouchTask, site: SiteConfig, surface: Surface) -> Touch:
    if task.hold_s <= 0.0:
        raise ConfigError(f"{where}: 'hold_s' = {task.hold_s!r} must be more than 0: a "
                          f"touch is scored by its push over the hold")
    if not site.target_ids:
        raise ConfigError(f"{where}: 'target' = {task.target!r}: the site names no "
                          f"target (site.target_ids is empty); a plan names a target "
                          f"by its 'id', which a scenario's target objects need "
                          f"(e.g. id: plate_a)")
    if task.target not in site.target_ids:
        raise ConfigError(f"{where}: 'target' = {task.target!r} is not one of "
                          f"site.target_ids {list(site.target_ids)!r}")
    return Touch(task.target, surface.point_map(task.near_uv_m),
                 surface.normal_map(task.near_uv_m), task.force_n, task.hold_s,
                 list(task.near_uv_m))


def _points_named(task: TouchTask | SlideTask) -> list[tuple[str, list[float]]]:
    if isinstance(task, TouchTask):
        return [('near_uv_m', list(task.near_uv_m))]
    return ([('from_uv_m', list(task.from_uv_m))]
            + [(f'via_uv_m[{k}]', list(p)) for k, p in enumerate(task.via_uv_m)]
            + [('to_uv_m', list(task.to_uv_m))])
