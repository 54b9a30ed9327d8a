"""The inspection mission's metrics, in one place for `uav-tilt report` (from a recording)
and the in-process runner and campaign (from their per-tick log). Pure numpy.

Inputs are time series in sim time: the controller's mode (from controller/status or each
tick), its last status, the F/T force with the true attitude at the same stamp, and the
true tool tip. Each key means one thing (DESIGN section 7):

- ``success``, ``contact_lost``: what the controller's last status says.
- ``force_setpoint_n``: the push the controller was asked for (its status key
  ``contact_force_n``); None when the status does not say.
- ``force_mean_n``, ``force_rms_error_n``: the push over HOLD, measured by the F/T sensor
  along the true surface normal (positive pushing); the error is against the setpoint.
- ``max_force_n``: the largest such push over the whole run.
- ``poi_error_m``, ``poi_error_max_m``: mean and largest distance from the true tool tip
  to the true point of interest over HOLD, along the surface (a wall that gives way lets the
  tip sink in along the normal; that depth is not an error of where it touches).
- ``tool_normal_angle_deg``, ``tool_normal_angle_max_deg``: mean and largest angle over
  HOLD between the tool's axis (base_link x, true attitude) and the true surface normal,
  into the surface: a probe that reads only when it sits square needs it small.
- ``hold_time_s``: sim time in HOLD, each run from its first sample to its last (with a
  plan, :func:`metrics.tasks.with_tasks` puts the first touch's here, which is measured the
  same way over its hold window); ``mission_time_s``: from leaving IDLE to being
  back in IDLE (or to the last sample).

The modes are samples of the controller's status (:func:`mode_samples`: each tick in
process, 10 Hz in a recording) with the time each mode was entered. HOLD is each run of
consecutive samples in that mode, from its first to its last sample.
"""
import math
from typing import Any, Iterable, Sequence

import numpy as np
import numpy.typing as npt

from uav_tilt_common.modes import NOT_FLYING, Mode
from uav_tilt_control import frames

# (t_s, mode) samples of the controller's mode, and the (t_first, t_last) runs of one mode
ModeSamples = list[tuple[float, Any]]
Runs = list[tuple[float, float]]

MISSION_KEYS = ('success', 'poi_error_m', 'poi_error_max_m', 'force_setpoint_n',
                'force_mean_n', 'force_rms_error_n', 'max_force_n', 'contact_lost',
                'tool_normal_angle_deg', 'tool_normal_angle_max_deg', 'hold_time_s',
                'mission_time_s')


def mode_samples(statuses: Iterable[tuple[float, dict[str, Any]]]) -> ModeSamples:
    """[(t_s, mode)] of the controller's ``(t_s, status)``, with a sample at the time a
    mode was entered (its ``time_in_mode_s`` before the first status that shows it, no
    earlier than the status before): a recording's statuses come at 10 Hz, the controller
    changes mode on a control tick, and the runner's and the recording's modes then start
    and end on the same tick."""
    out: ModeSamples = []
    for t, values in statuses:
        mode, since = values.get('mode'), json_number(values.get('time_in_mode_s'))
        if out and out[-1][1] != mode and since is not None:
            entered = max(t - since, out[-1][0])
            if entered < t:
                out.append((entered, mode))
        out.append((t, mode))
    return out


def runs_of_mode(modes: Iterable[tuple[float, Any]], mode: Any) -> Runs:
    """[(t_first, t_last)] of each run of consecutive ``(t_s, mode)`` samples in ``mode``:
    strictly inside the mode, whatever the sample rate."""
    runs: Runs = []
    start: float | None = None
    last = 0.0
    for t, current in modes:
        if current == mode:
            start = t if start is None else start
            last = t
        elif start is not None:
            runs.append((start, last))
            start = None
    if start is not None:
        runs.append((start, last))
    return runs


def inside(t: npt.ArrayLike, runs: Runs) -> np.ndarray:
    """Boolean mask of the times ``t`` inside any of ``runs``."""
    t = np.asarray(t, dtype=float)
    mask = np.zeros(t.shape, dtype=bool)
    for t0, t1 in runs:
        mask |= (t >= t0) & (t <= t1)
    return mask


def push_along_normal(R_map_base: npt.ArrayLike, force_ee: npt.ArrayLike,
                      R_map_target: npt.ArrayLike) -> float:
    """Push on the wall [N] of an F/T force (ee_link axes, FLU like base_link): the force
    on the tool in map along the target's normal z_t, which is positive when pushing."""
    return float((np.asarray(R_map_base) @ np.asarray(force_ee, dtype=float))
                 @ np.asarray(R_map_target)[:, 2])


