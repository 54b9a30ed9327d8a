"""PNG plots of a recording (:mod:`uav_tilt_tools.bag.reader`); a plot whose data is missing
is left out.

- trajectory.png: the world that was flown and the flight in it
  (:mod:`.world_plots`);
- force.png, poi_error.png, slides.png: each task against its own setpoint and target
  (:mod:`.task_plots`);
- actuators.png: tilts and rotor thrusts;
- vision.png: per frame, target seen or not; vision's image -> pose latency on the wall
  clock (vision/status, as ``vision_latency_ms_p95``).
"""
import os

import matplotlib
import numpy as np
from matplotlib.figure import Figure

from uav_tilt_common import names
from uav_tilt_tools.bag import reader
from uav_tilt_tools.bag.reader import Recording
from uav_tilt_tools.metrics.mission import json_number
from uav_tilt_tools.report import task_plots, world_plots

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402  (after the headless backend is chosen)


def write_plots(rec: Recording, out_dir: str, tool_tip_x_m: float) -> list[str]:
    """Write every plot the recording has data for; returns the paths written."""
    tasks = task_plots.report_tasks(rec)
    plots = (('trajectory.png', lambda: world_plots.plot_trajectory(rec, tool_tip_x_m, tasks)),
             ('force.png', lambda: task_plots.plot_force(rec, tasks)),
             ('actuators.png', lambda: plot_actuators(rec)),
             ('poi_error.png', lambda: task_plots.plot_poi_error(rec, tool_tip_x_m, tasks)),
             ('vision.png', lambda: plot_vision(rec)),
             ('slides.png', lambda: task_plots.plot_slides(rec, tool_tip_x_m, tasks)))
    written = []
    for name, make in plots:
        fig = make()
        if fig is None:
            continue
        path = os.path.join(out_dir, name)
        fig.savefig(path, dpi=100)
        plt.close(fig)
        written.append(path)
    return written


def plot_actuators(rec: Recording) -> Figure | None:
    """Tilt angles and rotor thrusts (measured if recorded, else commanded)."""
    topic = names.ACTUATORS_STATE if rec.get(names.ACTUATORS_STATE) else names.ACTUATORS_CMD
    msgs = [m for _, m in rec.get(topic, ())]
    if not msgs:
        return None
    t = np.array([reader.stamp_s(m) for m in msgs])
    effort = np.array([list(m.effort) for m in msgs])
    position = np.array([list(m.position) for m in msgs])
    fig, (ax_tilt, ax_thrust) = plt.subplots(2, 1, sharex=True, figsize=(10, 6))
    for i, name in enumerate(names.TILT_NAMES, start=len(names.ROTOR_NAMES)):
        ax_tilt.plot(t, np.degrees(position[:, i]), label=name)
    for i, name in enumerate(names.ROTOR_NAMES):
        ax_thrust.plot(t, effort[:, i], label=name)
    ax_tilt.set_ylabel('tilt [deg]')
    ax_thrust.set_ylabel('thrust [N]')
    ax_thrust.set_xlabel('sim time [s]')
    ax_tilt.set_title(topic)
    for ax in (ax_tilt, ax_thrust):
        ax.legend()
        ax.grid(True)
    return fig


def plot_vision(rec: Recording) -> Figure | None:
    """Per frame: target seen or not; and vision's image arrival -> pose publication latency
    (p50, p95 over each vision/status window), measured on the wall clock as
    ``vision_latency_ms_p95`` is (the recording's log times are sim time in a graph run)."""
    t, seen = reader.detections(rec)
    if not len(t):
        return None
    status = [(ts, json_number(v.get('latency_ms_p50')), json_number(v.get('latency_ms_p95')))
              for ts, v in reader.statuses(rec, names.VISION_STATUS)]
    fig, (ax_seen, ax_lat) = plt.subplots(2, 1, sharex=True, figsize=(10, 5))
    ax_seen.step(t, seen, where='post')
    ax_seen.set_yticks([0, 1], ['no target', 'target'])
    for column, (label, style) in enumerate((('p50', '.-'), ('p95', 'o-')), start=1):
        points = [(s[0], s[column]) for s in status if s[column] is not None]
        if points:
            ax_lat.plot(*np.array(points).T, style, ms=3, lw=0.8, label=label,
                        gid=f'latency_{label}')
    if ax_lat.get_lines():
        ax_lat.legend(fontsize=8)
    ax_lat.set_ylabel('image -> pose, wall clock [ms]')
    ax_lat.set_xlabel('sim time [s] (of the vision/status)')
    for ax in (ax_seen, ax_lat):
        ax.grid(True)
    return fig
