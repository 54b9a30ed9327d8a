"""Serving a node's callbacks with rclpy's EventsExecutor (run_node's ``spin``).

rclpy's default SingleThreadedExecutor rebuilds its wait set in Python on every wake-up
(subscriptions, timers, the parameter services, guard conditions). Measured on a 2-core
machine with plant_node and controller_node in lockstep (CPU per 300 Hz tick, plant /
controller): SingleThreadedExecutor 1450-1620 / 1380-1840 us, a hand-held rcl wait-set
loop 1100-1170 / 1010-1110 us, EventsExecutor 910-1040 / 800-910 us; real-time factor
1.1-1.4, 0.7-1.5 and 1.6-1.8.
"""
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from rclpy.node import Node
    from rclpy.task import Future

# How long a wait may block: the latency of noticing that the context was shut down.
WAIT_S = 0.1


def spin_events(node: 'Node', until: 'Future | None' = None) -> None:
    """Serve ``node`` with rclpy's EventsExecutor until the future ``until`` is done (a
    stop signal, between callbacks) or the context shuts down.

    In rclpy 7.1 ``EventsExecutor.spin()`` busy-waits (a core at 100% with nothing to do)
    and misses the shutdown; spin_once returns to Python after every callback. Bounded
    spins until a future that never completes do neither.
    """
    from rclpy.experimental import EventsExecutor
    from rclpy.task import Future
    executor = EventsExecutor(context=node.context)
    executor.add_node(node)
    until = Future() if until is None else until
    try:
        while node.context.ok() and not until.done():
            executor.spin_until_future_complete(until, timeout_sec=WAIT_S)
    finally:
        executor.shutdown()
