"""`uav-tilt report RUN_DIR`: summary.json (DESIGN section 7) and PNG plots of a recorded
run (:mod:`uav_tilt_tools.report`), the summary on stdout."""
import argparse
import json
import os
import sys
from typing import Any

from uav_tilt_common import cli_args
from uav_tilt_tools.bag import reader
from uav_tilt_tools.progress import FileProgress, on_terminal
from uav_tilt_tools.report.write import write_report


def register(sub: 'argparse._SubParsersAction[Any]') -> None:
    """Add the `report` sub-command."""
    parser = cli_args.add_command(
        sub, 'report', 'summary.json and plots of a recorded run',
        'summary.json and PNG plots of a recorded run, written beside the recording; the\n'
        'summary on stdout, progress on stderr when it is a terminal. Exit 0 when the run\n'
        'met the inspection bar, 1 when not, 2 when RUN_DIR holds no recording.')
    parser.add_argument('run_dir', metavar='RUN_DIR',
                        help='folder with the MCAP recording, or the MCAP file')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Write summary.json and the plots beside the recording; print the summary (stdout:
    the JSON alone). Returns 0 when the run met the inspection bar (``failure`` null), 1
    when it did not (as `uav-tilt fly`), or 2 with one line on stderr when RUN_DIR is no
    folder with one MCAP recording, nor such a file."""
    notes: list[str] = []
    # reading a large recording takes a while: a bar on a terminal, none in a pipe
    progress = FileProgress('reading') if on_terminal() else None
    try:
        path = reader.recording_file(args.run_dir)
        rec = reader.load_recording(path, notes=notes, progress=progress)
    except reader.RecordingError as err:
        print(f'uav-tilt report: {err}', file=sys.stderr)
        return 2
    finally:
        if progress is not None:
            progress.close()
    for note in notes:
        print(f'uav-tilt report: {note}', file=sys.stderr)
    summary = write_report(rec, os.path.dirname(path) or '.')
    print(json.dumps(summary))
    return 0 if summary['failure'] is None else 1
