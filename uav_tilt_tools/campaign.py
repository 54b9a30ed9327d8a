"""`uav-tilt campaign --n N --seed S`: the inspection mission over randomised scenarios.

Runs in-process with the same cores as the nodes (uav_tilt_tools.inprocess), spread over
the CPU cores, and prints JSON (DESIGN section 7): n, successes, success_rate, runs.
Targets come from ground truth by default; ``--target-source vision`` renders the camera
and runs the deployed detector pipeline in each run.
"""
import json
import multiprocessing
import os

import numpy as np

from uav_tilt_common.config import from_dict
from uav_tilt_control.controller_core import ControllerConfig
from uav_tilt_sim.scenario import OBJECT_CLASSES, Scenario, check_scenario

# Randomisation ranges of issue 5 (wall yaw, inclination, gusts, mass mismatch).
WALL_YAW_DEG = 30.0
WALL_INCLINATION_DEG = 15.0
GUST_MAX_M_S = 3.0
MASS_MISMATCH = 0.10


def random_scenario(seed):
    """One randomised, validated scenario drawn from ``seed``."""
    rng = np.random.default_rng(seed)
    yaw = rng.uniform(-WALL_YAW_DEG, WALL_YAW_DEG)
    distance = rng.uniform(2.0, 3.2)
    bearing = np.radians(rng.uniform(-10.0, 10.0))
    target_u, target_v = rng.uniform(-0.4, 0.4), rng.uniform(1.1, 1.9)
    others = [c for c in OBJECT_CLASSES if c != 'bolt_plate']
    objects = [dict(cls='bolt_plate', u_m=target_u, v_m=target_v, target=True)]
    for side in rng.permutation([-1.0, 1.0])[:rng.integers(1, 3)]:
        objects.append(dict(cls=str(rng.choice(others)),
                            u_m=target_u + side * rng.uniform(0.45, 0.8),
                            v_m=rng.uniform(1.0, 2.0)))
    # Mean wind plus gusts whose 3-sigma excursion stays within GUST_MAX_M_S.
    gust_std = rng.uniform(0.0, GUST_MAX_M_S / 3.0)
    heading = rng.uniform(0.0, 2 * np.pi)
    mean = rng.uniform(0.0, GUST_MAX_M_S - 3.0 * gust_std)
    data = dict(
        seed=int(seed),
        wall=dict(position_m=[float(distance * np.cos(bearing)),
                              float(distance * np.sin(bearing))],
                  yaw_deg=float(yaw),
                  inclination_deg=float(rng.uniform(-WALL_INCLINATION_DEG,
                                                    WALL_INCLINATION_DEG))),
        objects=objects,
        wind=dict(mean_m_s=[float(mean * np.cos(heading)), float(mean * np.sin(heading)), 0.0],
                  gust_std_m_s=float(gust_std)),
        noise=dict(imu_gyro_rad_s=float(rng.uniform(0, 0.005)),
                   imu_accel_m_s2=float(rng.uniform(0, 0.1)),
                   odom_pos_m=float(rng.uniform(0, 0.002)),
                   odom_att_rad=float(rng.uniform(0, 0.003)),
                   ft_force_n=float(rng.uniform(0, 0.1)),
                   depth_m=float(rng.uniform(0, 0.003))),
        mismatch=dict(mass_scale=float(rng.uniform(1 - MASS_MISMATCH, 1 + MASS_MISMATCH)),
                      inertia_scale=float(rng.uniform(0.85, 1.15))),
    )
    return check_scenario(from_dict(Scenario, data))


def run_one(job):
    """One campaign run (top level so that worker processes can pickle it)."""
    index, seed, target_source, duration_s = job
    # Imported here so that each worker process builds its own physics server.
    from uav_tilt_sim.plant import PlantCoreConfig
    from uav_tilt_tools.inprocess import camera_vision, run_mission
    scenario = random_scenario(seed)
    config = from_dict(ControllerConfig, {'target_source': target_source})
    plant_config, vision = PlantCoreConfig(), None
    if target_source == 'vision':   # the node's deployed model
        from uav_tilt_common.resources import locate
        from uav_tilt_vision.vision_node import VisionNodeConfig
        vision = camera_vision(plant_config, locate(VisionNodeConfig().model_path))
    result = run_mission(scenario, config, duration_s=duration_s, plant_config=plant_config,
                         vision=vision)
    result.update(index=index, seed=seed, wall_yaw_deg=scenario.wall.yaw_deg,
                  wall_inclination_deg=scenario.wall.inclination_deg,
                  mass_scale=scenario.mismatch.mass_scale)
    if not result['success']:
        result['failure'] = failure_reason(result)
    return result


def failure_reason(result):
    """A one-line reason for a failed run."""
    if result.get('failsafe_reason'):
        return f"failsafe: {result['failsafe_reason']}"
    if result.get('contact_lost'):
        return f"contact lost {result['contact_lost']} times during HOLD"
    last_mode = result['mode_history'][-1][1] if result.get('mode_history') else 'none'
    return f'mission did not complete (last mode {last_mode})'


def campaign(n, seed, workers=None, target_source='ground_truth', duration_s=90.0,
             progress=True):
    """Run ``n`` randomised missions; returns the DESIGN section 7 JSON dict."""
    seeds = np.random.default_rng(seed).integers(0, 2**31 - 1, size=n)
    jobs = [(i, int(s), target_source, duration_s) for i, s in enumerate(seeds)]
    workers = workers or min(n, os.cpu_count() or 1)
    runs = []
    with multiprocessing.get_context('spawn').Pool(workers) as pool:
        results = pool.imap_unordered(run_one, jobs)
        if progress:
            from tqdm import tqdm
            results = tqdm(results, total=n, desc='campaign', unit='run')
        runs.extend(results)
    runs.sort(key=lambda r: r['index'])
    successes = sum(r['success'] for r in runs)
    return dict(n=n, seed=seed, target_source=target_source, successes=successes,
                success_rate=successes / n if n else 0.0, runs=runs)


def register(sub):
    """Add the `campaign` sub-command."""
    parser = sub.add_parser('campaign', help='the mission over randomised scenarios (JSON)')
    parser.add_argument('--n', type=int, default=20)
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--workers', type=int, default=None)
    parser.add_argument('--duration', type=float, default=90.0,
                        help='simulated seconds allowed per mission')
    parser.add_argument('--target-source', choices=('ground_truth', 'vision'),
                        default='ground_truth',
                        help='vision: render the camera and run the deployed detector '
                             '(about 100 s of CPU per run)')
    parser.set_defaults(func=_run)


def _run(args):
    result = campaign(args.n, args.seed, args.workers, args.target_source, args.duration)
    print(json.dumps(result))
    return 0 if result['n'] else 1
