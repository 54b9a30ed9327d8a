"""What `ros2 topic list | echo | hz` offers, without it (`uav-tilt topic`): each prints
what it found and returns the command's exit code.

Topic names are absolute or relative to /uav; ROS_DOMAIN_ID comes from the environment.
"""
import array
import difflib
import os
import signal
import struct
import time
from typing import Any, Callable, Iterable

import numpy as np
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.signals import SignalHandlerOptions

from uav_tilt_common import cli_args
from uav_tilt_common.names import CLOCK
from uav_tilt_common.ros_params import STOP_SIGNALS, note_stop_signals
from uav_tilt_tools.graph import topics

# A monitor gives way to the graph it watches: on a machine with no core to spare the
# lockstep loop keeps its CPU, and the monitor drops what it cannot take (best effort).
MONITOR_NICENESS = 10
HZ_DEPTH = 1000
# Sequences longer than this print as a count, as image data would flood the terminal
# (`ros2 topic echo`'s default --truncate-length): statuses (40 key-values) and covariances
# (36) show whole.
MAX_SEQUENCE = 128


# --- pure helpers -------------------------------------------------------------------------
def to_yaml(msg: Any, indent: int = 0, max_sequence: int | None = MAX_SEQUENCE) -> str:
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


def _sequence(values: Any, indent: int, max_sequence: int | None) -> str:
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


def rate_stats(times_s: list[float]) -> dict[str, float] | None:
    """Average rate and min/max/std of the periods between arrival times, or None."""
    periods = np.diff(np.asarray(times_s, dtype=float))
    if not len(periods) or periods.mean() <= 0:
        return None
    return dict(rate_hz=1.0 / periods.mean(), min_s=periods.min(), max_s=periods.max(),
                std_s=periods.std(), window=len(periods))


def not_appeared(name: str, timeout_s: float, known: Iterable[str]) -> str:
    """The line for a topic that did not appear: with the graph's topic nearest its name
    when one is close (a misspelt name)."""
    close = difflib.get_close_matches(name, sorted(known), n=1)
    hint = f' (did you mean {close[0]}?)' if close else ''
    return f'topic {name} did not appear within {timeout_s} s{hint}'


def rate_lines(arrivals_s: list[float], stamps_s: list[float], sim_clock: bool
               ) -> list[str] | None:
    """What `topic hz` prints: the rate on the wall clock (``arrivals_s``, when the
    messages came) like `ros2 topic hz`, then, when the messages carry header stamps that
    advance (``stamps_s``), the rate per second of those: of sim time when the graph has a
    /clock (``sim_clock``; the rates the docs give), which is the wall clock's times the
    real-time factor. None without two messages."""
    stats = rate_stats(arrivals_s)
    if stats is None:
        return None
    lines = [f"average rate: {stats['rate_hz']:.3f} Hz (wall clock)",
             f"\tmin: {stats['min_s']:.5f}s max: {stats['max_s']:.5f}s "
             f"std dev: {stats['std_s']:.5f}s window: {stats['window']}"]
    span_s = max(stamps_s) - min(stamps_s) if len(stamps_s) > 1 else 0.0
    clock = 'sim time' if sim_clock else 'the header stamps'
    if span_s > 0.0:
        lines.append(f'rate per second of {clock}: {(len(stamps_s) - 1) / span_s:.3f} Hz '
                     f'(header stamps over {span_s:.3f} s)')
    else:
        lines.append('no rate per second of sim time: the messages carry no advancing '
                     'header stamp')
    return lines


def starts_with_header(message_class: Any) -> bool:
    """Whether messages of ``message_class`` begin with a std_msgs/Header."""
    fields = list(message_class.get_fields_and_field_types().items())
    return bool(fields) and fields[0] == ('header', 'std_msgs/Header')


def cdr_header_stamp_s(data: bytes) -> float | None:
    """The header stamp (seconds) of a serialized message that begins with a
    std_msgs/Header, read from its CDR bytes without deserializing the rest (its
    encapsulation, then int32 sec and uint32 nanosec); None when too short or of an
    unknown encapsulation."""
    if len(data) < 12 or data[1] not in (0, 1):
        return None
    sec, nanosec = struct.unpack_from('<iI' if data[1] == 1 else '>iI', data, 4)
    return sec + nanosec * 1e-9


