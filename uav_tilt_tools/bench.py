"""`uav-tilt bench sim|control|vision`: one JSON object on stdout (DESIGN section 7)."""
import importlib
import json

# what -> (module, function); each function takes the parsed args' seconds.
BENCHES = {
    'sim': ('uav_tilt_tools.bench_sim', 'bench_sim'),
}


def register(sub):
    """Add the `bench` sub-command."""
    parser = sub.add_parser('bench', help='speed measurements, one JSON object on stdout')
    parser.add_argument('what', choices=sorted(BENCHES))
    parser.add_argument('--seconds', type=float, default=10.0,
                        help='length of each measurement (simulated seconds for sim)')
    parser.set_defaults(func=run)


def run(args):
    """Run one bench and print its JSON."""
    module, function = BENCHES[args.what]
    result = getattr(importlib.import_module(module), function)(args.seconds)
    print(json.dumps(result))
    return 0
