"""`uav-tilt fly --scenario FILE [--plan FILE]`: one inspection mission (or plan)
in-process, its summary as JSON (:func:`uav_tilt_tools.runner.fly.fly`).

With ``--plan`` or ``--hint`` the controller's site (the wall and its target ids) comes from
the scenario, as a survey would give it, except what ``--set site.*`` says.
"""
import argparse
import json
import sys
from typing import Any

import yaml

from uav_tilt_common import cli_args
from uav_tilt_common.config import ConfigError, check_value, from_dict
from uav_tilt_control.controller_core import ControllerConfig, plan_of
from uav_tilt_control.mission import MissionConfig
from uav_tilt_sim.scenario import Scenario, load_scenario
from uav_tilt_tools.bag.folder import check_recording_folder
from uav_tilt_tools.runner.fly import DURATION_S, check_plan, check_world, fly, jsonable
from uav_tilt_tools.runner.site_params import site_overrides

# Controller parameters that fly's own options set.
OPTION_OF = {'target_source': '--target-source', 'plan_file': '--plan'}


def _overrides(pairs: list[str] | None) -> dict[str, Any]:
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


def _scenario_seed(text: str) -> int:
    """A seed in the range of a scenario's ``seed`` (argparse's error line when not)."""
    try:
        return check_value(Scenario, 'seed', cli_args.number(int, text))
    except ConfigError as err:
        raise argparse.ArgumentTypeError(str(err)) from None


def register(sub: 'argparse._SubParsersAction[Any]') -> None:
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
                        help='a controller parameter, e.g. mission.contact.hold_time_s=3')
    parser.add_argument('--record', default=None, metavar='DIR',
                        help='write the flight to DIR/recording.mcap, as the recorder writes a '
                             'run of the node graph (a rosbag2 bag `uav-tilt report DIR` '
                             'reads); a DIR that holds a recording is refused')
    parser.add_argument('--duration', type=cli_args.duration_s, default=None,
                        help=f'simulated seconds allowed (default {DURATION_S:.0f} per task, '
                             f'and the time it pushes beyond a '
                             f'{MissionConfig().contact.hold_time_s:g} s hold)')
    parser.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
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
