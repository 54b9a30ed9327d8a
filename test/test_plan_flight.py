"""The shipped inspection plan in-process with vision in the loop (the nodes' cores and the
deployed detector): two touches on two look-alike bolt plates named by id and a 1 m slide
at 0.1 m/s with 5 N, on a vertical wall and on one inclined 20 degrees, F/T noise 0.1 N.
Every task succeeds. Touches meet the demo's bar (tool tip within 1 cm of the point of
interest along the surface, the push within 0.1 N mean and 0.2 N RMS of the task's force);
the slide keeps the push within 0.3 N RMS and the tool tip within 1 cm RMS of the line;
contact is never lost. Seeds (textures, noise) are drawn fresh and printed on failure."""
import dataclasses
import json
import multiprocessing
import os
import pathlib
import subprocess
import sys

import numpy as np
import pytest

from uav_tilt_sim.scenario import load_scenario
from uav_tilt_tools.runner.fly import check_plan, fly

REPO = pathlib.Path(__file__).resolve().parent.parent
MODEL = REPO / 'models' / 'detector_int8.onnx'
SCENARIO = REPO / 'config' / 'scenarios' / 'plan.yaml'
PLAN = REPO / 'config' / 'plans' / 'inspection.yaml'
SEEDS = np.random.default_rng().integers(0, 2**31 - 1, size=2)
INCLINATIONS_DEG = (0.0, 20.0)

pytestmark = [pytest.mark.skipif(not MODEL.is_file(), reason='no committed detector weights'),
              pytest.mark.slow]     # minutes of missions: handed out first


def _world(inclination_deg, seed):
    base = load_scenario(SCENARIO)
    assert base.noise.ft_force_n == 0.1
    return dataclasses.replace(base, seed=int(seed), wall=dataclasses.replace(
        base.wall, inclination_deg=inclination_deg))


def _fly(job):
    inclination_deg, seed, record = job
    scenario = _world(inclination_deg, seed)
    return inclination_deg, fly(scenario, 'vision', check_plan(scenario, str(PLAN)),
                                model_path=MODEL, record=record)


@pytest.fixture(scope='module')
def bag_dir(tmp_path_factory):
    """Where the vertical wall's flight is recorded, as `campaign --record` records it."""
    return tmp_path_factory.mktemp('plan_flight')


@pytest.fixture(scope='module')
def flights(bag_dir):
    """inclination -> summary of the plan's flight, the two flown side by side."""
    records = [str(bag_dir), None]
    jobs = list(zip(INCLINATIONS_DEG, SEEDS, records))
    with multiprocessing.get_context('spawn').Pool(min(2, os.cpu_count() or 1)) as pool:
        return dict(pool.imap_unordered(_fly, jobs))


@pytest.mark.parametrize('inclination_deg', INCLINATIONS_DEG)
def test_two_touches_and_a_slide_with_vision_in_the_loop(flights, inclination_deg):
    result = flights[inclination_deg]
    details = f'inclination {inclination_deg} deg (seeds {SEEDS.tolist()}): {result}'
    assert result['success'], details
    touches = [t for t in result['tasks'] if t['kind'] == 'touch']
    slides = [t for t in result['tasks'] if t['kind'] == 'slide']
    assert [t['target'] for t in touches] == ['plate_a', 'plate_b'] and len(slides) == 1
    for task in result['tasks']:
        assert task['success'] and task['contact_lost'] == 0, details
    for task in touches:
        assert task['poi_error_max_m'] <= 0.01, details
        assert task['force_mean_n'] == pytest.approx(task['force_setpoint_n'], abs=0.1), details
        assert task['force_rms_error_n'] <= 0.2, details
    (slide,) = slides
    assert slide['force_setpoint_n'] == 5.0
    assert slide['force_rms_error_n'] <= 0.3, details
    assert slide['path_rms_error_m'] <= 0.01, details
    # the whole line, at 0.1 m/s plus the speed-up and slow-down
    assert slide['length_m'] == pytest.approx(1.0, abs=0.01), details
    assert 10.0 <= slide['duration_s'] <= 13.0, details


def test_the_recorded_plan_flight_reports_what_the_flight_did(flights, bag_dir):
    """`uav-tilt report` of the in-process recording: the same tasks, verdict and metrics
    as the flight's own summary (both measure the F/T push and the true tool tip), and the
    run's timing."""
    flown = flights[INCLINATIONS_DEG[0]]
    done = subprocess.run([sys.executable, '-m', 'uav_tilt_tools.cli', 'report', str(bag_dir)],
                          cwd=REPO, capture_output=True, text=True, timeout=300)
    assert done.returncode == (0 if flown['failure'] is None else 1), done.stderr
    reported = json.loads(done.stdout)
    assert reported['success'] == flown['success'] and reported['failure'] == flown['failure']
    assert [(t['kind'], t.get('target'), t['success']) for t in reported['tasks']] == \
        [(t['kind'], t.get('target'), t['success']) for t in flown['tasks']]
    for mine, theirs in zip(reported['tasks'], flown['tasks']):
        for key in ('force_mean_n', 'force_rms_error_n'):
            assert mine[key] == pytest.approx(theirs[key], abs=0.02), (key, mine, theirs)
    # touches' POI error and the first touch's keys at the top, as in the flight's summary
    assert reported['poi_error_max_m'] == pytest.approx(flown['poi_error_max_m'], abs=1e-3)
    # sim over wall time, ticks over wall time: of the flight, not of the file's closing
    assert reported['rtf'] == pytest.approx(flown['rtf'], rel=0.05)
    assert reported['controller_rate_hz'] == pytest.approx(flown['controller_rate_hz'], rel=0.05)