# --- the verbs -----------------------------------------------------------------------------
class _Session:
    """rclpy context and a node, for one command. Ctrl-C ends its spin (``interrupted``)
    instead of raising wherever the command is."""

    def __enter__(self) -> '_Session':
        os.nice(MONITOR_NICENESS)
        self._handlers = {number: signal.getsignal(number) for number in STOP_SIGNALS}
        self.stop = note_stop_signals()
        rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node('uav_tilt_topic_cli')
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)
        return self

    def __exit__(self, *exc: object) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown()
        for number, handler in self._handlers.items():
            signal.signal(number, handler)

    @property
    def interrupted(self) -> bool:
        return self.stop.done()

    def spin_until(self, predicate: Callable[[], bool], timeout_s: float) -> bool:
        """Spin until predicate() holds, the time is up or Ctrl-C; returns predicate()."""
        deadline = time.monotonic() + timeout_s
        while not (predicate() or self.interrupted) and time.monotonic() < deadline \
                and rclpy.ok():
            self.executor.spin_once(timeout_sec=0.05)
        return predicate()

    def subscribe(self, topic: str, timeout_s: float, callback: Callable[[Any], None],
                  raw: bool = False, depth: int = 100) -> str | None:
        """Wait for ``topic`` to appear, subscribe as a monitor (:func:`topics.monitor_qos`,
        keeping ``depth`` messages; ``raw``: the callback takes the serialized bytes);
        returns its type or None if it never did."""
        name = topics.resolve(topic)
        if not self.spin_until(lambda: name in topics.topic_types(self.node), timeout_s):
            if not self.interrupted:
                print(not_appeared(name, timeout_s, topics.topic_types(self.node)))
            return None
        type_name = topics.topic_types(self.node)[name]
        qos = topics.monitor_qos(self.node, name, depth)
        self.node.create_subscription(topics.message_class(type_name), name, callback, qos,
                                      raw=raw)
        return type_name


def list_topics(wait_s: float, timeout_s: float) -> int:
    """Print `name [type]` of every topic, once discovery has settled (at least ``wait_s``,
    at most ``timeout_s``)."""
    with _Session() as session:
        seen: dict[str, Any] = {}
        start = time.monotonic()

        def settled() -> bool:
            # Discovery is done when the graph has not changed for a second.
            current = topics.topic_types(session.node)
            now = time.monotonic()
            if current != seen.get('topics'):
                seen.update(topics=current, since=now)
            return now - start >= wait_s and now - seen['since'] > 1.0
        session.spin_until(settled, timeout_s)
        for name, type_name in sorted(seen['topics'].items()):
            print(f'{name} [{type_name}]')
    return 0


def echo(topic: str, n: int | None, max_sequence: int | None, timeout_s: float) -> int:
    """Print messages of ``topic`` until ``n`` have come (None: until Ctrl-C), separated by
    '---', sequences longer than ``max_sequence`` as their length (:func:`to_yaml`)."""
    printed: list[int] = []

    def show(msg: Any) -> None:
        if n is None or len(printed) < n:
            print(to_yaml(msg, max_sequence=max_sequence) + '\n---', flush=True)
            printed.append(1)
    with _Session() as session:
        if session.subscribe(topic, timeout_s, show) is None:
            return cli_args.INTERRUPTED if session.interrupted else 1
        session.spin_until(lambda: n is not None and len(printed) >= n, float('inf'))
    return 0


def hz(topic: str, window_s: float, timeout_s: float) -> int:
    """Listen to ``topic`` for ``window_s`` seconds of wall time (or until Ctrl-C), then
    print its rate like `ros2 topic hz`, and the rate per second of its header stamps
    (:func:`rate_lines`)."""
    arrivals: list[float] = []
    stamps: list[float] = []
    with_header = False     # known once subscribed, before any message is taken

    def heard(data: bytes) -> None:
        # serialized: a 300 Hz topic is not deserialized only to be counted
        arrivals.append(time.monotonic())
        stamp = cdr_header_stamp_s(data) if with_header else None
        if stamp is not None:
            stamps.append(stamp)
    with _Session() as session:
        # seconds of a 300 Hz topic: a monitor that waits for a core drops none of them
        type_name = session.subscribe(topic, timeout_s, heard, raw=True, depth=HZ_DEPTH)
        if type_name is None:
            return cli_args.INTERRUPTED if session.interrupted else 1
        with_header = starts_with_header(topics.message_class(type_name))
        start = time.monotonic()
        session.spin_until(lambda: False, window_s)
        listened_s = time.monotonic() - start
        sim_clock = CLOCK in topics.topic_types(session.node)
    lines = rate_lines(arrivals, stamps, sim_clock)
    if lines is None:
        print(f'no rate: {len(arrivals)} messages in {listened_s:.1f} s of wall clock')
        return 1
    print('\n'.join(lines))
    return 0
