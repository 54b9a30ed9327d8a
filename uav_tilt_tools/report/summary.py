"""summary.json (DESIGN section 7) of a recorded run.

The recording is read by :mod:`uav_tilt_tools.bag.reader` and the mission is scored by
:mod:`uav_tilt_tools.metrics.mission` (as the in-process runs are). This module adds what
only a run of the node graph has, measured on the wall clock:

- ``rtf``: sim time over wall time of the plant (plant/status ``sim_time_s`` and
  ``wall_time_s``, from its first status past sim time 0 to its last: a recorded lockstep
  run waits at sim time 0 for the recorder and the controller, seconds that are not the
  run's, and the controller's rate is counted from its first tick alike).
- ``controller_rate_hz``: control ticks over wall time of the controller (controller/status
  ``ticks`` and ``wall_time_s``, from its first status with a tick to its last), as `uav-tilt
  fly` counts its ticks over the flight's wall time.
- ``vision_fps``, ``vision_latency_ms_p95``: frames processed per second and the 95th
  percentile of image arrival -> pose publication in vision (vision/status ``fps``,
  ``latency_ms_p95``), each the median over the statuses recorded (a node's last status
  may cover a part window only, one sent as the graph stops).

Each is null when the statuses it needs are not recorded.
"""
from typing import Any

import numpy as np

from uav_tilt_common import names
from uav_tilt_tools.bag import reader
from uav_tilt_tools.bag.reader import Recording
from uav_tilt_tools.metrics.mission import (MISSION_KEYS, json_number, mission_summary,
                                            mode_samples)
from uav_tilt_tools.metrics.tasks import failure_of, task_results, with_tasks

# (t_s, {key: value}) of a status topic, :func:`bag.reader.statuses`
Statuses = list[tuple[float, dict[str, Any]]]

RUN_KEYS = ('rtf', 'controller_rate_hz', 'vision_fps', 'vision_latency_ms_p95')
SUMMARY_KEYS = MISSION_KEYS + RUN_KEYS + ('tasks', 'failure')


def per_wall_second(statuses: Statuses, key: str, from_first_count: bool = False
                    ) -> float | None:
    """How fast ``key`` grew over the statuses' ``wall_time_s``, first to last status that
    gives both (from the first where ``key`` is above 0 with ``from_first_count``: a loop's
    ticks, not its wait for sensors), or None. Over the whole span, a loop that slowed for a
    while counts with what it missed, which a median of the statuses' windows would not."""
    given = [(json_number(v.get(key)), json_number(v.get('wall_time_s'))) for _, v in statuses]
    spans = [(n, w) for n, w in given if n is not None and w is not None
             and (n > 0 or not from_first_count)]
    if len(spans) < 2 or spans[-1][1] <= spans[0][1]:
        return None
    return (spans[-1][0] - spans[0][0]) / (spans[-1][1] - spans[0][1])


def median_of(statuses: Statuses, key: str) -> float | None:
    """The median of ``key`` over the (time, values) statuses that give it a number, or
    None."""
    given = [json_number(values.get(key)) for _, values in statuses]
    numbers = [x for x in given if x is not None]
    return float(np.median(numbers)) if numbers else None


def summarize(rec: Recording, tool_tip_x_m: float) -> dict[str, Any]:
    """The summary.json dict (SUMMARY_KEYS); null where the recording lacks the data."""
    ctrl = reader.statuses(rec, names.CONTROLLER_STATUS)
    last = ctrl[-1][1] if ctrl else {}
    vision = reader.statuses(rec, names.VISION_STATUS)
    t_push, push, _ = reader.contact_forces(rec)
    t_tip, tips, axes = reader.tool_poses(rec, tool_tip_x_m)
    target = reader.target_pose(rec)
    poi, normal = (target[0], target[1][:, 2]) if target is not None else (None, None)
    summary = mission_summary(mode_samples(ctrl), last, t_push, push, t_tip, tips, poi,
                              normal, tool_axes_map=axes)
    summary.update(
        rtf=per_wall_second(reader.statuses(rec, names.PLANT_STATUS), 'sim_time_s',
                            from_first_count=True),
        controller_rate_hz=per_wall_second(ctrl, 'ticks', from_first_count=True),
        vision_fps=median_of(vision, 'fps'),
        vision_latency_ms_p95=median_of(vision, 'latency_ms_p95'))
    with_tasks(summary, task_summaries(rec, tool_tip_x_m))
    summary['failure'] = recorded_failure(summary, ctrl)
    return {k: summary[k] if k in MISSION_KEYS + ('tasks', 'failure')
            else json_number(summary[k]) for k in SUMMARY_KEYS}


def recorded_failure(summary: dict[str, Any], ctrl: Statuses) -> dict[str, Any] | None:
    """summary.json ``failure``: why the recorded run missed the inspection bar, judged on
    the truth as the in-process runs are (:func:`metrics.tasks.failure_of`), or None. Without
    a recorded plan the mission's one touch is judged on the summary's own keys; the
    controller's last failsafe reason (a task's failure writes one too, and a failsafe
    after it, such as a retreat held on its way, is what ended the run) is placed in the
    mode and phase of the last status before the statuses that gave it."""
    fired = None
    final = ctrl[-1][1].get('failsafe_reason') if ctrl else ''
    for i in range(len(ctrl) - 1, -1, -1) if final else ():
        if ctrl[i][1].get('failsafe_reason') != final:
            break
        fired = i
    before = ctrl[max(0, fired - 1)][1] if fired is not None else {}
    touch = {'kind': 'touch', 'success': bool(summary['success']), 'reason': '',
             **{k: summary[k] for k in ('poi_error_max_m', 'force_mean_n', 'force_setpoint_n',
                                        'force_rms_error_n')}}
    return failure_of({
        **summary, 'tasks': summary['tasks'] if summary['tasks'] is not None else [touch],
        'failsafe_reason': ctrl[fired][1]['failsafe_reason'] if fired is not None else '',
        'failsafe_where': {'mode': before.get('mode'), 'phase': before.get('phase', '')},
        'mode_history': mode_samples(ctrl)})


def task_summaries(rec: Recording, tool_tip_x_m: float) -> list[dict[str, Any]] | None:
    """summary.json ``tasks``: the recorded plan's results (:mod:`metrics.tasks`, the F/T
    force with the true attitude at its stamp, as for the mission's keys), or None without
    a plan."""
    tasks = reader.plan_tasks(rec)
    if tasks is None:
        return None
    targets = reader.target_poses(rec)
    normal = targets[''][1][:, 2] if '' in targets else None
    t_s, tips, forces, axes = reader.wrench_series(rec, tool_tip_x_m)
    return task_results(tasks, t_s, tips, forces, targets, normal, tool_axis_map=axes)
