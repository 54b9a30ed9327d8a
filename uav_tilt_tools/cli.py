"""The `uav-tilt` command line (DESIGN section 6)."""
import argparse
import json
import sys


def _bench(args):
    if args.what == 'sim':
        from uav_tilt_tools.bench_sim import bench_sim
        result = bench_sim(args.seconds)
    print(json.dumps(result))
    return 0


def build_parser():
    """The argument parser with every sub-command that exists."""
    parser = argparse.ArgumentParser(prog='uav-tilt', description=__doc__)
    sub = parser.add_subparsers(dest='command', required=True)
    bench = sub.add_parser('bench', help='speed measurements, one JSON object on stdout')
    bench.add_argument('what', choices=['sim'])
    bench.add_argument('--seconds', type=float, default=10.0,
                       help='simulated seconds per measurement')
    bench.set_defaults(func=_bench)
    return parser


def main(argv=None):
    """Entry point of `uav-tilt`."""
    args = build_parser().parse_args(argv)
    return args.func(args)


if __name__ == '__main__':
    sys.exit(main())
