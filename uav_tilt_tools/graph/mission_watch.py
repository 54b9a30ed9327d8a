"""Wait for the controller's mission to end and exit with its result (used by launch.sh).

Watches `controller/status`: the mission has started once the mode leaves IDLE and ended
when it is back in IDLE, or when an IDLE status says how its tasks went (a mission that
ended before the watcher heard it fly: a failsafe right after the start); the exit code is
0 when the status then says ``success``, else 1. On the way it prints the mission's log on
stdout (:mod:`.mission_log`: a line per mode change, task and failsafe, with sim time), and
at the end the verdict with the numbers the status has.
"""
from typing import Any

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.executors import ExternalShutdownException

from uav_tilt_common import cli_args, names, parent_watch, ros_msgs, ros_qos
from uav_tilt_common.modes import NOT_FLYING, Mode
from uav_tilt_tools.graph.mission_log import MissionLog

# Each line of the log starts so: launch.sh's own lines start with [launch].
PREFIX = '[mission]'


class MissionWatch:
    """Follows a stream of controller status dicts; ``result`` is None until the end."""

    def __init__(self) -> None:
        self.started = False
        self.result: bool | None = None
        self.mode: Any = None

    def update(self, values: dict[str, Any]) -> None:
        """Feed one status (key -> decoded value, :func:`ros_msgs.diagnostics_values`)."""
        self.mode = values.get('mode', self.mode)
        if self.mode not in NOT_FLYING:
            self.started = True
        elif self.mode == Mode.IDLE and self.result is None and (
                self.started or values.get('task_outcomes')):
            self.result = values.get('success') is True


def main(args: list[str] | None = None) -> int:
    """Exit 0 when the mission succeeded, 1 when it failed, 130 when interrupted first."""
    parent_watch.die_with_parent()
    rclpy.init(args=args)
    node = rclpy.create_node('mission_watch')
    watch = MissionWatch()
    log = MissionLog()

    def on_status(msg: Any) -> None:
        values = ros_msgs.diagnostics_values(msg)
        say(log.update(values))
        watch.update(values)

    node.create_subscription(DiagnosticArray, names.CONTROLLER_STATUS, on_status,
                             ros_qos.STATUS)
    code = cli_args.INTERRUPTED
    try:
        while watch.result is None and rclpy.ok():
            rclpy.spin_once(node, timeout_sec=0.5)
        if watch.result is not None:
            code = 0 if watch.result else 1
            say([log.end(watch.result)])
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return code


def say(lines: list[str]) -> None:
    """Print log lines (stdout, at once: the user follows the mission by them)."""
    for line in lines:
        print(f'{PREFIX} {line}', flush=True)


if __name__ == '__main__':
    raise SystemExit(main())
