"""The mission log launch.sh prints (uav_tilt_tools.graph.mission_log), and the line of a
recorded run's numbers (graph.run_summary): from controller statuses as the watcher decodes
them (numbers as floats)."""
import pytest

from uav_tilt_tools.graph.mission_log import MissionLog
from uav_tilt_tools.graph.mission_watch import MissionWatch
from uav_tilt_tools.graph.run_summary import summary_line


def status(t_s, mode, since, **extra):
    values = dict(t_s=t_s, mode=mode, time_in_mode_s=since, phase='', failsafe_reason='',
                  task_index=-1.0, task_count=0.0, task_kind='', task_target='',
                  task_outcomes='', f_normal_n=0.0, contact_force_n=5.0, success=False)
    values.update(extra)
    return values


def plan_statuses():
    """A two-touch plan whose second touch loses its target, at 10 Hz of status."""
    task = dict(task_count=2.0, task_kind='touch')
    first = dict(task, task_index=0.0, task_target='plate_a')
    second = dict(task, task_index=1.0, task_target='plate_b', task_outcomes='ok')
    return [
        dict(mode='WAITING_FOR_SENSORS'),
        status(0.0, 'IDLE', 0.0),
        status(0.4, 'TAKEOFF', 0.35),
        status(5.5, 'HOVER', 0.2, **first),
        status(6.0, 'SEARCH', 0.3, phase='sweep', **first),
        status(20.0, 'HOLD', 0.5, f_normal_n=4.9, **first),
        status(21.0, 'HOLD', 1.5, f_normal_n=5.1, **first),
        status(22.0, 'HOLD', 2.5, f_normal_n=5.0, **first),
        status(25.0, 'RETREAT', 0.1, phase='release', **dict(first, task_outcomes='ok')),
        status(30.0, 'SEARCH', 0.2, phase='sweep', **second),
        status(60.0, 'LAND', 0.4, failsafe_reason='target_not_found',
               **dict(second, task_outcomes='ok,target_not_found')),
        status(66.5, 'IDLE', 0.25, failsafe_reason='target_not_found',
               **dict(second, task_outcomes='ok,target_not_found')),
    ]


def test_one_line_per_mode_change_task_and_failsafe_with_sim_time():
    log, watch, lines = MissionLog(), MissionWatch(), []
    for values in plan_statuses():
        lines += log.update(values)
        watch.update(values)
    assert watch.result is False
    lines.append(log.end(watch.result))
    assert lines == [
        't =    0.00 s  IDLE',
        't =    0.05 s  TAKEOFF',                  # entered: t_s less time_in_mode_s
        't =    5.30 s  HOVER',
        't =    5.50 s  task 1 of 2: touch plate_a',
        't =    5.70 s  SEARCH (sweep)',
        't =   19.50 s  HOLD',
        't =   24.90 s  RETREAT (release)',
        't =   25.00 s  task 1 of 2 (touch plate_a): ok; push 5.00 N mean, 0.082 N RMS error '
        'of 5.0 N (3 status samples)',
        't =   29.80 s  SEARCH (sweep)',
        't =   30.00 s  task 2 of 2: touch plate_b',
        't =   59.60 s  LAND',
        't =   60.00 s  task 2 of 2 (touch plate_b): target_not_found',
        't =   60.00 s  failsafe: target_not_found',
        't =   66.25 s  IDLE',
        'mission ended at t =   66.25 s: failure; 1 of 2 tasks ok; failsafe target_not_found; '
        '66.2 s of sim time from the take-off',
    ]


def test_a_status_repeated_adds_no_line():
    log = MissionLog()
    first = log.update(status(1.0, 'HOVER', 0.5))
    assert first == ['t =    0.50 s  HOVER']
    assert log.update(status(1.1, 'HOVER', 0.6)) == []


@pytest.mark.parametrize('summary, words', [
    (dict(success=True, failure=None, poi_error_m=0.00123, poi_error_max_m=0.0021,
          force_mean_n=4.004, force_rms_error_n=0.031, force_setpoint_n=4.0,
          mission_time_s=44.31, tasks=None),
     ['[summary] success; POI error 1.23 mm (max 2.10 mm); push 4.00 N mean, 0.031 N RMS '
      'error of 4.0 N; mission 44.3 s of sim time', '`uav-tilt report run`']),
    (dict(success=False, failure={'reason': 'contact_lost', 'mode': 'HOLD', 'phase': ''},
          poi_error_m=None, force_mean_n=None, tasks=[{'success': True}, {'success': False}]),
     ['[summary] failure: contact_lost in HOLD; POI error n/a', '1 of 2 tasks ok']),
])
def test_the_recorded_summary_is_one_line_of_its_key_numbers(summary, words):
    line = summary_line(summary, 'run')
    assert '\n' not in line
    for word in words:
        assert word in line, line
