"""`uav-tilt fly --scenario FILE [--plan FILE]`: one inspection mission (or plan)
in-process, its summary as JSON (:func:`uav_tilt_tools.runner.fly.fly`).

With ``--plan`` or ``--hint`` the controller's site (the wall and its target ids) comes from
the scenario, as a survey would give it, except what ``--set site.*`` says.
"""
import argparse
import json
import sys
from typing import Any

from uav_tilt_common import cli_args
from uav_tilt_common.config import ConfigError, check_value
from uav_tilt_control.mission import MissionConfig
from uav_tilt_sim.scenario import Scenario, load_scenario
from uav_tilt_tools.bag import images
from uav_tilt_tools.bag.folder import check_recording_folder
from uav_tilt_tools.progress import SimProgress, on_terminal
from uav_tilt_tools.runner.fly import DURATION_S, check_mission, fly, jsonable
from uav_tilt_tools.runner.settings import parse_pairs
from uav_tilt_tools.runner.site_params import site_overrides

# Controller parameters that fly's own options set.
OPTION_OF = {'target_source': '--target-source', 'plan_file': '--plan'}


def _overrides(pairs: list[str] | None) -> dict[str, Any]:
    return parse_pairs('--set', pairs, OPTION_OF)


def _scenario_seed(text: str) -> int:
    """A seed in the range of a scenario's ``seed`` (argparse's error line when not)."""
    try:
        return check_value(Scenario, 'seed', cli_args.number(int, text))
    except ConfigError as err:
        raise argparse.ArgumentTypeError(str(err)) from None


def register(sub: 'argparse._SubParsersAction[Any]') -> None:
    """Add the `fly` sub-command."""
    parser = cli_args.add_command(
        sub, 'fly', 'one inspection mission in-process (JSON summary)',
        'One inspection mission (or plan) in one process, the same cores as the node graph;\n'
        'its summary as one JSON object on stdout, the flight\'s progress on stderr when it\n'
        'is a terminal. Exit 0 when the run met the inspection bar, 1 when not, 2 when an\n'
        'input was refused.')
    parser.add_argument('--scenario', type=cli_args.path, required=True,
                        help='scenario YAML; its keys: docs/scenario-schema.md')
    parser.add_argument('--target-source', choices=('vision', 'ground_truth'),
                        default='vision',
                        help="where the controller's target comes from: vision (the camera "
                             "and the deployed detector) or ground_truth (the truth, for "
                             "evaluation)")
    parser.add_argument('--seed', type=_scenario_seed, default=None,
                        help="overrides the scenario's seed (wind, noise, textures)")
    parser.add_argument('--hint', type=float, nargs=2, metavar=('U', 'V'), default=None,
                        help="roughly where the target is on the scenario's wall [m]")
    parser.add_argument('--plan', type=cli_args.path, default=None, metavar='FILE',
                        help='an inspection plan (YAML: touch and slide tasks; its keys: '
                             'docs/plan-schema.md)')
    parser.add_argument('--set', action='append', metavar='KEY=VALUE',
                        help='a controller parameter, e.g. mission.contact.hold_time_s=3, or '
                             "the vehicle's, e.g. vehicle.mass_kg=2.0 (the vehicle flown and "
                             "the controller's model of it) (the value is YAML; repeat for "
                             'more)')
    parser.add_argument('--record', default=None, metavar='DIR',
                        help='write the flight to DIR/recording.mcap, as the recorder writes a '
                             'run of the node graph (a rosbag2 bag `uav-tilt report DIR` '
                             'reads); a DIR that holds a recording is refused')
    parser.add_argument('--record-images', choices=images.PROFILES, default=None,
                        help='the camera images --record keeps: all, thin (the frames at the '
                             "detector's rate, 6 a second) or none (default none: the report "
                             'reads no image)')
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
        # the plan or the target, the settings, the world: one clear line when bad
        overrides = check_mission(scenario, overrides, args.plan)
        if args.record is not None:
            check_recording_folder(f'--record {args.record}', args.record)
        elif args.record_images is not None:
            raise ConfigError('--record-images goes with --record DIR')
    except (OSError, ConfigError) as err:
        print(f'uav-tilt fly: {err}', file=sys.stderr)
        return 2
    # the flight's progress on a terminal; none in a pipe (stdout is the JSON)
    progress = SimProgress('fly') if on_terminal() else None
    try:
        result = fly(scenario, args.target_source, overrides, args.duration,
                     record=args.record, record_images=args.record_images or 'none',
                     progress=progress)
    finally:
        if progress is not None:
            progress.close()
    print(json.dumps(result, default=jsonable))
    return 0 if result['failure'] is None else 1
