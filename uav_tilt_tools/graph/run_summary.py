"""The key numbers of a recorded run on one line: what launch.sh prints after a recorded
mission (``python -m uav_tilt_tools.graph.run_summary RUN_DIR``).

The numbers are those of ``uav-tilt report`` (:func:`uav_tilt_tools.report.summary.summarize`,
by the recorded truth), without the plots and without writing summary.json; the line says
so. Exit code 0 when a line was printed, 2 with one line on stderr when RUN_DIR holds no
recording.
"""
import sys
from typing import Any

from uav_tilt_common.vehicle import VehicleParams

PREFIX = '[summary]'


def _mm(value: Any) -> str:
    return 'n/a' if not isinstance(value, (int, float)) else f'{value * 1e3:.2f} mm'


def _n(value: Any, digits: int = 2) -> str:
    return 'n/a' if not isinstance(value, (int, float)) else f'{value:.{digits}f} N'


def summary_line(summary: dict[str, Any], run_dir: str) -> str:
    """One line of the summary's verdict and key numbers: POI error, push mean and RMS error
    against the setpoint, mission time; with several tasks, how many went well."""
    failure = summary.get('failure')
    verdict = 'success' if failure is None and summary.get('success') else (
        f"failure: {failure.get('reason')} in {failure.get('mode')}"
        if isinstance(failure, dict) else 'failure')
    parts = [verdict,
             f"POI error {_mm(summary.get('poi_error_m'))} (max "
             f"{_mm(summary.get('poi_error_max_m'))})",
             f"push {_n(summary.get('force_mean_n'))} mean, "
             f"{_n(summary.get('force_rms_error_n'), 3)} RMS error of "
             f"{_n(summary.get('force_setpoint_n'), 1)}"]
    tasks = summary.get('tasks')
    if isinstance(tasks, list) and len(tasks) > 1:
        ok = sum(1 for task in tasks if task.get('success'))
        parts.append(f'{ok} of {len(tasks)} tasks ok (the numbers above: the first touch)')
    mission_s = summary.get('mission_time_s')
    if isinstance(mission_s, (int, float)):
        parts.append(f'mission {mission_s:.1f} s of sim time')
    return (f"{PREFIX} {'; '.join(parts)} (by the recorded truth; `uav-tilt report "
            f"{run_dir}` writes summary.json and the plots)")


def main(argv: list[str] | None = None) -> int:
    """Print :func:`summary_line` of the recording in ``argv[0]``."""
    from uav_tilt_tools.bag import reader
    from uav_tilt_tools.report.summary import summarize
    run_dir = (sys.argv[1:] if argv is None else argv)[0]
    try:
        rec = reader.load_recording(run_dir)
    except reader.RecordingError as err:
        print(f'{PREFIX} no summary: {err}', file=sys.stderr)
        return 2
    print(summary_line(summarize(rec, VehicleParams().tool_tip_x_m), run_dir), flush=True)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
