"""Config dataclasses as ROS 2 parameters, and the standard node main()."""
import array
import difflib
import math
import os
import re
import signal
import sys
from typing import Any, Callable, Iterable, Mapping

import rclpy
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, \
    SetParametersResult
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.executors import ExternalShutdownException
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.signals import SignalHandlerOptions
from rclpy.task import Future

from uav_tilt_common import parent_watch
from uav_tilt_common.node_entry import STOP_SIGNALS
from uav_tilt_common.config import ConfigError, ConfigT, check_field, check_value, \
    description, fields_flat, from_dict, moved_to, read_yaml, replace_flat, unknown_message
from uav_tilt_common.ros_spin import spin_events

INT64 = (-2**63, 2**63 - 1)
_ARRAY_TYPES: dict[type | None, Parameter.Type] = {
    float: Parameter.Type.DOUBLE_ARRAY, int: Parameter.Type.INTEGER_ARRAY,
    str: Parameter.Type.STRING_ARRAY}


def declare_config(node: Node, cls: type[ConfigT], dynamic: Iterable[str] = (),
                   on_change: Callable[[dict[str, Any]], None] | None = None) -> ConfigT:
    """Declare every field of config ``cls`` as a parameter with a descriptor (description,
    unit, range, choices) and return the validated config.

    ``dynamic`` names the parameters whose change at run time the node honours: a
    ``ros2 param set`` of one is validated like a start value, written into the returned
    config, and ``on_change({name: value})`` is called. Every other parameter is read-only,
    so a change is refused with the reason. Raises ConfigError: one line naming the
    parameter, its value and what is allowed (a wrong type included), a parameter given that
    the node does not declare (:func:`check_overrides`), or a parameters file among the
    process's arguments that misses the node (:func:`check_params_files`).
    """
    fields = fields_flat(cls)
    values: dict[str, Any] = {}
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
    check_overrides(node, cls)
    check_params_files(node, params_files(sys.argv))
    return cfg


def parameter_descriptor(name: str, default: Any, meta: Mapping[str, Any],
                         read_only: bool = True) -> ParameterDescriptor:
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


def check_overrides(node: Node, cls: type | None = None) -> None:
    """ConfigError, one line, when a parameter given to the node (``-p``, a parameters file)
    is none it declares: rclpy would keep it unused, and a misspelt name would leave its
    parameter at the default without a word. A parameter of config ``cls`` that moved is
    named with its new place."""
    # rclpy has no public view of the overrides of parameters never declared
    given = getattr(node, '_parameter_overrides', {})
    unknown = sorted(name for name in given if not node.has_parameter(name))
    if not unknown:
        return
    more = f', and {len(unknown) - 1} more' if len(unknown) > 1 else ''
    if cls is not None and moved_to(cls, unknown[0]) is not None:
        raise ConfigError(f"{unknown_message(cls, unknown[0])} (node '{node.get_name()}'"
                          f"{more})")
    close = difflib.get_close_matches(unknown[0], list(node._parameters), n=1)
    hint = f" (did you mean '{close[0]}'?)" if close else ''
    raise ConfigError(f"unknown parameter '{unknown[0]}'{hint} of node "
                      f"'{node.get_name()}'{more}")


def params_files(argv: list[str]) -> list[str]:
    """The ``--params-file`` paths among the ROS arguments of ``argv``."""
    files, in_ros = [], False
    for i, arg in enumerate(argv):
        if arg == '--ros-args':
            in_ros = True
        elif arg == '--':
            in_ros = False
        elif in_ros and arg == '--params-file' and i + 1 < len(argv):
            files.append(argv[i + 1])
    return files


def section_applies(key: str, node_fqn: str) -> bool:
    """Whether rcl gives the node ``node_fqn`` ('/uav/plant') the parameters under ``key``
    of a parameters file: 'plant' is the node /plant only; '/**' is any namespace depth,
    '/*' one level (rclpy's own matching)."""
    pattern = key if key.startswith('/') else '/' + key
    pattern = re.escape(pattern).replace(r'/\*\*', '(/\\w+)*').replace(r'/\*', '(/\\w+)')
    return re.fullmatch(pattern, node_fqn) is not None


def check_params_files(node: Node, files: Iterable[str]) -> None:
    """ConfigError, one line, when a parameters file has a section named for this node that
    rcl does not apply to it: `plant:` is for a node /plant, so the node run in a namespace
    (/uav/plant) would take none of the file's values, and no misspelt name in it would be
    found. A file whose sections are all for other nodes is fine (one file for a graph)."""
    fqn, name = node.get_fully_qualified_name(), node.get_name()
    for path in files:
        sections = read_yaml(path)
        keys = [str(key) for key in sections] if isinstance(sections, dict) else []
        if any(section_applies(key, fqn) for key in keys):
            continue
        named = [key for key in keys if key.rstrip('/').rsplit('/', 1)[-1] == name]
        if named:
            raise ConfigError(f"parameters file {path}: section '{named[0]}' is not for node "
                              f"'{fqn}', so none of it applies; name the section '/**/{name}' "
                              f"(any namespace) or '{fqn}'")


# A file a refusal's line is added to, besides stderr: launch.sh names one per node, and
# repeats the line at its end, after every node's shutdown lines.
REFUSAL_FILE = 'UAV_TILT_REFUSAL_FILE'


def refuse(line: str) -> int:
    """Say why the node refuses to run (one line on stderr, and in the file that the
    environment's :data:`REFUSAL_FILE` names, if any); returns its exit code, 2."""
    print(f'[FATAL] {line}', file=sys.stderr, flush=True)
    path = os.environ.get(REFUSAL_FILE)
    if path:
        try:
            with open(path, 'a', encoding='utf-8') as stream:
                stream.write(line + '\n')
        except OSError:
            pass        # the line is on stderr all the same
    return 2


def run_node(node_factory: Callable[[], Node], args: list[str] | None = None) -> int:
    """Create the node, serve it (:func:`uav_tilt_common.ros_spin.spin_events`) until a
    stop signal, and shut down cleanly (the ros2/demos pattern).

    SIGINT and SIGTERM are this function's, not rclpy's: rclpy's handlers shut the context
    down at once, under whatever callback runs, whose next publish then raises and is
    logged by the executor as FATAL with its stack; here the spin ends between callbacks.
    A bad or unknown parameter ends the process with exit code 2 and one log line. Started by
    scripts/launch.sh, the node also ends when the script does (:mod:`parent_watch`).
    """
    parent_watch.die_with_parent()
    stop = note_stop_signals()
    try:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except _rclpy.RCLError as err:
        # a parameters file that is missing or no YAML: rcl's message, less its source lines
        return refuse(re.sub(r', at /[^,]*', '', str(err)))
    node = None
    code = 0
    try:
        node = node_factory()
        spin_events(node, stop)
    except ConfigError as err:
        code = refuse(str(err))
    except (KeyboardInterrupt, ExternalShutdownException):
        pass        # a handler set before ours raised, or the context was shut down
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return code


def note_stop_signals() -> Future:
    """A future done with the number of the first SIGINT or SIGTERM that arrives. A
    Python handler set before still runs, but for Python's default SIGINT one: its
    KeyboardInterrupt would land in whatever callback runs."""
    stop = Future()
    for number in STOP_SIGNALS:
        previous = signal.getsignal(number)

        def handler(signum, frame, previous=previous):
            if not stop.done():
                stop.set_result(signum)
            if callable(previous) and previous is not signal.default_int_handler:
                previous(signum, frame)

        signal.signal(number, handler)
    return stop
