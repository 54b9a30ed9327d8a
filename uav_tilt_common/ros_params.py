"""Config dataclasses as ROS 2 parameters, and the standard node main()."""
import array
import math
import signal
import sys

import rclpy
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, \
    SetParametersResult
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.executors import ExternalShutdownException
from rclpy.parameter import Parameter

from uav_tilt_common import parent_watch
from uav_tilt_common.config import ConfigError, check_field, check_value, description, \
    fields_flat, from_dict, replace_flat

INT64 = (-2**63, 2**63 - 1)
_ARRAY_TYPES = {float: Parameter.Type.DOUBLE_ARRAY, int: Parameter.Type.INTEGER_ARRAY,
                str: Parameter.Type.STRING_ARRAY}


def declare_config(node, cls, dynamic=(), on_change=None):
    """Declare every field of config ``cls`` as a parameter with a descriptor (description,
    unit, range, choices) and return the validated config.

    ``dynamic`` names the parameters whose change at run time the node honours: a
    ``ros2 param set`` of one is validated like a start value, written into the returned
    config, and ``on_change({name: value})`` is called. Every other parameter is read-only,
    so a change is refused with the reason. Raises ConfigError: one line naming the
    parameter, its value and what is allowed (a wrong type included).
    """
    fields = fields_flat(cls)
    values = {}
    for name, (default, meta) in fields.items():
        declared = default
        if isinstance(default, list) and not default:
            # an empty list carries no type: the field says its items' (lists of config
            # dataclasses, like a scenario's objects, are no ROS parameters)
            declared = _ARRAY_TYPES.get(meta.get('items'))
            if declared is None:
                continue
        descriptor = parameter_descriptor(name, default, meta, read_only=name not in dynamic)
        try:
            value = _plain(node.declare_parameter(name, declared, descriptor).value)
            values[name] = default if value is None else value
        except (InvalidParameterTypeException, InvalidParameterValueException):
            raise ConfigError(_explain(node, name, default, meta)) from None
    cfg = from_dict(cls, values)
    if dynamic:
        _watch_changes(node, cls, cfg, set(dynamic), on_change)
    return cfg


def parameter_descriptor(name, default, meta, read_only=True):
    """The ParameterDescriptor of config field ``name`` (``ros2 param describe``)."""
    descriptor = ParameterDescriptor(name=name, description=description(name, meta),
                                     read_only=read_only)
    lo, hi = meta.get('lo'), meta.get('hi')
    if meta.get('choices') is not None:
        descriptor.additional_constraints = 'one of ' + ', '.join(
            repr(c) for c in meta['choices'])
    if (lo is None and hi is None) or isinstance(default, (bool, list)):
        return descriptor       # ranges of array elements are checked by the config
    if isinstance(default, int):
        descriptor.integer_range = [IntegerRange(
            from_value=INT64[0] if lo is None else int(lo),
            to_value=INT64[1] if hi is None else int(hi), step=0)]
    elif isinstance(default, float):
        descriptor.floating_point_range = [FloatingPointRange(
            from_value=-math.inf if lo is None else float(lo),
            to_value=math.inf if hi is None else float(hi), step=0.0)]
    return descriptor


_TYPE_WORDS = ((bool, 'true or false'), (int, 'an integer'),
               (float, 'a floating-point number (write 1.0, not 1)'), (str, 'a string'))


def _explain(node, name, default, meta):
    """The one line for a start value that rclpy refused (wrong type or out of range)."""
    # Declared again without a type, the parameter shows the value it was given.
    raw = _plain(node.declare_parameter(
        name, None, ParameterDescriptor(dynamic_typing=True)).value)
    try:
        check_field(name, raw, default, meta)
    except ConfigError as err:
        return str(err)
    sample = default[0] if isinstance(default, list) and default else default
    wanted = next(word for kind, word in _TYPE_WORDS if isinstance(sample, kind))
    if isinstance(default, list):
        wanted = 'a list of ' + wanted.replace('an integer', 'integers').replace(
            'a floating-point number', 'floating-point numbers').replace('a string', 'strings')
    return f"parameter '{name}' = {raw!r} must be {wanted}"


def _watch_changes(node, cls, cfg, dynamic, on_change):
    """Validate run-time changes of ``dynamic`` parameters, then apply them to ``cfg``."""
    def validate(params):
        for p in params:
            if p.name in dynamic:
                try:
                    check_value(cls, p.name, _plain(p.value))
                except ConfigError as err:
                    return SetParametersResult(successful=False, reason=str(err))
        return SetParametersResult(successful=True)

    def apply(params):
        changed = {p.name: check_value(cls, p.name, _plain(p.value))
                   for p in params if p.name in dynamic}
        if changed:
            replace_flat(cfg, changed)
            node.get_logger().info('parameters changed: ' + ', '.join(
                f'{k}={v!r}' for k, v in changed.items()))
            if on_change is not None:
                on_change(changed)

    node.add_on_set_parameters_callback(validate)
    node.add_post_set_parameters_callback(apply)


def _plain(value):
    """A parameter value as config data (arrays as lists)."""
    return list(value) if isinstance(value, (array.array, tuple)) else value


def run_node(node_factory, args=None, spin=None):
    """Create the node, serve it with ``spin(node)`` (default ``rclpy.spin``, see
    :mod:`uav_tilt_common.ros_spin`) and shut down cleanly (the ros2/demos pattern).

    A bad parameter ends the process with exit code 2 and one log line. Started by
    scripts/launch.sh, the node also ends when the script does (:mod:`parent_watch`).
    """
    parent_watch.die_with_parent()
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
