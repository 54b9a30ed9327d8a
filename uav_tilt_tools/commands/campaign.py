"""`uav-tilt campaign --n N --seed S`: the inspection mission over a randomised world
(:func:`uav_tilt_tools.campaign.run.campaign`), its JSON (DESIGN section 7) on stdout.

``--backend local`` spreads the runs over this machine's cores, ``--backend ray`` over a
Ray cluster; ``--out DIR`` keeps each run as it finishes, so that ``--resume`` continues an
interrupted campaign; with ``--plan FILE --scenario FILE`` each run flies the plan on the
scenario's wall and objects.
"""
import argparse
import json
import sys
from typing import Any

from uav_tilt_common import cli_args
from uav_tilt_common.cli_args import INTERRUPTED
from uav_tilt_common.config import ConfigError
from uav_tilt_control.controller_core import plan_of
from uav_tilt_sim.scenario import load_scenario
from uav_tilt_tools.campaign.ray_backend import CampaignError
from uav_tilt_tools.campaign.run import BACKENDS, Interrupted, campaign
from uav_tilt_tools.runner.fly import DURATION_S, check_mission, jsonable
from uav_tilt_tools.runner.settings import parse_pairs, split_settings

# Controller parameters that the campaign's own options set.
OPTION_OF = {'target_source': '--target-source', 'plan_file': '--plan'}


def register(sub: 'argparse._SubParsersAction[Any]') -> None:
    """Add the `campaign` sub-command."""
    parser = cli_args.add_command(
        sub, 'campaign', 'the mission over randomised scenarios (JSON)',
        'The inspection mission over N randomised worlds, in-process, spread over the cores;\n'
        'the success statistics as one JSON object on stdout (DESIGN section 7), progress\n'
        'on stderr when it is a terminal.')
    parser.add_argument('--n', type=cli_args.count, default=20,
                        help='runs, each in a world of its own')
    parser.add_argument('--seed', type=cli_args.seed, default=0,
                        help='campaign seed: run i flies world i of it, whatever the backend')
    parser.add_argument('--workers', type=cli_args.count, default=None,
                        help='runs at once (local) or CPUs of the local Ray (default: one per '
                             'core)')
    parser.add_argument('--backend', choices=BACKENDS, default='local',
                        help='local: a process pool on this machine; ray: one Ray task per '
                             'run (pip install uav_tilt[ray])')
    parser.add_argument('--address', default=None,
                        help="with --backend ray: join this cluster ('auto', HOST:6379)")
    parser.add_argument('--out', default=None, metavar='DIR',
                        help='write one JSON line per finished run to DIR/runs.jsonl')
    parser.add_argument('--resume', action='store_true',
                        help='skip the runs DIR/runs.jsonl already holds')
    parser.add_argument('--record', action='store_true',
                        help='one MCAP per run: DIR/run_NNNN/recording.mcap')
    parser.add_argument('--duration', type=cli_args.duration_s, default=None,
                        help=f'simulated seconds allowed per mission (default {DURATION_S:.0f}'
                             f' per task and the time it pushes beyond the default hold)')
    parser.add_argument('--plan', type=cli_args.path, default=None, metavar='FILE',
                        help='fly this inspection plan (needs --scenario) in every run')
    parser.add_argument('--scenario', type=cli_args.path, default=None, metavar='FILE',
                        help="with --plan: the scenario whose wall and objects it names")
    parser.add_argument('--target-source', choices=('ground_truth', 'vision'),
                        default='ground_truth',
                        help="where the controller's target comes from: ground_truth (the "
                             "truth) or vision (render the camera and run the deployed "
                             "detector)")
    parser.add_argument('--corners', action='store_true',
                        help='draw every range of the world at one of its ends')
    parser.add_argument('--structures', action='store_true',
                        help='draw worlds of structure kinds (wall, corner, pillar, pipe, '
                             'vertical_pipe, tank, mesh, pillar_between: a pillar in the '
                             "approach's way) in place of walls; the JSON gives success by "
                             'kind')
    parser.add_argument('--set', action='append', metavar='KEY=VALUE',
                        help="as fly's, in every run: a controller parameter or the vehicle's, "
                             "e.g. vehicle.mass_kg=2.0 (not site.*: each run's world has its "
                             "own)")
    parser.set_defaults(func=_run)


def _settings(args: argparse.Namespace) -> dict[str, Any]:
    """The runs' ``--set`` settings, checked with the plan on its scenario, or with the
    one-touch inspection on the vehicle (ConfigError when bad)."""
    settings = parse_pairs('--set', args.set, OPTION_OF)
    site = next((k for k in settings if k.split('.')[0] == 'site'), None)
    if site is not None:
        raise ConfigError(f"--set {site}: a campaign's site is each run's world's (its wall "
                          f"and target ids, and a hint where it has a look-alike)")
    if args.plan:
        check_mission(load_scenario(args.scenario), settings, args.plan)
    else:
        plan_of(*split_settings(settings))
    return settings


def _run(args: argparse.Namespace) -> int:
    if bool(args.plan) != bool(args.scenario):
        print('uav-tilt campaign: --plan and --scenario go together', file=sys.stderr)
        return 2
    try:
        settings = _settings(args)
    except (OSError, ConfigError) as err:
        print(f'uav-tilt campaign: {err}', file=sys.stderr)
        return 2
    try:
        result = campaign(args.n, args.seed, args.workers, args.target_source, args.duration,
                          backend=args.backend, address=args.address, out=args.out,
                          resume=args.resume, record=args.record, plan_file=args.plan,
                          scenario_file=args.scenario, corners=args.corners, settings=settings,
                          structures=args.structures,
                          progress=sys.stderr.isatty())    # a bar on a terminal, none in pipes
    except ConfigError as err:
        print(f'uav-tilt campaign: {err}', file=sys.stderr)
        return 2
    except CampaignError as err:
        print(f'uav-tilt campaign: {err}', file=sys.stderr)
        return 1
    except Interrupted as err:
        print(f'uav-tilt campaign: {err}', file=sys.stderr)
        return INTERRUPTED
    print(json.dumps(result, default=jsonable))
    return 0 if result['n'] else 1
