"""Per-task results of a plan (summary.json ``tasks``), from the truth of a flight.

One place for both the in-process summary (uav_tilt_tools.runner.inprocess) and the report
of a recording (uav_tilt_tools.report.summary). Inputs are plain arrays on one time base:
the tool tip (map) and the contact force on the vehicle (map), with the plan as
``controller/plan`` carries it (each task's description and its TaskRecord: kind, success,
reason, contact_lost, t_contact_s = [start, end] of HOLD or SLIDE, ...).

- touch: over the hold, the tool tip's distance from the target's point of interest along
  the surface (``poi_error_m``, ``poi_error_max_m``), the push's mean and RMS error against
  the task's force, the tool axis's angle from the surface normal
  (``tool_normal_angle_deg``, ``tool_normal_angle_max_deg``); a touch the controller
  completed that misses the inspection bar (:func:`missed_bar`), or that nothing could
  score (no truth of its target, no push measured: 'unscored'), is no success, its reason
  the bar's;
- slide: over the slide, the push's RMS error, the tool tip's distance from the requested
  path along the surface (``path_rms_error_m``, ``path_max_error_m``), the length of path
  it covered, measured along the line as the mission measures it (``length_m``,
  :class:`uav_tilt_control.plan.LineProgress`: a line that comes back on itself does not
  fold), and the time it took (``duration_s``).

The push is the contact force along the surface's outward normal (positive pushing): the
true wall's for a touch and for a slide on the wall, the site's along a slide's path on a
cylinder (its ``normals_map``).
"""
from typing import Any, Iterable, Sequence

import numpy as np
import numpy.typing as npt

from uav_tilt_common.modes import Mode
from uav_tilt_control import frames
from uav_tilt_control.plan import LineProgress, nearest_on_path
from uav_tilt_tools.metrics.mission import tool_normal_angles_deg

# The inspection bar (DESIGN section 7): over the hold, the true tool tip within 1 cm of the
# point of interest along the surface, and the push within 0.1 N mean and 0.2 N RMS of the
# task's force.
POI_BAR_M = 0.01
FORCE_MEAN_BAR_N = 0.1
FORCE_RMS_BAR_N = 0.2
# A task the controller completed that the truth cannot judge (no target truth, no tool tip
# or push measured over it): never a success.
UNSCORED = 'unscored'
# a target's truth: (POI in map, R_map_target)
Truth = tuple[np.ndarray, np.ndarray]


def task_results(tasks: Iterable[dict[str, Any]], t_s: npt.ArrayLike, tip_map: npt.ArrayLike,
                 force_map: npt.ArrayLike, targets: dict[str, Truth] | None = None,
                 wall_normal_map: npt.ArrayLike | None = None,
                 tool_axis_map: npt.ArrayLike | None = None) -> list[dict[str, Any]]:
    """One dict per task.

    ``tasks``: controller/plan's task entries; ``t_s`` (N,), ``tip_map`` (N, 3),
    ``force_map`` (N, 3), ``tool_axis_map`` (N, 3, the tool's axis; None: not known): the
    truth on one time base; ``targets``: target id ('' = the first target) ->
    (poi_map, R_map_target) of the truth; ``wall_normal_map``: the true outward normal of
    the wall (None: the plan's, i.e. the site's).
    """
    t_s = np.asarray(t_s, dtype=float)
    tip_map = np.asarray(tip_map, dtype=float).reshape(-1, 3)
    force_map = np.asarray(force_map, dtype=float).reshape(-1, 3)
    axes = None if tool_axis_map is None else np.asarray(tool_axis_map,
                                                         dtype=float).reshape(-1, 3)
    out = []
    for task in tasks:
        entry = dict(index=task.get('index'), kind=task['kind'],
                     success=task.get('success') is True, reason=task.get('reason') or '',
                     contact_lost=int(task.get('contact_lost') or 0),
                     force_setpoint_n=task.get('force_n'))
        mask = pushing(task, t_s)
        if task['kind'] == 'touch':
            entry.update(target=task.get('target', ''),
                         **_touch(task, t_s[mask], tip_map[mask], force_map[mask],
                                  (targets or {}).get(task.get('target', '')), wall_normal_map,
                                  None if axes is None else axes[mask]))
        else:
            normals = slide_normals(task, wall_normal_map)
            tips = tip_map[mask]
            push = np.sum(force_map[mask] * normals_at(tips, task, normals), axis=1)
            entry.update(_slide(task, t_s[mask], tips, push, normals))
        missed = entry['success'] and missed_bar(entry)
        if missed:
            # completed by the controller, yet off the bar by the truth (a push that fell
            # short of its force, a press on a look-alike), or with no truth to judge by
            entry.update(success=False, reason=missed)
        out.append(entry)
    return out


