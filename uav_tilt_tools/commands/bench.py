"""`uav-tilt bench sim|control|vision|graph|campaign|campaign_vision|gym|slide`: one JSON
object on stdout (DESIGN section 7; :mod:`uav_tilt_tools.bench`)."""
import argparse
import json
from typing import Any

from uav_tilt_common import cli_args
from uav_tilt_tools.bench.suite import BENCHES, run_bench


def register(sub: 'argparse._SubParsersAction[Any]') -> None:
    """Add the `bench` sub-command."""
    parser = cli_args.add_command(sub, 'bench', 'speed measurements, one JSON object on stdout')
    parser.add_argument('what', choices=sorted(BENCHES), help='what to measure')
    parser.add_argument('--seconds', type=cli_args.duration_s, default=None,
                        help='length of each measurement (default: 30 s control, 20 s of '
                             'simulated time graph, the whole mission campaign*, else 10 s; '
                             'slide flies whole slides)')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run one bench in a ROS domain of its own and print its JSON."""
    print(json.dumps(run_bench(args.what, args.seconds)))
    return 0