def poi_errors_m(tips_map: npt.ArrayLike, poi_map: npt.ArrayLike,
                 normal_map: npt.ArrayLike | None = None) -> np.ndarray:
    """Distance [m] of each true tool tip (N, 3) from the POI, along the surface when
    ``normal_map`` is given (the tip's depth into a wall that gives way is no POI error)."""
    offsets = np.asarray(tips_map, dtype=float).reshape(-1, 3) - poi_map
    if normal_map is not None:
        n = np.asarray(normal_map, dtype=float)
        offsets = offsets - np.outer(offsets @ n, n)
    return np.linalg.norm(offsets, axis=1)


def tool_normal_angles_deg(tool_axes_map: npt.ArrayLike, normal_map: npt.ArrayLike
                           ) -> np.ndarray:
    """Angle [deg] between each tool axis (N, 3; unit, pointing from the vehicle to the tip)
    and the inward surface normal -``normal_map``."""
    axes = np.asarray(tool_axes_map, dtype=float).reshape(-1, 3)
    cosine = axes @ -frames.unit(normal_map) / np.linalg.norm(axes, axis=1)
    return np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0)))


def mission_time_s(modes: Sequence[tuple[float, Any]]) -> float | None:
    """Sim time from leaving IDLE to being back in IDLE (or the last sample); None if the
    vehicle never flew."""
    flying = [i for i, (_, m) in enumerate(modes) if m not in NOT_FLYING]
    if not flying:
        return None
    start = modes[flying[0]][0]
    back = [t for t, m in modes[flying[0]:] if m == Mode.IDLE]
    return (back[0] if back else modes[-1][0]) - start


def mission_summary(modes: Sequence[tuple[float, Any]], status: dict[str, Any],
                    t_push: npt.ArrayLike, push_n: npt.ArrayLike, t_tip: npt.ArrayLike,
                    tips_map: npt.ArrayLike, poi_map: npt.ArrayLike | None,
                    normal_map: npt.ArrayLike | None = None,
                    tool_axes_map: npt.ArrayLike | None = None) -> dict[str, Any]:
    """The MISSION_KEYS dict; None where the inputs lack the data.

    ``modes``: [(t_s, mode)]; ``status``: the controller's last status {key: value};
    ``t_push``, ``push_n``: F/T push samples (:func:`push_along_normal`); ``t_tip``,
    ``tips_map``: true tool tip positions (N, 3); ``poi_map``: the true POI or None, and
    ``normal_map`` the surface normal there; ``tool_axes_map``: the true tool axis at each
    tool tip sample (N, 3), or None.
    """
    hold = runs_of_mode(modes, Mode.HOLD)
    push_n = np.asarray(push_n, dtype=float)
    held = push_n[inside(t_push, hold)]
    tips_map = np.asarray(tips_map, dtype=float).reshape(-1, 3)
    errors = np.zeros(0)
    if poi_map is not None:
        errors = poi_errors_m(tips_map[inside(t_tip, hold)], poi_map, normal_map)
    angles = np.zeros(0)
    if tool_axes_map is not None and normal_map is not None:
        axes = np.asarray(tool_axes_map, dtype=float).reshape(-1, 3)[inside(t_tip, hold)]
        angles = tool_normal_angles_deg(axes, normal_map) if len(axes) else angles
    setpoint = json_number(status.get('contact_force_n'))
    success, lost = status.get('success'), json_number(status.get('contact_lost'))
    summary = dict(
        success=success if isinstance(success, bool) else None,
        poi_error_m=float(errors.mean()) if len(errors) else None,
        poi_error_max_m=float(errors.max()) if len(errors) else None,
        force_setpoint_n=setpoint,
        force_mean_n=float(held.mean()) if len(held) else None,
        force_rms_error_n=(float(np.sqrt(np.mean((held - setpoint) ** 2)))
                           if len(held) and setpoint is not None else None),
        max_force_n=float(push_n.max()) if len(push_n) else None,
        contact_lost=int(lost) if lost is not None else None,
        tool_normal_angle_deg=float(angles.mean()) if len(angles) else None,
        tool_normal_angle_max_deg=float(angles.max()) if len(angles) else None,
        hold_time_s=float(sum(t1 - t0 for t0, t1 in hold)) if hold else None,
        mission_time_s=mission_time_s(modes),
    )
    return {k: (v if isinstance(v, (bool, int, type(None))) else json_number(v))
            for k, v in summary.items()}


def json_number(x: Any) -> float | None:
    """JSON-safe float: None for missing, non-numeric or non-finite (bools are not numbers)."""
    if isinstance(x, (int, float, np.number)) and not isinstance(x, bool) \
            and math.isfinite(float(x)):
        return float(x)
    return None
