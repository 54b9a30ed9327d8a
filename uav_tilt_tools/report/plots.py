"""PNG plots of a recording (:mod:`uav_tilt_tools.bag.reader`); a plot whose data is missing
is left out."""
import os
from typing import Any

import matplotlib
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from uav_tilt_common import names
from uav_tilt_common.modes import Mode
from uav_tilt_tools.bag import reader
from uav_tilt_tools.bag.reader import Recording
from uav_tilt_tools.metrics.mission import Runs, mode_samples, runs_of_mode
from uav_tilt_tools.report import task_plots

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402  (after the headless backend is chosen)

WALL_HALF_LENGTH_M = 1.5


def write_plots(rec: Recording, out_dir: str, tool_tip_x_m: float) -> list[str]:
    """Write every plot the recording has data for; returns the paths written."""
    ctrl = reader.statuses(rec, names.CONTROLLER_STATUS)
    hold = runs_of_mode(mode_samples(ctrl), Mode.HOLD)
    plots = (('trajectory.png', lambda: plot_trajectory(rec, tool_tip_x_m)),
             ('force.png', lambda: plot_force(rec, ctrl, hold)),
             ('actuators.png', lambda: plot_actuators(rec)),
             ('poi_error.png', lambda: plot_poi_error(rec, tool_tip_x_m, hold)),
             ('vision.png', lambda: plot_vision(rec)),
             ('slides.png', lambda: task_plots.plot_slides(rec, tool_tip_x_m)))
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


def _shade(ax: Axes, runs: Runs) -> None:
    for t0, t1 in runs:
        ax.axvspan(t0, t1, color='tab:green', alpha=0.15, lw=0)


def plot_trajectory(rec: Recording, tool_tip_x_m: float) -> Figure | None:
    """Top (x-y) and side (x-z) views of the vehicle and tool tip, the wall and the POI."""
    poses = reader.vehicle_poses(rec)
    if not poses:
        return None
    body = np.array([p for p, _ in poses.values()])
    _, tips = reader.tool_tips(rec, tool_tip_x_m)
    target = reader.target_pose(rec)
    fig, axes = plt.subplots(1, 2, figsize=(11, 5))
    for ax, (a, b), title in ((axes[0], (0, 1), 'top view'), (axes[1], (0, 2), 'side view')):
        ax.plot(body[:, a], body[:, b], label='vehicle')
        ax.plot(tips[:, a], tips[:, b], label='tool tip', lw=0.8)
        if target is not None:
            poi, R = target
            normal = R[:, 2]
            # The wall's trace in this view's plane through the POI is normal to n.
            along = np.array([-normal[b], normal[a]])
            if np.linalg.norm(along) > 1e-6:
                along /= np.linalg.norm(along)
                ends = np.array([poi[[a, b]] - WALL_HALF_LENGTH_M * along,
                                 poi[[a, b]] + WALL_HALF_LENGTH_M * along])
                ax.plot(ends[:, 0], ends[:, 1], 'k-', lw=3, label='wall')
            ax.plot(poi[a], poi[b], 'r*', ms=12, label='target')
        ax.set_xlabel('xyz'[a] + ' [m]')
        ax.set_ylabel('xyz'[b] + ' [m]')
        ax.set_title(title)
        ax.axis('equal')
        ax.grid(True)
    axes[0].legend()
    return fig


def plot_force(rec: Recording, ctrl: list[tuple[float, dict[str, Any]]], hold: Runs
               ) -> Figure | None:
    """Push along the normal against the setpoint; HOLD shaded."""
    t, push, magnitude = reader.contact_forces(rec)
    if not len(t):
        return None
    setpoint = ctrl[-1][1].get('contact_force_n') if ctrl else None
    fig, ax = plt.subplots(figsize=(10, 4))
    ax.plot(t, push, label='push along the normal (F/T)')
    ax.plot(t, magnitude, lw=0.6, alpha=0.6, label='|F|')
    if isinstance(setpoint, float):
        ax.axhline(setpoint, color='k', ls='--', label='setpoint')
    _shade(ax, hold)
    ax.set_xlabel('sim time [s]')
    ax.set_ylabel('force [N]')
    ax.legend()
    ax.grid(True)
    return fig


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


def plot_poi_error(rec: Recording, tool_tip_x_m: float, hold: Runs) -> Figure | None:
    """Tool tip minus POI in the target frame (z = surface normal); HOLD shaded."""
    target = reader.target_pose(rec)
    t, tips = reader.tool_tips(rec, tool_tip_x_m)
    if target is None or not len(t):
        return None
    poi, R = target
    error = (tips - poi) @ R
    fig, ax = plt.subplots(figsize=(10, 4))
    for i, axis in enumerate('xyz'):
        ax.plot(t, error[:, i], label=f'{axis}_t')
    _shade(ax, hold)
    ax.set_xlabel('sim time [s]')
    ax.set_ylabel('tool tip - POI [m]')
    ax.legend()
    ax.grid(True)
    return fig


def plot_vision(rec: Recording) -> Figure | None:
    """Per frame: target seen or not, and image -> pose latency."""
    t, seen = reader.detections(rec)
    if not len(t):
        return None
    t_lat, latency = reader.frame_latencies_ms(rec)
    fig, (ax_seen, ax_lat) = plt.subplots(2, 1, sharex=True, figsize=(10, 5))
    ax_seen.step(t, seen, where='post')
    ax_seen.set_yticks([0, 1], ['no target', 'target'])
    ax_lat.plot(t_lat, latency, '.', ms=3)
    ax_lat.set_ylabel('image -> pose, recorder clock [ms]')
    ax_lat.set_xlabel('sim time [s]')
    for ax in (ax_seen, ax_lat):
        ax.grid(True)
    return fig
