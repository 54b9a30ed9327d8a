"""`uav-tilt topic list | echo TOPIC | hz TOPIC`: what `ros2 topic` offers, without it.

Topic names are absolute or relative to /uav; ROS_DOMAIN_ID comes from the environment.
"""
import argparse
import array
import signal
import time

import numpy as np

from uav_tilt_common import cli_args

# Sequences longer than this print as a count, as image data would flood the terminal
# (`ros2 topic echo`'s default --truncate-length): statuses (40 key-values) and covariances
# (36) show whole.
MAX_SEQUENCE = 128
# The exit code of a command Ctrl-C stopped before it had anything to show (128 + SIGINT).


def register(sub):
    """Add the `topic` sub-command."""
    parser = sub.add_parser('topic', help='list, echo and measure topics of the running graph')
    verbs = parser.add_subparsers(dest='verb', required=True)
    listing = verbs.add_parser('list', help='topic names and types')
    listing.add_argument('--wait', type=cli_args.duration_s, default=3.0,
                         help='seconds of discovery at least (no daemon keeps the graph)')
    listing.set_defaults(func=run_list, own_signals=True)
    echo = verbs.add_parser('echo', help='print messages as YAML')
    echo.add_argument('topic', type=topic_name)
    count = echo.add_mutually_exclusive_group()
    count.add_argument('--once', action='store_const', const=1, dest='n')
    count.add_argument('-n', type=cli_args.count, help='stop after N messages')
    length = echo.add_mutually_exclusive_group()
    length.add_argument('--truncate-length', '-l', type=cli_args.count, default=MAX_SEQUENCE,
                        metavar='N', help='print longer sequences as their length '
                                          f'(default {MAX_SEQUENCE})')
    length.add_argument('--full-length', '-f', action='store_const', const=None,
                        dest='truncate_length', help='print every sequence whole')
    echo.set_defaults(func=run_echo, own_signals=True)
    hz = verbs.add_parser('hz', help='message rate over a window of wall time')
    hz.add_argument('topic', type=topic_name)
    hz.add_argument('--window', type=cli_args.duration_s, default=5.0,
                    help='seconds to listen (Ctrl-C: the rate so far)')
    hz.set_defaults(func=run_hz, own_signals=True)
    for verb in (listing, echo, hz):
        verb.add_argument('--timeout', type=cli_args.duration_s, default=10.0,
                          help='seconds to wait for the topic to appear')


def topic_name(text):
    """A topic name, absolute or relative to /uav, that ROS accepts."""
    from rclpy.exceptions import InvalidTopicNameException
    from rclpy.validate_full_topic_name import validate_full_topic_name
    from uav_tilt_tools import topic_graph
    try:
        validate_full_topic_name(topic_graph.resolve(text))
    except InvalidTopicNameException as err:
        raise argparse.ArgumentTypeError(' '.join(str(err).split())) from None
    return text


# --- pure helpers -------------------------------------------------------------------------
def to_yaml(msg, indent=0, max_sequence=MAX_SEQUENCE):
    """YAML-ish text of a ROS message (what `ros2 topic echo` prints); a sequence longer
    than ``max_sequence`` (None: no limit) prints as its length."""
    pad = '  ' * indent
    lines = []
    for name, field_type in msg.get_fields_and_field_types().items():
        value = getattr(msg, name)
        if field_type == 'octet':       # rclpy holds a single byte as bytes of length 1
            value = value[0]
        if hasattr(value, 'get_fields_and_field_types'):
            lines.append(f'{pad}{name}:')
            lines.append(to_yaml(value, indent + 1, max_sequence))
        elif isinstance(value, (list, tuple, array.array, np.ndarray, bytes)):
            lines.append(f'{pad}{name}:' + _sequence(value, indent, max_sequence))
        else:
            lines.append(f'{pad}{name}: {value!r}' if isinstance(value, str)
                         else f'{pad}{name}: {value}')
    return '\n'.join(lines)


def _sequence(values, indent, max_sequence):
    if max_sequence is not None and len(values) > max_sequence:
        return f" '<sequence of {len(values)} values>'"
    if not len(values):
        return ' []'
    pad = '  ' * indent
    items = []
    for value in values:
        if hasattr(value, 'get_fields_and_field_types'):
            items.append(f'{pad}-\n' + to_yaml(value, indent + 1, max_sequence))
        else:
            items.append(f'{pad}- {value!r}' if isinstance(value, str) else f'{pad}- {value}')
    return '\n' + '\n'.join(items)


