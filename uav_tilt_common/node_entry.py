"""The nodes' executables (setup.py console scripts; what launch.sh and `ros2 run` start).

Each handles the stop signals from its first instant: Ctrl-C or SIGTERM while the node still
imports its libraries (seconds: rclpy, PyBullet, torch) ends it at once with exit code 0 and
no traceback, as DESIGN section 3 says a node ends on them. Once imported, the node's own
``main`` (:func:`uav_tilt_common.ros_params.run_node`) takes them over.
"""
import importlib
import os
import signal

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


def _exit_quietly(signum: int, frame: object) -> None:
    # Nothing runs yet that would need shutting down. Not sys.exit: the handler may run inside
    # an extension's import (torch's), where a raised SystemExit aborts the process (SIGABRT).
    os._exit(0)


def _run(module):
    previous = {number: signal.signal(number, _exit_quietly) for number in STOP_SIGNALS}
    main = importlib.import_module(module).main
    for number, handler in previous.items():
        signal.signal(number, handler)
    return main()


def plant():
    """plant_node."""
    return _run('uav_tilt_sim.plant_node')


def controller():
    """controller_node."""
    return _run('uav_tilt_control.controller_node')


def vision():
    """vision_node."""
    return _run('uav_tilt_vision.vision_node')


def recorder():
    """recorder_node."""
    return _run('uav_tilt_tools.bag.recorder_node')


def foxglove():
    """foxglove_bridge."""
    return _run('uav_tilt_tools.graph.foxglove_bridge')
