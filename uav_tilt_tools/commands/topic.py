"""`uav-tilt topic list | echo TOPIC | hz TOPIC`: what `ros2 topic` offers, without it
(:mod:`uav_tilt_tools.graph.topic_tool`).

Topic names are absolute or relative to /uav; ROS_DOMAIN_ID comes from the environment.
"""
import argparse
from typing import Any

from rclpy.exceptions import InvalidTopicNameException
from rclpy.validate_full_topic_name import validate_full_topic_name

from uav_tilt_common import cli_args
from uav_tilt_tools.graph import topic_tool, topics
from uav_tilt_tools.graph.topic_tool import MAX_SEQUENCE

TOPIC_HELP = 'topic name, absolute or relative to /uav (imu: /uav/imu)'


def register(sub: 'argparse._SubParsersAction[Any]') -> None:
    """Add the `topic` sub-command."""
    parser = cli_args.add_command(
        sub, 'topic', 'list, echo and measure topics of the running graph',
        'What `ros2 topic list | echo | hz` offers, without it. Topic names are absolute or\n'
        'relative to /uav; ROS_DOMAIN_ID comes from the environment.')
    verbs = parser.add_subparsers(dest='verb', required=True, metavar='VERB')
    listing = cli_args.add_command(verbs, 'list', 'topic names and types')
    listing.add_argument('--wait', type=cli_args.duration_s, default=3.0, metavar='S',
                         help='seconds of discovery at least (no daemon keeps the graph)')
    listing.add_argument('--timeout', type=cli_args.duration_s, default=10.0, metavar='S',
                         help='seconds of discovery at most, should the graph keep changing')
    listing.set_defaults(func=run_list, own_signals=True)
    echo = cli_args.add_command(verbs, 'echo', 'print messages as YAML (until Ctrl-C)')
    echo.add_argument('topic', type=topic_name, metavar='TOPIC', help=TOPIC_HELP)
    count = echo.add_mutually_exclusive_group()
    count.add_argument('--once', action='store_const', const=1, dest='n',
                       help='stop after the first message (-n 1)')
    count.add_argument('-n', type=cli_args.count, help='stop after N messages')
    length = echo.add_mutually_exclusive_group()
    length.add_argument('--truncate-length', '-l', type=cli_args.count, default=MAX_SEQUENCE,
                        metavar='N', help='print longer sequences as their length')
    length.add_argument('--full-length', '-f', action='store_const', const=None,
                        dest='truncate_length', help='print every sequence whole')
    echo.set_defaults(func=run_echo, own_signals=True)
    hz = cli_args.add_command(
        verbs, 'hz', 'message rate over a window of wall time',
        'The rate of a topic over a window of wall-clock time, and, when the graph runs on\n'
        'simulated time (/clock), the rate per second of simulated time as well.')
    hz.add_argument('topic', type=topic_name, metavar='TOPIC', help=TOPIC_HELP)
    hz.add_argument('--window', type=cli_args.duration_s, default=5.0, metavar='S',
                    help='wall-clock seconds to listen (Ctrl-C: the rate so far)')
    hz.set_defaults(func=run_hz, own_signals=True)
    for verb in (echo, hz):
        verb.add_argument('--timeout', type=cli_args.duration_s, default=10.0, metavar='S',
                          help='seconds to wait for TOPIC to appear')


def topic_name(text: str) -> str:
    """A topic name, absolute or relative to /uav, that ROS accepts."""
    try:
        validate_full_topic_name(topics.resolve(text))
    except InvalidTopicNameException as err:
        raise argparse.ArgumentTypeError(' '.join(str(err).split())) from None
    return text


def run_list(args: argparse.Namespace) -> int:
    """`topic list`: every topic's name and type."""
    return topic_tool.list_topics(args.wait, args.timeout)


def run_echo(args: argparse.Namespace) -> int:
    """`topic echo TOPIC`: its messages as YAML."""
    return topic_tool.echo(args.topic, args.n, args.truncate_length, args.timeout)


def run_hz(args: argparse.Namespace) -> int:
    """`topic hz TOPIC`: its rate over the window."""
    return topic_tool.hz(args.topic, args.window, args.timeout)
