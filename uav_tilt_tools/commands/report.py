"""`uav-tilt report RUN_DIR`: summary.json (DESIGN section 7) and PNG plots of a recorded
run (:mod:`uav_tilt_tools.report`), the summary on stdout."""
import argparse
import json
import os
import sys
from typing import Any

from uav_tilt_tools.bag import reader
from uav_tilt_tools.report.write import write_report


def register(sub: 'argparse._SubParsersAction[Any]') -> None:
    """Add the `report` sub-command."""
    parser = sub.add_parser('report', help='summary.json and plots of a recorded run')
    parser.add_argument('run_dir', help='folder with the MCAP recording, or the MCAP file')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Write summary.json and the plots beside the recording; print the summary (stdout:
    the JSON alone). Returns 0 when the run met the inspection bar (``failure`` null), 1
    when it did not (as `uav-tilt fly`), or 2 with one line on stderr when RUN_DIR is no
    folder with one MCAP recording, nor such a file."""
    notes: list[str] = []
    try:
        path = reader.recording_file(args.run_dir)
        rec = reader.load_recording(path, notes=notes)
    except reader.RecordingError as err:
        print(f'uav-tilt report: {err}', file=sys.stderr)
        return 2
    for note in notes:
        print(f'uav-tilt report: {note}', file=sys.stderr)
    summary = write_report(rec, os.path.dirname(path) or '.')
    print(json.dumps(summary))
    return 0 if summary['failure'] is None else 1
