"""`uav-tilt fly --scenario FILE`: one inspection mission in-process, its summary as JSON.

The same cores as the node graph (uav_tilt_tools.inprocess), with the target from the
deployed detector on the rendered camera (``--target-source vision``, the default) or from
ground truth. It prints the ``summary.json`` keys (DESIGN section 7) plus ``failure`` (why
a failed run failed, and in which mode and phase) and ``mode_history``: how a user checks a
world of their own in a minute, and what the campaign runs for each draw.
"""
import json
import sys
import time

import numpy as np
import yaml

from uav_tilt_common.config import ConfigError, from_dict, to_flat
from uav_tilt_common.modes import Mode
from uav_tilt_control.controller_core import ControllerConfig
from uav_tilt_sim.plant import PlantCoreConfig
from uav_tilt_sim.scenario import load_scenario

DURATION_S = 150.0


def site_overrides(scenario, hint_uv_m=None):
    """Controller parameters that give it the scenario's wall as a survey would, and the
    hint (u, v on that wall) when there is one."""
    wall = scenario.wall
    out = {'site.wall_position_m': [float(v) for v in wall.position_m],
           'site.wall_yaw_deg': float(wall.yaw_deg),
           'site.wall_inclination_deg': float(wall.inclination_deg)}
    if hint_uv_m is not None:
        out['site.target_hint_uv_m'] = [float(v) for v in hint_uv_m]
    return out


def fly(scenario, target_source='vision', overrides=None, duration_s=DURATION_S,
        model_path=None, threads=0, record=None):
    """Fly the inspection mission of ``scenario``; returns the summary dict.

    ``threads``: the detector's (and OpenCV's) thread pool, 0 = the libraries' defaults;
    ``record``: an MCAP path to write the flight to, as the recorder would
    (:mod:`uav_tilt_tools.flight_bag`).
    """
    from uav_tilt_tools.inprocess import camera_vision, run_mission
    values = {'target_source': target_source, **(overrides or {})}
    config = from_dict(ControllerConfig, values)
    plant_config, vision = PlantCoreConfig(), None
    if target_source == 'vision':
        from uav_tilt_common.resources import locate
        from uav_tilt_vision.vision_node import VisionNodeConfig
        vision = camera_vision(plant_config, model_path or locate(VisionNodeConfig().model_path),
                               threads=threads)
    bag = None
    if record is not None:
        from uav_tilt_tools.flight_bag import FlightBag
        bag = FlightBag(record, config, plant_config.camera, vision)
    start = time.perf_counter()
    try:
        result = run_mission(scenario, config, duration_s=duration_s,
                             plant_config=plant_config, vision=vision, recorder=bag)
    finally:
        if bag is not None:
            bag.close()
    wall_s = time.perf_counter() - start
    result['rtf'] = result['sim_time_s'] / wall_s
    result['controller_rate_hz'] = result['ticks'] / wall_s
    if vision is not None:
        result['vision_fps'] = vision.frames / wall_s
    result['failure'] = None if result['success'] else failure_of(result)
    return result


def failure_of(result):
    """Why a run failed, as {'reason', 'mode', 'phase'}: the failsafe that ended it and
    where it fired, else what kept it from completing."""
    reason = result.get('failsafe_reason')
    where = result.get('failsafe_where') or {}
    if not reason:
        if result.get('contact_lost'):
            reason = 'contact_lost'
            where = {'mode': Mode.HOLD.value, 'phase': ''}
        else:
            last = result['mode_history'][-1][1] if result.get('mode_history') else 'none'
            reason, where = 'not_completed', {'mode': last, 'phase': ''}
    return {'reason': reason, 'mode': where.get('mode'), 'phase': where.get('phase')}


def _overrides(pairs):
    out = {}
    for pair in pairs or ():
        key, sep, text = pair.partition('=')
        if not sep:
            raise ConfigError(f"--set {pair!r}: expected KEY=VALUE")
        out[key] = yaml.safe_load(text)
    return out


def register(sub):
    """Add the `fly` sub-command."""
    parser = sub.add_parser('fly', help='one inspection mission in-process (JSON summary)')
    parser.add_argument('--scenario', required=True, help='scenario YAML (DESIGN section 5)')
    parser.add_argument('--target-source', choices=('vision', 'ground_truth'),
                        default='vision')
    parser.add_argument('--seed', type=int, default=None,
                        help="overrides the scenario's seed (wind, noise, textures)")
    parser.add_argument('--hint', type=float, nargs=2, metavar=('U', 'V'), default=None,
                        help="roughly where the target is on the scenario's wall [m]")
    parser.add_argument('--set', action='append', metavar='KEY=VALUE',
                        help='a controller parameter, e.g. mission.hold_time_s=3')
    parser.add_argument('--duration', type=float, default=DURATION_S,
                        help='simulated seconds allowed')
    parser.set_defaults(func=_run)


def _run(args):
    try:
        scenario = load_scenario(args.scenario)
        if args.seed is not None:
            scenario.seed = args.seed
        overrides = {**_overrides(args.set)}
        if args.hint is not None:
            overrides.update(site_overrides(scenario, args.hint))
        to_flat(from_dict(ControllerConfig, overrides))     # one clear line when bad
    except (OSError, ConfigError) as err:
        print(f'uav-tilt fly: {err}', file=sys.stderr)
        return 2
    result = fly(scenario, args.target_source, overrides, args.duration)
    print(json.dumps(result, default=jsonable))
    return 0 if result['success'] else 1


def jsonable(value):
    """``json.dumps`` default for numpy values."""
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f'{type(value).__name__} is not JSON serialisable')
