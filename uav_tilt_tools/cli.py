"""The `uav-tilt` command line (DESIGN section 6).

Each sub-command lives in its own module exposing ``register(subparsers)``, which adds
its parser (``cli_args.add_command``: every option's help shows its default) and sets
``func`` (args -> exit code); a command that parses its own arguments sets ``full_parser``,
a function returning that parser, so that its help can be checked as the others'. This
list is the only place that names them: nothing else imports a command module.
"""
import argparse
import importlib
import signal
import sys
import types

from uav_tilt_common.cli_args import INTERRUPTED, HelpFormatter

COMMAND_MODULES = (
    'uav_tilt_tools.commands.bench',
    'uav_tilt_tools.commands.campaign',
    'uav_tilt_tools.commands.fly',
    'uav_tilt_vision.training.cli',
    'uav_tilt_tools.commands.report',
    'uav_tilt_tools.commands.topic',
)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every sub-command."""
    parser = argparse.ArgumentParser(
        prog='uav-tilt', formatter_class=HelpFormatter,
        description='The uav_tilt command line: fly, campaign, report, topic, bench, vision.',
        epilog="`uav-tilt COMMAND --help` shows a command's options and their defaults.")
    sub = parser.add_subparsers(dest='command', required=True, metavar='COMMAND')
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of `uav-tilt`. Ctrl-C, or SIGTERM (kill, timeout), ends a command with
    one line and exit code 130: what it started (worker processes, temporary folders, a
    graph) goes with it, which a process killed by the signal would leave behind."""
    args = build_parser().parse_args(argv)
    if not getattr(args, 'own_signals', False):     # `topic` stops its ROS session itself
        signal.signal(signal.SIGTERM, _interrupt)
    try:
        return args.func(args)
    except KeyboardInterrupt:
        print(f'uav-tilt {args.command}: interrupted', file=sys.stderr)
        return INTERRUPTED


def _interrupt(signum: int, frame: types.FrameType | None) -> None:
    raise KeyboardInterrupt


if __name__ == '__main__':
    sys.exit(main())