def missed_bar(task: dict[str, Any]) -> str | None:
    """Why a task the controller completed is no success by the truth: a touch
    'off_target' (the tool tip pressed elsewhere, such as on a look-alike) or
    'force_off_setpoint'; :data:`UNSCORED` for a touch without its POI error or push (no
    truth of its target: none designated, a real vehicle) or a slide without its path
    error; None when it meets the bar (a slide: has its scores)."""
    if task['kind'] != 'touch':
        return UNSCORED if task.get('path_max_error_m') is None else None
    mean_n, rms_n = task['force_mean_n'], task['force_rms_error_n']
    if task['poi_error_max_m'] is None or mean_n is None:
        return UNSCORED
    if task['poi_error_max_m'] > POI_BAR_M:
        return 'off_target'
    if abs(mean_n - task['force_setpoint_n']) > FORCE_MEAN_BAR_N or rms_n > FORCE_RMS_BAR_N:
        return 'force_off_setpoint'
    return None


def first_missed_bar(tasks: Iterable[dict[str, Any]] | None) -> str | None:
    """The :func:`missed_bar` reason of the first of ``tasks`` that misses the bar, or None."""
    return next((m for m in map(missed_bar, tasks or ()) if m), None)


def failure_of(result: dict[str, Any]) -> dict[str, Any] | None:
    """Why a run missed the inspection bar, as {'reason', 'mode', 'phase'}, or None when it
    met it: the failsafe that ended it (the controller's last failsafe reason: a task's
    failure writes one too) and where it fired, else what kept it from
    completing; for a run the controller completed, the first task that the truth puts
    off the bar or cannot score (:func:`missed_bar`, in HOLD or SLIDE). `uav-tilt fly`,
    `uav-tilt report` and the campaign all judge a run by this."""
    if result['success']:
        for task in result.get('tasks') or ():
            missed = missed_bar(task)
            if missed:
                mode = Mode.HOLD if task['kind'] == 'touch' else Mode.SLIDE
                return {'reason': missed, 'mode': mode.value, 'phase': ''}
        return None
    reason = result.get('failsafe_reason')
    where = result.get('failsafe_where') or {}
    failed = [t for t in result.get('tasks', ()) if not t['success'] and t['reason']]
    if not reason and failed:
        mode = Mode.HOLD if failed[0]['kind'] == 'touch' else Mode.SLIDE
        reason, where = failed[0]['reason'], {'mode': mode.value, 'phase': ''}
    if not reason:
        if result.get('contact_lost'):
            reason = 'contact_lost'
            where = {'mode': Mode.HOLD.value, 'phase': ''}
        else:
            last = result['mode_history'][-1][1] if result.get('mode_history') else 'none'
            reason, where = 'not_completed', {'mode': last, 'phase': ''}
    return {'reason': reason, 'mode': where.get('mode'), 'phase': where.get('phase')}


# A recording's stamps are whole nanoseconds, a task record's times the controller's own
# floats: a sample within this of a bound is the sample at it (ticks are 3.3 ms apart).
STAMP_TOLERANCE_S = 1e-6


def pushing(task: dict[str, Any], t_s: np.ndarray) -> np.ndarray:
    """Samples of the task's HOLD or SLIDE: start <= t < end (the end of the data while it
    had not ended), to STAMP_TOLERANCE_S."""
    window = task.get('t_contact_s')
    if not window or window[0] is None:
        return np.zeros(t_s.shape, dtype=bool)
    end = np.inf if window[1] is None else window[1]
    return (t_s >= window[0] - STAMP_TOLERANCE_S) & (t_s < end - STAMP_TOLERANCE_S)


def _normal(task: dict[str, Any], wall_normal_map: npt.ArrayLike | None) -> np.ndarray:
    normal = wall_normal_map if wall_normal_map is not None else task.get('normal_map')
    return frames.unit(normal if normal is not None else [0.0, 0.0, 1.0])


def _force_stats(push: np.ndarray, force_n: float) -> dict[str, float | None]:
    if not len(push):
        return dict(force_mean_n=None, force_rms_error_n=None)
    return dict(force_mean_n=float(push.mean()),
                force_rms_error_n=float(np.sqrt(np.mean((push - force_n) ** 2))))


def _touch(task: dict[str, Any], t_s: np.ndarray, tips: np.ndarray, forces: np.ndarray,
           truth: Truth | None, wall_normal_map: npt.ArrayLike | None,
           axes: np.ndarray | None) -> dict[str, Any]:
    out = dict(poi_error_m=None, poi_error_max_m=None, hold_time_s=None, hold_tip_map=None,
               tool_normal_angle_deg=None, tool_normal_angle_max_deg=None,
               **_force_stats(np.zeros(0), 0.0))
    if truth is not None:
        normal = truth[1][:, 2]
    else:
        normal = _normal(task, wall_normal_map)
    if not len(t_s):
        return out
    out.update(_force_stats(forces @ normal, task['force_n']),
               hold_time_s=float(t_s[-1] - t_s[0]),
               hold_tip_map=tips.mean(axis=0).tolist())
    if truth is not None:
        # along the surface: a wall that gives way lets the tip sink in along the normal
        offsets = tips - truth[0]
        errors = np.linalg.norm(offsets - np.outer(offsets @ normal, normal), axis=1)
        out.update(poi_error_m=float(errors.mean()), poi_error_max_m=float(errors.max()))
        if axes is not None:
            angles = tool_normal_angles_deg(axes, normal)
            out.update(tool_normal_angle_deg=float(angles.mean()),
                       tool_normal_angle_max_deg=float(angles.max()))
    return out


