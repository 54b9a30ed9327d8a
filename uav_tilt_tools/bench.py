"""`uav-tilt bench sim|control|vision|graph|campaign|campaign_vision|gym|slide`: one JSON
object on stdout (DESIGN section 7). ``slide`` is an accuracy bench
(uav_tilt_tools.bench_slide), not a speed one."""
import json
import os

from uav_tilt_common import cli_args


def _sim(seconds):
    from uav_tilt_tools.bench_sim import bench_sim
    return bench_sim(seconds)


def _control(seconds):
    from uav_tilt_tools.bench_control import bench_control
    return bench_control(duration_s=seconds)


def _vision(seconds):
    from uav_tilt_tools.bench_vision import bench_vision
    return bench_vision(seconds)


def _graph(seconds):
    from uav_tilt_tools.bench_graph import bench_graph
    return bench_graph(seconds)


def _campaign(seconds, target_source='ground_truth', runs_per_cpu=2):
    from uav_tilt_tools.bench_scale import bench_campaign
    return bench_campaign(target_source, (os.cpu_count() or 1) * runs_per_cpu, seconds)


def _campaign_vision(seconds):
    # a vision run costs minutes of CPU: one per core
    return _campaign(seconds, 'vision', runs_per_cpu=1)


def _gym(seconds):
    from uav_tilt_tools.bench_scale import bench_gym
    return bench_gym(seconds)


def _slide(seconds):
    from uav_tilt_tools.bench_slide import bench_slide
    return bench_slide()        # each case flies its whole slide: no length to choose


# Imported on demand: the sim bench need not load torch or the controller.
BENCHES = {'sim': _sim, 'control': _control, 'vision': _vision, 'graph': _graph,
           'campaign': _campaign, 'campaign_vision': _campaign_vision, 'gym': _gym,
           'slide': _slide}


def register(sub):
    """Add the `bench` sub-command."""
    parser = sub.add_parser('bench', help='speed measurements, one JSON object on stdout')
    parser.add_argument('what', choices=sorted(BENCHES))
    parser.add_argument('--seconds', type=cli_args.duration_s, default=None,
                        help='length of each measurement (default: 30 s control, 20 s of '
                             'simulated time graph, the whole mission campaign*, else 10 s; '
                             'slide flies whole slides)')
    parser.set_defaults(func=run)


def run(args):
    """Run one bench in a ROS domain of its own and print its JSON."""
    # Benches start node processes: keep them local and away from a running system.
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    os.environ.setdefault('ROS_DOMAIN_ID', str(100 + os.getpid() % 100))
    defaults = {'sim': 10.0, 'control': 30.0, 'vision': 10.0, 'graph': 20.0,
                'campaign': None, 'campaign_vision': None, 'gym': 10.0, 'slide': 0.0}
    seconds = args.seconds if args.seconds is not None else defaults[args.what]
    print(json.dumps(BENCHES[args.what](seconds)))
    return 0
