"""Sliding accuracy: one slide with 5 N over speed, surface friction, wall inclination and
the line's direction, in-process (uav-tilt fly), sensor noise as in
config/scenarios/plan.yaml (F/T 0.1 N). ``python -m uav_tilt_tools.bench.slide [--seed S]
[--directions up across pipe_round ...]`` prints one JSON object: ``runs``, one entry per
case with the slide's force RMS error and path RMS and max error
(uav_tilt_tools.metrics.tasks), and ``table``, the same as Markdown.

On the wall lines (1 m) run up it (v) or across it (u): across, the friction's moment
about the wall's normal is a yaw moment, which the rotors' drag torque cannot hold beyond
small frictions. On cylinders (CURVED, a plan's ``on``, the wall replaced by the
cylinder): round a 0.3 m horizontal pipe's side (+-25 deg: the normal pitches through 50
deg), along it (1 m, across), up a 0.3 m vertical pipe's crest (1 m), round a 2 m tank at
constant height (1 m, across). Curved cases run on an upright surface only.
"""
import argparse
import dataclasses
import itertools
import json
import math
import multiprocessing
import os
import pathlib
import tempfile
from typing import Any, Sequence

import numpy as np
import yaml

from uav_tilt_common.config import from_dict
from uav_tilt_sim.scenario import Scenario, check_scenario, load_scenario
from uav_tilt_tools.runner.fly import check_plan, fly

SCENARIO = pathlib.Path(__file__).resolve().parents[2] / 'config' / 'scenarios' / 'plan.yaml'
SPEEDS_M_S = (0.1, 0.2)
FRICTIONS = (0.3, 0.8)
INCLINATIONS_DEG = (0.0, 20.0)
LINES_UV_M = {'up': ([1.3, 1.0], [1.3, 2.0]), 'across': ([0.9, 1.0], [1.9, 1.0])}
FORCE_N = 5.0
PIPE_R_M, TANK_R_M, FACE_X_M = 0.3, 2.0, 2.5
# name -> (the cylinder, its face FACE_X_M ahead of the start; the line's ends (u, v))
CURVED: dict[str, tuple[dict[str, Any], list[float], list[float]]] = {
    'pipe_round': (dict(position_m=[FACE_X_M + PIPE_R_M, 0.0, 1.6], yaw_deg=90.0,
                        radius_m=PIPE_R_M, length_m=4.0),
                   [PIPE_R_M * math.radians(-25.0), 0.0], [PIPE_R_M * math.radians(25.0), 0.0]),
    'pipe_along': (dict(position_m=[FACE_X_M + PIPE_R_M, 0.0, 1.6], yaw_deg=90.0,
                        radius_m=PIPE_R_M, length_m=4.0), [0.0, -0.5], [0.0, 0.5]),
    'vertical_pipe_up': (dict(position_m=[FACE_X_M + PIPE_R_M, 0.0, 2.5], elevation_deg=90.0,
                              radius_m=PIPE_R_M, length_m=5.0),
                         [PIPE_R_M * math.pi / 2, -1.5], [PIPE_R_M * math.pi / 2, -0.5]),
    'tank_round': (dict(position_m=[FACE_X_M + TANK_R_M, 0.0, 2.5], elevation_deg=90.0,
                        radius_m=TANK_R_M, length_m=5.0),
                   [TANK_R_M * math.pi / 2 - 0.5, -1.0], [TANK_R_M * math.pi / 2 + 0.5, -1.0]),
}


def run_case(case: tuple[float, float, float, str, int]) -> dict[str, Any]:
    """One slide: (speed, friction, inclination, direction, seed) -> its results."""
    speed, friction, inclination, direction, seed = case
    base = load_scenario(SCENARIO)
    slide: dict[str, Any] = {'speed_m_s': speed, 'force_n': FORCE_N}
    if direction in CURVED:
        cylinder, start, end = CURVED[direction]
        data = dict(dataclasses.asdict(base), seed=seed, wall=None, objects=[], structures=[
            dict(id='pipe', kind='cylinder', friction=friction, **cylinder)])
        scenario = check_scenario(from_dict(Scenario, data))
        slide['on'] = 'pipe'
    else:
        scenario = dataclasses.replace(base, seed=seed, wall=dataclasses.replace(
            base.wall, friction=friction, inclination_deg=inclination))
        start, end = LINES_UV_M[direction]
    with tempfile.TemporaryDirectory() as folder:
        plan = pathlib.Path(folder) / 'slide.yaml'
        plan.write_text(yaml.safe_dump({'tasks': [{'slide': {
            **slide, 'from_uv_m': start, 'to_uv_m': end}}]}))
        result = fly(scenario, 'ground_truth', check_plan(scenario, str(plan)))
    (slide,) = result['tasks']
    return dict(speed_m_s=speed, friction=friction, inclination_deg=inclination,
                direction=direction, seed=seed, success=slide['success'],
                reason=slide['reason'], force_rms_error_n=slide['force_rms_error_n'],
                path_rms_error_m=slide['path_rms_error_m'],
                path_max_error_m=slide['path_max_error_m'], length_m=slide['length_m'])


def table(runs: list[dict[str, Any]]) -> str:
    """The runs as a Markdown table."""
    lines = ['| line | speed [m/s] | friction | wall [deg] | force RMS error [N] | '
             'path RMS error [cm] | path max error [cm] | outcome |',
             '|---|---|---|---|---|---|---|---|']
    for r in runs:
        cm = (lambda x: '-' if x is None else f'{100 * x:.2f}')
        force = '-' if r['force_rms_error_n'] is None else f"{r['force_rms_error_n']:.3f}"
        wall = '-' if r['direction'] in CURVED else f"{r['inclination_deg']:.0f}"
        lines.append(f"| {r['direction']} | {r['speed_m_s']} | {r['friction']} | "
                     f"{wall} | {force} | {cm(r['path_rms_error_m'])} | "
                     f"{cm(r['path_max_error_m'])} | {'ok' if r['success'] else r['reason']} |")
    return '\n'.join(lines)


def bench_slide(seed: int = 0, directions: Sequence[str] = ('up',), workers: int | None = None
                ) -> dict[str, Any]:
    """Every case of the grid; returns {'runs': [...], 'table': str}."""
    grid = [c for c in itertools.product(SPEEDS_M_S, FRICTIONS, INCLINATIONS_DEG, directions)
            if c[3] not in CURVED or c[2] == 0.0]
    seeds = np.random.default_rng(seed).integers(0, 2**31 - 1, size=len(grid))
    cases = [(*c, int(s)) for c, s in zip(grid, seeds)]
    with multiprocessing.get_context('spawn').Pool(workers or min(2, os.cpu_count() or 1)) \
            as pool:
        runs = pool.map(run_case, cases)
    return dict(runs=runs, table=table(runs))


def main(argv: list[str] | None = None) -> int:
    """Print the benchmark's JSON."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--directions', nargs='+', choices=sorted({*LINES_UV_M, *CURVED}),
                        default=['up'])
    parser.add_argument('--workers', type=int, default=None)
    args = parser.parse_args(argv)
    print(json.dumps(bench_slide(args.seed, tuple(args.directions), args.workers)))
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
