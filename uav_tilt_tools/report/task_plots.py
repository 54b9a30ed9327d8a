"""Plots of a recorded plan's slides (see uav_tilt_tools.report.plots): per slide, the push
along the path against the task's force, and the tool tip's path on the wall against the
line."""
import matplotlib
import numpy as np
from matplotlib.figure import Figure

from uav_tilt_tools.bag import reader
from uav_tilt_tools.bag.reader import Recording
from uav_tilt_tools.metrics.tasks import line_uv, pushing, slide_geometry

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402  (after the headless backend is chosen)


def plot_slides(rec: Recording, tool_tip_x_m: float) -> Figure | None:
    """One row per slide of the recorded plan; None without a slide."""
    slides = [t for t in reader.plan_tasks(rec) or () if t['kind'] == 'slide']
    t_s, tips, forces = reader.wrench_series(rec, tool_tip_x_m)
    if not slides or not len(t_s):
        return None
    targets = reader.target_poses(rec)
    fig, axes = plt.subplots(len(slides), 2, figsize=(11, 4 * len(slides)), squeeze=False)
    for (ax_force, ax_path), task in zip(axes, slides):
        normal = targets[''][1][:, 2] if '' in targets else np.asarray(task['normal_map'])
        mask = pushing(task, t_s)
        _, along, uv = slide_geometry(task, tips[mask], normal)
        ax_force.plot(along, forces[mask] @ normal, label='push along the normal')
        ax_force.axhline(task['force_n'], color='k', ls='--', label='task force')
        ax_force.set_xlabel('along the line [m]')
        ax_force.set_ylabel('force [N]')
        ax_force.set_title(f"task {task['index']}: slide at {task.get('speed_m_s')} m/s")
        line = line_uv(task, normal)
        ax_path.plot(line[:, 0], line[:, 1], 'k--', lw=2, label='requested line')
        ax_path.plot(uv[:, 0], uv[:, 1], label='tool tip')
        ax_path.set_xlabel('u (right) [m]')
        ax_path.set_ylabel('v (up) [m]')
        ax_path.set_title('path on the wall')
        ax_path.axis('equal')
        for ax in (ax_force, ax_path):
            ax.grid(True)
            ax.legend()
    fig.tight_layout()
    return fig