def slide_normals(task: dict[str, Any], wall_normal_map: npt.ArrayLike | None
                  ) -> np.ndarray:
    """The outward normal a slide is judged against: one (3,) on the wall (the true wall's
    when given), else the site's at each point of its path (M, 3)."""
    if task.get('on') and task.get('normals_map'):
        return np.asarray(task['normals_map'], dtype=float)
    return _normal(task, wall_normal_map)


def normals_at(tips: npt.ArrayLike, task: dict[str, Any], normals: np.ndarray) -> np.ndarray:
    """The normal of :func:`slide_normals` at each tool tip (N, 3): at the path's point
    nearest it, interpolated between the path's points."""
    tips = np.asarray(tips, dtype=float).reshape(-1, 3)
    if normals.ndim == 1:
        return np.broadcast_to(normals, tips.shape)
    return nearest_on_path(tips, task['points_map'], normals)[1]


def slide_geometry(task: dict[str, Any], tips: npt.ArrayLike, normals: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(distance from the path along the surface, how far along it the tips have come
    (:class:`LineProgress`), tips in the (u, v) of the plane the path starts in) of each
    tool tip (N, 3) of slide ``task``, in their order; ``normals``: :func:`slide_normals`.
    On a wall (u, v) are the wall's coordinates; round a cylinder they are its tangent
    plane's where the path begins."""
    points = np.asarray(task['points_map'], dtype=float)
    first = normals if normals.ndim == 1 else normals[0]
    # the path's own frame: x along the surface (horizontal), y up it, as a wall's (u, v)
    R, origin = frames.target_frame_from_normal(points[0], first)
    uv0 = np.asarray(task.get('points_uv') or [[0.0, 0.0]], dtype=float)[0]
    tips = np.asarray(tips, dtype=float).reshape(-1, 3)
    distance = nearest_on_path(tips, points, normals)[0] if len(tips) else np.zeros(0)
    progress = LineProgress(points)
    along = np.array([progress.update(tip) for tip in tips])
    uv = uv0 + ((tips - origin) @ R)[:, :2]
    return distance, along, uv


def line_uv(task: dict[str, Any], normals: np.ndarray) -> np.ndarray:
    """The requested path's points in the (u, v) of :func:`slide_geometry`."""
    points = np.asarray(task['points_map'], dtype=float)
    return slide_geometry(task, points, normals)[2]


def _slide(task: dict[str, Any], t_s: np.ndarray, tips: np.ndarray, push: np.ndarray,
           normals: np.ndarray) -> dict[str, Any]:
    out = dict(path_rms_error_m=None, path_max_error_m=None, length_m=0.0, duration_s=0.0,
               line_length_m=task.get('length_m'), **_force_stats(push, task['force_n']))
    if not len(t_s):
        return out
    distance, along, _ = slide_geometry(task, tips, normals)
    out.update(path_rms_error_m=float(np.sqrt(np.mean(distance ** 2))),
               path_max_error_m=float(distance.max()),
               length_m=float(along[-1] - along[0]), duration_s=float(t_s[-1] - t_s[0]))
    return out


# The first touch's keys that summary.json also has at its top level (metrics.mission).
FIRST_TOUCH_KEYS = ('poi_error_m', 'poi_error_max_m', 'force_setpoint_n', 'force_mean_n',
                    'force_rms_error_n', 'tool_normal_angle_deg', 'tool_normal_angle_max_deg',
                    'hold_time_s', 'hold_tip_map')


def with_tasks(summary: dict[str, Any], tasks: Sequence[dict[str, Any]] | None
               ) -> dict[str, Any]:
    """``summary`` (a :mod:`metrics.mission` summary) with the plan's ``tasks`` (None: no plan
    recorded) and, with a plan, its touch keys (:data:`FIRST_TOUCH_KEYS`) from the first
    touch alone (None without a touch): over every HOLD they would mix targets and
    setpoints, and the top level then says what its task says (the one-touch inspection is
    a plan of one touch). Returns ``summary``."""
    summary['tasks'] = tasks
    if tasks:
        touches = [task for task in tasks if task['kind'] == 'touch']
        for key in FIRST_TOUCH_KEYS:
            if key in summary:
                summary[key] = touches[0].get(key) if touches else None
    return summary
