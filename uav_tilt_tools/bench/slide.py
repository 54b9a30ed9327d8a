"""Sliding accuracy: one 1 m slide with 5 N over speed, wall friction, inclination and the
line's direction, in-process (uav-tilt fly), sensor noise as in config/scenarios/plan.yaml
(F/T 0.1 N). ``python -m uav_tilt_tools.bench.slide [--seed S] [--directions up across]``
prints one JSON object: ``runs``, one entry per case with the slide's force RMS error and
path RMS and max error (uav_tilt_tools.metrics.tasks), and ``table``, the same as Markdown.

Lines run up the wall (v) or across it (u): across, the friction's moment about the wall's
normal is a yaw moment, which the rotors' drag torque cannot hold beyond small frictions.
"""
import argparse
import dataclasses
import itertools
import json
import multiprocessing
import os
import pathlib
import tempfile
from typing import Any, Sequence

import numpy as np
import yaml

from uav_tilt_sim.scenario import load_scenario
from uav_tilt_tools.runner.fly import check_plan, fly

SCENARIO = pathlib.Path(__file__).resolve().parents[2] / 'config' / 'scenarios' / 'plan.yaml'
SPEEDS_M_S = (0.1, 0.2)
FRICTIONS = (0.3, 0.8)
INCLINATIONS_DEG = (0.0, 20.0)
LINES_UV_M = {'up': ([1.3, 1.0], [1.3, 2.0]), 'across': ([0.9, 1.0], [1.9, 1.0])}
FORCE_N = 5.0


def run_case(case: tuple[float, float, float, str, int]) -> dict[str, Any]:
    """One slide: (speed, friction, inclination, direction, seed) -> its results."""
    speed, friction, inclination, direction, seed = case
    base = load_scenario(SCENARIO)
    scenario = dataclasses.replace(base, seed=seed, wall=dataclasses.replace(
        base.wall, friction=friction, inclination_deg=inclination))
    start, end = LINES_UV_M[direction]
    with tempfile.TemporaryDirectory() as folder:
        plan = pathlib.Path(folder) / 'slide.yaml'
        plan.write_text(yaml.safe_dump({'tasks': [{'slide': {
            'from_uv_m': start, 'to_uv_m': end, 'speed_m_s': speed, 'force_n': FORCE_N}}]}))
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
        lines.append(f"| {r['direction']} | {r['speed_m_s']} | {r['friction']} | "
                     f"{r['inclination_deg']:.0f} | {force} | {cm(r['path_rms_error_m'])} | "
                     f"{cm(r['path_max_error_m'])} | {'ok' if r['success'] else r['reason']} |")
    return '\n'.join(lines)


def bench_slide(seed: int = 0, directions: Sequence[str] = ('up',), workers: int | None = None
                ) -> dict[str, Any]:
    """Every case of the grid; returns {'runs': [...], 'table': str}."""
    grid = list(itertools.product(SPEEDS_M_S, FRICTIONS, INCLINATIONS_DEG, directions))
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
    parser.add_argument('--directions', nargs='+', choices=sorted(LINES_UV_M), default=['up'])
    parser.add_argument('--workers', type=int, default=None)
    args = parser.parse_args(argv)
    print(json.dumps(bench_slide(args.seed, tuple(args.directions), args.workers)))
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
