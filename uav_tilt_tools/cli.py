"""The `uav-tilt` command line (DESIGN section 6).

Each sub-command lives in its own module exposing ``register(subparsers)``, which adds
its parser and sets ``func`` (args -> exit code).
"""
import argparse
import importlib
import sys

COMMAND_MODULES = (
    'uav_tilt_tools.bench',
    'uav_tilt_tools.campaign',
    'uav_tilt_tools.fly',
    'uav_tilt_vision.vision_cli',
    'uav_tilt_tools.report',
    'uav_tilt_tools.topic_cli',
)


def build_parser():
    """The argument parser with every sub-command."""
    parser = argparse.ArgumentParser(prog='uav-tilt', description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest='command', required=True)
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    return parser


def main(argv=None):
    """Entry point of `uav-tilt`."""
    args = build_parser().parse_args(argv)
    return args.func(args)


if __name__ == '__main__':
    sys.exit(main())