def rate_stats(times_s):
    """Average rate and min/max/std of the periods between arrival times, or None."""
    periods = np.diff(np.asarray(times_s, dtype=float))
    if not len(periods) or periods.mean() <= 0:
        return None
    return dict(rate_hz=1.0 / periods.mean(), min_s=periods.min(), max_s=periods.max(),
                std_s=periods.std(), window=len(periods))


# --- commands -----------------------------------------------------------------------------
class _Session:
    """rclpy context and a node, for one command (rclpy only when a topic verb runs).
    Ctrl-C ends its spin (``interrupted``) instead of raising wherever the command is."""

    def __enter__(self):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.signals import SignalHandlerOptions
        from uav_tilt_common.ros_params import STOP_SIGNALS, note_stop_signals
        self._handlers = {number: signal.getsignal(number) for number in STOP_SIGNALS}
        self.stop = note_stop_signals()
        rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
        self.rclpy = rclpy
        self.node = rclpy.create_node('uav_tilt_topic_cli')
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)
        return self

    def __exit__(self, *exc):
        self.executor.shutdown()
        self.node.destroy_node()
        self.rclpy.try_shutdown()
        for number, handler in self._handlers.items():
            signal.signal(number, handler)

    @property
    def interrupted(self):
        return self.stop.done()

    def spin_until(self, predicate, timeout_s):
        """Spin until predicate() holds, the time is up or Ctrl-C; returns predicate()."""
        deadline = time.monotonic() + timeout_s
        while not (predicate() or self.interrupted) and time.monotonic() < deadline \
                and self.rclpy.ok():
            self.executor.spin_once(timeout_sec=0.05)
        return predicate()

    def subscribe(self, topic, timeout_s, callback):
        """Wait for ``topic`` to appear, subscribe; returns its type or None if it never did."""
        from uav_tilt_tools import topic_graph
        name = topic_graph.resolve(topic)
        if not self.spin_until(lambda: name in topic_graph.topic_types(self.node), timeout_s):
            if not self.interrupted:
                print(f'topic {name} did not appear within {timeout_s} s')
            return None
        type_name = topic_graph.topic_types(self.node)[name]
        qos = topic_graph.subscription_qos(self.node, name, depth=100)
        self.node.create_subscription(topic_graph.message_class(type_name), name, callback, qos)
        return type_name


def run_list(args):
    """Print `name [type]` of every topic, once discovery has settled."""
    from uav_tilt_tools import topic_graph
    with _Session() as session:
        seen = {}
        start = time.monotonic()

        def settled():
            # Discovery is done when the graph has not changed for a second.
            current = topic_graph.topic_types(session.node)
            now = time.monotonic()
            if current != seen.get('topics'):
                seen.update(topics=current, since=now)
            return now - start >= args.wait and now - seen['since'] > 1.0
        session.spin_until(settled, args.timeout)
        for name, type_name in sorted(seen['topics'].items()):
            print(f'{name} [{type_name}]')
    return 0


def run_echo(args):
    """Print messages until N have come (or forever), separated by '---'."""
    printed = []

    def show(msg):
        if args.n is None or len(printed) < args.n:
            print(to_yaml(msg, max_sequence=args.truncate_length) + '\n---', flush=True)
            printed.append(1)
    with _Session() as session:
        if session.subscribe(args.topic, args.timeout, show) is None:
            return cli_args.INTERRUPTED if session.interrupted else 1
        session.spin_until(lambda: args.n is not None and len(printed) >= args.n,
                           float('inf'))
    return 0


def run_hz(args):
    """Listen ``--window`` seconds (or until Ctrl-C), then print the rate like `ros2 topic
    hz`."""
    arrivals = []
    with _Session() as session:
        if session.subscribe(args.topic, args.timeout,
                             lambda _: arrivals.append(time.monotonic())) is None:
            return cli_args.INTERRUPTED if session.interrupted else 1
        start = time.monotonic()
        session.spin_until(lambda: False, args.window)
        listened_s = time.monotonic() - start
    stats = rate_stats(arrivals)
    if stats is None:
        print(f'no rate: {len(arrivals)} messages in {listened_s:.1f} s')
        return 1
    print(f"average rate: {stats['rate_hz']:.3f}\n"
          f"\tmin: {stats['min_s']:.5f}s max: {stats['max_s']:.5f}s "
          f"std dev: {stats['std_s']:.5f}s window: {stats['window']}")
    return 0
