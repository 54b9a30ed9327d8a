"""What `uav-tilt report` leaves beside a recording: summary.json (:mod:`.summary`) and
the PNG plots (:mod:`.plots`)."""
import json
import os
from typing import Any

from uav_tilt_common.vehicle import VehicleParams
from uav_tilt_tools.bag.reader import Recording
from uav_tilt_tools.report.summary import summarize


def write_report(rec: Recording, folder: str) -> dict[str, Any]:
    """Write summary.json and the plots of ``rec`` into ``folder``; returns the summary."""
    # matplotlib (half a second) only when a report is written: the command line imports
    # this module for every command
    from uav_tilt_tools.report.plots import write_plots
    tool_tip_x_m = VehicleParams().tool_tip_x_m
    summary = summarize(rec, tool_tip_x_m)
    with open(os.path.join(folder, 'summary.json'), 'w', encoding='utf-8') as stream:
        json.dump(summary, stream, indent=2)
    write_plots(rec, folder, tool_tip_x_m)
    return summary
