"""`uav-tilt bench campaign|campaign_vision|gym`: the scale-out paths on this machine.

campaign*: the same campaign (full missions, ground truth or vision in the loop) with the
local backend and then with a local Ray of as many CPUs, one after the other; runs per
hour of each and the Ray overhead as the ratio of their wall times. gym: steps per second
of ContactInspection-v0 (start='takeoff', the action held, auto-reset) for 1 and 2
environments (a vector across processes), without and with the camera image.
"""
import os
import time
from typing import Any

import numpy as np

from uav_tilt_sim.plant import PlantCoreConfig
from uav_tilt_tools.campaign.run import campaign
from uav_tilt_tools.runner.fly import DURATION_S

SEED = 1


def bench_campaign(target_source: str = 'ground_truth', n: int = 4,
                   duration_s: float | None = None) -> dict[str, Any]:
    """Local then Ray: {backend: {runs_per_hour, wall_s, successes}}, ray_overhead."""
    cpus = os.cpu_count() or 1
    out: dict[str, Any] = dict(target_source=target_source, n=n, cpus=cpus,
                               duration_s=duration_s or DURATION_S)
    for backend in ('local', 'ray'):
        start = time.perf_counter()
        result = campaign(n, SEED, workers=cpus, target_source=target_source,
                          duration_s=out['duration_s'], progress=False, backend=backend)
        wall_s = time.perf_counter() - start
        out[backend] = dict(wall_s=wall_s, runs_per_hour=3600.0 * n / wall_s,
                            successes=result['successes'])
    out['ray_overhead'] = out['ray']['wall_s'] / out['local']['wall_s']
    return out


def _steps_per_s(num_envs: int, camera: bool, seconds: float) -> float:
    # gymnasium is the optional extra uav_tilt[gym], for this bench alone; importing the
    # environment registers its id
    import gymnasium as gym
    from uav_tilt_tools.gym.env import ENV_ID
    options: dict[str, Any] = dict(camera=camera, start='takeoff', episode_s=600.0)
    envs: Any
    if num_envs == 1:
        envs = gym.make(ENV_ID, **options)
    else:
        envs = gym.make_vec(f'uav_tilt_tools.gym.env:{ENV_ID}', num_envs=num_envs,
                            vectorization_mode='async', vector_kwargs={'context': 'spawn'},
                            **options)
    try:
        envs.reset(seed=SEED)
        action = np.zeros(envs.action_space.shape, dtype=np.float32)
        steps, start = 0, time.perf_counter()
        while time.perf_counter() - start < seconds:
            _, _, terminated, truncated, _ = envs.step(action)
            steps += num_envs
            if num_envs == 1 and (terminated or truncated):
                envs.reset()            # (a vector resets by itself)
        return steps / (time.perf_counter() - start)
    finally:
        envs.close()


def bench_gym(seconds: float = 10.0) -> dict[str, Any]:
    """Env steps/s (and the simulated real-time factor) of 1 and 2 envs, camera off/on."""
    from uav_tilt_tools.gym.env import ContactEnvConfig     # gymnasium: as above
    step_s = round(PlantCoreConfig().control_hz / ContactEnvConfig().action_rate_hz) \
        / PlantCoreConfig().control_hz
    out: dict[str, Any] = dict(seconds=seconds, step_sim_s=step_s)
    for camera in (False, True):
        for num_envs in (1, 2):
            rate = _steps_per_s(num_envs, camera, seconds)
            out[f'envs{num_envs}_camera_{"on" if camera else "off"}'] = dict(
                steps_per_s=rate, rtf=rate * step_s)
    return out
