"""The runs of a campaign: run i flies world seed i of the campaign seed, so that a run's
result depends only on (seed, index), whatever the backend runs it.

Each run is ``uav-tilt fly`` (:func:`uav_tilt_tools.runner.fly.fly`, the same cores as the
nodes) on one draw of :func:`uav_tilt_sim.randomise.random_draw` (with ``structures``, of
:func:`uav_tilt_sim.randomise_structures.structure_draw`); with a plan, on the scenario's
wall and objects under the drawn conditions.
"""
import dataclasses
import os
import tempfile
from typing import Any

import numpy as np

from uav_tilt_sim.randomise import random_draw
from uav_tilt_sim.randomise_structures import structure_draw
from uav_tilt_sim.scenario import Scenario, load_scenario
from uav_tilt_tools.bag.folder import RECORDING_FILE
from uav_tilt_tools.runner.fly import fly
from uav_tilt_tools.runner.site_params import site_overrides

# one run: its index and world seed, and how it flies (see :func:`jobs_of`)
Job = dict[str, Any]


def jobs_of(n: int, seed: int, target_source: str = 'ground_truth',
            duration_s: float | None = None, threads: int = 0, record: bool = False,
            plan_file: str | None = None, scenario_file: str | None = None,
            corners: bool = False, settings: dict[str, Any] | None = None,
            structures: bool = False) -> list[Job]:
    """The ``n`` runs of campaign ``seed``: one world seed each, by run index; ``settings``:
    every run's controller and vehicle parameters (``uav-tilt fly --set``); ``structures``:
    worlds of structure kinds."""
    seeds = np.random.default_rng(seed).integers(0, 2**31 - 1, size=n)
    return [dict(index=i, seed=int(s), target_source=target_source, duration_s=duration_s,
                 threads=threads, record=record, plan_file=plan_file,
                 scenario_file=scenario_file, corners=corners, settings=dict(settings or {}),
                 structures=structures)
            for i, s in enumerate(seeds)]


def with_conditions(scenario: Scenario, drawn: Scenario) -> Scenario:
    """``scenario``'s wall and objects under the seed, wind, noise, mismatch and wall
    contact of the drawn scenario ``drawn`` (a plan's campaign)."""
    wall = dataclasses.replace(scenario.wall, stiffness_n_per_m=drawn.wall.stiffness_n_per_m,
                               friction=drawn.wall.friction)
    return dataclasses.replace(scenario, seed=drawn.seed, wall=wall, wind=drawn.wind,
                               noise=drawn.noise, mismatch=drawn.mismatch)


def run_one(job: Job) -> tuple[dict[str, Any], bytes | None]:
    """One campaign run (top level so that worker processes can pickle it): (the run's
    dict, the bytes of its MCAP recording when ``job['record']``, else None)."""
    kind = None
    if job.get('structures'):
        scenario, kind, hint = structure_draw(job['seed'])
    else:
        scenario, hint = random_draw(job['seed'], job['corners'])
    settings = job.get('settings') or {}
    overrides = {**settings, **(site_overrides(scenario, hint) if hint is not None else {})}
    with tempfile.TemporaryDirectory(prefix='uav_tilt_run_') as tmp:
        if job['plan_file']:
            scenario = with_conditions(load_scenario(job['scenario_file']), scenario)
            hint, overrides = None, {**site_overrides(scenario), **settings,
                                     'plan_file': job['plan_file']}
        result = fly(scenario, job['target_source'], overrides, job['duration_s'],
                     threads=job['threads'], record=tmp if job['record'] else None)
        bag = None
        if job['record']:
            with open(os.path.join(tmp, RECORDING_FILE), 'rb') as stream:
                bag = stream.read()
    result.update(index=job['index'], seed=job['seed'], hint_uv_m=hint, structure=kind,
                  wall_distance_m=float(np.hypot(*scenario.wall.position_m)),
                  wall_yaw_deg=scenario.wall.yaw_deg,
                  wall_inclination_deg=scenario.wall.inclination_deg,
                  wall_stiffness_n_per_m=scenario.wall.stiffness_n_per_m,
                  mass_scale=scenario.mismatch.mass_scale)
    return result, bag
