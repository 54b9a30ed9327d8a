"""Plots of a recorded run's tasks (see :mod:`uav_tilt_tools.report.plots`), each task
against its own setpoint and target:

- force.png: the push along the normal over the whole run, each task's hold or slide
  window shaded and its setpoint drawn over it, then one panel per task (its window and a
  second either side);
- poi_error.png: each touch's tool tip against its own target: its distance over the whole
  run (log scale), and over its hold its POI error (along the surface) in millimetres,
  against time and in the target's plane, with the inspection bar's 1 cm;
- slides.png: per slide, the push along the path against the task's force, and the tool
  tip's path on the wall against the line.

The tasks are the recorded plan's (controller/plan); a recording without one gets one touch
of its first target over its HOLD modes, at the controller's ``contact_force_n``. The
artists a test reads carry a ``gid``: ``setpoint:<index>`` (over the whole run),
``poi_error:<index>`` (the hold's error in millimetres).
"""
import dataclasses
import math
from typing import Any

import matplotlib
import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import MultipleLocator

from uav_tilt_common import names
from uav_tilt_common.modes import Mode
from uav_tilt_tools.bag import reader
from uav_tilt_tools.bag.reader import Recording
from uav_tilt_tools.metrics.mission import json_number, mode_samples, runs_of_mode
from uav_tilt_tools.metrics.tasks import (FORCE_MEAN_BAR_N, POI_BAR_M, line_uv, normals_at,
                                          pushing, slide_geometry, slide_normals)

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402  (after the headless backend is chosen)

# Task colours: not the blue and orange of the vehicle's and the tool tip's paths.
COLOURS = ('tab:green', 'tab:red', 'tab:purple', 'tab:brown', 'tab:pink', 'tab:olive',
           'tab:cyan', 'tab:gray')
# The hold's error axis [mm]: at least this tall (the bar and some room above it), at most
# that (so that a millimetre stays readable; a larger error runs off it, the overview shows
# it in full).
ERROR_AXIS_MM = (12.0, 30.0)
# Each task's panel of force.png shows this much of the run either side of its window.
MARGIN_S = 1.0


def task_colour(index: int) -> str:
    """The colour of task ``index`` in every plot."""
    return COLOURS[index % len(COLOURS)]


@dataclasses.dataclass
class ReportTask:
    """A task of the recorded run: ``record`` is its controller/plan entry (its window
    ``t_contact_s``, a slide's ``points_map``)."""

    index: int
    kind: str
    target: str
    force_n: float | None
    record: dict[str, Any]

    @property
    def points_map(self) -> np.ndarray | None:
        """A slide's line (N, 3) in map, or None."""
        points = self.record.get('points_map')
        return None if points is None else np.asarray(points, dtype=float).reshape(-1, 3)

    @property
    def name(self) -> str:
        """'task 1: touch plate_b' or 'task 2: slide'."""
        what = f'touch {self.target}' if self.kind == 'touch' and self.target else self.kind
        return f'task {self.index}: {what}'

    def window(self, t_s: np.ndarray) -> tuple[float, float] | None:
        """(start, end) of its hold or slide in ``t_s`` (the end of the data while it had not
        ended), or None when it did not push."""
        mask = pushing(self.record, t_s)
        return (float(t_s[mask][0]), float(t_s[mask][-1])) if mask.any() else None


def report_tasks(rec: Recording) -> list[ReportTask]:
    """The recorded plan's tasks, or without a plan the one touch of the HOLD modes."""
    plan = reader.plan_tasks(rec)
    if plan is not None:
        return [ReportTask(int(task.get('index', i)), task['kind'], task.get('target') or '',
                           json_number(task.get('force_n')), task)
                for i, task in enumerate(plan)]
    ctrl = reader.statuses(rec, names.CONTROLLER_STATUS)
    hold = runs_of_mode(mode_samples(ctrl), Mode.HOLD)
    if not hold:
        return []
    setpoint = json_number(ctrl[-1][1].get('contact_force_n'))
    # the last sample's stamp included (a task's window ends before its end)
    window = [hold[0][0], hold[-1][1] + 1e-3]
    return [ReportTask(0, 'touch', '', setpoint, dict(kind='touch', target='',
                                                      force_n=setpoint, t_contact_s=window))]


