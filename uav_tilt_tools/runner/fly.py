"""One inspection mission (or plan) in-process, its summary as ``uav-tilt fly`` prints it.

The same cores as the node graph (:mod:`uav_tilt_tools.runner.inprocess`), with the target
from the deployed detector on the rendered camera (``target_source='vision'``) or from
ground truth. The summary holds the ``summary.json`` keys (DESIGN section 7) plus
``failure`` (why a failed run failed, and in which mode and phase), ``mode_history`` and
``tasks`` (one entry per task of the plan): how a user checks a world of their own in a
minute, and what the campaign runs for each draw.
"""
import time
from typing import TYPE_CHECKING, Any, Iterable

import numpy as np

from uav_tilt_common.config import ConfigError
from uav_tilt_common.vehicle import VehicleParams
from uav_tilt_control.controller_core import plan_of
from uav_tilt_control.mission import MissionConfig
from uav_tilt_sim.plant import Plant, PlantCoreConfig
from uav_tilt_sim.scenario import Scenario, check_target, target_ids
from uav_tilt_tools.bag.flight_bag import FlightBag
from uav_tilt_tools.bag.folder import recording_folder
from uav_tilt_tools.metrics.tasks import failure_of
from uav_tilt_tools.runner.inprocess import Progress, run_mission
from uav_tilt_tools.runner.settings import split_settings
from uav_tilt_tools.runner.site_params import check_reach, obstacle_overrides, site_overrides

if TYPE_CHECKING:     # the vision stack (torch) is imported only for a flight with vision
    from uav_tilt_tools.runner.camera_vision import CameraVision

# a whole search (mission.search.timeout_s) and an inspection after it
DURATION_S = 210.0


def default_duration_s(plan: Iterable[Any]) -> float:
    """The simulated time a plan's flight is allowed: DURATION_S a task, plus the time its
    tasks push beyond the default touch's hold (a long hold, a long or slow slide)."""
    hold_s = MissionConfig().contact.hold_time_s
    return sum(DURATION_S + max(0.0, task.contact_s - hold_s) for task in plan)


def fly(scenario: Scenario, target_source: str = 'vision',
        overrides: dict[str, Any] | None = None, duration_s: float | None = None,
        model_path: str = '', threads: int = 0, record: str | None = None,
        record_images: str = 'none', progress: Progress | None = None) -> dict[str, Any]:
    """Fly the inspection mission of ``scenario`` (the plan in ``overrides['plan_file']``
    when given) for at most ``duration_s`` (default :func:`default_duration_s`); returns the
    summary dict. ``overrides``: the controller's parameters and ``vehicle.*``, the vehicle
    flown and the controller's model of it (:mod:`uav_tilt_tools.runner.settings`).

    ``threads``: the detector's (and OpenCV's) thread pool, 0 = the libraries' defaults;
    ``record``: a folder to write the flight to as the recorder writes a run
    (:mod:`uav_tilt_tools.bag.flight_bag`: recording.mcap and rosbag2's metadata.yaml;
    FileExistsError when it holds a recording, :func:`bag.folder.recording_folder`), with the
    camera images ``record_images`` keeps (``all``, ``thin``, ``none``:
    :mod:`uav_tilt_tools.bag.images`); ``progress``: see :func:`run_mission`.
    """
    # the structures are known as a survey lists them, unless the overrides say otherwise
    values = {'target_source': target_source, **obstacle_overrides(scenario),
              **(overrides or {})}
    config, vehicle = split_settings(values)
    if duration_s is None:
        duration_s = default_duration_s(plan_of(config, vehicle))
    plant_config = PlantCoreConfig(vehicle=vehicle)
    vision: CameraVision | None = None
    if target_source == 'vision':
        # the vision stack (torch) only for a flight that has vision in the loop
        from uav_tilt_tools.runner.camera_vision import camera_vision
        vision = camera_vision(plant_config, model_path, threads=threads)
    bag = None
    if record is not None:
        bag = FlightBag(recording_folder(record), config, plant_config.camera, vision,
                        images=record_images,
                        own_folder=True)
    start = time.perf_counter()
    try:
        result = run_mission(scenario, config, duration_s=duration_s, vehicle=vehicle,
                             plant_config=plant_config, vision=vision, recorder=bag,
                             progress=progress)
        wall_s = time.perf_counter() - start    # of the flight, not of the file's closing
    finally:
        if bag is not None:
            bag.close()
    # the keys of a node graph's summary.json, on this process's wall clock
    result.update(rtf=result['sim_time_s'] / wall_s,
                  controller_rate_hz=result['ticks'] / wall_s, vision_fps=None,
                  vision_latency_ms_p95=None)
    if vision is not None:
        result['vision_fps'] = vision.frames / wall_s
        if vision.latency_ms:
            result['vision_latency_ms_p95'] = float(np.percentile(vision.latency_ms, 95))
    result['failure'] = failure_of(result)
    return result


def check_mission(scenario: Scenario, overrides: dict[str, Any] | None = None,
                  plan_file: str | None = None) -> dict[str, Any]:
    """What :func:`fly` flies, checked before it flies (ConfigError, one line, when bad):
    the plan ``plan_file`` against ``scenario`` (:func:`check_plan`) or, for the one-touch
    inspection, the target the scenario designates; the settings ``overrides`` (the
    controller's and ``vehicle.*``); the world, built once with that vehicle. Returns the
    overrides that fly it."""
    if plan_file:
        overrides = check_plan(scenario, plan_file, overrides)
    else:
        check_target(scenario)
    config, vehicle = split_settings(overrides)
    plan = plan_of(config, vehicle)
    check_reach(scenario, [task.target for task in plan if task.kind == 'touch'],
                config.mission.contact.max_pitch_rad)
    check_world(scenario, vehicle)
    return dict(overrides or {})


def check_plan(scenario: Scenario, plan_file: str, overrides: dict[str, Any] | None = None
               ) -> dict[str, Any]:
    """Validate ``plan_file`` against the site of ``scenario`` (ConfigError when bad): each
    touch names one of the scenario's target ids, even where the user's ``site.target_ids``
    says otherwise. Returns the controller overrides that fly it: the scenario's site, where
    ``overrides`` (the user's) do not say otherwise."""
    overrides = {**site_overrides(scenario), **(overrides or {}), 'plan_file': plan_file}
    ids = target_ids(scenario)
    for i, task in enumerate(plan_of(*split_settings(overrides))):
        if task.kind == 'touch' and task.target not in ids:
            raise ConfigError(f"plan_file '{plan_file}': tasks[{i}] (touch): 'target' = "
                              f"{task.target!r} is not a target of the scenario (its "
                              f"targets with an id: {ids!r})")
    return overrides


def check_world(scenario: Scenario, vehicle: VehicleParams | None = None) -> None:
    """ConfigError when ``scenario``'s world cannot be flown by ``vehicle`` (default
    VehicleParams()): it is built once, as the plant builds it (a start in the wall is
    refused there)."""
    Plant(PlantCoreConfig(vehicle=vehicle or VehicleParams()), scenario).close()


def jsonable(value: Any) -> Any:
    """``json.dumps`` default for numpy values."""
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f'{type(value).__name__} is not JSON serialisable')
