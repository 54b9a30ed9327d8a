"""The benches of `uav-tilt bench` by name, each run with its default length.

``slide`` is an accuracy bench (:mod:`uav_tilt_tools.bench.slide`), not a speed one.
"""
import os
from typing import Any, Callable

from uav_tilt_tools.bench.control import bench_control
from uav_tilt_tools.bench.graph import bench_graph
from uav_tilt_tools.bench.scale import bench_campaign, bench_gym
from uav_tilt_tools.bench.sim import bench_sim
from uav_tilt_tools.bench.slide import bench_slide

# simulated or wall seconds of each measurement when none is given (None: the campaign's
# whole missions; slide flies whole slides)
DEFAULT_SECONDS: dict[str, float | None] = {
    'sim': 10.0, 'control': 30.0, 'vision': 10.0, 'graph': 20.0, 'campaign': None,
    'campaign_vision': None, 'gym': 10.0, 'slide': 0.0}


def _control(seconds: float) -> dict[str, Any]:
    return bench_control(duration_s=seconds)


def _vision(seconds: float) -> dict[str, Any]:
    # torch (a second to import) only for this bench: the command line imports this module
    # for every command
    from uav_tilt_tools.bench.vision import bench_vision
    return bench_vision(seconds)


def _campaign(seconds: float | None, target_source: str = 'ground_truth',
              runs_per_cpu: int = 2) -> dict[str, Any]:
    return bench_campaign(target_source, (os.cpu_count() or 1) * runs_per_cpu, seconds)


def _campaign_vision(seconds: float | None) -> dict[str, Any]:
    # a vision run costs minutes of CPU: one per core
    return _campaign(seconds, 'vision', runs_per_cpu=1)


def _slide(seconds: float) -> dict[str, Any]:
    return bench_slide()        # each case flies its whole slide: no length to choose


BENCHES: dict[str, Callable[[Any], dict[str, Any]]] = {
    'sim': bench_sim, 'control': _control, 'vision': _vision, 'graph': bench_graph,
    'campaign': _campaign, 'campaign_vision': _campaign_vision, 'gym': bench_gym,
    'slide': _slide}


def run_bench(what: str, seconds: float | None = None) -> dict[str, Any]:
    """The result of bench ``what`` over ``seconds`` (None: its default), in a ROS domain of
    its own."""
    # Benches start node processes: keep them local and away from a running system.
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    os.environ.setdefault('ROS_DOMAIN_ID', str(100 + os.getpid() % 100))
    return BENCHES[what](seconds if seconds is not None else DEFAULT_SECONDS[what])
