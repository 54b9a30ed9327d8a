"""Config dataclasses as ROS 2 parameters, and the standard node main()."""
import signal
import sys

import rclpy
from rclpy.executors import ExternalShutdownException

from uav_tilt_common.config import ConfigError, from_dict, to_flat


def declare_config(node, cls):
    """Declare every field of config ``cls`` as a parameter and return the validated config.

    Raises ConfigError (one line naming the parameter, value and allowed range).
    """
    defaults = to_flat(cls())
    values = {}
    for name, default in defaults.items():
        # Empty lists cannot carry a parameter type; those fields are not ROS parameters.
        if isinstance(default, list) and not default:
            continue
        param = node.declare_parameter(name, default)
        values[name] = param.value
    return from_dict(cls, values)


def run_node(node_factory, args=None, spin=None):
    """Create the node, serve it with ``spin(node)`` (default ``rclpy.spin``, see
    :mod:`uav_tilt_common.spin`) and shut down cleanly (the ros2/demos pattern).

    A bad parameter ends the process with exit code 2 and one log line.
    """
    interrupted = note_sigint()
    rclpy.init(args=args)
    node = None
    code = 0
    try:
        node = node_factory()
        (spin or rclpy.spin)(node)
    except ConfigError as err:
        print(f'[FATAL] {err}', file=sys.stderr, flush=True)
        code = 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except RuntimeError:
        # A signal shuts the context down under the executor: a callback that publishes
        # then raises RCLError, a message take a pybind RuntimeError. Neither is an error.
        # The KeyboardInterrupt can also land inside a take before the context is down,
        # and pybind turns it into a RuntimeError too.
        if rclpy.ok() and not interrupted:
            raise
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return code


def note_sigint():
    """A list that gets the signal number when SIGINT arrives; the Python handler before
    still runs. Call before rclpy.init, whose signal handler then chains to this one."""
    seen, previous = [], signal.getsignal(signal.SIGINT)

    def handler(signum, frame):
        seen.append(signum)
        if callable(previous):
            previous(signum, frame)

    signal.signal(signal.SIGINT, handler)
    return seen
