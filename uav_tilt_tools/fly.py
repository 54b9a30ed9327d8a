"""`uav-tilt fly --scenario FILE [--plan FILE]`: one inspection mission (or plan)
in-process, its summary as JSON.

The same cores as the node graph (uav_tilt_tools.inprocess), with the target from the
deployed detector on the rendered camera (``--target-source vision``, the default) or from
ground truth. It prints the ``summary.json`` keys (DESIGN section 7) plus ``failure`` (why
a failed run failed, and in which mode and phase), ``mode_history`` and ``tasks`` (one entry
per task of the plan): how a user checks a world of their own in a minute, and what the
campaign runs for each draw. With ``--plan`` the controller's site (the wall and its target
ids) comes from the scenario, as a survey would give it.
"""
import argparse
import json
import sys
import time

import numpy as np
import yaml

from uav_tilt_common.config import ConfigError, check_value, from_dict
from uav_tilt_control.controller_core import ControllerConfig, plan_of
from uav_tilt_control.mission import MissionConfig
from uav_tilt_sim.plant import PlantCoreConfig
from uav_tilt_sim.scenario import Scenario, load_scenario
from uav_tilt_common import cli_args
from uav_tilt_tools.mcap_bag import check_recording_folder, recording_folder
from uav_tilt_tools.site_params import site_overrides
from uav_tilt_tools.task_metrics import failure_of

# a whole search (mission.search_timeout_s) and an inspection after it
DURATION_S = 210.0
__all__ = ['DURATION_S', 'check_plan', 'check_world', 'default_duration_s', 'fly', 'jsonable',
           'register', 'site_overrides']


def default_duration_s(plan):
    """The simulated time a plan's flight is allowed: DURATION_S a task, plus the time its
    tasks push beyond the default touch's hold (a long hold, a long or slow slide)."""
    hold_s = MissionConfig().hold_time_s
    return sum(DURATION_S + max(0.0, task.contact_s - hold_s) for task in plan)


def fly(scenario, target_source='vision', overrides=None, duration_s=None, model_path='',
        threads=0, record=None):
    """Fly the inspection mission of ``scenario`` (the plan in ``overrides['plan_file']``
    when given) for at most ``duration_s`` (default :func:`default_duration_s`); returns the
    summary dict.

    ``threads``: the detector's (and OpenCV's) thread pool, 0 = the libraries' defaults;
    ``record``: a folder to write the flight to as the recorder writes a run
    (:mod:`uav_tilt_tools.flight_bag`: recording.mcap and rosbag2's metadata.yaml;
    FileExistsError when it holds a recording, :func:`mcap_bag.recording_folder`).
    """
    from uav_tilt_tools.inprocess import camera_vision, run_mission
    values = {'target_source': target_source, **(overrides or {})}
    config = from_dict(ControllerConfig, values)
    if duration_s is None:
        duration_s = default_duration_s(plan_of(config))
    plant_config, vision = PlantCoreConfig(), None
    if target_source == 'vision':
        vision = camera_vision(plant_config, model_path, threads=threads)
    bag = None
    if record is not None:
        from uav_tilt_tools.flight_bag import FlightBag
        bag = FlightBag(recording_folder(record), config, plant_config.camera, vision,
                        own_folder=True)
    start = time.perf_counter()
    try:
        result = run_mission(scenario, config, duration_s=duration_s,
                             plant_config=plant_config, vision=vision, recorder=bag)
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


def check_plan(scenario, plan_file, overrides=None):
    """Validate ``plan_file`` against the site of ``scenario`` (ConfigError when bad);
    returns the controller overrides that fly it: the scenario's site, where ``overrides``
    (the user's) do not say otherwise."""
    overrides = {**site_overrides(scenario), **(overrides or {}), 'plan_file': plan_file}
    plan_of(from_dict(ControllerConfig, overrides))
    return overrides