def plot_force(rec: Recording, tasks: list[ReportTask]) -> Figure | None:
    """The push against each task's setpoint over the run, and one panel per task."""
    t, push, magnitude = reader.contact_forces(rec)
    if not len(t):
        return None
    windows = [(task, task.window(t)) for task in tasks]
    shown = [(task, w) for task, w in windows if w is not None]
    cols = 2 if len(shown) > 1 else 1
    rows = math.ceil(len(shown) / cols)
    fig = plt.figure(figsize=(12, 3.8 + 2.8 * rows))
    grid = fig.add_gridspec(1 + rows, cols, height_ratios=[1.5] + [1.0] * rows)
    ax = fig.add_subplot(grid[0, :])
    ax.plot(t, push, color='k', lw=0.7, label='push along the normal (F/T)')
    ax.plot(t, magnitude, color='0.5', lw=0.5, alpha=0.5, label='|F|')
    for task, window in shown:
        colour = task_colour(task.index)
        phase = 'hold' if task.kind == 'touch' else 'slide'
        ax.axvspan(*window, color=colour, alpha=0.15, lw=0, label=f'{task.name} ({phase})')
        if task.force_n is not None:
            ax.plot(window, [task.force_n] * 2, '--', color=colour, lw=1.8,
                    gid=f'setpoint:{task.index}',
                    label=f'task {task.index} setpoint {task.force_n:g} N')
    ax.set_xlabel('sim time [s]')
    ax.set_ylabel('force [N]')
    ax.set_title('push against the setpoint of each task')
    ax.legend(fontsize=7, ncol=2, loc='upper left')
    ax.grid(True)
    for k, (task, (t0, t1)) in enumerate(shown):
        sub = fig.add_subplot(grid[1 + k // cols, k % cols])
        near = (t >= t0 - MARGIN_S) & (t <= t1 + MARGIN_S)
        colour = task_colour(task.index)
        sub.plot(t[near], push[near], color='k', lw=0.7, label='push')
        sub.axvspan(t0, t1, color=colour, alpha=0.15, lw=0)
        if task.force_n is not None:
            sub.plot((t0, t1), [task.force_n] * 2, '--', color=colour, lw=1.8,
                     label=f'setpoint {task.force_n:g} N')
            if task.kind == 'touch':
                sub.axhspan(task.force_n - FORCE_MEAN_BAR_N, task.force_n + FORCE_MEAN_BAR_N,
                            color=colour, alpha=0.2, lw=0,
                            label=f'bar: mean within {FORCE_MEAN_BAR_N:g} N')
        sub.set_title(task.name, fontsize=9)
        sub.set_xlabel('sim time [s]')
        sub.set_ylabel('force [N]')
        sub.legend(fontsize=7, loc='lower center')
        sub.grid(True)
    fig.tight_layout()
    return fig


def plot_poi_error(rec: Recording, tool_tip_x_m: float, tasks: list[ReportTask]
                   ) -> Figure | None:
    """Each touch's tool tip against its own target; None without a touch whose target's
    truth was recorded."""
    targets = reader.target_poses(rec)
    t, tips = reader.tool_tips(rec, tool_tip_x_m)
    scored = [(task, targets[task.target]) for task in tasks
              if task.kind == 'touch' and task.target in targets]
    if not len(t) or not scored:
        return None
    fig = plt.figure(figsize=(12, 7.5))
    grid = fig.add_gridspec(2, 2, width_ratios=[2.0, 1.0])
    ax_run = fig.add_subplot(grid[0, :])
    ax_mm, ax_plane = fig.add_subplot(grid[1, 0]), fig.add_subplot(grid[1, 1])
    largest_mm = 0.0
    for task, (poi, R) in scored:
        colour = task_colour(task.index)
        error = (tips - poi) @ R            # in the target's frame: x_t, y_t along the wall
        along = np.hypot(error[:, 0], error[:, 1])
        name = f'task {task.index} to {task.target or "the target"}'
        distance = np.linalg.norm(error, axis=1)
        ax_run.plot(t, np.maximum(distance, 1e-5), color=colour, lw=0.8, label=name)
        mask = pushing(task.record, t)
        if not mask.any():
            continue
        ax_run.axvspan(t[mask][0], t[mask][-1], color=colour, alpha=0.15, lw=0,
                       label=f'task {task.index} hold')
        held_mm = along[mask] * 1e3
        largest_mm = max(largest_mm, float(held_mm.max()))
        ax_mm.plot(t[mask] - t[mask][0], held_mm, color=colour, lw=1,
                   gid=f'poi_error:{task.index}',
                   label=f'{name}: mean {held_mm.mean():.1f} mm, max {held_mm.max():.1f} mm')
        ax_plane.plot(error[mask, 0] * 1e3, error[mask, 1] * 1e3, '.', ms=2, color=colour,
                      label=f'task {task.index}')
    bar_mm = POI_BAR_M * 1e3
    top_mm = min(max(1.15 * largest_mm, ERROR_AXIS_MM[0]), ERROR_AXIS_MM[1])
    ax_run.axhline(POI_BAR_M, color='k', ls=':', lw=1, label=f'bar {bar_mm:g} mm')
    ax_run.set_yscale('log')
    ax_run.set_ylabel('tool tip to target [m]')
    ax_run.set_xlabel('sim time [s]')
    ax_run.set_title("each touch's tool tip against its own target")
    ax_run.legend(fontsize=7, ncol=2, loc='upper right')
    ax_run.grid(True, which='both', alpha=0.4)
    ax_mm.axhline(bar_mm, color='k', ls='--', lw=1, label=f'inspection bar {bar_mm:g} mm')
    ax_mm.set_ylim(0.0, top_mm)
    ax_mm.yaxis.set_major_locator(MultipleLocator(2.0 if top_mm <= 15.0 else 5.0))
    ax_mm.yaxis.set_minor_locator(MultipleLocator(1.0))
    ax_mm.set_xlabel('time since the hold began [s]')
    ax_mm.set_ylabel('POI error along the wall [mm]')
    ax_mm.set_title('over each hold (millimetres)')
    ax_mm.legend(fontsize=7, loc='upper right')
    ax_mm.grid(True, which='both', alpha=0.4)
    ring = np.linspace(0.0, 2.0 * np.pi, 100)
    ax_plane.plot(bar_mm * np.cos(ring), bar_mm * np.sin(ring), 'k--', lw=1)
    ax_plane.set_xlim(-top_mm, top_mm)
    ax_plane.set_ylim(-top_mm, top_mm)
    ax_plane.set_aspect('equal')
    ax_plane.set_xlabel('x_t (along the wall) [mm]')
    ax_plane.set_ylabel('y_t (up the wall) [mm]')
    ax_plane.set_title('over each hold, on the target')
    ax_plane.grid(True)
    fig.tight_layout()
    return fig


def plot_slides(rec: Recording, tool_tip_x_m: float, tasks: list[ReportTask]
                ) -> Figure | None:
    """One row per slide of the recorded plan; None without a slide."""
    slides = [task.record for task in tasks if task.kind == 'slide']
    t_s, tips, forces, _ = reader.wrench_series(rec, tool_tip_x_m)
    if not slides or not len(t_s):
        return None
    targets = reader.target_poses(rec)
    fig, axes = plt.subplots(len(slides), 2, figsize=(11, 4 * len(slides)), squeeze=False)
    for (ax_force, ax_path), task in zip(axes, slides):
        normals = slide_normals(task, targets[''][1][:, 2] if '' in targets else None)
        mask = pushing(task, t_s)
        _, along, uv = slide_geometry(task, tips[mask], normals)
        colour = task_colour(int(task.get('index', 0)))
        push = np.sum(forces[mask] * normals_at(tips[mask], task, normals), axis=1)
        ax_force.plot(along, push, color=colour, label='push along the normal')
        ax_force.axhline(task['force_n'], color='k', ls='--', label='task force')
        ax_force.set_xlabel('along the line [m]')
        ax_force.set_ylabel('force [N]')
        ax_force.set_title(f"task {task['index']}: slide at {task.get('speed_m_s')} m/s")
        line = line_uv(task, normals)
        ax_path.plot(line[:, 0], line[:, 1], 'k--', lw=2, label='requested line')
        ax_path.plot(uv[:, 0], uv[:, 1], color=colour, label='tool tip')
        ax_path.set_xlabel('u (right) [m]')
        ax_path.set_ylabel('v (up) [m]')
        ax_path.set_title('path on the surface')
        ax_path.axis('equal')
        for ax in (ax_force, ax_path):
            ax.grid(True)
            ax.legend()
    fig.tight_layout()
    return fig
