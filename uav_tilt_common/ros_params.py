"""Config dataclasses as ROS 2 parameters, and the standard node main()."""
import signal
import sys

import rclpy
from rclpy.exceptions import InvalidParameterTypeException
from rclpy.executors import ExternalShutdownException
from rclpy.parameter import Parameter

from uav_tilt_common.config import ConfigError, flat_fields, from_dict

# The parameter type of an empty list field, by its items (uav_tilt_common.config.param).
_ARRAY_TYPES = {float: Parameter.Type.DOUBLE_ARRAY, str: Parameter.Type.STRING_ARRAY}


def declare_config(node, cls):
    """Declare every field of config ``cls`` as a parameter and return the validated config.

    Raises ConfigError (one line naming the parameter, value and allowed range).
    """
    values = {}
    for name, default, meta in flat_fields(cls):
        try:
            if isinstance(default, list) and not default:
                # an empty list has no type of its own: the field's items give it one,
                # and the parameter is declared typed, without a value
                kind = _ARRAY_TYPES.get(meta.get('items'))
                if kind is None or meta.get('item_length') is not None:
                    continue
                value = node.declare_parameter(name, kind).value
                if value is not None:
                    values[name] = list(value)
                continue
            values[name] = node.declare_parameter(name, default).value
        except InvalidParameterTypeException as err:
            raise ConfigError(f"parameter '{name}': {err}") from None
    return from_dict(cls, values)


def run_node(node_factory, args=None):
    """Create the node, spin it, and shut down cleanly (the ros2/demos pattern).

    A bad parameter ends the process with exit code 2 and one log line.
    """
    interrupted = note_sigint()
    rclpy.init(args=args)
    node = None
    code = 0
    try:
        node = node_factory()
        rclpy.spin(node)
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