def check_world(scenario):
    """ConfigError when ``scenario``'s world cannot be flown: it is built once, as the plant
    builds it (a start in the wall is refused there)."""
    from uav_tilt_sim.plant import Plant
    Plant(PlantCoreConfig(), scenario).close()


# Controller parameters that fly's own options set.
OPTION_OF = {'target_source': '--target-source', 'plan_file': '--plan'}


def _overrides(pairs):
    out = {}
    for pair in pairs or ():
        key, sep, text = pair.partition('=')
        if not sep:
            raise ConfigError(f"--set {pair!r}: expected KEY=VALUE")
        if key in OPTION_OF:
            raise ConfigError(f"--set {pair!r}: that is {OPTION_OF[key]}")
        try:
            out[key] = yaml.safe_load(text)
        except yaml.YAMLError as err:
            raise ConfigError(f"--set {pair!r}: {' '.join(str(err).split())}") from None
    return out


def _scenario_seed(text):
    """A seed in the range of a scenario's ``seed`` (argparse's error line when not)."""
    try:
        return check_value(Scenario, 'seed', cli_args.number(int, text))
    except ConfigError as err:
        raise argparse.ArgumentTypeError(str(err)) from None


def register(sub):
    """Add the `fly` sub-command."""
    parser = sub.add_parser('fly', help='one inspection mission in-process (JSON summary)')
    parser.add_argument('--scenario', type=cli_args.path, required=True,
                        help='scenario YAML (DESIGN section 5)')
    parser.add_argument('--target-source', choices=('vision', 'ground_truth'),
                        default='vision')
    parser.add_argument('--seed', type=_scenario_seed, default=None,
                        help="overrides the scenario's seed (wind, noise, textures)")
    parser.add_argument('--hint', type=float, nargs=2, metavar=('U', 'V'), default=None,
                        help="roughly where the target is on the scenario's wall [m]")
    parser.add_argument('--plan', type=cli_args.path, default=None, metavar='FILE',
                        help='an inspection plan (YAML: touch and slide tasks)')
    parser.add_argument('--set', action='append', metavar='KEY=VALUE',
                        help='a controller parameter, e.g. mission.hold_time_s=3')
    parser.add_argument('--record', default=None, metavar='DIR',
                        help='write the flight to DIR/recording.mcap, as the recorder writes a '
                             'run of the node graph (a rosbag2 bag `uav-tilt report DIR` '
                             'reads); a DIR that holds a recording is refused')
    parser.add_argument('--duration', type=cli_args.duration_s, default=None,
                        help=f'simulated seconds allowed (default {DURATION_S:.0f} per task, '
                             f'and the time it pushes beyond a {MissionConfig().hold_time_s:g} s '
                             f'hold)')
    parser.set_defaults(func=_run)


def _run(args):
    try:
        scenario = load_scenario(args.scenario)
        if args.seed is not None:
            scenario.seed = args.seed
        overrides = {**_overrides(args.set)}
        if args.hint is not None and args.plan:
            raise ConfigError('--hint is where the one-touch inspection looks; a plan\'s '
                              'touches say it in their near_uv_m')
        if args.hint is not None:
            # the user's --set site.* wins over the scenario's, as launch.sh's --param
            overrides = {**site_overrides(scenario), **overrides,
                         'site.target_hint_uv_m': [float(v) for v in args.hint]}
        if args.plan:
            overrides = check_plan(scenario, args.plan, overrides)
        plan_of(from_dict(ControllerConfig, overrides))     # one clear line when bad
        check_world(scenario)
        if args.record is not None:
            check_recording_folder(f'--record {args.record}', args.record)
    except (OSError, ConfigError) as err:
        print(f'uav-tilt fly: {err}', file=sys.stderr)
        return 2
    result = fly(scenario, args.target_source, overrides, args.duration, record=args.record)
    print(json.dumps(result, default=jsonable))
    return 0 if result['failure'] is None else 1


def jsonable(value):
    """``json.dumps`` default for numpy values."""
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f'{type(value).__name__} is not JSON serialisable')
